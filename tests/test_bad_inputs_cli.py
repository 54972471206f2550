"""The bad-input corpus at the command line: every bad input gives exit code 2 and one ``error:`` line
naming the file and the problem, no traceback; inputs stay byte-identical and no output is left.

The reader-level corpus (tests/bad_inputs, expected fragments in tests/test_io.py and
tests/test_weights_io.py) is reused here through the commands; the cases that need the file system
or the model at run time (output = input, read-only folder, 10M-vertex file, checkpoints, objects
that are not faces, wrong options) are built by the tests.
"""
import os
import tempfile
from pathlib import Path

import pytest
import torch

from retarget import api
from retarget.cli import main
from retarget.io import save_mesh

from .test_api import head_mesh, tiny_checkpoint
from .test_io import MESH_CASES
from .test_weights_io import WEIGHT_CASES

BAD = Path(__file__).parent / "bad_inputs"


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    """Valid inputs: a tiny checkpoint, a target, a source, a weight file."""
    d = tmp_path_factory.mktemp("good")
    tiny_checkpoint(d / "tiny.pt")
    save_mesh(d / "target.obj", head_mesh(2))
    save_mesh(d / "source.obj", head_mesh(2, smile=1.0))
    (d / "w.csv").write_text("jawOpen\n0.5\n")
    return d


def _tree(*folders) -> dict:
    return {p: p.read_bytes() for f in folders for p in Path(f).rglob("*") if p.is_file()}


def refused(capsys, argv, names, fragment, good, out_dir, bundled: bool = False) -> str:
    """Run the CLI in-process (with the tiny checkpoint unless ``--checkpoint`` is in argv or
    ``bundled``); assert exit 2, exactly one error line (the last) naming every name in ``names``
    with ``fragment``, no traceback, inputs unchanged and nothing written under out_dir."""
    argv = [str(a) for a in argv] + (["--device", "cpu"] if argv[0] not in ("train", "synth") else [])
    if "--checkpoint" not in argv and not bundled:
        argv += ["--checkpoint", str(good / "tiny.pt")]
    before = _tree(BAD, good)
    out_before = _tree(out_dir)
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("error: ")]
    assert len(errors) == 1 and lines[-1] == errors[0] and "Traceback" not in err, err
    assert all(ln.startswith(("warning: ", "note: ")) for ln in lines[:-1]), err  # no Python warnings
    assert len(errors[0]) <= 1000, errors[0][:200]
    for name in names:
        assert str(name) in errors[0], errors[0]
    assert fragment in errors[0], errors[0]
    assert _tree(BAD, good) == before
    assert _tree(out_dir) == out_before and not [p for p in Path(out_dir).rglob(".*tmp*")]
    return errors[0]


# ------------------------------------------------------------------------------- corpus files
@pytest.mark.parametrize("name,fragment", sorted(MESH_CASES.items()))
def test_bad_target_mesh(capsys, good, tmp_path, name, fragment):
    refused(capsys, ["animate", BAD / name, "--weights", good / "w.csv", "-o", tmp_path / "o.obj"],
            [BAD / name], fragment, good, tmp_path)


@pytest.mark.parametrize("name", ["nan.obj", "truncated.glb", "point_cloud.ply", "degenerate.obj"])
def test_bad_source_mesh(capsys, good, tmp_path, name):
    refused(capsys, ["transfer", BAD / name, good / "target.obj", "-o", tmp_path / "o.obj"],
            [BAD / name], MESH_CASES[name], good, tmp_path)


@pytest.mark.parametrize("folder,fragment", [("seq_counts", "has 4 vertices but"),
                                             ("seq_faces", "faces differ")])
def test_frames_that_do_not_match(capsys, good, tmp_path, folder, fragment):
    for cmd in (["transfer", BAD / folder, good / "target.obj", "-o", tmp_path / "frames"],
                ["invert", BAD / folder, "-o", tmp_path / "w.csv"]):
        refused(capsys, cmd, [BAD / folder / "frame_2.obj"], fragment, good, tmp_path)


@pytest.mark.parametrize("name,fragment", sorted(WEIGHT_CASES.items()))
def test_bad_weight_file(capsys, good, tmp_path, name, fragment):
    for cmd in ("animate", "export-rig"):
        out = tmp_path / ("o.obj" if cmd == "animate" else "o.glb")
        refused(capsys, [cmd, good / "target.obj", "--weights", BAD / name, "-o", out],
                [BAD / name], fragment, good, tmp_path)


