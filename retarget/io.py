"""Mesh files in and out: OBJ, PLY, OFF, GLB and GLTF.

Reading keeps the file's vertex order and count exactly (no merging of duplicate positions, no
removal of unreferenced vertices, no splitting at UV seams), because vertex i of one frame must be
vertex i of the next. PLY is read with trimesh (``process=False, maintain_order=True``). OBJ and OFF
are parsed here: trimesh splits an OBJ with several objects/groups/materials into parts that each
carry every vertex, needs an extra package for non-UTF-8 text, and mis-reads OFF polygons. Quads and
polygons are triangulated as fans. GLB/GLTF are read directly (pygltflib): every triangle
primitive of every mesh node of the default scene is concatenated in scene order (depth-first
over the scene's root nodes, children in file order, primitives in file order) with the node's world
transform applied — a multi-part head (face, eyes, teeth) comes in as one mesh whose parts follow
the file. Morph targets, skins and materials are ignored.

Every failure a user can cause (missing file, folder given, unknown extension, unreadable or
truncated file, empty mesh, NaN coordinates, point cloud, bad indices, frames that do not match)
raises :class:`RetargetError` with one line naming the file. Writes are atomic (temporary file in
the destination folder, then ``os.replace``), so an error never leaves a partial output behind, and
:func:`check_output` refuses an output that is one of the inputs.
"""
from __future__ import annotations

import base64
import glob as globmod
import os
import re
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .errors import RetargetError
from .mesh import Mesh, as_mesh, check_mesh, is_mesh_like

READ_FORMATS = (".obj", ".ply", ".off", ".glb", ".gltf")
WRITE_FORMATS = (".obj", ".ply")
MAX_VERTICES = 10_000_000  # larger meshes are refused unless force=True
# Rough peak memory per vertex of processing a mesh (bytes): parsing (the OBJ reader peaks at
# ~0.9 KiB/vertex, tracemalloc on a 164k-vertex sphere), the mesh, normals and canonical
# features (~0.2 KiB), per-vertex decoding of 128-wide codes in chunks and the outputs (~1 KiB).
BYTES_PER_VERTEX = 2048
_MIN_BYTES_PER_VERTEX = 8  # no format stores a vertex in fewer bytes ("v 0 0 0\n")
_AXES = {f"{s}{a}": (1.0 if s == "+" else -1.0) * np.eye(3)[i] for i, a in enumerate("xyz") for s in "+-"}


# ----------------------------------------------------------------------------------------- writing
@contextmanager
def atomic_output(path):
    """Write a file atomically: yields a temporary path in the destination folder, renamed onto
    ``path`` (os.replace) only if the block succeeds; on any error the temporary file is removed, so
    no partial output is left. Parent folders are created. The temporary name keeps the extension.

    Raises RetargetError naming ``path`` if the folder cannot be created or written, or ``path`` is a
    folder.
    """
    path = Path(path)
    if path.is_dir():
        raise RetargetError(f"{path}: is a folder, not an output file")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}")
    except OSError as e:
        raise RetargetError(f"{path}: cannot write to folder {path.parent} ({e.strerror or e})") from None
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 would make outputs private
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as e:
        raise RetargetError(f"{path}: cannot write ({e.strerror or e})") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def check_output(out_path, input_paths) -> None:
    """Raise RetargetError if ``out_path`` is (resolves to, or is a hard link of) any input file."""
    out = Path(out_path)
    for inp in input_paths:
        inp = Path(inp)
        same = out.resolve() == inp.resolve()
        if not same and out.exists() and inp.exists():
            same = os.path.samefile(out, inp)
        if same:
            raise RetargetError(f"{out}: refusing to overwrite the input file {inp}; choose another output")


