"""GLB rig export: structure, accessor bounds, morph data, animation, reload with pygltflib/trimesh."""
import os
from pathlib import Path

import numpy as np
import pygltflib
import pytest
import trimesh

from retarget.errors import RetargetError
from retarget.glb import read_glb_morph_names, write_rig_glb, write_sequence_glb

COMPONENTS = {"SCALAR": 1, "VEC3": 3}


@pytest.fixture(scope="module")
def rig():
    s = trimesh.creation.icosphere(subdivisions=1)
    v = np.asarray(s.vertices) * 8.0
    rng = np.random.default_rng(0)
    deltas = rng.normal(0, 0.5, (3, len(v), 3))
    deltas[1] = 0.0  # a shape that moves nothing still needs valid bounds
    anim = rng.uniform(0, 1, (12, 3))
    return v, np.asarray(s.faces), deltas, ["jawOpen", "eyeBlink_L", "mouthSmile_R"], anim


def accessor_array(gltf, index):
    """Independent reader: accessor -> (count, width) float64 from the GLB blob."""
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    dtype = {5126: "<f4", 5125: "<u4"}[acc.componentType]
    width = COMPONENTS[acc.type]
    raw = gltf.binary_blob()[view.byteOffset + (acc.byteOffset or 0):][: acc.count * width * 4]
    return np.frombuffer(raw, dtype=dtype).reshape(acc.count, width).astype(np.float64)


def test_rig_structure(tmp_path, rig):
    v, f, deltas, names, anim = rig
    path = tmp_path / "out" / "rig.glb"
    write_rig_glb(path, v, f, deltas, names, animation=anim, fps=24)
    g = pygltflib.GLTF2().load(str(path))
    assert len(g.meshes) == 1 and len(g.meshes[0].primitives) == 1
    mesh, prim = g.meshes[0], g.meshes[0].primitives[0]
    assert mesh.extras["targetNames"] == names and read_glb_morph_names(path) == names
    assert mesh.weights == [0.0, 0.0, 0.0] and len(prim.targets) == 3
    assert prim.mode == 4
    # every accessor has min/max equal to its data's bounds, and lies inside the buffer
    blob_len = len(g.binary_blob())
    assert g.buffers[0].byteLength == blob_len == sum(bv.byteLength + (-bv.byteLength) % 4 for bv in g.bufferViews)
    for i, acc in enumerate(g.accessors):
        data = accessor_array(g, i)
        assert acc.min is not None and acc.max is not None
        assert np.allclose(acc.min, data.min(axis=0), atol=1e-6) and np.allclose(acc.max, data.max(axis=0), atol=1e-6)
        view = g.bufferViews[acc.bufferView]
        assert view.byteOffset % 4 == 0 and view.byteOffset + view.byteLength <= blob_len
    assert np.allclose(accessor_array(g, prim.attributes.POSITION), v, atol=1e-5)
    assert np.array_equal(accessor_array(g, prim.indices).reshape(-1, 3), f)
    normals = accessor_array(g, prim.attributes.NORMAL)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-5)
    assert (np.einsum("ij,ij->i", normals, v) > 0).all()  # outward on a sphere
    for k, target in enumerate(prim.targets):
        assert g.accessors[target["POSITION"]].count == len(v)
        assert np.allclose(accessor_array(g, target["POSITION"]), deltas[k], atol=1e-6)
    # animation: times in seconds, T·K weights, LINEAR, channel on the node's weights
    (animation,) = g.animations
    sampler, channel = animation.samplers[0], animation.channels[0]
    assert sampler.interpolation == "LINEAR" and channel.target.path == "weights" and channel.target.node == 0
    times = accessor_array(g, sampler.input).ravel()
    assert np.allclose(times, np.arange(12) / 24) and g.accessors[sampler.input].max == pytest.approx([11 / 24])
    assert g.accessors[sampler.output].count == 12 * 3
    assert np.allclose(accessor_array(g, sampler.output).reshape(12, 3), anim, atol=1e-6)
    assert g.scenes[g.scene].nodes == [0] and g.nodes[0].mesh == 0
    assert [p.name for p in path.parent.iterdir()] == ["rig.glb"]


def test_rig_loads_in_trimesh(tmp_path, rig):
    v, f, deltas, names, _ = rig
    path = tmp_path / "rig.glb"
    write_rig_glb(path, v, f, deltas, names, normals=False)
    scene = trimesh.load(path, process=False)
    (geom,) = scene.geometry.values()
    assert np.allclose(geom.vertices, v, atol=1e-5) and np.array_equal(geom.faces, f)
    g = pygltflib.GLTF2().load(str(path))
    assert g.meshes[0].primitives[0].attributes.NORMAL is None and not g.animations