# ------------------------------------------------------------------------------- outputs
def test_output_that_is_an_input(capsys, good, tmp_path):
    src, tgt, w = good / "source.obj", good / "target.obj", good / "w.csv"
    refused(capsys, ["transfer", src, tgt, "-o", tgt], [tgt], "refusing to overwrite the input",
            good, tmp_path)
    refused(capsys, ["transfer", src, tgt, "-o", src], [src], "refusing to overwrite the input",
            good, tmp_path)
    os.link(tgt, tmp_path / "hardlink.obj")  # another name of the same file
    refused(capsys, ["animate", tgt, "--weights", w, "-o", tmp_path / "hardlink.obj"],
            ["hardlink.obj"], "refusing to overwrite the input", good, tmp_path)
    refused(capsys, ["invert", src, "-o", src], [src], "written as .csv, not .obj", good, tmp_path)
    refused(capsys, ["export-rig", tgt, "-o", tmp_path / "rig.obj"], ["rig.obj"], "written as .glb",
            good, tmp_path)
    refused(capsys, ["animate", tgt, "--weights", w, "-o", tmp_path / "o.csv"], ["o.csv"],
            "cannot write .csv", good, tmp_path)
    (tmp_path / "plainfile").write_text("x")
    refused(capsys, ["transfer", src, tgt, "-o", tmp_path / "plainfile"], ["plainfile"],
            "exists and is not a folder", good, tmp_path)


def test_read_only_output_folder(capsys, good, tmp_path, monkeypatch):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    if os.geteuid() == 0:  # root writes anyway: make the folder refuse the temporary file
        real = tempfile.mkstemp

        def mkstemp(*a, dir=None, **k):
            if Path(dir) == ro:
                raise PermissionError(13, "Permission denied")
            return real(*a, dir=dir, **k)
        monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    try:
        refused(capsys, ["transfer", good / "source.obj", good / "target.obj", "-o", ro / "o.obj"],
                [ro / "o.obj"], "cannot write to folder", good, tmp_path)
        refused(capsys, ["invert", good / "source.obj", "-o", ro / "w.csv"], [ro / "w.csv"],
                "cannot write to folder", good, tmp_path)
    finally:
        ro.chmod(0o755)


# ------------------------------------------------------------------------------- sizes and shapes
def test_ten_million_vertices_refused_up_front(capsys, good, tmp_path):
    """A binary PLY announcing 10M vertices (sparse file): refused before parsing, with the memory it
    would need; --force goes on to parse it (and finds it truncated)."""
    huge = tmp_path / "in" / "huge.ply"
    huge.parent.mkdir()
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 10000001\nproperty float x\n"
              b"property float y\nproperty float z\nelement face 0\nproperty list uchar int "
              b"vertex_indices\nend_header\n")
    with open(huge, "wb") as fh:
        fh.write(header)
        fh.truncate(80_000_100)  # holes: no disk used
    out = tmp_path / "out"
    out.mkdir()
    msg = refused(capsys, ["animate", huge, "--weights", good / "w.csv", "-o", out / "o.obj"],
                  [huge], "10,000,001 vertices is above the limit", good, out)
    assert "GiB of memory" in msg and "--force" in msg
    refused(capsys, ["animate", huge, "--weights", good / "w.csv", "-o", out / "o.obj", "--force"],
            [huge], "cannot read as PLY", good, out)


def test_objects_that_are_not_faces(capsys, good, tmp_path):
    plate = head_mesh(2)
    save_mesh(tmp_path / "plate.obj", plate.vertices * [1.0, 1.0, 0.02], plate.faces)
    save_mesh(tmp_path / "ico.obj", head_mesh(0))
    out = tmp_path / "out"
    out.mkdir()
    for cmd in (["animate", tmp_path / "plate.obj", "--weights", good / "w.csv", "-o", out / "o.obj"],
                ["transfer", tmp_path / "plate.obj", good / "target.obj", "-o", out / "o.obj"],
                ["invert", tmp_path / "plate.obj", "-o", out / "w.csv"]):
        refused(capsys, cmd, [tmp_path / "plate.obj"], "not a face-sized object", good, out)
    refused(capsys, ["export-rig", tmp_path / "ico.obj", "-o", out / "rig.glb"], [tmp_path / "ico.obj"],
            "only 12 vertices", good, out)