def save_mesh(path, mesh_or_vertices, faces=None) -> None:
    """Write a mesh as OBJ (text, vertices with 9 decimals) or PLY (binary, float32), atomically.

    mesh_or_vertices: a mesh (anything :func:`retarget.mesh.as_mesh` takes: a Mesh, a
    trimesh.Trimesh, a (vertices, faces) pair), or (V,3) vertices with ``faces`` (F,3). Vertex order
    is kept. RetargetError for an unknown extension or an unwritable destination.
    """
    import trimesh

    path = Path(path)
    if path.suffix.lower() not in WRITE_FORMATS:
        raise RetargetError(f"{path}: cannot write {path.suffix or 'files without extension'}; "
                            f"use {', '.join(WRITE_FORMATS)}")
    if faces is None and is_mesh_like(mesh_or_vertices):
        mesh = as_mesh(mesh_or_vertices, role=str(path))
        verts, faces = mesh.vertices, mesh.faces
    else:
        verts = np.asarray(mesh_or_vertices, dtype=np.float64)
        faces = np.zeros((0, 3), np.int64) if faces is None else np.asarray(faces, dtype=np.int64)
    tm = trimesh.Trimesh(verts, faces, process=False, validate=False)
    with atomic_output(path) as tmp:
        if path.suffix.lower() == ".obj":
            tm.export(tmp, file_type="obj", include_normals=False, include_texture=False, digits=9)
        else:
            tm.export(tmp, file_type="ply", encoding="binary")


# ----------------------------------------------------------------------------------------- reading
def axis_rotation(up: str | None = None, forward: str | None = None) -> np.ndarray:
    """(3,3) rotation taking a mesh whose up/forward axes are ``up``/``forward`` (e.g. "+z", "-y")
    into the project frame (+y up, +z forward, right-handed). Apply as ``v @ R.T``; ``R.T`` maps
    back. A missing axis defaults to the project's (+y up, +z forward)."""
    names = {"up": up or "+y", "forward": forward or "+z"}
    for key, val in names.items():
        if val.lower() not in _AXES:
            raise RetargetError(f"--{key} {val!r}: expected one of {', '.join(_AXES)}")
    u, f = _AXES[names["up"].lower()], _AXES[names["forward"].lower()]
    if abs(u @ f) > 0:
        raise RetargetError(f"--up {names['up']} and --forward {names['forward']} must be different axes")
    return np.stack([np.cross(u, f), u, f])


def peek_vertex_count(path) -> int | None:
    """The vertex count from a file's header (PLY, OFF, GLB/GLTF) or by counting ``v`` lines (OBJ),
    without parsing the geometry; None if it cannot be told."""
    path = Path(path)
    ext = path.suffix.lower()
    try:
        if ext in (".ply", ".off"):
            with open(path, "rb") as fh:
                head = fh.read(4096).decode("latin-1")
            m = (re.search(r"element\s+vertex\s+(\d+)", head) if ext == ".ply"
                 else re.search(r"^\s*[A-Z]*OFF\s+(\d+)|^\s*(\d+)\s+\d+", re.sub(r"#.*", "", head), re.M))
            return int(next(g for g in m.groups() if g)) if m else None
        if ext == ".obj":
            count, prev = 0, b"\n"
            with open(path, "rb") as fh:
                while chunk := fh.read(1 << 24):
                    count += (prev + chunk).count(b"\nv ") + (prev + chunk).count(b"\nv\t")
                    prev = chunk[-1:]
            return count
        if ext in (".glb", ".gltf"):
            gltf = _load_gltf(path)
            return sum(gltf.accessors[p.attributes.POSITION].count
                       for m in gltf.meshes for p in m.primitives if p.attributes.POSITION is not None)
    except (OSError, RetargetError, StopIteration, IndexError, TypeError):
        return None
    return None


def estimate_memory(n_vertices: int) -> int:
    """Rough peak memory (bytes) of processing a mesh of ``n_vertices`` (see BYTES_PER_VERTEX)."""
    return int(n_vertices) * BYTES_PER_VERTEX


