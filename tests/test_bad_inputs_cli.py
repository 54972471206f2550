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
    argv = [str(a) for a in argv] + ["--device", "cpu"]
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

