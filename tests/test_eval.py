"""retarget eval: metrics on known answers, the (u,v) oracle, every suite on a tiny checkpoint."""
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from data_synth.facs import ARKIT_NAMES, FACS_NAMES
from data_synth.identity import sample_identity
from data_synth.rig import build_rig
from data_synth.tessellate import tessellate
from nets.model import NFSConfig, NFSModel
from retarget.cli import main
from retarget.errors import RetargetError
from retarget.evaluate import (SUITES, TRANSFER_SUITES, ClosestPointMethod, DoNothingMethod, Evaluation, OracleMethod,
                               RealRig, EvalData, arkit_ict_matrix,
                               case_errors, ict_to_arkit_weights, load_eval_config,
                               parse_checkpoints, summarise, to_markdown)
from retarget.metrics import (mse_mm2, second_difference_jitter_mm, segment_mse_mm2, standard_error,
                             weight_mae)
from retarget.oracle import (closest_point_rig, closest_point_transfer, displacement_transfer, fit_rig_weights,
                            locate, uv_transfer_matrix)
from retarget.train import CHECKPOINT_FORMAT, save_checkpoint

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "configs" / "eval" / "tiny.yaml"
REAL_RIG = ROOT / "data_synth" / "makehuman" / "data" / "makehuman_arkit.npz"   # the packaged copy


def tiny_checkpoint(path: Path, **overrides) -> Path:
    """An untrained tiny model in the inference checkpoint format of ``Trainer.export``."""
    torch.manual_seed(0)
    model = NFSModel(NFSConfig.preset("tiny", **overrides))
    save_checkpoint(path, {"format": CHECKPOINT_FORMAT, "model_config": model.cfg.to_dict(),
                           "train_config": {}, "model": model.state_dict(), "step": 0})
    return path


def tiny_config():
    cfg = load_eval_config(TINY)
    cfg["real_rig"]["path"] = str(REAL_RIG)
    return cfg


# ------------------------------------------------------------------------------------- metrics
def test_metrics_known_answers():
    rng = np.random.default_rng(0)
    gt = rng.normal(size=(3, 50, 3))
    assert mse_mm2(gt, gt) == 0.0
    d = np.array([0.1, -0.2, 0.3])                       # cm
    assert mse_mm2(gt + d, gt) == pytest.approx(100 * (d ** 2).sum())
    seg = rng.integers(0, 4, 50)
    mean, per = segment_mse_mm2(gt + d, gt, seg, 5)
    assert mean == pytest.approx(100 * (d ** 2).sum())
    assert np.isnan(per[4]) and np.allclose(per[:4], 100 * (d ** 2).sum())


def test_segment_average_hand_made():
    gt = np.zeros((4, 3))
    pred = gt.copy()
    pred[:, 0] = [0.1, 0.1, 0.1, 0.4]                      # cm -> 1, 1, 1, 16 mm²
    mean, per = segment_mse_mm2(pred, gt, np.array([0, 0, 0, 1]), 3)
    assert per[:2] == pytest.approx([1.0, 16.0])
    assert mean == pytest.approx(8.5)                      # (1 + 16) / 2, the empty segment skipped
    assert mse_mm2(pred, gt) == pytest.approx(19.0 / 4)    # vertex mean differs
    # pooled over two cases: per-segment means of the cases, then the mean over segments
    other = case_errors(gt[None] + 0.2, gt[None], np.array([0, 0, 1, 1]), 3)   # 12 mm² everywhere
    pooled = summarise([case_errors(pred[None], gt[None], np.array([0, 0, 0, 1]), 3), other])
    assert pooled["per_segment_mm2"][:2] == pytest.approx([6.5, 14.0])
    assert pooled["per_segment_mm2"][2] is None
    assert pooled["seg_mse_mm2"] == pytest.approx(10.25)
    assert pooled["mse_mm2"] == pytest.approx((19.0 / 4 + 12.0) / 2)