def check_vertex_budget(n_vertices: int, path, limit: int = MAX_VERTICES, force: bool = False) -> None:
    """RetargetError (stating the memory it would need) for a mesh above ``limit`` vertices,
    unless ``force``."""
    if n_vertices > limit and not force:
        raise RetargetError(
            f"{path}: {n_vertices:,} vertices is above the limit of {limit:,}; it would need about "
            f"{estimate_memory(n_vertices) / 2**30:.1f} GiB of memory (use --force to try anyway)"
        )


def load_mesh(path, up: str | None = None, forward: str | None = None, force: bool = False,
              max_vertices: int = MAX_VERTICES) -> Mesh:
    """Read and validate a triangle mesh.

    path: .obj, .ply, .off, .glb or .gltf. up/forward: the file's axes (e.g. up="+z", forward="-y")
    if they are not the project's +y up / +z forward; the mesh is rotated into the project frame.
    Meshes above ``max_vertices`` are refused before parsing unless ``force``.
    Returns Mesh(vertices (V,3) float64 in the file's units, faces (F,3) int64, name=str(path)).
    """
    path = Path(path)
    if not path.exists():
        raise RetargetError(f"{path}: no such file")
    if path.is_dir():
        raise RetargetError(f"{path}: is a folder, not a mesh file")
    ext = path.suffix.lower()
    if ext not in READ_FORMATS:
        raise RetargetError(f"{path}: unknown mesh format {ext or '(no extension)'}; "
                            f"expected {', '.join(READ_FORMATS)}")
    if path.stat().st_size >= _MIN_BYTES_PER_VERTEX * max_vertices:
        n = peek_vertex_count(path)
        if n is not None:
            check_vertex_budget(n, path, max_vertices, force)
    try:
        verts, faces = _READERS[ext](path)
    except RetargetError:
        raise
    except Exception as e:  # any parser failure on a user file is a user error
        reason = f"{type(e).__name__}: {e}".splitlines()[0]
        raise RetargetError(f"{path}: cannot read as {ext[1:].upper()} ({reason})") from None
    mesh = check_mesh(Mesh(verts, faces, name=str(path)), path)
    if up is not None or forward is not None:
        mesh = Mesh(mesh.vertices @ axis_rotation(up, forward).T, mesh.faces, mesh.name)
    return mesh


def _read_ply(path: Path):
    """PLY (ASCII or binary, trimesh) -> vertices (V,3), faces (F,3); point clouds give F=0."""
    import trimesh

    loaded = trimesh.load(str(path), process=False, maintain_order=True)
    verts = np.asarray(loaded.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)  # PointCloud: none
    return verts, faces.reshape(-1, 3)


