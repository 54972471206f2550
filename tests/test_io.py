"""Mesh IO: formats, vertex order, triangulation, axes, atomic writes, sequences and bad inputs."""
import os
import shutil
from pathlib import Path

import numpy as np
import pygltflib
import pytest
import trimesh

from retarget.errors import RetargetError
from retarget.io import (axis_rotation, check_output, check_vertex_budget, estimate_memory, load_mesh,
                         load_sequence, peek_vertex_count, save_mesh, sequence_files)
from retarget.mesh import Mesh, check_mesh, vertex_normals

BAD = Path(__file__).parent / "bad_inputs"

# OBJ whose faces visit vertices out of order, with a duplicate position (vertices 1 and 5), an
# unreferenced vertex (6) and a quad
SCRAMBLED_OBJ = """v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 0
v 9 9 9
v 0.5 0.5 1
f 3 1 2
f 4 5 7 3
f 7 2 3
"""
SCRAMBLED_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 0], [9, 9, 9], [0.5, 0.5, 1]], float)


def rng_mesh(seed=0, n=30):
    """A small random closed-ish mesh: a perturbed icosphere."""
    s = trimesh.creation.icosphere(subdivisions=1)
    v = s.vertices * (1 + 0.1 * np.random.default_rng(seed).standard_normal((len(s.vertices), 1)))
    return v * 7.3 + [1.0, -2.0, 3.0], np.asarray(s.faces)


def test_obj_keeps_vertex_order_duplicates_and_triangulates_quads(tmp_path):
    p = tmp_path / "scrambled.obj"
    p.write_text(SCRAMBLED_OBJ)
    m = load_mesh(p)
    assert np.array_equal(m.vertices, SCRAMBLED_V)  # nothing merged, dropped or reordered
    assert m.faces.dtype == np.int64 and m.faces.shape == (4, 3)
    assert tuple(m.faces[0]) == (2, 0, 1) and tuple(m.faces[-1]) == (6, 1, 2)
    quad = m.faces[1:3]  # the quad 4 5 7 3 -> two triangles over its four corners
    assert set(quad.ravel()) == {3, 4, 6, 2}
    edges = SCRAMBLED_V[quad[:, 1:]] - SCRAMBLED_V[quad[:, :1]]  # (2, 2, 3)
    assert (np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1) > 0).all()
    assert m.name == str(p)


@pytest.mark.parametrize("ext", [".obj", ".ply"])
def test_write_read_round_trip(tmp_path, ext):
    v, f = rng_mesh()
    out = tmp_path / "deep" / "er" / f"mesh{ext}"
    save_mesh(out, Mesh(v, f))
    back = load_mesh(out)
    assert np.array_equal(back.faces, f)
    assert np.allclose(back.vertices, v, rtol=1e-6 if ext == ".ply" else 1e-8, atol=1e-8)  # PLY: float32
    assert [p.name for p in out.parent.iterdir()] == [out.name]  # no temp file left


def test_save_mesh_accepts_arrays_and_overwrites_atomically(tmp_path):
    v, f = rng_mesh()
    out = tmp_path / "m.obj"
    save_mesh(out, v, f)
    save_mesh(out, v * 2, f)
    assert np.allclose(load_mesh(out).vertices, v * 2)


def test_off_with_polygons(tmp_path):
    p = tmp_path / "poly.off"
    p.write_text("OFF\n# a pentagon and a triangle\n6 2 0\n0 0 0\n1 0 0\n1.5 1 0\n0.5 1.7 0\n-0.5 1 0\n0 0 1\n"
                 "5 0 1 2 3 4\n3 0 5 1\n")
    m = load_mesh(p)
    assert m.n_vertices == 6 and len(m.faces) == 4  # pentagon -> 3 triangles
    assert set(m.faces[:3].ravel()) == {0, 1, 2, 3, 4}
    pent_area = 0.5 * np.linalg.norm(np.cross(m.vertices[m.faces[:3, 1]] - m.vertices[m.faces[:3, 0]],
                                              m.vertices[m.faces[:3, 2]] - m.vertices[m.faces[:3, 0]]), axis=1).sum()
    xy = m.vertices[:5, :2]
    shoelace = 0.5 * abs(np.dot(xy[:, 0], np.roll(xy[:, 1], -1)) - np.dot(xy[:, 1], np.roll(xy[:, 0], -1)))
    assert np.isclose(pent_area, shoelace)