def test_jitter_and_weight_mae():
    t = np.arange(10.0)[:, None, None]
    linear = np.ones((10, 5, 3)) * t * np.array([1.0, 0, 0])
    assert second_difference_jitter_mm(linear) == pytest.approx(0.0, abs=1e-12)
    quadratic = np.ones((10, 5, 3)) * t ** 2 * np.array([0, 0.05, 0])   # second difference 0.1 cm
    assert second_difference_jitter_mm(quadratic) == pytest.approx(1.0)
    assert weight_mae(np.full(53, 0.25), np.zeros(53)) == pytest.approx(0.25)
    # sample standard deviation / sqrt(n): values 1, 2, 3, 4 -> sqrt(5/3) / 2
    assert standard_error([1.0, 2.0, 3.0, 4.0]) == pytest.approx(np.sqrt(5.0 / 3.0) / 2.0)
    assert standard_error([0.3]) is None and standard_error(np.full(5, 0.2)) == pytest.approx(0.0)


def test_arkit_weight_mapping():
    m = arkit_ict_matrix(ARKIT_NAMES)
    w = np.zeros(53)
    w[FACS_NAMES.index("browInnerUp_L")] = 1.0
    w[FACS_NAMES.index("mouthSmile_R")] = 0.5
    a = ict_to_arkit_weights(w, m)
    assert a[ARKIT_NAMES.index("browInnerUp")] == pytest.approx(0.5)       # mean of the halves
    assert a[ARKIT_NAMES.index("mouthSmileRight")] == pytest.approx(0.5)
    assert a[ARKIT_NAMES.index("tongueOut")] == 0.0 and a.sum() == pytest.approx(1.0)
    back = a @ m
    assert back[FACS_NAMES.index("browInnerUp_R")] == pytest.approx(0.5)
    with pytest.raises(RetargetError, match="not an ARKit"):
        arkit_ict_matrix(["smileLeft"])


# ------------------------------------------------------------------------------------- oracle
def test_oracle_exact_on_one_tessellation_and_close_across():
    z = sample_identity(0, split="test")
    a = build_rig(z, tessellate(600, "regular", seed=0))
    b = build_rig(z, tessellate(1500, "jittered", seed=1))
    w = np.random.default_rng(1).uniform(0, 1, (2, 53)).astype(np.float32)
    m = uv_transfer_matrix(a.uv, a.faces, a.uv)
    assert np.allclose(m.sum(axis=1), 1.0)
    same = displacement_transfer(m, a.neutral, a.evaluate(w), a.neutral)
    assert mse_mm2(same, a.evaluate(w)) < 1e-8
    cross = displacement_transfer(uv_transfer_matrix(a.uv, a.faces, b.uv), a.neutral,
                                  a.evaluate(w), b.neutral)
    motion = mse_mm2(b.evaluate(w), b.neutral[None])
    assert mse_mm2(cross, b.evaluate(w)) < 0.05 * motion      # interpolation error only


def test_closest_point_transfer_converts_units_and_beats_nothing_across_topologies():
    z = sample_identity(0, split="test")
    a = build_rig(z, tessellate(900, "regular", seed=0))
    b = build_rig(z, tessellate(1500, "jittered", region="face", seed=1))
    w = np.random.default_rng(1).uniform(0, 1, (2, 53)).astype(np.float32)
    # the target in mm and moved: the result is in its units, its displacements 10x the cm ones
    mm = closest_point_transfer(a.neutral, a.faces, a.evaluate(w), b.neutral * 10 + 5.0, b.faces)
    cm = closest_point_transfer(a.neutral, a.faces, a.evaluate(w), b.neutral, b.faces)
    assert cm.shape == (2, len(b.neutral), 3)
    assert np.allclose(mm, cm * 10 + 5.0, atol=1e-6)
    err, nothing = mse_mm2(cm, b.evaluate(w)), mse_mm2(b.neutral[None], b.evaluate(w))
    assert err < 0.3 * nothing
    same = closest_point_transfer(a.neutral, a.faces, a.evaluate(w)[0], a.neutral, a.faces)
    assert np.allclose(same, a.evaluate(w)[0], atol=1e-6)


