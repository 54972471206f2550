"""The user's own rig: the three layouts, name mapping, errors, vertex ranges, the rig sampler,
the masked losses, and fine-tuning lowering the MakeHuman ARKit rig's self-retargeting error."""
from pathlib import Path

import numpy as np
import pytest
import torch

from data_synth.facs import FACS_INDEX, FACS_NAMES, N_FACS
from data_synth.identity import sample_identity
from data_synth.rig import build_rig
from data_synth.tessellate import tessellate
from retarget.api import Retargeter
from retarget.errors import RetargetError
from retarget.io import save_mesh
from retarget.mesh import Mesh
from retarget.train import Trainer, group_losses, load_config
from retarget.training_data import RigPool
from retarget.user_rig import UnknownShapeWarning, keep_range, load_user_rig, side_weights

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "configs" / "train" / "tiny.yaml"
MAKEHUMAN = ROOT.parent / "shared" / "rigs" / "makehuman_arkit.npz"


@pytest.fixture(scope="module")
def proc_rig():
    """A procedural rig on a 400-vertex tessellation (cm, ICT order)."""
    return build_rig(sample_identity(3, split="test"), tessellate(400, kind="regular", seed=0))


def write_folder(folder: Path, neutral_name: str, vertices, faces, shapes: dict) -> Path:
    """A rig folder: the neutral and one OBJ per shape (the full shaped mesh)."""
    folder.mkdir(parents=True, exist_ok=True)
    save_mesh(folder / f"{neutral_name}.obj", vertices, faces)
    for name, delta in shapes.items():
        save_mesh(folder / f"{name}.obj", vertices + delta, faces)
    return folder


def save_npz(path: Path, rig, names, **extra) -> Path:
    np.savez(path, neutral=rig.neutral, faces=rig.faces, names=np.array(names),
             deltas=rig.deltas[[FACS_INDEX[n] for n in names]], **extra)
    return path


# ------------------------------------------------------------------------------------- layouts
def test_npz_and_ict_folder_give_the_same_rig(tmp_path, proc_rig):
    names = list(FACS_NAMES)
    from_npz = load_user_rig(save_npz(tmp_path / "rig.npz", proc_rig, names))
    folder = write_folder(tmp_path / "rig", "neutral", proc_rig.neutral, proc_rig.faces,
                          dict(zip(names, proc_rig.deltas)))
    from_folder = load_user_rig(folder)
    for rig in (from_npz, from_folder):
        assert rig.present.all() and rig.identity is None and rig.segments is None
        np.testing.assert_array_equal(rig.faces, proc_rig.faces)
        np.testing.assert_allclose(rig.deltas, proc_rig.deltas, atol=1e-5)
    w = np.random.default_rng(0).uniform(0, 1, N_FACS)
    np.testing.assert_allclose(from_folder.evaluate(w), proc_rig.evaluate(w), atol=1e-4)


def test_arkit_names_map_to_ict_slots_and_the_merged_shapes_split_by_side(tmp_path, proc_rig):
    d = proc_rig.deltas
    shapes = {"jawOpen": d[FACS_INDEX["jawOpen"]], "mouthSmileLeft": d[FACS_INDEX["mouthSmile_L"]],
              "EYEBLINKRIGHT": d[FACS_INDEX["eyeBlink_R"]], "tongueOut": 0 * d[0],
              "browInnerUp": d[FACS_INDEX["browInnerUp_L"]] + d[FACS_INDEX["browInnerUp_R"]]}
    rig = load_user_rig(write_folder(tmp_path / "arkit", "neutral", proc_rig.neutral,
                                     proc_rig.faces, shapes))
    expected = {"jawOpen", "mouthSmile_L", "eyeBlink_R", "browInnerUp_L", "browInnerUp_R"}
    assert {FACS_NAMES[i] for i in np.flatnonzero(rig.present)} == expected
    for ict, arkit in (("jawOpen", "jawOpen"), ("mouthSmile_L", "mouthSmileLeft"),
                       ("eyeBlink_R", "EYEBLINKRIGHT")):
        np.testing.assert_allclose(rig.deltas[FACS_INDEX[ict]], shapes[arkit], atol=1e-5)
    left, right = rig.deltas[FACS_INDEX["browInnerUp_L"]], rig.deltas[FACS_INDEX["browInnerUp_R"]]
    np.testing.assert_allclose(left + right, shapes["browInnerUp"], atol=1e-5)
    x = rig.neutral[:, 0] - 0.5 * (rig.neutral[:, 0].min() + rig.neutral[:, 0].max())
    assert np.abs(left[x < -0.5]).max() == 0 and np.abs(right[x > 0.5]).max() == 0
    assert np.abs(left[x > 0.5]).max() > 0.05 and np.abs(right[x < -0.5]).max() > 0.05
    s = side_weights(rig.neutral)
    assert s.min() == 0 and s.max() == 1 and np.all(np.diff(s[np.argsort(x)]) >= 0)


