"""GLB export: a blendshape rig (one mesh, K named morph targets, optional weight animation).

The file holds one node, one mesh and one triangle primitive: POSITION (neutral), NORMAL (of the
neutral, optional), indices, and K morph targets each a POSITION displacement accessor; target names
are in ``mesh.extras.targetNames`` (read by Blender, three.js and Babylon), default weights 0. An
optional animation drives the node's morph weights: sampler input = time in seconds, output = T·K
weights, channel path "weights". Every accessor carries min and max. Units are those of the arrays
given (the pipeline passes the target mesh's own units); glTF viewers assume metres, +y up, +z
forward, which is the project frame.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import RetargetError
from .io import atomic_output, check_fps
from .mesh import vertex_normals

_FLOAT, _UINT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


class _BinaryBuilder:
    """Accumulates accessors (each with its own bufferView) into one binary buffer."""

    def __init__(self, gltf):
        self.gltf = gltf
        self.chunks: list[bytes] = []
        self.length = 0

    def add(self, array: np.ndarray, kind: str, target: int | None = None) -> int:
        """Append ``array`` ((n,) or (n,c), float32 or uint32) as an accessor of type ``kind``
        ("SCALAR", "VEC3"); returns the accessor index."""
        import pygltflib

        data = np.ascontiguousarray(array)
        raw = data.astype("<f4" if data.dtype.kind == "f" else "<u4").tobytes()
        self.gltf.bufferViews.append(pygltflib.BufferView(
            buffer=0, byteOffset=self.length, byteLength=len(raw), target=target))
        flat = data.reshape(len(data), -1)
        cast = float if data.dtype.kind == "f" else int
        self.gltf.accessors.append(pygltflib.Accessor(
            bufferView=len(self.gltf.bufferViews) - 1, componentType=_FLOAT if data.dtype.kind == "f" else _UINT,
            count=len(data), type=kind,
            min=[cast(x) for x in flat.min(axis=0)], max=[cast(x) for x in flat.max(axis=0)]))
        pad = (-len(raw)) % 4
        self.chunks.append(raw + b"\0" * pad)
        self.length += len(raw) + pad
        return len(self.gltf.accessors) - 1

    def blob(self) -> bytes:
        return b"".join(self.chunks)


def rig_arrays(neutral, faces, deltas, names, what: str = "shapes"):
    """A rig's arrays checked and typed for writing: neutral (V,3) float32, faces (F,3) int64,
    deltas (K,V,3) float32, names [K] str. ValueError for mismatched shapes or face indices."""
    neutral = np.asarray(neutral, dtype=np.float32).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    deltas = np.asarray(deltas, dtype=np.float32)
    names = [str(n) for n in names]
    if deltas.ndim != 3 or deltas.shape[1:] != neutral.shape:
        raise ValueError(f"deltas must be (K,{len(neutral)},3), got {deltas.shape}")
    if len(names) != len(deltas):
        raise ValueError(f"{len(deltas)} {what} but {len(names)} names")
    if faces.size and (faces.min() < 0 or faces.max() >= len(neutral)):
        raise ValueError("face index out of range")
    return neutral, faces, deltas, names


def write_rig_glb(path, neutral, faces, deltas, names, animation=None, fps: float = 30.0,
                  normals: bool = True, interpolation: str = "LINEAR") -> None:
    """Write a morph-target rig as GLB, atomically.

    neutral (V,3), faces (F,3), deltas (K,V,3) displacements of each shape (same units as neutral),
    names (K,) target names. animation: optional (T,K) weights, frame t at time t/fps seconds,
    interpolated with ``interpolation`` ("LINEAR" or "STEP"). normals: store the neutral's vertex
    normals.
    """
    import pygltflib

    neutral, faces, deltas, names = rig_arrays(neutral, faces, deltas, names, "morph targets")

    gltf = pygltflib.GLTF2(asset=pygltflib.Asset(generator="retarget", version="2.0"))
    b = _BinaryBuilder(gltf)
    attributes = pygltflib.Attributes(POSITION=b.add(neutral, "VEC3", _ARRAY_BUFFER))
    if normals:
        attributes.NORMAL = b.add(vertex_normals(neutral, faces).astype(np.float32), "VEC3", _ARRAY_BUFFER)
    indices = b.add(faces.astype(np.uint32).ravel(), "SCALAR", _ELEMENT_ARRAY_BUFFER)
    targets = [pygltflib.Attributes(POSITION=b.add(d, "VEC3", _ARRAY_BUFFER)) for d in deltas]
    primitive = pygltflib.Primitive(attributes=attributes, indices=indices, mode=4, targets=targets or None)
    gltf.meshes.append(pygltflib.Mesh(primitives=[primitive], weights=[0.0] * len(names) or None,
                                      extras={"targetNames": names}))
    gltf.nodes.append(pygltflib.Node(mesh=0, name=Path(path).stem))
    gltf.scenes.append(pygltflib.Scene(nodes=[0]))
    gltf.scene = 0
    if animation is not None:
        w = np.asarray(animation, dtype=np.float32)
        if w.ndim != 2 or w.shape[1] != len(names):
            raise ValueError(f"animation must be (T,{len(names)}) weights, got {w.shape}")
        times = np.arange(len(w), dtype=np.float32) / np.float32(check_fps(fps))
        sampler = pygltflib.AnimationSampler(input=b.add(times, "SCALAR"), output=b.add(w.ravel(), "SCALAR"),
                                             interpolation=interpolation)
        channel = pygltflib.AnimationChannel(sampler=0, target=pygltflib.AnimationChannelTarget(node=0, path="weights"))
        gltf.animations.append(pygltflib.Animation(name="weights", samplers=[sampler], channels=[channel]))
    blob = b.blob()
    gltf.buffers.append(pygltflib.Buffer(byteLength=len(blob)))
    gltf.set_binary_blob(blob)
    with atomic_output(path) as tmp:
        gltf.save_binary(tmp)


def write_sequence_glb(path, frames, faces, fps: float = 30.0) -> None:
    """Write a vertex animation (T,V,3) as GLB: frame 0 is the base mesh, every frame t is a morph
    target (frames[t] − frames[0], named ``frame_0000``...) switched on alone at t/fps with STEP
    interpolation. Exact, and it plays in any glTF viewer, but heavy: about 12·T·V bytes of targets
    plus 4·T² bytes of weights (300 frames of a 10k-vertex head ≈ 36 MB). To keep a rig editable,
    prefer :func:`write_rig_glb` with 53 shapes and a (T,53) weight animation (12·53·V bytes)."""
    frames = np.asarray(frames, dtype=np.float32)
    if frames.ndim != 3 or frames.shape[2] != 3:
        raise ValueError(f"frames must be (T,V,3), got {frames.shape}")
    n = len(frames)
    write_rig_glb(path, frames[0], faces, frames - frames[0], [f"frame_{t:04d}" for t in range(n)],
                  animation=np.eye(n, dtype=np.float32), fps=fps, interpolation="STEP")


def read_glb_morph_names(path) -> list[str]:
    """The morph target names of a GLB's first mesh (``mesh.extras.targetNames``)."""
    import pygltflib

    path = Path(path)
    if not path.is_file():
        raise RetargetError(f"{path}: no such file")
    try:
        gltf = pygltflib.GLTF2().load(str(path))
    except Exception as e:  # any parser failure on a user file is a user error
        raise RetargetError(f"{path}: cannot read as GLB ({e})".splitlines()[0]) from None
    if gltf is None or not gltf.meshes:
        raise RetargetError(f"{path}: holds no mesh")
    extras = gltf.meshes[0].extras or {}
    return list(extras.get("targetNames", []))