def test_closest_point_rig_copies_a_rig_onto_itself_and_converts_units():
    z = sample_identity(0, split="test")
    a = build_rig(z, tessellate(900, "regular", seed=0))
    same = closest_point_rig(a.neutral, a.faces, a.deltas[:5], a.neutral, a.faces)
    assert same.shape == (5, len(a.neutral), 3)
    assert np.allclose(same, a.deltas[:5], atol=1e-6)
    b = build_rig(z, tessellate(1500, "jittered", seed=1))
    cm = closest_point_rig(a.neutral, a.faces, a.deltas[:5], b.neutral, b.faces)
    mm = closest_point_rig(a.neutral, a.faces, a.deltas[:5], b.neutral * 10 + 5.0, b.faces)
    assert np.allclose(mm, cm * 10, atol=1e-5)      # displacements in the target's units
    # the same identity on another tessellation: closer to its own shapes than no shapes
    assert np.square(cm - b.deltas[:5]).sum() < 0.5 * np.square(b.deltas[:5]).sum()


def test_fit_rig_weights_recovers_weights_and_keeps_them_in_bounds():
    rng = np.random.default_rng(0)
    deltas = rng.normal(size=(6, 40, 3))
    neutral = rng.normal(size=(40, 3))
    w = rng.uniform(0, 1, (4, 6))
    frames = neutral + np.tensordot(w, deltas, axes=(1, 0))
    assert np.allclose(fit_rig_weights(deltas, neutral, frames), w, atol=1e-6)
    one = fit_rig_weights(deltas, neutral, frames[0])
    assert one.shape == (6,) and np.allclose(one, w[0], atol=1e-6)
    # a frame that needs weights outside [0, 1]: the bounded minimiser, not the clipped free one
    far = neutral + 2.0 * deltas[0] - 0.5 * deltas[1]
    got = fit_rig_weights(deltas, neutral, far)
    assert got.min() >= 0 and got.max() <= 1 and got[0] == pytest.approx(1.0)
    from scipy.optimize import lsq_linear
    a = deltas.reshape(6, -1).T
    ref = lsq_linear(a, (far - neutral).ravel(), bounds=(0, 1)).x
    assert np.allclose(got, ref, atol=1e-6)


def test_oracle_locates_and_falls_back_to_nearest():
    uv = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    face, bary, inside = locate(uv, faces, np.array([[0.2, 0.2], [0.9, 0.8], [2.0, 2.0]]))
    assert list(face[:2]) == [0, 1] and list(inside) == [True, True, False]
    assert np.allclose(bary[0], [0.6, 0.2, 0.2])
    m = uv_transfer_matrix(uv, faces, np.array([[2.0, 2.0], [-1.0, 0.1]])).toarray()
    assert np.allclose(m, [[0, 0, 0, 1], [1, 0, 0, 0]])


# ------------------------------------------------------------------------------------- suites
class GroundTruthMethod:
    """A stand-in method that returns the GT moved by a constant offset (cm)."""

    def __init__(self, offset):
        self.name, self.offset = "gt+offset", np.asarray(offset, float)

    def transfer(self, case, filters=(None,), fps=30.0):
        return {f: case.gt + self.offset for f in filters}

    def animate(self, case):
        return case.gt + self.offset

    def invert(self, case):
        return case.source_weights