def test_bad_axes(capsys, good, tmp_path):
    base = ["transfer", good / "source.obj", good / "target.obj", "-o", tmp_path / "o.obj"]
    refused(capsys, base + ["--up", "+w"], [], "--up '+w': expected one of", good, tmp_path)
    refused(capsys, base + ["--up", "+y", "--forward", "-y"], [], "must be different axes", good, tmp_path)


def test_empty_folder_and_glob(capsys, good, tmp_path):
    (tmp_path / "empty").mkdir()
    refused(capsys, ["invert", tmp_path / "empty", "-o", tmp_path / "w.csv"], [tmp_path / "empty"],
            "no mesh files", good, tmp_path)
    refused(capsys, ["transfer", f"{tmp_path}/none_*.obj", good / "target.obj", "-o", tmp_path / "o.obj"],
            ["none_*.obj"], "no mesh files", good, tmp_path)


# ------------------------------------------------------------------------------- checkpoints
def test_bad_checkpoints(capsys, good, tmp_path, monkeypatch):
    base = ["animate", good / "target.obj", "--weights", good / "w.csv", "-o", tmp_path / "o.obj"]
    wider = tiny_checkpoint(tmp_path / "wider.pt", enc_width=32)
    state = torch.load(wider, weights_only=True)
    state["model_config"]["enc_width"] = 16  # claims the tiny config, holds other weights
    torch.save(state, tmp_path / "other_config.pt")
    state["train_config"] = {"evil": Path("x")}  # a pickled object: refused by weights_only
    torch.save(state, tmp_path / "tampered.pt")
    (tmp_path / "garbage.pt").write_bytes(b"not a checkpoint at all")
    cases = {"other_config.pt": "checkpoint does not match", "tampered.pt": "holds pickled code",
             "garbage.pt": "not a loadable checkpoint", "missing.pt": "checkpoint not found"}
    for name, fragment in cases.items():
        refused(capsys, base + ["--checkpoint", tmp_path / name], [tmp_path / name], fragment, good,
                tmp_path)
    assert not (tmp_path / "o.obj").exists()
    monkeypatch.setattr(api, "default_checkpoint_path", lambda: tmp_path / "bundled" / "default.pt")
    msg = refused(capsys, base, [], "no bundled checkpoint at", good, tmp_path, bundled=True)
    assert "retarget train" in msg and "--checkpoint" in msg and "default.pt" in msg



# ------------------------------------------------------------------------------- hostile inputs
@pytest.fixture
def no_hang():
    """Fail (instead of blocking the suite forever) if a command waits on a FIFO or device."""
    import signal

    def hung(signum, frame):
        raise AssertionError("the command blocked (read a FIFO or device?)")
    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(60)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


def test_special_files_are_refused(capsys, good, tmp_path, no_hang):
    """FIFOs, devices and symlink loops given as a mesh, weights or checkpoint: named, never read."""
    d = tmp_path / "special"
    d.mkdir()
    for name in ("pipe.obj", "pipe.csv", "pipe.pt"):
        os.mkfifo(d / name)
    os.symlink("/dev/zero", d / "zero.obj")
    os.symlink("/dev/zero", d / "zero.json")
    os.symlink("loop_b.obj", d / "loop_a.obj")
    os.symlink("loop_a.obj", d / "loop_b.obj")
    os.symlink("loop_d.csv", d / "loop_c.csv")
    os.symlink("loop_c.csv", d / "loop_d.csv")
    out = tmp_path / "out"
    out.mkdir()
    w, tgt = good / "w.csv", good / "target.obj"
    cases = [(["animate", d / "pipe.obj", "--weights", w], d / "pipe.obj", "is a named pipe (FIFO)"),
             (["animate", tgt, "--weights", d / "pipe.csv"], d / "pipe.csv", "is a named pipe (FIFO)"),
             (["animate", tgt, "--weights", w, "--checkpoint", d / "pipe.pt"], d / "pipe.pt",
              "is a named pipe (FIFO)"),
             (["animate", d / "zero.obj", "--weights", w], d / "zero.obj", "is a device"),
             (["animate", tgt, "--weights", d / "zero.json"], d / "zero.json", "is a device"),
             (["animate", d / "loop_a.obj", "--weights", w], d / "loop_a.obj", "is a symlink loop"),
             (["animate", tgt, "--weights", d / "loop_c.csv"], d / "loop_c.csv", "is a symlink loop")]
    for argv, name, fragment in cases:
        refused(capsys, argv + ["-o", out / "o.obj"], [name], fragment, good, out)
    refused(capsys, ["transfer", good / "source.obj", tgt, "-o", d / "loop_a.obj"], [d / "loop_a.obj"],
            "is a symlink loop", good, out)