def test_facexmodel_folder_with_quads_and_identity_shapes(tmp_path):
    n = 12
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    neutral = np.stack([8 * u.ravel(), 10 * v.ravel(), 3 * np.cos(u.ravel())], 1)
    quads = np.array([[i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j]
                      for i in range(n - 1) for j in range(n - 1)])
    rng = np.random.default_rng(1)
    shapes = {"jawOpen": rng.normal(size=neutral.shape), "mouthPucker": rng.normal(size=neutral.shape),
              "identity000": rng.normal(size=neutral.shape), "identity001": rng.normal(size=neutral.shape)}
    folder = tmp_path / "FaceXModel"
    folder.mkdir()

    def write_quads(path, verts):
        lines = [f"v {a:.6f} {b:.6f} {c:.6f}" for a, b, c in verts]
        lines += ["f " + " ".join(str(i + 1) for i in q) for q in quads]
        path.write_text("\n".join(lines) + "\n")

    write_quads(folder / "generic_neutral_mesh.obj", neutral)
    for name, delta in shapes.items():
        write_quads(folder / f"{name}.obj", neutral + delta)
    (folder / "vertex_indices.json").write_text("{}")
    rig = load_user_rig(folder)
    assert rig.faces.shape == (2 * len(quads), 3) and rig.n_vertices == n * n
    np.testing.assert_allclose(rig.neutral, neutral, atol=1e-5)
    assert [FACS_NAMES[i] for i in np.flatnonzero(rig.present)] == ["jawOpen", "mouthPucker"]
    np.testing.assert_allclose(rig.deltas[FACS_INDEX["mouthPucker"]], shapes["mouthPucker"], atol=1e-5)
    assert rig.identity_deltas.shape == (2, n * n, 3)
    np.testing.assert_allclose(rig.identity_deltas[1], shapes["identity001"], atol=1e-5)


# ------------------------------------------------------------------------------------- errors
def test_unknown_names_are_left_out_or_refused_duplicates_and_vertex_counts_refused(tmp_path, proc_rig):
    d = proc_rig.deltas[0]
    folder = write_folder(tmp_path / "bad", "neutral", proc_rig.neutral, proc_rig.faces,
                          {"jawOpen": d, "smileBig": d, "frown": d})
    with pytest.warns(UnknownShapeWarning, match=r"bad: left out 2 shapes that have no ICT or "
                                                 r"ARKit name: frown, smileBig$") as caught:
        rig = load_user_rig(folder)
    assert len(caught) == 1 and [FACS_NAMES[i] for i in np.flatnonzero(rig.present)] == ["jawOpen"]
    with pytest.raises(RetargetError, match=r"bad: unknown blendshape names frown, smileBig"):
        load_user_rig(folder, strict=True)
    npz = _renamed_npz(tmp_path / "bad.npz", proc_rig, ["jawOpen", "notAShape"])
    with pytest.warns(UnknownShapeWarning, match=r"bad.npz: left out 1 shapes .*: notAShape"):
        load_user_rig(npz)
    with pytest.raises(RetargetError, match=r"unknown blendshape names notAShape"):
        load_user_rig(npz, strict=True)
    only_unknown = _renamed_npz(tmp_path / "none.npz", proc_rig, [f"corrective{i:02d}" for i in range(20)])
    with pytest.raises(RetargetError, match=r"none.npz: unknown blendshape names corrective00, .*"
                                            r"corrective11 and 8 more \(expected ICT"):
        load_user_rig(only_unknown)                     # nothing known at all: refused
    with pytest.raises(RetargetError, match=r"'browInnerUp'.*browInnerUp_L|'browInnerUp_L'.*browInnerUp"):
        load_user_rig(write_folder(tmp_path / "dup", "neutral", proc_rig.neutral, proc_rig.faces,
                                   {"browInnerUp": d, "browInnerUp_L": d}))
    short = write_folder(tmp_path / "short", "neutral", proc_rig.neutral, proc_rig.faces, {"jawOpen": d})
    fewer = proc_rig.faces[np.all(proc_rig.faces < len(d) - 5, axis=1)]
    save_mesh(short / "jawOpen.obj", proc_rig.neutral[:-5], fewer)
    with pytest.raises(RetargetError, match=rf"jawOpen\.obj: {len(d) - 5} vertices.*neutral\.obj has {len(d)}"):
        load_user_rig(short)
    with pytest.raises(RetargetError, match="no such rig"):
        load_user_rig(tmp_path / "missing.npz")
    with pytest.raises(RetargetError, match="names given twice: jawOpen"):
        load_user_rig(_renamed_npz(tmp_path / "twice.npz", proc_rig, ["jawOpen", "jawOpen"]))
    (tmp_path / "junk.npz").write_bytes(b"not an npz")
    with pytest.raises(RetargetError, match="junk.npz: not a readable rig npz"):
        load_user_rig(tmp_path / "junk.npz")
    np.savez(tmp_path / "nodeltas.npz", neutral=proc_rig.neutral, faces=proc_rig.faces)
    with pytest.raises(RetargetError, match="nodeltas.npz: rig npz lacks names, deltas"):
        load_user_rig(tmp_path / "nodeltas.npz")