def test_suites_score_ground_truth_zero_and_a_known_offset():
    cfg = tiny_config()
    d = np.array([0.0, 0.2, 0.1])
    expected = 100 * (d ** 2).sum()
    res = Evaluation(cfg, [DoNothingMethod(), GroundTruthMethod(d), ClosestPointMethod(),
                           OracleMethod()], progress=False).run(
        ["self", "cross_topology", "inverse", "jitter", "animate"])["suites"]
    # doing nothing scores the motion itself; every error is also a ratio to it
    cases = EvalData(cfg).cases("self")
    motion = np.mean([mse_mm2(c.gt, c.target.neutral[None]) for c in cases])
    nothing = res["self"]["methods"]["do nothing"]["mse_mm2"]
    assert nothing == pytest.approx(motion)
    assert res["self"]["ratios"]["gt+offset"]["mse_mm2"] == pytest.approx(expected / nothing)
    assert res["self"]["methods"]["closest point"]["mse_mm2"] < 1e-8      # one mesh: exact
    inv_nothing = res["inverse"]["methods"]["do nothing"]
    inv_cases = EvalData(cfg).cases("inverse")
    assert inv_nothing["weight_mae"] == pytest.approx(np.mean([c.source_weights.mean() for c in inv_cases]))
    per_identity = [c.source_weights.mean() for c in inv_cases]      # predicting 0: each case's MAE
    assert inv_nothing["weight_mae_se"] == pytest.approx(np.std(per_identity, ddof=1) / np.sqrt(len(inv_cases)))
    # closest point drives and inverts with the template ARKit rig carried onto each head
    cp_inv = res["inverse"]["methods"]["closest point"]
    assert 0 < cp_inv["mse_mm2"] < inv_nothing["mse_mm2"] and 0 < cp_inv["weight_mae"] < 1
    assert res["animate"]["methods"]["closest point"]["mse_mm2"] > 0
    case = EvalData(cfg).cases("self")[0]
    template, arkit_ict = ClosestPointMethod().template
    assert "tongueOut" not in template.names and arkit_ict.shape == (len(template.names), 53)
    shapes = closest_point_rig(template.neutral, template.faces, template.deltas, case.target.neutral,
                               case.target.faces)
    a = ict_to_arkit_weights(case.target_weights, arkit_ict)
    assert np.allclose(ClosestPointMethod().animate(case),
                       case.target.neutral + np.tensordot(a, shapes, axes=(1, 0)), atol=1e-5)
    assert res["jitter"]["methods"]["do nothing"]["raw"]["jitter_mm"] == 0.0
    gt = res["self"]["methods"]["gt+offset"]
    assert gt["mse_mm2"] == pytest.approx(expected) and gt["seg_mse_mm2"] == pytest.approx(expected)
    # each case's MSE, in case order: doing nothing there is that case's motion
    assert res["self"]["methods"]["do nothing"]["case_mse_mm2"] == pytest.approx(
        [mse_mm2(c.gt, c.target.neutral[None]) for c in cases])
    assert gt["case_mse_mm2"] == pytest.approx([expected] * len(cases))
    assert res["self"]["methods"]["oracle (u,v)"]["mse_mm2"] < 1e-8
    assert res["cross_topology"]["methods"]["gt+offset"]["mse_mm2"] == pytest.approx(expected)
    inv = res["inverse"]["methods"]["gt+offset"]
    assert inv["mse_mm2"] < 1e-8 and inv["weight_mae"] == 0.0
    assert "oracle (u,v)" not in res["inverse"]["methods"]
    assert res["animate"]["methods"]["gt+offset"]["mse_mm2"] == pytest.approx(expected)
    assert res["animate"]["methods"]["do nothing"]["mse_mm2"] > 0.01
    assert "oracle (u,v)" not in res["animate"]["methods"]
    jit = res["jitter"]["methods"]["gt+offset"]["raw"]
    assert jit["jitter_mm"] == pytest.approx(res["jitter"]["gt_jitter_mm"])