def test_glb_buffer_through_a_link_or_fifo(capsys, good, tmp_path, no_hang):
    """A .gltf whose relative buffer URI is a FIFO in its folder, or a link to a device or to a file
    outside its folder."""
    gltf = (BAD / "buffer_device.gltf").read_text()
    d = tmp_path / "scene"
    d.mkdir()
    os.mkfifo(d / "pipe.bin")
    os.symlink("/dev/zero", d / "zero.bin")
    (tmp_path / "secret.bin").write_bytes(b"\0" * 64)
    os.symlink(tmp_path / "secret.bin", d / "elsewhere.bin")
    for name in ("pipe", "zero", "elsewhere"):
        (d / f"{name}.gltf").write_text(gltf.replace("/dev/zero", f"{name}.bin"))
    out = tmp_path / "out"
    out.mkdir()
    for name, fragment in (("pipe.gltf", "is a named pipe (FIFO)"),
                           ("zero.gltf", "points outside the glTF's folder"),
                           ("elsewhere.gltf", "points outside the glTF's folder")):
        refused(capsys, ["animate", d / name, "--weights", good / "w.csv", "-o", out / "o.obj"],
                [d / name, "buffer 0"], fragment, good, out)


def test_an_existing_name_with_glob_characters_is_taken_literally(good, tmp_path):
    from retarget.io import sequence_files

    shutil_copy = (good / "source.obj").read_bytes()
    (tmp_path / "a[1].obj").write_bytes(shutil_copy)
    (tmp_path / "a1.obj").write_bytes(shutil_copy)
    assert sequence_files(tmp_path / "a[1].obj") == [tmp_path / "a[1].obj"]
    assert sequence_files(f"{tmp_path}/a[12].obj") == [tmp_path / "a1.obj"]  # not a file: a pattern


def test_outputs_that_are_not_files_of_the_command(capsys, good, tmp_path, monkeypatch):
    """``-o -`` (no folder named - is made) and extensions that are not the command's."""
    monkeypatch.chdir(tmp_path)
    src, tgt, w = good / "source.obj", good / "target.obj", good / "w.csv"
    for argv in (["transfer", src, tgt], ["animate", tgt, "--weights", w], ["invert", src]):
        refused(capsys, argv + ["-o", "-"], [], "standard output is not supported", good, tmp_path)
    refused(capsys, ["export-rig", tgt, "-o", "-"], [], "-: the rig is written as .glb", good, tmp_path)
    refused(capsys, ["invert", src, "-o", tmp_path / "x.obj"], ["x.obj"], "written as .csv, not .obj",
            good, tmp_path)
    refused(capsys, ["invert", src, "-o", tmp_path / "w"], [tmp_path / "w"], "written as .csv",
            good, tmp_path)
    refused(capsys, ["train", "--config", "tiny", "--out", "-"], [], "written to a folder", good,
            tmp_path, bundled=True)
    assert list(tmp_path.iterdir()) == []


def test_a_take_is_never_mixed_with_older_frames(capsys, good, tmp_path):
    take = tmp_path / "take"
    take.mkdir()
    for t in range(5):
        (take / f"frame_{t:04d}.obj").write_text("older take")
    (tmp_path / "w2.csv").write_text("jawOpen\n0.5\n0.2\n")
    refused(capsys, ["animate", good / "target.obj", "--weights", tmp_path / "w2.csv", "-o", take],
            [take / "frame_0000.obj"], "holds frames already (5 frame files)", good, tmp_path)