def _renamed_npz(path, rig, names):
    np.savez(path, neutral=rig.neutral, faces=rig.faces, names=np.array(names),
             deltas=rig.deltas[:len(names)])
    return path


def test_keep_vertices_restricts_and_reindexes(tmp_path, proc_rig):
    labels = np.eye(20)[proc_rig.segments]                       # (V, L) memberships
    rig = load_user_rig(save_npz(tmp_path / "rig.npz", proc_rig, ["jawOpen", "eyeBlink_L"],
                                 segments=labels, identity_deltas=proc_rig.deltas[:3]))
    np.testing.assert_array_equal(rig.segments, proc_rig.segments)
    a, b = 50, 300
    cut = load_user_rig(tmp_path / "rig.npz", keep_vertices=f"{a}:{b}")
    inside = np.all((proc_rig.faces >= a) & (proc_rig.faces < b), axis=1)
    np.testing.assert_array_equal(cut.faces, proc_rig.faces[inside] - a)
    np.testing.assert_array_equal(cut.neutral, proc_rig.neutral[a:b])
    np.testing.assert_array_equal(cut.deltas[FACS_INDEX["jawOpen"]], proc_rig.deltas[FACS_INDEX["jawOpen"], a:b])
    assert cut.segments.shape == (b - a,) and cut.identity_deltas.shape == (3, b - a, 3)
    assert keep_range(rig, ":300").n_vertices == 300 and keep_range(rig, "100:").n_vertices == len(rig.neutral) - 100
    for spec in ("10-20", "300:50", f"0:{len(rig.neutral) + 1}"):
        with pytest.raises(RetargetError, match="rig.npz"):
            keep_range(rig, spec)


# ------------------------------------------------------------------------------------- training
def rig_cfg(rig_path, mix=1.0, steps=6):
    cfg = load_config(TINY)
    cfg["data"].update(rig=str(rig_path), rig_mix=mix)
    cfg["train"]["steps"] = steps
    return cfg


def test_rig_sampler_is_deterministic_masks_absent_shapes_and_mixes(tmp_path, proc_rig):
    names = ["jawOpen", "mouthSmile_L", "mouthSmile_R", "eyeBlink_L"]
    path = save_npz(tmp_path / "partial.npz", proc_rig, names)
    cfg = rig_cfg(path, mix=0.5)
    a, b = (RigPool(cfg["data"], Trainer(cfg, tmp_path / "x", progress=False).model_cfg, 0)
            for _ in range(2))
    kinds = []
    for step in range(8):
        ga, gb = a.sample(step), b.sample(step)
        np.testing.assert_array_equal(ga.gt_dv, gb.gt_dv)
        np.testing.assert_array_equal(ga.sources[0].feat, gb.sources[0].feat)
        kinds.append(ga.target is a.entry)
        if ga.target is a.entry:
            w = np.stack([s.weights for s in ga.sources])
            assert np.all(w[:, ~a.entry.present] == 0) and w.max() > 0
    assert any(kinds) and not all(kinds)