@pytest.mark.skipif(not REAL_RIG.exists(), reason="makehuman_arkit.npz not present")
def test_every_suite_on_a_tiny_checkpoint(tmp_path):
    a = tiny_checkpoint(tmp_path / "full.pt")
    b = tiny_checkpoint(tmp_path / "noskin.pt", use_skinning=False)
    out, heat = tmp_path / "out", tmp_path / "heat"
    rc = main(["eval", "--config", str(TINY), "--checkpoint", f"full={a}", "--checkpoint", str(b),
               "--real-rig", str(REAL_RIG), "--out", str(out), "--heatmaps", str(heat),
               "--no-progress"])
    assert rc == 0
    res = json.loads((out / "eval.json").read_text())
    assert set(res["suites"]) == set(SUITES)
    baselines = {"do nothing", "closest point", "oracle (u,v)"}
    for suite in ("self", "cross_identity", "cross_topology", "jitter"):
        assert set(res["suites"][suite]["methods"]) == {"full", "noskin"} | baselines, suite
        ratio = res["suites"][suite]["ratios"]["do nothing"]
        assert (ratio["raw"] if suite == "jitter" else ratio)["mse_mm2"] == 1.0
    assert res["suites"]["self"]["methods"]["oracle (u,v)"]["mse_mm2"] < 1e-8
    assert res["suites"]["self"]["methods"]["closest point"]["mse_mm2"] < 1e-8
    for suite in ("head_self", "head_cross_identity", "head_cross_topology", "head_cross_crop"):
        assert set(res["suites"][suite]["methods"]) == {"full", "noskin", "do nothing",
                                                        "closest point"}, suite   # no (u, v)
    assert res["suites"]["head_self"]["methods"]["closest point"]["mse_mm2"] < 1e-8
    assert "bust->head" in res["suites"]["head_cross_crop"]["methods"]["full"]["pairs"]
    assert len(res["suites"]["head_self"]["methods"]["full"]["per_segment_mm2"]) == 20
    assert res["suites"]["self"]["methods"]["full"]["mse_mm2"] > 0
    assert set(res["suites"]["animate"]["methods"]) == {"full", "noskin", "do nothing", "closest point"}
    assert res["suites"]["animate"]["methods"]["full"]["mse_mm2"] > 0
    assert len(res["suites"]["self"]["methods"]["full"]["per_segment_mm2"]) == 20
    real = res["suites"]["real_rig"]["methods"]["full"]
    assert set(real["per_shape"]) == {"jawOpen", "eyeBlinkLeft"}
    assert real["sampled"]["invert"]["weight_mae"] >= 0
    assert real["sampled"]["invert"]["weight_mae_se"] > 0      # over the rig's sampled frames
    frames = real["sampled"]["invert"]["frame_weight_mae"]     # and each frame's, for pairing
    assert len(frames) > 1 and np.mean(frames) == pytest.approx(real["sampled"]["invert"]["weight_mae"])
    assert np.std(frames, ddof=1) / np.sqrt(len(frames)) == pytest.approx(real["sampled"]["invert"]["weight_mae_se"])
    assert " ± " in (out / "eval.md").read_text()           # the tables give the standard errors
    real_methods = res["suites"]["real_rig"]["methods"]
    assert set(real_methods) == {"full", "noskin", "do nothing", "closest point"}
    assert real_methods["closest point"]["sampled"]["real_to_real"]["mse_mm2"] < 1e-8
    # the template of closest point's rig is this rig: exact on its inversion and animation
    assert real_methods["closest point"]["sampled"]["invert"]["rig_mse_mm2"] < 1e-6
    assert real_methods["closest point"]["sampled"]["invert"]["weight_mae"] < 1e-4
    assert real_methods["closest point"]["sampled"]["animate"]["mse_mm2"] < 1e-6
    # the floor: the unmoved neutral onto itself; doing nothing is exact there, so no ratio
    assert real_methods["do nothing"]["sampled"]["unmoved"]["mse_mm2"] == 0.0
    assert real["sampled"]["unmoved"]["mse_mm2"] > 0
    assert res["suites"]["real_rig"]["ratios"]["full"]["sampled"]["unmoved"]["mse_mm2"] is None
    assert "unmoved.mse_mm2" not in real["per_shape"]["jawOpen"]
    ratio = res["suites"]["real_rig"]["ratios"]["full"]["sampled"]["real_to_real"]["mse_mm2"]
    assert ratio == pytest.approx(real["sampled"]["real_to_real"]["mse_mm2"]
                                  / real_methods["do nothing"]["sampled"]["real_to_real"]["mse_mm2"])
    for suite in ("head_inverse", "head_animate"):   # the realistic heads' inverse and animate
        assert {"full", "noskin", "do nothing"} <= set(res["suites"][suite]["methods"]), suite
        assert res["suites"][suite]["methods"]["full"]["mse_mm2"] > 0
    assert 0 <= res["suites"]["head_inverse"]["methods"]["full"]["weight_mae"] <= 1
    md_text = (out / "eval.md").read_text()
    assert "Realistic heads: Inverse rigging" in md_text and "Realistic heads: Driving" in md_text
    frame = res["suites"]["frame"]["makehuman"]
    assert abs(frame["face"]["bust"]["scale_ratio"] - 1) < 0.05 and frame["bbox"]["bust"]["scale_ratio"] < 0.5
    assert real["sampled"]["animate"]["mse_mm2"] > 0
    assert real_methods["do nothing"]["sampled"]["animate"]["mse_mm2"] > 0
    md = (out / "eval.md").read_text()
    for title in ("Self-retargeting", "Cross-identity", "Cross-topology", "Inverse rigging",
                  "Jitter", "Real ARKit rig", "Driving from FACS weights", "| full |",
                  "| oracle (u,v) |", "| do nothing | ", "(1.00×)", "Canonical frame under crops",
                  "Realistic heads: cross-crop", "Realistic test heads", "the floor"):
        assert title in md
    pngs = sorted(heat.glob("*.png"))
    assert len(pngs) == len(TRANSFER_SUITES) and all(p.stat().st_size > 100 for p in pngs)