def test_sequence_glb_switches_one_frame_at_a_time(tmp_path, rig):
    v, f, *_ = rig
    frames = np.stack([v, v * 1.1, v + 0.5, v * 0.9])
    path = tmp_path / "seq.glb"
    write_sequence_glb(path, frames, f, fps=10)
    g = pygltflib.GLTF2().load(str(path))
    prim = g.meshes[0].primitives[0]
    assert read_glb_morph_names(path) == ["frame_0000", "frame_0001", "frame_0002", "frame_0003"]
    base = accessor_array(g, prim.attributes.POSITION)
    for t, target in enumerate(prim.targets):
        assert np.allclose(base + accessor_array(g, target["POSITION"]), frames[t], atol=1e-5)
    sampler = g.animations[0].samplers[0]
    assert sampler.interpolation == "STEP"
    assert np.allclose(accessor_array(g, sampler.output).reshape(4, 4), np.eye(4))
    assert np.allclose(accessor_array(g, sampler.input).ravel(), [0, 0.1, 0.2, 0.3])


def test_bad_arguments_and_files(tmp_path, rig):
    v, f, deltas, names, _ = rig
    with pytest.raises(ValueError, match="names"):
        write_rig_glb(tmp_path / "x.glb", v, f, deltas, names[:2])
    with pytest.raises(ValueError, match="deltas must be"):
        write_rig_glb(tmp_path / "x.glb", v, f, deltas[:, :-1], names)
    with pytest.raises(ValueError, match="animation must be"):
        write_rig_glb(tmp_path / "x.glb", v, f, deltas, names, animation=np.zeros((4, 2)))
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(RetargetError, match="cannot write to folder"):
        write_rig_glb(blocker / "x.glb", v, f, deltas, names)
    with pytest.raises(RetargetError, match="no such file"):
        read_glb_morph_names(tmp_path / "missing.glb")
    garbage = tmp_path / "g.glb"
    garbage.write_bytes(b"\x01\x02not a glb")
    with pytest.raises(RetargetError, match="g.glb: cannot read"):
        read_glb_morph_names(garbage)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "g.glb"]


# ----------------------------------------------------------------------------------------------
# The Khronos glTF validator (npm package gltf-validator), installed by `make test` into
# build/gltf-validator when npm is present; the test is skipped where it is not.
VALIDATOR_DIR = Path(os.environ.get("GLTF_VALIDATOR_DIR",
                                    Path(__file__).resolve().parents[1] / "build" / "gltf-validator")).resolve()


def khronos_issues(path) -> dict:
    import json
    import shutil
    import subprocess

    if shutil.which("node") is None or not (VALIDATOR_DIR / "node_modules" / "gltf-validator").is_dir():
        pytest.skip("Khronos glTF validator not installed (make test installs it with npm)")
    script = Path(__file__).parent / "tools" / "gltf_validate.mjs"
    res = subprocess.run(["node", str(script), str(path)], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "GLTF_VALIDATOR_DIR": str(VALIDATOR_DIR)})
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def test_rig_and_sequence_glb_pass_the_khronos_validator(tmp_path):
    m = trimesh.creation.icosphere(2)
    rng = np.random.default_rng(0)
    deltas = rng.normal(size=(4, len(m.vertices), 3)).astype(np.float32) * 0.1
    write_rig_glb(tmp_path / "rig.glb", m.vertices, m.faces, deltas, ["a", "b", "c", "d"],
                  animation=rng.random((12, 4)), fps=24)
    write_sequence_glb(tmp_path / "seq.glb", m.vertices[None] + deltas, m.faces, fps=30)
    for name in ("rig.glb", "seq.glb"):
        issues = khronos_issues(tmp_path / name)
        assert issues["numErrors"] == 0, (name, issues["messages"])


def test_rig_glb_imports_into_blender_with_named_shape_keys(tmp_path):
    import json
    import shutil
    import subprocess

    if shutil.which("blender") is None:
        pytest.skip("Blender is not installed")
    m = trimesh.creation.icosphere(2)
    names = ["jawOpen", "mouthSmile_L", "eyeBlink_R"]
    deltas = np.random.default_rng(1).normal(size=(3, len(m.vertices), 3)).astype(np.float32) * 0.1
    write_rig_glb(tmp_path / "rig.glb", m.vertices, m.faces, deltas, names,
                  animation=np.random.default_rng(2).random((8, 3)), fps=30)
    script = Path(__file__).parent / "tools" / "blender_import.py"
    res = subprocess.run(["blender", "-b", "--python", str(script), "--", str(tmp_path / "rig.glb")],
                         capture_output=True, text=True, timeout=300)
    line = [ln for ln in res.stdout.splitlines() if ln.startswith("RESULT ")]
    assert line, res.stdout[-2000:] + res.stderr[-2000:]
    out = json.loads(line[0][len("RESULT "):])
    assert out["meshes"] == 1 and out["vertices"] == len(m.vertices)
    assert out["shape_keys"] == ["Basis", *names] and out["animated"]