def test_losses_on_a_partial_rig_skip_id_and_nll_and_mask_absent_shapes(tmp_path, proc_rig):
    path = save_npz(tmp_path / "partial.npz", proc_rig, ["jawOpen", "mouthPucker", "eyeBlink_R"])
    cfg = rig_cfg(path)
    trainer = Trainer(cfg, tmp_path / "run", progress=False)
    group = trainer.pool.sample(0)
    losses = group_losses(trainer.model, group, cfg["loss"], 0, np.random.default_rng(0), "cpu")
    assert "L_ID" not in losses and "L_nll" not in losses
    assert torch.isfinite(losses["total"])
    present = group.target.present
    with torch.no_grad():
        model = trainer.model
        z = torch.stack([model.encode_expression(torch.from_numpy(s.feat), model.image_code(
            torch.from_numpy(s.image)[None])[0], s.entry.mesh.ops.to_torch("cpu")) for s in group.sources])
    w = np.stack([s.weights for s in group.sources])
    zn = z.numpy()
    expected = (((zn[:, :N_FACS][:, present] - w[:, present]) ** 2).sum(1)
                + (zn[:, N_FACS:] ** 2).sum(1)).mean()  # eq. 4: summed over the supervised dims
    assert losses["L_Exp"].item() == pytest.approx(expected, rel=1e-4)


def test_rig_run_resumes_exactly(tmp_path, proc_rig):
    path = save_npz(tmp_path / "partial.npz", proc_rig, ["jawOpen", "mouthPucker", "eyeBlink_R"])
    full = Trainer(rig_cfg(path, steps=4), tmp_path / "full", progress=False)
    full.run()
    Trainer(rig_cfg(path, steps=4), tmp_path / "half", progress=False).run(stop_at=2)
    resumed = Trainer(rig_cfg(path, steps=4), tmp_path / "half", progress=False)
    assert resumed.resume() and resumed.step == 2
    resumed.run()
    a, b = full.model.state_dict(), resumed.model.state_dict()
    assert all(torch.allclose(a[k], b[k], atol=1e-6) for k in a)
    start = Trainer(rig_cfg(path), tmp_path / "fresh", progress=False).model.state_dict()
    assert not torch.equal(a["decoder.0.weight"], start["decoder.0.weight"]), "no training happened"


def test_model_mismatch_with_init_checkpoint_is_refused(tmp_path):
    cfg = load_config(TINY)
    Trainer(cfg, tmp_path / "a", progress=False).export(tmp_path / "tiny.pt")
    other = load_config(TINY)
    other["model"] = {"preset": "tiny", "decoder_width": 16}
    with pytest.raises(RetargetError, match="tiny.pt: the checkpoint's model does not match"):
        Trainer(other, tmp_path / "b", init=tmp_path / "tiny.pt", progress=False)


def self_retargeting_mse_mm2(checkpoint, rig, weights) -> float:
    """Mean over the weight vectors (T,53) of the per-vertex squared error (mm², rig in cm) of
    retargeting the rig's own frames onto its neutral with ``Retargeter``."""
    r = Retargeter.load(checkpoint)
    target = r.prepare(Mesh(rig.neutral, rig.faces, "neutral"))
    errs = []
    for w in weights:
        frame = rig.evaluate(w)
        pred = r.transfer(Mesh(frame, rig.faces, "frame"), target)
        errs.append((((pred - frame) * 10.0) ** 2).sum(-1).mean())
    return float(np.mean(errs))