def test_real_rig_self_retargeting_ground_truth_is_exact():
    if not REAL_RIG.exists():
        pytest.skip("real rig not present")
    cfg = tiny_config()
    cases = EvalData(cfg).real_cases()["per_shape"]
    c = cases["real_to_real"]
    assert c.exact and not cases["procedural_to_real"].exact
    jaw = ["jawOpen", "eyeBlinkLeft"].index("jawOpen")
    rig = RealRig.load(REAL_RIG)
    assert np.allclose(c.gt[jaw], rig.neutral + rig.deltas[rig.names.index("jawOpen")])
    # the procedural source receives the same FACS weights in ICT form
    w = cases["procedural_to_real"].source_weights[jaw]
    assert w[FACS_NAMES.index("jawOpen")] == 1.0 and w.sum() == 1.0


class RealRigGroundTruth:
    """A stand-in method that is exact on the real rig: it evaluates the rig with the ARKit weights
    of the ICT weights it is given."""

    name = "real gt"

    def __init__(self, names):
        self.m = arkit_ict_matrix(names)

    def transfer(self, case, filters=(None,), fps=30.0):
        return {f: case.gt for f in filters}

    def invert(self, case):
        return case.source_weights @ self.m

    def animate(self, case, weights=None):
        return case.target.evaluate(ict_to_arkit_weights(weights, self.m))


def test_real_rig_animate_is_scored_against_the_rig_with_the_do_nothing_error():
    if not REAL_RIG.exists():
        pytest.skip("real rig not present")
    cfg = tiny_config()
    rig = RealRig.load(REAL_RIG)
    res = Evaluation(cfg, [DoNothingMethod(), RealRigGroundTruth(rig.names)],
                     progress=False).run(["real_rig"])
    methods = res["suites"]["real_rig"]["methods"]
    m, nothing = methods["real gt"], methods["do nothing"]
    assert m["sampled"]["animate"]["mse_mm2"] < 1e-8 and m["per_shape"]["jawOpen"]["animate.mse_mm2"] < 1e-8
    assert nothing["sampled"]["animate"]["mse_mm2"] > 0.01
    assert nothing["per_shape"]["jawOpen"]["animate.mse_mm2"] > 0.01
    assert "animate from true weights MSE (exact)" in to_markdown(res)