def test_glb_scene_concatenated_in_file_order_with_transforms(tmp_path):
    sphere, box = trimesh.creation.icosphere(1), trimesh.creation.box()
    scene = trimesh.Scene()
    shift = trimesh.transformations.translation_matrix([5.0, 0.0, 0.0])
    turn = trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0])
    scene.add_geometry(sphere, node_name="zz_sphere", geom_name="zz_sphere", transform=shift)
    scene.add_geometry(box, node_name="aa_box", geom_name="aa_box", transform=turn)
    p = tmp_path / "two.glb"
    scene.export(p)
    order = [n.name for n in pygltflib.GLTF2().load(str(p)).nodes if n.mesh is not None]
    parts = {"zz_sphere": sphere.vertices @ shift[:3, :3].T + shift[:3, 3],
             "aa_box": box.vertices @ turn[:3, :3].T}
    m = load_mesh(p)
    expected = np.concatenate([parts[n] for n in order])
    assert np.allclose(m.vertices, expected, atol=1e-6)
    assert len(m.faces) == len(sphere.faces) + len(box.faces)
    # .gltf with an external buffer reads the same
    files = scene.export(file_type="gltf")
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    assert np.allclose(load_mesh(tmp_path / "model.gltf").vertices, expected, atol=1e-6)


def test_glb_written_by_our_exporter_round_trips(tmp_path):
    from retarget.glb import write_rig_glb

    v, f = rng_mesh()
    write_rig_glb(tmp_path / "r.glb", v, f, np.zeros((2, len(v), 3)), ["a", "b"])
    m = load_mesh(tmp_path / "r.glb")
    assert np.array_equal(m.faces, f) and np.allclose(m.vertices, v, atol=1e-5)


def test_axis_conversion(tmp_path):
    r = axis_rotation("+z", "-y")  # e.g. a Z-up file whose face looks along -y
    assert np.allclose(r @ r.T, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0)
    assert np.allclose(r @ [0, 0, 1], [0, 1, 0]) and np.allclose(r @ [0, -1, 0], [0, 0, 1])
    assert np.allclose(axis_rotation(), np.eye(3))
    p = tmp_path / "tri.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 0 2\nf 1 2 3\n")
    m = load_mesh(p, up="+z", forward="-y")
    assert np.allclose(m.vertices[2], [0, 2, 0]) and np.allclose(m.vertices[1], [1, 0, 0])
    with pytest.raises(RetargetError, match="different axes"):
        axis_rotation("+y", "-y")
    with pytest.raises(RetargetError, match="--up"):
        axis_rotation("up", "+z")


def test_mesh_normals_and_copy():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0.0]])
    m = Mesh(v, [[0, 1, 2]])
    n = m.vertex_normals
    assert np.allclose(n[:3], [0, 0, 1])  # CCW -> +z
    assert np.isclose(np.linalg.norm(n[3]), 1.0)  # unused vertex: normal of its neighbourhood (nets.geometry)
    assert m.vertex_normals is n  # cached
    c = m.copy()
    c.vertices[0] = 5
    assert m.vertices[0, 0] == 0 and m.n_vertices == 4
    # area weighting: a vertex shared by a large +z face and a small +x face leans to +z
    v2 = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [0, 0.1, 0], [0, 0, 0.1]], float)
    n2 = vertex_normals(v2, [[0, 1, 2], [0, 3, 4]])
    assert n2[0, 2] > 0.99 and n2[0, 0] > 0


