"""The ``retarget`` commands end to end on tiny meshes with a tiny checkpoint made in the test: the
files they write agree with the Python API, every output format round-trips, GLB structure, axes
and units; --help shows an example; one real subprocess checks the exit codes."""
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pygltflib
import pytest

from retarget import FACS_NAMES
from retarget.api import Retargeter
from retarget.cli import COMMANDS, main
from retarget.glb import read_glb_morph_names
from retarget.io import axis_rotation, load_mesh, save_mesh
from retarget.weights_io import read_weights

from .test_api import head_mesh, tiny_checkpoint

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A tiny checkpoint, a target, a 3-frame source sequence and a weight file (2 frames)."""
    d = tmp_path_factory.mktemp("cli")
    tiny_checkpoint(d / "tiny.pt")
    save_mesh(d / "target.obj", head_mesh(2, name="target"))
    for t, s in enumerate((0.0, 0.5, 1.0)):
        save_mesh(d / "seq" / f"frame_{t + 1}.obj", head_mesh(2, smile=s))
    (d / "w.csv").write_text("jawOpen,eyeBlink_L\n0.5,0.25\n1.0,0\n")
    return d


def run(*argv, files=None) -> int:
    """main() in-process, with the tiny checkpoint unless --checkpoint is given."""
    argv = [str(a) for a in argv]
    if files is not None and "--checkpoint" not in argv:
        argv += ["--checkpoint", str(files / "tiny.pt"), "--device", "cpu"]
    return main(argv)


def api(files) -> Retargeter:
    return Retargeter.load(files / "tiny.pt", device="cpu")


def glb_positions(path: Path):
    """(base (V,3), morph deltas (K,V,3), names, animation weights (T,K) or None) of a GLB."""
    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob()

    def arr(i):
        acc, view = g.accessors[i], g.bufferViews[g.accessors[i].bufferView]
        n = {"SCALAR": 1, "VEC3": 3}[acc.type]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        return np.frombuffer(blob, np.float32, acc.count * n, start).reshape(acc.count, n)

    prim = g.meshes[0].primitives[0]
    deltas = np.stack([arr(t["POSITION"]) for t in prim.targets])
    anim = None
    if g.animations:
        out = arr(g.animations[0].samplers[0].output)
        anim = out.reshape(-1, len(deltas))
    return arr(prim.attributes.POSITION), deltas, read_glb_morph_names(path), anim


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_help_shows_an_example(command, capsys):
    with pytest.raises(SystemExit) as e:
        main([command, "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert "example:" in out and f"retarget {command}" in out.split("example:")[1]


def test_transfer_one_frame_obj_and_ply_equal_the_api(files, tmp_path):
    src = files / "seq" / "frame_3.obj"
    expected = api(files).transfer(load_mesh(src), load_mesh(files / "target.obj"))
    for ext in ("obj", "ply"):
        assert run("transfer", src, files / "target.obj", "-o", tmp_path / f"out.{ext}", files=files) == 0
        got = load_mesh(tmp_path / f"out.{ext}")
        assert np.allclose(got.vertices, expected, atol=1e-4)
        assert np.array_equal(got.faces, load_mesh(files / "target.obj").faces)


def test_transfer_sequence_to_folder_glob_and_glb(files, tmp_path):
    r = api(files)
    frames = [load_mesh(files / "seq" / f"frame_{t}.obj") for t in (1, 2, 3)]
    expected = r.transfer(frames, load_mesh(files / "target.obj"), smooth="savgol")
    assert run("transfer", files / "seq", files / "target.obj", "-o", tmp_path / "frames",
               "--format", "ply", "--smooth", "savgol", files=files) == 0
    written = sorted((tmp_path / "frames").iterdir())
    assert [p.name for p in written] == ["frame_0000.ply", "frame_0001.ply", "frame_0002.ply"]
    for p, e in zip(written, expected):
        assert np.allclose(load_mesh(p).vertices, e, atol=1e-4)
    assert run("transfer", f"{files}/seq/frame_*.obj", files / "target.obj", "-o", tmp_path / "perf.glb",
               "--smooth", "savgol", "--fps", "24", files=files) == 0
    base, deltas, names, anim = glb_positions(tmp_path / "perf.glb")
    assert names == ["frame_0000", "frame_0001", "frame_0002"]
    assert np.allclose(base + deltas, expected, atol=1e-4) and np.allclose(anim, np.eye(3))
    # several frames cannot go into one mesh file: refused before any work
    assert run("transfer", files / "seq", files / "target.obj", "-o", tmp_path / "x.obj", files=files) == 2
    assert not (tmp_path / "x.obj").exists()


def test_animate_json_csv_baked_and_clamp(files, tmp_path, capsys):
    r = api(files)
    target = load_mesh(files / "target.obj")
    (tmp_path / "smile.json").write_text(json.dumps({"mouthSmile_L": 0.8, "mouthSmile_R": 0.8}))
    assert run("animate", files / "target.obj", "--weights", tmp_path / "smile.json",
               "-o", tmp_path / "smile.obj", files=files) == 0
    expected = r.animate(target, {"mouthSmile_L": 0.8, "mouthSmile_R": 0.8})
    assert np.allclose(load_mesh(tmp_path / "smile.obj").vertices, expected, atol=1e-4)
    # out-of-range weights: a warning naming the file, kept; --clamp clips them
    (tmp_path / "wide.csv").write_text("jawOpen\n1.5\n-0.5\n")
    capsys.readouterr()
    assert run("animate", files / "target.obj", "--weights", tmp_path / "wide.csv",
               "-o", tmp_path / "wide", files=files) == 0
    err = capsys.readouterr().err
    assert "warning: " in err and "wide.csv: 2 weights outside [0, 1]" in err
    k = FACS_NAMES.index("jawOpen")
    kept = load_mesh(tmp_path / "wide" / "frame_0000.obj").vertices
    assert np.allclose(kept, r.animate(target, 1.5 * np.eye(53)[k]), atol=1e-4)
    assert run("animate", files / "target.obj", "--weights", tmp_path / "wide.csv", "--clamp", "--baked",
               "-o", tmp_path / "clamped.glb", files=files) == 0
    base, deltas, _, _ = glb_positions(tmp_path / "clamped.glb")
    rig = r.bake(target)
    assert np.allclose(base + deltas[1], rig.neutral, atol=1e-4)  # -0.5 clipped to 0
    assert np.allclose(base, rig.evaluate(np.eye(53)[k]), atol=1e-4)  # 1.5 clipped to 1


def test_invert_csv_round_trip(files, tmp_path):
    frames = [load_mesh(files / "seq" / f"frame_{t}.obj") for t in (1, 2, 3)]
    expected = api(files).invert(frames, smooth="one_euro")
    for names in ("ict", "arkit"):
        out = tmp_path / f"w_{names}.csv"
        assert run("invert", files / "seq", "-o", out, "--names", names, "--smooth", "one_euro",
                   files=files) == 0
        track = read_weights(out)
        assert track.weights.shape == (3, 53) and track.fps == pytest.approx(30.0, rel=1e-4)
        if names == "ict":
            assert np.allclose(track.weights, expected, atol=1e-5)
            assert out.read_text().splitlines()[0].split(",")[2:] == list(FACS_NAMES)


def test_export_rig_structure(files, tmp_path):
    target = load_mesh(files / "target.obj")
    rig = api(files).bake(target)
    assert run("export-rig", files / "target.obj", "-o", tmp_path / "rig.glb", files=files) == 0
    base, deltas, names, anim = glb_positions(tmp_path / "rig.glb")
    assert names == list(FACS_NAMES) and anim is None
    assert np.allclose(base, rig.neutral, atol=1e-4) and np.allclose(deltas, rig.deltas, atol=1e-4)
    assert run("export-rig", files / "target.obj", "-o", tmp_path / "arkit.glb", "--names", "arkit",
               "--weights", files / "w.csv", files=files) == 0
    _, deltas, names, anim = glb_positions(tmp_path / "arkit.glb")
    assert len(names) == 51 == deltas.shape[0] and "jawOpen" in names and "browInnerUp" in names
    assert anim.shape == (2, 51) and anim[0, names.index("jawOpen")] == pytest.approx(0.5)
    assert run("export-rig", files / "target.obj", "-o", tmp_path / "rig.obj", files=files) == 2


def test_up_forward_axes_map_back_to_the_files_frame(files, tmp_path):
    """A z-up, -y-forward copy of the inputs gives the z-up copy of the y-up result."""
    to_file = axis_rotation("+z", "-y")  # project frame -> the z-up file axes: v @ R (R orthonormal)
    src, tgt = load_mesh(files / "seq" / "frame_3.obj"), load_mesh(files / "target.obj")
    save_mesh(tmp_path / "src_z.obj", src.vertices @ to_file, src.faces)
    save_mesh(tmp_path / "tgt_z.obj", tgt.vertices @ to_file, tgt.faces)
    assert run("transfer", files / "seq" / "frame_3.obj", files / "target.obj", "-o", tmp_path / "y.obj",
               files=files) == 0
    assert run("transfer", tmp_path / "src_z.obj", tmp_path / "tgt_z.obj", "-o", tmp_path / "z.obj",
               "--up", "+z", "--forward", "-y", files=files) == 0
    y, z = load_mesh(tmp_path / "y.obj").vertices, load_mesh(tmp_path / "z.obj").vertices
    assert np.allclose(z, y @ to_file, atol=1e-4)


def test_millimetre_files_give_the_centimetre_result_times_ten(files, tmp_path):
    src, tgt = load_mesh(files / "seq" / "frame_3.obj"), load_mesh(files / "target.obj")
    save_mesh(tmp_path / "src_mm.ply", src.vertices * 10, src.faces)
    save_mesh(tmp_path / "tgt_mm.ply", tgt.vertices * 10, tgt.faces)
    assert run("transfer", files / "seq" / "frame_3.obj", files / "target.obj", "-o", tmp_path / "cm.ply",
               files=files) == 0
    assert run("transfer", tmp_path / "src_mm.ply", tmp_path / "tgt_mm.ply", "-o", tmp_path / "mm.ply",
               files=files) == 0
    cm, mm = load_mesh(tmp_path / "cm.ply").vertices, load_mesh(tmp_path / "mm.ply").vertices
    assert np.abs(cm - tgt.vertices).max() > 1e-3  # an expression, not the neutral
    assert np.allclose(mm, 10 * cm, atol=1e-3)  # float32 PLY: ~1e-6 relative


def test_demo_runs_on_a_tiny_checkpoint(files, tmp_path, capsys):
    pytest.importorskip("data_synth.rig")
    assert run("demo", "-o", tmp_path / "demo", "--frames", "4", files=files) == 0
    out = capsys.readouterr().out
    assert "without the source's neutral, estimated from the take" in out
    # beside the model: doing nothing and closest point, for the transfer and for the weights
    cp = re.search(r"closest-point displacement transfer: MSE ([0-9.]+) mm", out)
    nothing = re.search(r"doing nothing \(target left neutral\): MSE ([0-9.]+) mm", out)
    assert cp and nothing and 0 < float(cp.group(1)) < float(nothing.group(1))
    assert re.search(r"predicting 0: [0-9.]+; the ARKit template rig carried over by closest point "
                     r"and fitted: 0\.[0-9]{3}\)", out)
    produced = {p.suffix for p in (tmp_path / "demo").rglob("*") if p.is_file()}
    assert {".obj", ".glb", ".png"} <= produced


def test_subprocess_exit_codes_and_no_traceback(files, tmp_path):
    """Real processes: success exits 0; a user error exits 2 with one 'error:' line on stderr."""
    cmd = [sys.executable, "-m", "retarget.cli"]
    env = {"PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"}
    ok = subprocess.run(cmd + ["animate", str(files / "target.obj"), "--weights", str(files / "w.csv"),
                               "-o", str(tmp_path / "a.glb"), "--checkpoint", str(files / "tiny.pt"),
                               "--device", "cpu"], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert ok.returncode == 0, ok.stderr
    assert "wrote 2 frame(s)" in ok.stdout and (tmp_path / "a.glb").is_file()
    bad = subprocess.run(cmd + ["transfer", str(tmp_path / "missing.obj"), str(files / "target.obj"),
                                "-o", str(tmp_path / "b.obj"), "--checkpoint", str(files / "tiny.pt")],
                         capture_output=True, text=True, env=env, cwd=tmp_path)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    lines = bad.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "missing.obj: no such file" in lines[0]


def test_quad_obj_target_is_triangulated_and_keeps_its_vertices(files, tmp_path):
    """A quad-dominant OBJ (lat-long ellipsoid, 'f a b c d' lines) works as a target."""
    rows, cols = 10, 16
    th, ph = np.meshgrid(np.linspace(0.2, np.pi - 0.2, rows), np.linspace(0, 2 * np.pi, cols, endpoint=False),
                         indexing="ij")
    v = np.stack([8 * np.sin(th) * np.cos(ph), 11 * np.cos(th), 9 * np.sin(th) * np.sin(ph)], -1).reshape(-1, 3)
    quads = [(r * cols + c, (r + 1) * cols + c, (r + 1) * cols + (c + 1) % cols, r * cols + (c + 1) % cols)
             for r in range(rows - 1) for c in range(cols)]
    lines = [f"v {x} {y} {z}" for x, y, z in v] + ["f " + " ".join(str(i + 1) for i in q) for q in quads]
    (tmp_path / "quads.obj").write_text("\n".join(lines) + "\n")
    assert run("animate", tmp_path / "quads.obj", "--weights", files / "w.csv", "-o", tmp_path / "q",
               files=files) == 0
    out = load_mesh(tmp_path / "q" / "frame_0000.obj")
    assert out.vertices.shape == v.shape and len(out.faces) == 2 * len(quads)
    assert np.isfinite(out.vertices).all() and np.abs(out.vertices - v).max() > 1e-4


def test_failed_sequence_leaves_no_partial_folder(tmp_path, monkeypatch):
    import argparse

    from retarget.commands import _common
    from retarget.errors import RetargetError

    calls = []

    def failing_save(path, verts, faces):
        calls.append(path)
        if len(calls) == 3:
            raise RetargetError(f"{path}: disk full")
        Path(path).write_text("v 0 0 0\n")

    monkeypatch.setattr(_common, "save_mesh", failing_save)
    args = argparse.Namespace(up=None, forward=None, format="obj")
    frames = np.zeros((5, 3, 3))
    with pytest.raises(RetargetError, match="disk full"):
        _common.write_frames(str(tmp_path / "out"), frames, np.array([[0, 1, 2]]), [], args)
    assert not (tmp_path / "out").exists()
    assert list(tmp_path.iterdir()) == []  # staging folder removed too


def test_a_streamed_sequence_is_written_one_frame_at_a_time(tmp_path, monkeypatch):
    """write_frames takes an iterator (Retargeter.iter_decode): each frame is saved before the next
    is made, and the files equal those of the same frames given as one array."""
    import argparse

    from retarget.commands import _common

    args = argparse.Namespace(up=None, forward=None, format="obj")
    frames = np.random.default_rng(0).normal(size=(4, 3, 3))
    faces = np.array([[0, 1, 2]])
    made, saved = [], []
    real_save = _common.save_mesh
    monkeypatch.setattr(_common, "save_mesh", lambda p, v, f: (saved.append(len(made)), real_save(p, v, f)))

    def stream():
        for f in frames:
            made.append(1)
            yield f

    _common.write_frames(str(tmp_path / "streamed"), stream(), faces, [], args, n_frames=4)
    assert saved == [1, 2, 3, 4]                 # frame t saved when t frames had been made
    _common.write_frames(str(tmp_path / "array"), frames, faces, [], args)
    for name in (f"frame_{t:04d}.obj" for t in range(4)):
        assert (tmp_path / "streamed" / name).read_text() == (tmp_path / "array" / name).read_text()
    with pytest.raises(ValueError, match="n_frames"):
        _common.write_frames(str(tmp_path / "x"), iter(frames), faces, [], args)


def test_a_tilted_head_is_reported_and_no_upright_keeps_it(tmp_path, capsys):
    from retarget.canonical import turn_matrix
    from retarget.mesh import Mesh

    a = np.load(Path(__file__).resolve().parents[1] / "data_synth" / "makehuman" / "data"
                / "makehuman_arkit.npz", allow_pickle=False)
    turn = turn_matrix(-20.0, 0.0)
    save_mesh(tmp_path / "tilted.obj", Mesh(a["neutral"] @ turn.T, a["faces"]))
    (tmp_path / "w.json").write_text('{"jawOpen": 0.8}')
    ckpt = tiny_checkpoint(tmp_path / "face.pt", canonical="face")
    common = [str(tmp_path / "tilted.obj"), "--weights", str(tmp_path / "w.json"), "--checkpoint",
              str(ckpt), "--device", "cpu"]
    assert main(["animate", *common, "-o", str(tmp_path / "a.obj")]) == 0
    import re
    turned = re.search(r"tilted.obj: the head is turned ([0-9.]+) degrees", capsys.readouterr().err)
    assert turned and abs(float(turned.group(1)) - 20.0) < 2.0
    assert main(["animate", *common, "-o", str(tmp_path / "b.obj"), "--no-upright"]) == 0
    assert "turned" not in capsys.readouterr().err
    assert not np.allclose(load_mesh(tmp_path / "a.obj").vertices, load_mesh(tmp_path / "b.obj").vertices)


def test_separate_parts_are_reported_and_all_parts_feeds_them(tmp_path, capsys):
    from .test_api import with_parts

    full = with_parts(head_mesh(2))
    save_mesh(tmp_path / "parts.obj", full)
    (tmp_path / "w.json").write_text('{"jawOpen": 0.8, "eyeLookUp_L": 1.0}')
    common = [str(tmp_path / "parts.obj"), "--weights", str(tmp_path / "w.json"), "--checkpoint",
              str(tiny_checkpoint(tmp_path / "tiny.pt")), "--device", "cpu"]
    assert main(["animate", *common, "-o", str(tmp_path / "a.obj")]) == 0
    err = capsys.readouterr().err
    assert "parts.obj: the network saw the face alone (162 of 254 vertices" in err
    assert "84 vertices in 2 part(s) of two eyeballs, which turn with the gaze" in err
    out = load_mesh(tmp_path / "a.obj").vertices           # the left eye (x > 0) looks up, alone
    assert np.allclose(out[162:204], full.vertices[162:204], atol=1e-6)
    assert np.allclose(out[246:], full.vertices[246:], atol=1e-6)
    assert (out[204:246, 1] - full.vertices[204:246, 1]).max() > 0.3
    assert main(["animate", *common, "-o", str(tmp_path / "c.obj"), "--still-parts"]) == 0
    assert "eyeballs" not in capsys.readouterr().err
    assert np.allclose(load_mesh(tmp_path / "c.obj").vertices[162:], full.vertices[162:], atol=1e-6)
    assert main(["animate", *common, "-o", str(tmp_path / "b.obj"), "--all-parts"]) == 0
    assert "face alone" not in capsys.readouterr().err
    assert np.abs(load_mesh(tmp_path / "b.obj").vertices[162:] - full.vertices[162:]).max() > 1e-3