def test_markdown_marks_missing_rows():
    res = {"methods": ["a"], "segment_names": ["s0"], "config": {"cross_topology": []},
           "suites": {"inverse": {"methods": {}}}}
    assert "| a | — | — | — |" in to_markdown(res)


# ------------------------------------------------------------------------------------- errors
def test_config_and_checkpoint_errors(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("identitiez: 3\n")
    with pytest.raises(RetargetError, match=r"bad\.yaml.*identitiez"):
        load_eval_config(bad)
    with pytest.raises(RetargetError, match="checkpoint not found"):
        parse_checkpoints([str(tmp_path / "missing.pt")])
    ck = tiny_checkpoint(tmp_path / "m.pt")
    assert parse_checkpoints([f"mine={ck}", str(ck)]) == [("mine", ck), ("m", ck)]
    with pytest.raises(RetargetError, match="given twice"):
        parse_checkpoints([str(ck), f"m={ck}"])
    with pytest.raises(RetargetError, match="real rig not found"):
        RealRig.load(tmp_path / "none.npz")
    assert main(["eval", "--config", str(TINY), "--checkpoint", str(tmp_path / "x.pt")]) == 2


def test_split_val_draws_validation_identities_and_a_bad_split_is_named(tmp_path):
    cfg = tiny_config()
    assert cfg["split"] == "test"
    val = dict(cfg, split="val")
    test_rig, val_rig = EvalData(cfg).rig(0), EvalData(val).rig(0)
    assert val_rig.neutral.shape == test_rig.neutral.shape
    assert not np.allclose(val_rig.neutral, test_rig.neutral)
    expected = build_rig(sample_identity(0, split="val"), tessellate(seed=0, **cfg["tessellation"]),
                         cfg["n_segments"])
    np.testing.assert_array_equal(val_rig.neutral, expected.neutral)
    assert "'val' split, not the test set" in to_markdown({"methods": [], "suites": {}, "config": val})
    assert "not the test set" not in to_markdown({"methods": [], "suites": {}, "config": cfg})
    bad = tmp_path / "bad_split.yaml"
    bad.write_text("split: train\n")
    with pytest.raises(RetargetError, match=r"bad_split\.yaml: split must be one of test, val, got 'train'"):
        load_eval_config(bad)
    assert load_eval_config(ROOT / "configs" / "eval" / "validation.yaml")["split"] == "val"
    # the weights' config: the test split, a superset of the default eval's identities and frames
    weights, default = (load_eval_config(ROOT / "configs" / "eval" / f"{n}.yaml") for n in ("weights", "default"))
    assert weights["split"] == "test" and weights["seed"] == default["seed"]
    assert weights["identities"] > default["identities"] and weights["heads"]["identities"] > default["heads"]["identities"]
    assert weights["real_rig"]["expressions"] > default["real_rig"]["expressions"]
    assert weights["real_rig"]["path"] == default["real_rig"]["path"]


def test_a_missing_real_rig_leaves_its_suite_out_unless_asked_for(tmp_path, capsys):
    ck = tiny_checkpoint(tmp_path / "m.pt")
    cfg = tmp_path / "norig.yaml"
    cfg.write_text((TINY.read_text().replace("data_synth/makehuman/data/makehuman_arkit.npz",
                                             str(tmp_path / "absent.npz"))))
    assert main(["eval", "--config", str(cfg), "--checkpoint", str(ck), "--no-oracle",
                 "--no-progress", "--out", str(tmp_path / "out")]) == 0
    assert "absent.npz not found, the real_rig suite is left out" in capsys.readouterr().out
    res = json.loads((tmp_path / "out" / "eval.json").read_text())
    assert "real_rig" not in res["suites"] and "self" in res["suites"]
    assert main(["eval", "--config", str(cfg), "--checkpoint", str(ck), "--suite", "real_rig",
                 "--no-progress"]) == 2
    assert "absent.npz: real rig not found" in capsys.readouterr().err


def test_merge_puts_separately_evaluated_checkpoints_in_one_table(tmp_path, capsys):
    a, b = tiny_checkpoint(tmp_path / "a.pt"), tiny_checkpoint(tmp_path / "b.pt", use_skinning=False)
    for name, ck, extra in (("a", a, []), ("b", b, ["--no-oracle"])):
        assert main(["eval", "--config", str(TINY), "--checkpoint", f"{name}={ck}", "--suite", "self",
                     "inverse", "--no-progress", "--out", str(tmp_path / name)] + extra) == 0
    both = tmp_path / "both"
    assert main(["eval", "--merge", str(tmp_path / "a/eval.json"), str(tmp_path / "b/eval.json"),
                 "--out", str(both)]) == 0
    res = json.loads((both / "eval.json").read_text())
    single = json.loads((tmp_path / "b/eval.json").read_text())
    assert res["methods"] == ["do nothing", "a", "b", "closest point", "oracle (u,v)"]   # baselines once
    assert res["suites"]["self"]["ratios"]["b"] == single["suites"]["self"]["ratios"]["b"]
    assert res["suites"]["self"]["methods"]["b"] == single["suites"]["self"]["methods"]["b"]
    assert set(res["suites"]["inverse"]["methods"]) == {"a", "b", "do nothing", "closest point"}
    assert "| b |" in (both / "eval.md").read_text()
    capsys.readouterr()
    # the same method twice, another config, a file that is not an eval.json: clear errors
    assert main(["eval", "--merge", str(tmp_path / "a/eval.json"), str(tmp_path / "a/eval.json")]) == 2
    assert "already in the merged table" in capsys.readouterr().err
    other = json.loads((tmp_path / "a/eval.json").read_text())
    other["config"]["seed"] = 99
    other["methods"] = ["c"]
    (tmp_path / "c.json").write_text(json.dumps(other))
    assert main(["eval", "--merge", str(tmp_path / "a/eval.json"), str(tmp_path / "c.json")]) == 2
    assert "c.json: evaluated with another eval config" in capsys.readouterr().err
    (tmp_path / "junk.json").write_text("[1, 2]")
    assert main(["eval", "--merge", str(tmp_path / "junk.json")]) == 2
    assert "junk.json: not an eval.json" in capsys.readouterr().err


def test_merge_joins_one_checkpoints_suites_evaluated_apart(tmp_path, capsys):
    """One checkpoint's suites run in two processes merge into one table, as one run gives it; one
    name for two checkpoints is refused."""
    ck = tiny_checkpoint(tmp_path / "a.pt")
    for out, suites in (("whole", ["self", "inverse"]), ("p1", ["self"]), ("p2", ["inverse"])):
        assert main(["eval", "--config", str(TINY), "--checkpoint", f"a={ck}", "--suite", *suites,
                     "--no-progress", "--out", str(tmp_path / out)]) == 0
    assert main(["eval", "--merge", str(tmp_path / "p1/eval.json"), str(tmp_path / "p2/eval.json"),
                 "--out", str(tmp_path / "joined")]) == 0
    whole = json.loads((tmp_path / "whole/eval.json").read_text())
    joined = json.loads((tmp_path / "joined/eval.json").read_text())
    assert joined["methods"] == whole["methods"] and set(joined["suites"]) == {"self", "inverse"}
    for suite in ("self", "inverse"):
        assert joined["suites"][suite]["methods"]["a"] == whole["suites"][suite]["methods"]["a"]
        assert joined["suites"][suite]["ratios"] == whole["suites"][suite]["ratios"]
    capsys.readouterr()
    other = json.loads((tmp_path / "p2/eval.json").read_text())
    other["checkpoints"]["a"] = "elsewhere.pt"
    (tmp_path / "other.json").write_text(json.dumps(other))
    assert main(["eval", "--merge", str(tmp_path / "p1/eval.json"), str(tmp_path / "other.json")]) == 2
    assert "checkpoint name 'a' is elsewhere.pt" in capsys.readouterr().err