@pytest.mark.parametrize("fps", ["0", "-30", "nan", "inf", "abc"])
def test_frame_rates_must_be_positive(capsys, good, tmp_path, fps):
    src, tgt = good / "source.obj", good / "target.obj"
    for argv in (["transfer", src, tgt, "-o", tmp_path / "o.obj"],
                 ["invert", src, "-o", tmp_path / "w.csv", "--smooth", "one_euro"],
                 ["invert", src, "-o", tmp_path / "w.csv"]):
        refused(capsys, argv + [f"--fps={fps}"], [f"--fps {fps}"], "frame rate must be a finite number "
                "above 0", good, tmp_path)


def test_training_numbers_and_run_folders(capsys, good, tmp_path):
    """Steps, learning rate, config values; --out over another run's files without --resume."""
    out = tmp_path / "run"
    base = ["train", "--config", "tiny", "--out", out, "--no-progress"]
    for extra, fragment in ((["--steps", "-3"], "--steps -3: must be at least 1"),
                            (["--steps", "0"], "--steps 0: must be at least 1"),
                            (["--steps", "abc"], "argument --steps: invalid int value: 'abc'"),
                            (["--lr=-1e-3"], "--lr must be > 0"),
                            (["--lr", "nan"], "--lr must be > 0"),
                            (["--max-minutes", "nan"], "--max-minutes must be >= 0")):
        refused(capsys, base + extra, [], fragment, good, tmp_path, bundled=True)
    for text, fragment in (("train: {steps: abc}", "train.steps must be an integer >= 1, got 'abc'"),
                           ("train: {steps: 0}", "train.steps must be an integer >= 1, got '0'"),
                           ("optim: {lr: -0.001}", "optim.lr must be a number > 0.0"),
                           ("data: {rig_mix: 2}", "data.rig_mix must be a number >= 0.0 and <= 1.0")):
        cfg = tmp_path / "bad.yaml"
        cfg.write_text(f"base: {Path(__file__).parents[1] / 'configs/train/tiny.yaml'}\n{text}\n")
        refused(capsys, ["train", "--config", cfg, "--out", out], [cfg], fragment, good, tmp_path,
                bundled=True)
        cfg.unlink()
    out.mkdir()
    for name in ("model.pt", "train_log.csv"):  # another run's outputs, without its last.pt
        (out / name).write_text("another run")
        refused(capsys, base, [out / name], "another run's output is in", good, tmp_path, bundled=True)
        refused(capsys, base + ["--resume"], [out / name], "without the last.pt", good, tmp_path,
                bundled=True)
        (out / name).unlink()
    (tmp_path / "file").write_text("x")
    refused(capsys, ["train", "--config", "tiny", "--out", tmp_path / "file"], [tmp_path / "file"],
            "exists and is not a folder", good, tmp_path, bundled=True)


def test_checkpoint_configs_are_not_trusted(capsys, good, tmp_path, no_hang):
    """Absurd or wrongly typed config values and fields: refused on load, quickly, in one line."""
    state = torch.load(good / "tiny.pt", weights_only=True)
    cases = {"huge_k_eig": ({"model_config": {**state["model_config"], "k_eig": 10**9}},
                            "NFSConfig.k_eig: expected an int in 1..512, got '1000000000'"),
             "string_config": ({"model_config": "tiny"}, "model_config is a str, not a mapping"),
             "float_width": ({"model_config": {**state["model_config"], "enc_width": 16.5}},
                             "NFSConfig.enc_width: expected an int"),
             "wide_claim": ({"model_config": {**state["model_config"], "decoder_width": 2048}},
                            "checkpoint does not match this version's model"),
             "channels": ({"model_config": {**state["model_config"], "image_channels": 3}},
                          "image_channels 3"),
             "string_step": ({"step": "many"}, "step 'many' is not an integer >= 0"),
             "weights_list": ({"model": [1, 2, 3]}, "model is not a mapping of names to tensors")}
    out = tmp_path / "out"
    out.mkdir()
    for name, (change, fragment) in cases.items():
        torch.save({**state, **change}, tmp_path / f"{name}.pt")
        refused(capsys, ["animate", good / "target.obj", "--weights", good / "w.csv", "-o", out / "o.obj",
                         "--checkpoint", tmp_path / f"{name}.pt"], [tmp_path / f"{name}.pt"], fragment,
                good, out)