def test_memory_estimate_and_refusal(tmp_path):
    assert estimate_memory(2_000_000) == 2 * estimate_memory(1_000_000) > 0
    with pytest.raises(RetargetError, match=r"big\.obj: 12,000,000 vertices .* GiB"):
        check_vertex_budget(12_000_000, "big.obj")
    check_vertex_budget(12_000_000, "big.obj", force=True)
    v, f = rng_mesh()
    for ext in (".obj", ".ply"):
        save_mesh(tmp_path / f"m{ext}", v, f)
        assert peek_vertex_count(tmp_path / f"m{ext}") == len(v)
        with pytest.raises(RetargetError, match="above the limit"):
            load_mesh(tmp_path / f"m{ext}", max_vertices=10)
        assert load_mesh(tmp_path / f"m{ext}", max_vertices=10, force=True).n_vertices == len(v)
    (tmp_path / "q.off").write_text("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    assert peek_vertex_count(tmp_path / "q.off") == 4


def test_sequence_folder_glob_and_natural_order(tmp_path):
    v, f = rng_mesh()
    for t in (10, 2, 1):
        save_mesh(tmp_path / "seq" / f"frame_{t}.obj", v + t, f)
    (tmp_path / "seq" / "notes.txt").write_text("not a mesh")
    frames = load_sequence(tmp_path / "seq")
    assert [Path(m.name).name for m in frames] == ["frame_1.obj", "frame_2.obj", "frame_10.obj"]
    assert np.allclose(frames[2].vertices, v + 10)
    assert all(m.faces is frames[0].faces for m in frames)
    assert [p.name for p in sequence_files(str(tmp_path / "seq" / "frame_1*.obj"))] == ["frame_1.obj", "frame_10.obj"]
    assert len(load_sequence(tmp_path / "seq" / "frame_2.obj")) == 1
    with pytest.raises(RetargetError, match="no mesh files"):
        load_sequence(str(tmp_path / "seq" / "*.ply"))


def test_check_output_refuses_inputs(tmp_path):
    inp = tmp_path / "in.obj"
    inp.write_text(SCRAMBLED_OBJ)
    for same in (inp, tmp_path / "sub" / ".." / "in.obj"):
        with pytest.raises(RetargetError, match="refusing to overwrite the input"):
            check_output(same, [tmp_path / "other.obj", inp])
    (tmp_path / "sub").mkdir()
    os.link(inp, tmp_path / "hard.obj")
    os.symlink(inp, tmp_path / "soft.obj")
    for alias in ("hard.obj", "soft.obj"):
        with pytest.raises(RetargetError, match=alias):
            check_output(tmp_path / alias, [inp])
    check_output(tmp_path / "out.obj", [inp])


# ------------------------------------------------------------------------------- bad-input corpus
MESH_CASES = {
    "empty.obj": "empty",
    "comments_only.obj": "empty",
    "garbage.obj": "binary data",
    "garbage.ply": "cannot read as PLY",
    "garbage.off": "cannot read as OFF",
    "garbage.glb": "cannot read as GLB",
    "truncated.glb": "truncated",
    "truncated.ply": "cannot read as PLY",
    "nan.obj": "NaN/inf",
    "inf.ply": "NaN/inf",
    "degenerate.obj": "degenerate",
    "point_cloud.obj": "is a point cloud (no faces)",
    "point_cloud.ply": "is a point cloud (no faces)",
    "index_out_of_range.obj": "face index out of range",
    "index_out_of_range.off": "face index out of range",
    "unknown_format.stl": "unknown mesh format",
    "does_not_exist.obj": "no such file",
    "seq_counts": "is a folder",
    "face_index_zero.obj": "line 4: face index 0 (OBJ vertex indices start at 1)",
    "collinear.obj": "the vertices lie on a line",
    "huge_coordinate.obj": "coordinates beyond",
    "buffer_absolute.gltf": "is not a relative path",
    "buffer_device.gltf": "is not a relative path",
    "buffer_file_scheme.gltf": "is not a relative path",
    "buffer_escapes.gltf": "points outside the glTF's folder",
    "buffer_escapes_encoded.gltf": "points outside the glTF's folder",
    "draco.gltf": "requires the glTF extension(s) KHR_draco_mesh_compression",
    "meshopt.gltf": "requires the glTF extension(s) EXT_meshopt_compression",
    "node_cycle.gltf": "the node hierarchy has a cycle",
}


def _tree_bytes(folder: Path) -> dict:
    return {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.mark.parametrize("name,fragment", sorted(MESH_CASES.items()))
def test_bad_mesh_inputs(tmp_path, name, fragment):
    """Each bad file: RetargetError naming it, input untouched, and no output left behind."""
    before = _tree_bytes(BAD)
    out = tmp_path / "out" / "result.obj"
    with pytest.raises(RetargetError) as err:
        save_mesh(out, load_mesh(BAD / name))
    msg = str(err.value)
    assert str(BAD / name) in msg and fragment in msg and "\n" not in msg
    assert _tree_bytes(BAD) == before
    assert not out.exists() and (not out.parent.exists() or not any(out.parent.iterdir()))


@pytest.mark.parametrize("folder,fragment", [("seq_counts", "has 4 vertices but"), ("seq_faces", "faces differ")])
def test_bad_sequences(folder, fragment):
    with pytest.raises(RetargetError, match=fragment) as err:
        load_sequence(BAD / folder)
    assert "frame_2.obj" in str(err.value) and "frame_1.obj" in str(err.value)


def test_bad_outputs_leave_nothing(tmp_path):
    v, f = rng_mesh()
    blocker = tmp_path / "a_file"
    blocker.write_text("I am a file, not a folder")
    with pytest.raises(RetargetError, match="cannot write to folder") as err:
        save_mesh(blocker / "out.obj", v, f)  # parent is a regular file: unwritable as root too
    assert str(blocker / "out.obj") in str(err.value)
    with pytest.raises(RetargetError, match="cannot write .stl"):
        save_mesh(tmp_path / "out.stl", v, f)
    (tmp_path / "dir.obj").mkdir()
    with pytest.raises(RetargetError, match="is a folder"):
        save_mesh(tmp_path / "dir.obj", v, f)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a_file", "dir.obj"]
    assert blocker.read_text() == "I am a file, not a folder"


def test_check_mesh_direct_messages():
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    check_mesh(Mesh(tri, [[0, 1, 2]], "ok.obj"))
    cases = [(Mesh(np.zeros((0, 3)), np.zeros((0, 3)), "e.obj"), "empty"),
             (Mesh(tri, [[0, 1, 3]], "r.obj"), "out of range"),
             (Mesh(tri, [[0, -1, 2]], "n.obj"), "out of range"),
             (Mesh(tri, [[0, 0, 1]], "d.obj"), "degenerate")]
    for mesh, fragment in cases:
        with pytest.raises(RetargetError, match=fragment) as err:
            check_mesh(mesh)
        assert str(err.value).startswith(mesh.name + ":")


def test_corpus_script_is_in_sync():
    from tests.bad_inputs.make_corpus import corpus

    for name, data in corpus().items():
        if not name.endswith(".glb"):  # GLB bytes depend on the exporter's JSON formatting
            assert (BAD / name).read_bytes() == data, name


def test_unreadable_file_is_a_user_error(tmp_path):
    if os.geteuid() == 0:
        pytest.skip("root can read files without read permission")
    p = tmp_path / "locked.obj"
    shutil.copy(BAD / "nan.obj", p)
    p.chmod(0)
    with pytest.raises(RetargetError, match="locked.obj"):
        load_mesh(p)


def test_obj_objects_groups_materials_and_relative_indices(tmp_path):
    """Several objects/groups/materials stay one mesh in file order; negative indices resolve."""
    p = tmp_path / "multi.obj"
    p.write_text("mtllib missing.mtl\no second\nv 5 5 5\nv 6 5 5\nv 5 6 5\nvt 0 0\nf -3/1 -2/1 -1/1\n"
                 "o first\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl skin\ns 1\nf 4 5 6\ng grp\nusemtl eye\nf 4//1 6//1 1//1\n")
    m = load_mesh(p)
    assert np.array_equal(m.vertices[:3], [[5, 5, 5], [6, 5, 5], [5, 6, 5]]) and m.n_vertices == 6
    assert m.faces.tolist() == [[0, 1, 2], [3, 4, 5], [3, 5, 0]]
    latin = tmp_path / "latin.obj"
    latin.write_bytes(b"# cr\xe9\xe9 par un vieil exporteur\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert load_mesh(latin).n_vertices == 3


# ------------------------------------------------------------------------------- hostile inputs
def test_byte_order_marks_and_utf16_text(tmp_path):
    """A UTF-8 BOM does not hide the first line; UTF-16 text (with or without a BOM) is text."""
    from retarget.weights_io import read_weights

    obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    for name, data in (("bom.obj", b"\xef\xbb\xbf" + obj.encode()), ("utf16.obj", obj.encode("utf-16")),
                       ("utf16le.obj", obj.encode("utf-16-le"))):
        (tmp_path / name).write_bytes(data)
        m = load_mesh(tmp_path / name)
        assert np.array_equal(m.vertices[0], [0, 0, 0]) and m.n_vertices == 3, name
    (tmp_path / "w.csv").write_bytes("jawOpen,eyeBlink_L\n0.25,0.5\n".encode("utf-16"))
    from data_synth.facs import FACS_INDEX
    w = read_weights(tmp_path / "w.csv").weights[0]
    assert (w[FACS_INDEX["jawOpen"]], w[FACS_INDEX["eyeBlink_L"]]) == (0.25, 0.5)


def test_two_heads_in_one_file_give_a_warning(tmp_path):
    from retarget.io import SeveralHeadsWarning

    from .test_api import head_mesh

    head = head_mesh(2)
    eye = trimesh.creation.icosphere(1).vertices * 1.2 + [3.0, 2.0, 9.0]
    eyes = Mesh(np.concatenate([head.vertices, eye]),
                np.concatenate([head.faces, trimesh.creation.icosphere(1).faces + head.n_vertices]))
    save_mesh(tmp_path / "eyes.obj", eyes)
    save_mesh(tmp_path / "two.obj", np.concatenate([head.vertices, head.vertices + [30.0, 0, 0]]),
              np.concatenate([head.faces, head.faces + head.n_vertices]))
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_mesh(tmp_path / "eyes.obj")  # a head and a small part: no warning
    with pytest.warns(SeveralHeadsWarning, match=r"two\.obj: holds 2 disconnected parts.*162 and 162"):
        load_mesh(tmp_path / "two.obj")
    take = tmp_path / "take"
    take.mkdir()
    for i in range(3):
        (take / f"frame_{i:04d}.obj").write_bytes((tmp_path / "two.obj").read_bytes())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_sequence(take)
    assert [str(w.message).split(":")[0] for w in caught] == [str(take / "frame_0000.obj")]


def test_a_killed_writers_leftovers_are_removed_by_the_next_write(tmp_path):
    """SIGKILL inside atomic_output and inside a frame folder's staging: the next write into the
    same folder removes both; a temporary of a process that still runs is kept."""
    import subprocess
    import sys

    code = ("import os, signal, sys; import numpy as np; from retarget.io import atomic_output; "
            "from retarget.commands._common import write_frames\n"
            "from argparse import Namespace\n"
            "out = sys.argv[1]\n"
            "def frames():\n    yield np.zeros((3, 3))\n    os.kill(os.getpid(), signal.SIGKILL)\n"
            "if sys.argv[2] == 'file':\n"
            "    with atomic_output(out) as tmp:\n        open(tmp, 'w').write('partial')\n"
            "        os.kill(os.getpid(), signal.SIGKILL)\n"
            "write_frames(out, frames(), np.array([[0, 1, 2]]), [], Namespace(up=None, forward=None, "
            "format='obj'), n_frames=2)\n")
    root = Path(__file__).parents[1]
    env = {**os.environ, "PYTHONPATH": str(root)}
    for target, mode in ((tmp_path / "o.obj", "file"), (tmp_path / "frames", "folder")):
        proc = subprocess.run([sys.executable, "-c", code, str(target), mode], env=env, cwd=root)
        assert proc.returncode == -9
        left = [p.name for p in tmp_path.iterdir()]  # the previous run's leftover is gone
        assert len(left) == 1 and left[0].startswith(f".{target.name}.pid") and ".tmp" in left[0], left
    running = tmp_path / f".x.obj.pid{os.getpid()}.abcdefgh.tmp.obj"  # a write in progress
    running.write_text("busy")
    v, f = rng_mesh()
    save_mesh(tmp_path / "next.obj", v, f)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["next.obj", running.name])