@pytest.mark.skipif(not MAKEHUMAN.is_file(), reason="shared/rigs/makehuman_arkit.npz not present")
def test_finetuning_lowers_the_makehuman_self_retargeting_error(tmp_path, capsys):
    from retarget.cli import main

    torch.manual_seed(0)
    Trainer(load_config(TINY), tmp_path / "init", progress=False).export(tmp_path / "init.pt")
    rig = load_user_rig(MAKEHUMAN)
    weights = np.zeros((4, N_FACS), np.float32)
    weights[0, FACS_INDEX["jawOpen"]] = 1.0
    weights[1, [FACS_INDEX["mouthSmile_L"], FACS_INDEX["mouthSmile_R"]]] = 1.0
    weights[2, [FACS_INDEX["eyeBlink_L"], FACS_INDEX["browInnerUp_L"], FACS_INDEX["browInnerUp_R"]]] = 1.0
    weights[3] = np.random.default_rng(5).uniform(0, 0.5, N_FACS)
    before = self_retargeting_mse_mm2(tmp_path / "init.pt", rig, weights)

    cfg = rig_cfg(MAKEHUMAN, mix=0.8, steps=40)
    cfg["optim"].update(lr=3e-3, warmup_steps=5)
    cfg["train"]["val_every"] = 1000
    Trainer(cfg, tmp_path / "ft", init=tmp_path / "init.pt", progress=False).run()
    after = self_retargeting_mse_mm2(tmp_path / "ft" / "model.pt", rig, weights)
    with capsys.disabled():
        print(f"\nmakehuman self-retargeting MSE: before {before:.3f} mm^2, after {after:.3f} mm^2")
    assert after < 0.5 * before, (before, after)

    # the command line: --rig without --config fine-tunes with finetune.yaml and the init's model
    assert main(["train", "--rig", str(MAKEHUMAN), "--keep-vertices", "0:3386", "--rig-mix", "1",
                 "--init", str(tmp_path / "init.pt"), "--out", str(tmp_path / "cli"),
                 "--steps", "1", "--no-progress"]) == 0
    assert "saved" in capsys.readouterr().out and (tmp_path / "cli" / "model.pt").is_file()


def test_a_tilted_rig_is_fine_tuned_upright(tmp_path):
    from retarget.canonical import rotation_angle, turn_matrix
    from retarget.training_data import upright_rig

    a = np.load(ROOT / "data_synth" / "makehuman" / "data" / "makehuman_arkit.npz", allow_pickle=False)
    turn = turn_matrix(-20.0, 0.0)
    np.savez(tmp_path / "tilted.npz", neutral=a["neutral"] @ turn.T, faces=a["faces"],
             names=a["names"], deltas=a["deltas"] @ turn.T)
    np.savez(tmp_path / "upright.npz", neutral=a["neutral"], faces=a["faces"], names=a["names"],
             deltas=a["deltas"])
    rig = load_user_rig(tmp_path / "upright.npz")
    assert upright_rig(rig) is rig                               # upright: left as it is
    tilted = load_user_rig(tmp_path / "tilted.npz")
    turned = upright_rig(tilted)
    # the rotation taking the tilted neutral to the turned one (Kabsch) undoes the tilt within 2°
    p = tilted.neutral - tilted.neutral.mean(0)
    q = turned.neutral - turned.neutral.mean(0)
    u, _, vt = np.linalg.svd(p.T.astype(np.float64) @ q)
    rotation = (u @ vt).T
    assert np.allclose(q, p @ rotation.T, atol=1e-3)
    assert rotation_angle(rotation @ turn) < 2.0
    assert np.allclose(turned.deltas, tilted.deltas @ rotation.T.astype(np.float32), atol=1e-4)


def test_a_rig_with_separate_parts_is_fine_tuned_on_its_face(tmp_path, capsys):
    from retarget.training_data import face_rig

    from .test_api import with_parts

    a = np.load(ROOT / "data_synth" / "makehuman" / "data" / "makehuman_arkit.npz", allow_pickle=False)
    n = len(a["neutral"])
    full = with_parts(Mesh(a["neutral"].astype(np.float64), a["faces"].astype(np.int64)))
    extra = full.n_vertices - n
    deltas = np.concatenate([a["deltas"], np.ones((len(a["deltas"]), extra, 3))], axis=1)  # parts move
    np.savez(tmp_path / "parts.npz", neutral=full.vertices, faces=full.faces, names=a["names"],
             deltas=deltas)
    rig = load_user_rig(tmp_path / "parts.npz")
    face = face_rig(rig)
    assert "fine-tuning on the face alone (3,386 of 3,478 vertices" in capsys.readouterr().out
    assert np.array_equal(face.neutral, rig.neutral[:n]) and np.array_equal(face.faces, a["faces"])
    assert np.array_equal(face.deltas, rig.deltas[:, :n])
    assert face_rig(face) is face                                 # one part: left as it is