def _read_text(path: Path) -> str:
    """A text mesh file as str: binary junk refused, UTF-8 or else Latin-1 (old exporters)."""
    data = path.read_bytes()
    if b"\0" in data:
        raise RetargetError(f"{path}: holds binary data, not a text {path.suffix[1:].upper()} file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _fan(polygons) -> np.ndarray:
    """Polygons (lists of vertex indices) -> (F,3) int64 triangles (v0, vk, vk+1)."""
    tris = [(p[0], p[k], p[k + 1]) for p in polygons for k in range(1, len(p) - 1)]
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


def _read_obj(path: Path):
    """OBJ -> vertices (V,3) in the order of the ``v`` lines, faces (F,3) in the order of the ``f``
    lines, whatever the objects, groups and materials (trimesh would split those into parts);
    ``a/b/c`` and negative (relative) indices accepted, polygons fanned, everything else ignored."""
    verts, polygons = [], []
    for raw in _read_text(path).splitlines():
        tok = raw.split()
        if not tok:
            continue
        if tok[0] == "v":
            if len(tok) < 4:
                raise ValueError(f"a vertex line has fewer than 3 coordinates: {raw.strip()!r}")
            verts.append(tok[1:4])
        elif tok[0] == "f":
            n = len(verts)
            idx = [int(t.split("/")[0]) for t in tok[1:]]
            polygons.append([i - 1 if i > 0 else n + i for i in idx])
    return np.array(verts, dtype=np.float64).reshape(-1, 3), _fan(polygons)


def _read_off(path: Path):
    """OFF (also COFF/NOFF/..., whose extra per-vertex values are ignored) -> vertices (V,3),
    faces (F,3); polygons fanned, comments (#) allowed. (trimesh mis-reads OFF polygons.)"""
    lines = [ln.split() for ln in (raw.split("#", 1)[0] for raw in _read_text(path).splitlines())
             if ln.strip()]
    if not lines or not lines[0][0].endswith("OFF"):
        raise ValueError("the file does not start with OFF")
    counts = lines[0][1:] or lines[1]
    start = 1 if lines[0][1:] else 2
    nv, nf = int(counts[0]), int(counts[1])
    verts = np.array([[float(x) for x in ln[:3]] for ln in lines[start:start + nv]], dtype=np.float64)
    if len(verts) != nv or nf > len(lines) - start - nv:
        raise ValueError(f"the header announces {nv} vertices and {nf} faces but the file is shorter")
    polygons = [[int(i) for i in ln[1:1 + int(ln[0])]] for ln in lines[start + nv:start + nv + nf]]
    return verts.reshape(-1, 3), _fan(polygons)


def _load_gltf(path: Path):
    import pygltflib

    gltf = pygltflib.GLTF2().load(str(path))
    if gltf is None:
        raise RetargetError(f"{path}: not a glTF file")
    return gltf


_GL_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_GL_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _gltf_buffers(gltf, path: Path) -> list[bytes]:
    """The bytes of every glTF buffer (GLB chunk, data URI or external file beside the file)."""
    out = []
    for buf in gltf.buffers:
        if buf.uri is None:
            out.append(gltf.binary_blob() or b"")
        elif buf.uri.startswith("data:"):
            out.append(base64.b64decode(buf.uri.split(",", 1)[1]))
        else:
            out.append((path.parent / buf.uri).read_bytes())
    return out


def _gltf_accessor(gltf, buffers, index: int, path: Path) -> np.ndarray:
    """Accessor ``index`` as an (count, width) array (normalised integers mapped to [−1, 1])."""
    acc = gltf.accessors[index]
    if acc.sparse is not None or acc.bufferView is None:
        raise RetargetError(f"{path}: accessor {index} is sparse or has no data (Draco-compressed?); "
                            "re-export without compression")
    dtype, width = np.dtype(_GL_DTYPES[acc.componentType]), _GL_WIDTH[acc.type]
    view = gltf.bufferViews[acc.bufferView]
    data = buffers[view.buffer]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    stride = view.byteStride or dtype.itemsize * width
    end = start + stride * (acc.count - 1) + dtype.itemsize * width if acc.count else start
    if end > len(data):
        raise RetargetError(f"{path}: truncated (accessor {index} needs {end} bytes, buffer has {len(data)})")
    arr = np.ndarray((acc.count, width), dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize))
    if acc.normalized and dtype.kind in "iu":
        return np.maximum(arr / np.iinfo(dtype).max, -1.0)
    return np.array(arr)


def _node_matrix(node) -> np.ndarray:
    """A glTF node's local 4x4 transform (matrix, or T·R·S)."""
    from scipy.spatial.transform import Rotation

    if node.matrix is not None:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    if node.scale is not None:
        m = np.diag([*node.scale, 1.0]) @ m
    if node.rotation is not None:
        r = np.eye(4)
        r[:3, :3] = Rotation.from_quat(node.rotation).as_matrix()  # glTF quaternions are x, y, z, w
        m = r @ m
    if node.translation is not None:
        m[:3, 3] += node.translation
    return m