def test_python_warnings_never_precede_the_error(capsys, good, tmp_path, monkeypatch):
    """A numpy/torch warning raised before a user error is not printed; after a command that
    succeeds it is, as one ``warning:`` line; the project's own warnings print at once."""
    import warnings

    from retarget.commands import invert
    from retarget.errors import RetargetError, RetargetWarning

    def failing(args):
        warnings.warn("overflow encountered in cast", RuntimeWarning)
        raise RetargetError(f"{args.frames}: refused")
    monkeypatch.setattr(invert, "run", failing)
    msg = refused(capsys, ["invert", good / "source.obj", "-o", tmp_path / "w.csv"], [good / "source.obj"],
                  "refused", good, tmp_path)
    assert "overflow" not in capsys.readouterr().err + msg

    def working(args):
        warnings.warn("overflow encountered in cast", RuntimeWarning)
        warnings.warn("two heads?", RetargetWarning)
        print("done")
        return 0
    monkeypatch.setattr(invert, "run", working)
    assert main(["invert", str(good / "source.obj"), "-o", str(tmp_path / "w.csv")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["warning: two heads?", "warning: overflow encountered in cast"]


def test_a_huge_take_is_refused_before_any_work(capsys, good, tmp_path, monkeypatch):
    """100,000 frames of weights: the size of the take is estimated first (a sequence GLB is
    built in memory whole; frame files must fit on the disk)."""
    import shutil
    from collections import namedtuple

    from retarget import api as api_module

    big = tmp_path / "in" / "long.csv"
    big.parent.mkdir()
    big.write_text("jawOpen\n" + "0.5\n" * 100_000)
    out = tmp_path / "out"
    out.mkdir()
    monkeypatch.setattr(api_module.Retargeter, "prepare", lambda *a: pytest.fail("work was started"))
    msg = refused(capsys, ["animate", good / "target.obj", "--weights", big, "-o", out / "take.glb"],
                  [out / "take.glb"], "100,000 frame(s) of 162 vertices as one GLB would need about",
                  good, out)
    assert "export-rig --weights" in msg and "--force" in msg
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**9, 10**9 - 10**6, 10**6))
    refused(capsys, ["animate", good / "target.obj", "--weights", big, "-o", out / "frames"],
            [out / "frames"], "GB free", good, out)
    monkeypatch.setattr(api_module.Retargeter, "expression_codes",
                        lambda *a, **k: pytest.fail("work was started"))
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**9, 10**9 - 10, 10))
    refused(capsys, ["transfer", good / "source.obj", good / "target.obj", "-o", out / "t.obj"],
            [out / "t.obj"], "1 frame(s) of 162 vertices would take about", good, out)


def test_other_commands_refuse_special_names(capsys, good, tmp_path, monkeypatch, no_hang):
    """demo / synth with ``-o -``; a FIFO given as a training config or a rig."""
    monkeypatch.chdir(tmp_path)
    refused(capsys, ["demo", "-o", "-"], [], "standard output is not supported", good, tmp_path)
    refused(capsys, ["synth", "--preview", "--out", "-"], [], "standard output is not supported", good,
            tmp_path, bundled=True)
    os.mkfifo(tmp_path / "cfg.yaml")
    os.mkfifo(tmp_path / "rig.npz")
    refused(capsys, ["train", "--config", tmp_path / "cfg.yaml", "--out", tmp_path / "run"],
            [tmp_path / "cfg.yaml"], "is a named pipe (FIFO)", good, tmp_path, bundled=True)
    refused(capsys, ["train", "--rig", tmp_path / "rig.npz", "--init", good / "tiny.pt", "--steps", "1",
                     "--out", tmp_path / "run"], [tmp_path / "rig.npz"], "is a named pipe (FIFO)", good,
            tmp_path, bundled=True)
    refused(capsys, ["eval", "--checkpoint", f"tiny={good / 'tiny.pt'}", "--config", "tiny",
                     "--suite", "real_rig", "--real-rig", tmp_path / "rig.npz", "--out",
                     tmp_path / "eval"], [tmp_path / "rig.npz"], "is a named pipe (FIFO)", good,
            tmp_path)
    capsys.readouterr()
    assert main(["calibrate", "--rig", str(tmp_path / "rig.npz")]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "rig.npz") in err and "is a named pipe (FIFO)" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cfg.yaml", "rig.npz"]