def _read_gltf(path: Path):
    """GLB/GLTF -> vertices (V,3), faces (F,3): every triangle primitive of the default scene,
    concatenated depth-first in scene order with world transforms applied."""
    gltf = _load_gltf(path)
    buffers = _gltf_buffers(gltf, path)
    if gltf.scenes:
        roots = gltf.scenes[gltf.scene or 0].nodes or []
    else:  # no scene: every node that is nobody's child
        children = {c for n in gltf.nodes for c in (n.children or [])}
        roots = [i for i in range(len(gltf.nodes)) if i not in children]
    verts, faces, offset = [], [], 0
    stack = [(n, np.eye(4)) for n in reversed(roots)]
    while stack:
        index, parent = stack.pop()
        node = gltf.nodes[index]
        world = parent @ _node_matrix(node)
        stack.extend((c, world) for c in reversed(node.children or []))
        if node.mesh is None:
            continue
        for prim in gltf.meshes[node.mesh].primitives:
            if prim.mode not in (None, 4):
                raise RetargetError(f"{path}: primitive mode {prim.mode} is not triangles; triangulate on export")
            if prim.attributes.POSITION is None:
                continue
            p = _gltf_accessor(gltf, buffers, prim.attributes.POSITION, path).astype(np.float64)
            idx = (np.arange(len(p)) if prim.indices is None
                   else _gltf_accessor(gltf, buffers, prim.indices, path).ravel().astype(np.int64))
            if len(idx) % 3:
                raise RetargetError(f"{path}: a triangle primitive has {len(idx)} indices (not a multiple of 3)")
            verts.append(p @ world[:3, :3].T + world[:3, 3])
            faces.append(idx.reshape(-1, 3) + offset)
            offset += len(p)
    if not verts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return np.concatenate(verts), np.concatenate(faces)


_READERS = {".obj": _read_obj, ".ply": _read_ply, ".off": _read_off, ".glb": _read_gltf, ".gltf": _read_gltf}


def _natural_key(path: Path):
    """Sort key putting frame_2 before frame_10."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", str(path))]


def sequence_files(spec) -> list[Path]:
    """The mesh files of a sequence given as a folder (its mesh files), a glob pattern or one file,
    sorted naturally. RetargetError if nothing matches."""
    spec = str(spec)
    if os.path.isdir(spec):
        files = [p for p in Path(spec).iterdir() if p.is_file() and p.suffix.lower() in READ_FORMATS]
    elif globmod.has_magic(spec):
        files = [Path(p) for p in globmod.glob(spec) if os.path.isfile(p)]
    else:
        files = [Path(spec)]
    if not files:
        raise RetargetError(f"{spec}: no mesh files ({', '.join(READ_FORMATS)}) found")
    return sorted(files, key=_natural_key)


def load_sequence(spec, up: str | None = None, forward: str | None = None,
                  force: bool = False) -> list[Mesh]:
    """Read the frames of a sequence (folder, glob or single file; see :func:`sequence_files`).
    ``force``: read frames above the vertex limit anyway (see :func:`load_mesh`).

    All frames must share the first frame's vertex count and face array (RetargetError naming the
    first offending file). Shows a progress bar for long sequences on a terminal.
    """
    from tqdm import tqdm

    files = sequence_files(spec)
    frames = []
    for f in tqdm(files, desc="reading frames", unit="frame", disable=True if len(files) < 20 else None):
        mesh = load_mesh(f, up=up, forward=forward, force=force)
        if frames:
            first = frames[0]
            if mesh.n_vertices != first.n_vertices:
                raise RetargetError(f"{f}: has {mesh.n_vertices} vertices but {first.name} has "
                                    f"{first.n_vertices}; all frames of a sequence must match")
            if not np.array_equal(mesh.faces, first.faces):
                raise RetargetError(f"{f}: its faces differ from those of {first.name}; "
                                    "all frames must share one topology")
            mesh = Mesh(mesh.vertices, first.faces, mesh.name)  # share one face array
        frames.append(mesh)
    return frames
