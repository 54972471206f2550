"""The neutral-aware expression encoder (NFSConfig.neutral_channels) and analysis-by-synthesis
(Retargeter.refine, SourceRig): channels, training sources, codes, bounded least squares on a
baked rig, the CLI flags and the eval modes; tiny untrained models throughout."""
import csv
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from data_synth.identity import sample_identity
from data_synth.rig import build_rig
from data_synth.tessellate import tessellate
from nets.model import NEUTRAL_CHANNEL_DIM, NFSConfig, NFSModel
from retarget.api import BakedRig, Retargeter, SourceRig
from retarget.cli import main
from retarget.errors import RetargetError
from retarget.io import save_mesh
from retarget.mesh import Mesh
from retarget.prepare import neutral_channels, vertex_features
from retarget.train import Trainer, group_losses, load_config, model_cfg

from .test_api import tiny_checkpoint

ROOT = Path(__file__).resolve().parents[1]
TINY_TRAIN = ROOT / "configs" / "train" / "tiny.yaml"
TINY_EVAL = ROOT / "configs" / "eval" / "tiny.yaml"


@pytest.fixture(scope="module")
def rig():
    return build_rig(sample_identity(0, split="test"), tessellate(n_vertices=400, kind="regular"))


@pytest.fixture(scope="module")
def weights():
    return (np.random.default_rng(0).random((3, 53)) * 0.6).astype(np.float32)


@pytest.fixture(scope="module")
def r():
    # frames here are drawn from the baked rig, whose neutral is the untrained decoder's output at
    # zero weights, far from the source neutral even on its rest vertices: without stabilisation
    # (tests/test_stabilise.py), which would take that offset for head motion
    torch.manual_seed(0)
    return Retargeter(NFSModel(NFSConfig.preset("tiny", neutral_channels=True)), device="cpu",
                      stabilise=False)


# ------------------------------------------------------------------------------- channels
def test_channels_are_zero_and_flag_without_a_neutral_and_the_displacement_with_one(rig, weights):
    torch.manual_seed(0)
    model = NFSModel(NFSConfig.preset("tiny", neutral_channels=True))
    frame = rig.evaluate(weights[0]).astype(np.float64)
    feat = torch.from_numpy(vertex_features(frame.astype(np.float32), rig.faces))
    c = torch.zeros(model.cfg.image_code_dim)
    x = model.expression_input(feat, None)
    assert x.shape == (len(frame), 6 + NEUTRAL_CHANNEL_DIM)
    assert model.expression_encoder.first.in_features == 6 + model.cfg.image_code_dim + NEUTRAL_CHANNEL_DIM
    assert torch.all(x[:, -NEUTRAL_CHANNEL_DIM:-1] == 0) and torch.all(x[:, -1] == 1)
    ch = neutral_channels(frame, rig.neutral, rig.faces)
    assert ch.shape == (len(frame), NEUTRAL_CHANNEL_DIM) and np.all(ch[:, -1] == 0)
    np.testing.assert_allclose(ch[:, :3], frame - rig.neutral, atol=1e-5)
    assert np.abs(ch[:, 3:6]).max() > 1e-3                       # the expression turns normals
    assert np.abs(neutral_channels(rig.neutral, rig.neutral, rig.faces)).max() == 0
    x = model.expression_input(feat, torch.from_numpy(ch))
    assert torch.equal(x[:, -NEUTRAL_CHANNEL_DIM:], torch.from_numpy(ch))
    with pytest.raises(ValueError, match="neutral channels must be"):
        model.expression_input(feat, torch.from_numpy(ch[:-1]))


def test_old_configs_load_with_the_switch_off_and_ignore_the_neutral():
    d = NFSConfig.preset("tiny").to_dict()
    del d["neutral_channels"]
    cfg = NFSConfig.from_dict(d)
    assert cfg.neutral_channels is False
    torch.manual_seed(0)
    model = NFSModel(cfg)
    assert model.expression_encoder.first.in_features == 6 + cfg.image_code_dim
    on = NFSModel(NFSConfig.preset("tiny", neutral_channels=True))
    assert on.expression_encoder.first.in_features == 6 + cfg.image_code_dim + NEUTRAL_CHANNEL_DIM


def test_given_normals_give_the_same_channels_render_and_features(rig, weights):
    from nets.geometry import vertex_normals
    from retarget.prepare import prepare_mesh
    from retarget.render import render_frontal

    frame = rig.evaluate(weights[1]).astype(np.float64)
    n_frame, n_neutral = vertex_normals(frame, rig.faces), vertex_normals(rig.neutral.astype(np.float64), rig.faces)
    np.testing.assert_array_equal(neutral_channels(frame, rig.neutral, rig.faces, n_frame, n_neutral),
                                  neutral_channels(frame, rig.neutral, rig.faces))
    cv = frame.astype(np.float32)
    np.testing.assert_array_equal(vertex_features(cv, rig.faces, vertex_normals(cv.astype(np.float64), rig.faces)),
                                  vertex_features(cv, rig.faces))
    np.testing.assert_array_equal(render_frontal(cv, rig.faces, 32, normals=vertex_normals(cv.astype(np.float64), rig.faces)),
                                  render_frontal(cv, rig.faces, 32))
    p = prepare_mesh(frame, rig.faces, 16, 32, ("shaded", "depth"))
    np.testing.assert_array_equal(p.normals, vertex_normals(p.vertices.astype(np.float64), rig.faces))
    np.testing.assert_array_equal(p.feat[:, 3:], p.normals.astype(np.float32))


def test_the_neutral_reference_is_made_once_per_source_neutral(r, rig, weights):
    frames = [Mesh(f, rig.faces) for f in rig.evaluate(weights)]
    neutral = Mesh(rig.neutral, rig.faces)
    r.clear_source_cache()
    z_batch = r.encode(frames, source_neutral=neutral)
    (src,) = r._sources.values()
    base = src.neutral[0]
    z_stream = np.stack([r.encode(f, source_neutral=neutral) for f in frames])
    assert len(r._sources) == 1 and src.neutral[0] is base       # reused, not remade
    np.testing.assert_allclose(z_stream, z_batch, atol=1e-6)
    other = Mesh(rig.neutral * 1.1, rig.faces)                    # another performer: its own entry
    r.encode(frames[0], source_neutral=other)
    assert len(r._sources) == 2


def test_codes_change_with_the_neutral(r, rig, weights):
    frames = [Mesh(f, rig.faces) for f in rig.evaluate(weights)]
    neutral = Mesh(rig.neutral, rig.faces)
    z_none, z_neutral = r.encode(frames), r.encode(frames, source_neutral=neutral)
    assert z_none.shape == z_neutral.shape == (3, 128)
    assert np.abs(z_none - z_neutral).max() > 1e-4


# ------------------------------------------------------------------------------- training
def _cfg(neutral: bool, share: float) -> dict:
    cfg = load_config(TINY_TRAIN)
    cfg["model"]["neutral_channels"] = neutral
    cfg["data"]["source_neutral_share"] = share
    return cfg


def test_training_gives_a_share_of_sources_their_neutral(tmp_path):
    trainer = Trainer(_cfg(True, 1.0), tmp_path, progress=False)
    group = trainer.pool.sample(0)
    for s in group.sources:
        assert s.neutral is not None and s.neutral.shape == (len(s.feat), NEUTRAL_CHANNEL_DIM)
        assert np.all(s.neutral[:, -1] == 0) and np.abs(s.neutral[:, :3]).max() > 0
    losses = group_losses(trainer.model, group, trainer.cfg["loss"], 200,
                          np.random.default_rng(0), "cpu")
    assert torch.isfinite(losses["total"])
    assert all(s.neutral is None for s in Trainer(_cfg(True, 0.0), tmp_path / "b",
                                                  progress=False).pool.sample(0).sources)


def test_the_no_neutral_ablation_sees_the_same_sources_less_their_neutrals(tmp_path):
    pools = (Trainer(_cfg(True, 0.5), tmp_path / "a", progress=False).pool,
             Trainer(_cfg(False, 0.5), tmp_path / "b", progress=False).pool)
    given = []
    for step in range(4):
        with_channels, ablation = (pool.sample(step) for pool in pools)
        for sa, sb in zip(with_channels.sources, ablation.sources):
            given.append(sa.neutral is not None)
            assert sb.neutral is None and sa.kind == sb.kind
            assert np.array_equal(sa.weights, sb.weights)
            if sa.neutral is None:              # canonicalised on its own in both: the same input
                assert np.array_equal(sa.feat, sb.feat)
    assert any(given) and not all(given)
    # no share: no draw and no neutral, with or without the channels (the procedural configs)
    a, b = (Trainer(_cfg(channels, 0.0), tmp_path / f"c{channels}", progress=False).pool.sample(3)
            for channels in (True, False))
    for sa, sb in zip(a.sources, b.sources):
        assert sa.neutral is None and sb.neutral is None and sa.kind == sb.kind
        assert np.array_equal(sa.feat, sb.feat) and np.array_equal(sa.weights, sb.weights)


def test_neutral_and_no_neutral_configs_differ_from_default_only_in_the_switch():
    configs = {n: load_config(ROOT / "configs" / "train" / f"{n}.yaml")
               for n in ("default", "neutral", "no_neutral")}
    assert model_cfg(configs["neutral"]).neutral_channels is True
    assert model_cfg(configs["no_neutral"]) == model_cfg(configs["default"])
    assert model_cfg(configs["default"]).neutral_channels is False
    for name in ("neutral", "no_neutral"):
        assert configs[name]["train"] == configs["default"]["train"]
        assert configs[name]["loss"] == configs["default"]["loss"]


# ------------------------------------------------------------------------------- analysis by synthesis
def test_bounded_least_squares_recovers_the_weights_of_an_exactly_linear_rig(rig):
    w = np.random.default_rng(1).random(53).astype(np.float32)
    w[:5] = 0.0
    w[5:10] = 1.0                                                  # on the bounds
    # (a tiny prior: on this coarse rig eyeLookIn_L and eyeLookOut_L are nearly opposite, their
    # sum is almost invisible, and a prior of 1e-6 already decides it)
    src = SourceRig.make(None, BakedRig(rig.neutral, rig.deltas))
    start = np.full(53, 0.5, np.float32)
    fit = src.fit(rig.evaluate(w), start, prior=1e-10)
    assert fit.min() >= 0 and fit.max() <= 1
    assert np.abs(fit - w).max() < 1e-3
    # an expression beyond the box is projected into it: the weights stay in [0, 1]
    far = src.fit(rig.neutral + 3.0 * (rig.evaluate(w) - rig.neutral), start, prior=1e-10)
    # a strong prior keeps the weights near the estimate (what invert uses), a weak one does not
    near = src.fit(rig.evaluate(w), start, prior=1e3)
    assert np.abs(near - start).max() < 0.05 < np.abs(fit - start).max()
    assert far.min() >= 0 and far.max() <= 1 and far[5:10].min() == pytest.approx(1.0)


def test_sparse_fit_is_the_minimiser_of_the_l1_objective(rig):
    """SourceRig.fit with sparsity μ: the weights satisfy the optimality conditions of
    |A w − b|² + λ|w − w0|² + μ Σw on [0, 1] (gradient 0 inside, ≥ 0 at 0, ≤ 0 at 1), and the
    pull towards 0 lowers the sum of the weights."""
    w = np.random.default_rng(2).random(53).astype(np.float32) * 0.6
    w[:20] = 0.0
    src = SourceRig.make(None, BakedRig(rig.neutral, rig.deltas))
    frame = rig.evaluate(w) + 0.002 * np.random.default_rng(3).standard_normal(rig.neutral.shape)
    w0 = np.full(53, 0.2, np.float32)
    scale = float(np.trace(src.gram)) / 53
    plain = src.fit(frame, w0, prior=0.1)
    for mu in (0.02, 0.2):
        fit = src.fit(frame, w0, prior=0.1, sparsity=mu).astype(np.float64)
        b = (frame - rig.neutral).reshape(-1).astype(np.float64)
        grad = (2 * (src.gram @ fit - src.basis.astype(np.float64) @ b)
                + 2 * 0.1 * scale * (fit - w0) + mu * scale)
        tol = 1e-3 * scale
        inside = (fit > 1e-6) & (fit < 1 - 1e-6)
        assert np.abs(grad[inside]).max() < tol
        assert grad[fit <= 1e-6].min(initial=0.0) > -tol and grad[fit >= 1 - 1e-6].max(initial=0.0) < tol
        assert fit.sum() < plain.sum()


def test_balanced_fit_is_the_minimiser_with_pulls_per_shape(rig):
    """SourceRig.fit with balance β: the weights satisfy the optimality conditions of
    |A w − b|² + Σ λ s_k (w_k − w0_k)² + Σ μ s_k w_k on [0, 1] with s_k = m^(1−β) |B_k|^(2β), and
    β = 0 is the fit that pulls every weight alike."""
    rng = np.random.default_rng(5)
    w = rng.random(53).astype(np.float32) * 0.6
    src = SourceRig.make(None, BakedRig(rig.neutral, rig.deltas))
    frame = rig.evaluate(w) + 0.002 * rng.standard_normal(rig.neutral.shape)
    w0 = np.full(53, 0.2, np.float32)
    np.testing.assert_array_equal(src.fit(frame, w0, 0.1, 0.02), src.fit(frame, w0, 0.1, 0.02,
                                                                          balance=0.0))
    d = np.diag(src.gram)
    for beta in (0.5, 1.0):
        fit = src.fit(frame, w0, prior=0.1, sparsity=0.02, balance=beta).astype(np.float64)
        s = d.mean() ** (1 - beta) * d ** beta
        b = (frame - rig.neutral).reshape(-1).astype(np.float64)
        grad = 2 * (src.gram @ fit - src.basis.astype(np.float64) @ b) + 2 * 0.1 * s * (fit - w0) + 0.02 * s
        tol = 1e-3 * d.mean()
        inside = (fit > 1e-6) & (fit < 1 - 1e-6)
        assert np.abs(grad[inside]).max() < tol
        assert grad[fit <= 1e-6].min(initial=0.0) > -tol and grad[fit >= 1 - 1e-6].max(initial=0.0) < tol


def test_balanced_fit_pulls_small_shapes_less():
    """A rig of 53 shapes that each move their own vertex, of sizes 0.05 to 1, every weight 0.8 in
    the frame, the encoder's estimate 0: each fitted weight is the closed form
    0.8 d_k / (d_k + λ s_k), and with balance 0.5 the small shapes come back nearer 0.8 than with
    the pull of the mean shape's size on each (balance 0)."""
    sizes = np.linspace(0.05, 1.0, 53)
    deltas = np.zeros((53, 60, 3), np.float32)
    deltas[np.arange(53), np.arange(53), 0] = sizes
    neutral = np.random.default_rng(6).random((60, 3)).astype(np.float32)
    src = SourceRig.make(None, BakedRig(neutral, deltas))
    frame = neutral + 0.8 * deltas.sum(0)
    d = sizes ** 2
    errors = {}
    for beta in (0.0, 0.5):
        fit = src.fit(frame, np.zeros(53, np.float32), prior=0.1, balance=beta)
        s = d.mean() ** (1 - beta) * d ** beta
        np.testing.assert_allclose(fit, 0.8 * d / (d + 0.1 * s), atol=1e-5)
        errors[beta] = np.abs(fit[:10] - 0.8).mean()
    assert errors[0.5] < 0.5 * errors[0.0]


def test_dense_frames_are_fitted_again_without_the_l1_pull():
    """SourceRig.fit with dense (count, threshold, prior, balance): a frame that moves every shape
    (each its own vertex, weight 0.6) is fitted again without the L1 pull, so its weights come back
    nearer 0.6 than the sparse fit's, and are the plain fit with the dense prior and balance; a frame
    of three shapes keeps the sparse fit bit for bit."""
    sizes = np.linspace(0.2, 1.0, 53)
    deltas = np.zeros((53, 60, 3), np.float32)
    deltas[np.arange(53), np.arange(53), 1] = sizes
    neutral = np.random.default_rng(7).random((60, 3)).astype(np.float32)
    src = SourceRig.make(None, BakedRig(neutral, deltas))
    w0 = np.full(53, 0.3, np.float32)
    sparse = dict(prior=0.01, sparsity=0.05, reweight=(0.2, 0.05, 2), balance=0.5)
    dense = (20, 0.05, 0.02, 0.25)
    every = neutral + 0.6 * deltas.sum(0)
    before = src.fit(every, w0, **sparse)
    after = src.fit(every, w0, **sparse, dense=dense)
    assert (before > 0.05).sum() > 20                              # read as moving many shapes
    np.testing.assert_array_equal(after, src.fit(every, w0, 0.02, balance=0.25))
    assert np.abs(after - 0.6).mean() < np.abs(before - 0.6).mean()
    few = neutral + 0.7 * deltas[[3, 20, 40]].sum(0)
    np.testing.assert_array_equal(src.fit(few, w0, **sparse, dense=dense), src.fit(few, w0, **sparse))
    assert (src.fit(few, w0, **sparse) > 0.05).sum() <= 20


def test_reweighted_fit_leaves_the_unused_shapes_at_0(rig):
    """SourceRig.fit with reweight: a frame of a few shapes, with the prior pulling every weight
    towards 0.2, is explained by weights nearer the true ones than the plain L1 fit's, with less
    weight on the shapes the frame does not use."""
    rng = np.random.default_rng(4)
    w = np.zeros(53, np.float32)
    active = rng.choice(53, 5, replace=False)
    w[active] = rng.uniform(0.5, 0.9, 5)
    src = SourceRig.make(None, BakedRig(rig.neutral, rig.deltas))
    frame = rig.evaluate(w) + 0.002 * rng.standard_normal(rig.neutral.shape)
    w0 = np.full(53, 0.2, np.float32)
    plain = src.fit(frame, w0, prior=0.1, sparsity=0.02)
    again = src.fit(frame, w0, prior=0.1, sparsity=0.02, reweight=())
    np.testing.assert_array_equal(plain, again)
    rew = src.fit(frame, w0, prior=0.1, sparsity=0.02, reweight=(0.1, 0.05, 2))
    assert rew.min() >= 0 and rew.max() <= 1
    unused = np.ones(53, bool)
    unused[active] = False
    assert rew[unused].sum() < 0.5 * plain[unused].sum()
    assert np.abs(rew - w).mean() < np.abs(plain - w).mean()


def test_refine_fits_the_decoders_own_baked_rig(r, rig, weights):
    neutral = Mesh(rig.neutral, rig.faces)
    baked = r.source_rig(neutral).baked
    assert r.source_rig(neutral).baked is baked                    # baked once per neutral
    frames = [Mesh(f, rig.faces) for f in baked.evaluate(weights)]
    z = r.expression_codes(frames, source_neutral=neutral, refine=True)
    w = z[:, :53]
    assert z.shape == (3, 128) and w.min() >= 0 and w.max() <= 1 and np.all(z[:, 53:] == 0)
    # the fit explains the frames at least as well as the weights that made them (up to the prior)
    for f, wi, true in zip(frames, w, weights):
        fitted = np.square(baked.evaluate(wi) - f.vertices).sum()
        scale = np.square(f.vertices - baked.neutral).sum()
        assert fitted <= np.square(baked.evaluate(true) - f.vertices).sum() + 1e-2 * scale
    # invert pulls the weights towards the encoder's with its own, stronger prior, and towards 0
    inverted = r.invert(frames, source_neutral=neutral, refine=True)
    np.testing.assert_array_equal(inverted, r.expression_codes(
        frames, source_neutral=neutral, refine=True, refine_prior=r.REFINE_PRIOR_INVERT,
        refine_sparsity=r.REFINE_SPARSITY_INVERT, refine_reweight=r.REFINE_REWEIGHT_INVERT,
        refine_balance=r.REFINE_BALANCE_INVERT)[:, :53])
    encoder = np.clip(r.invert(frames, source_neutral=neutral), 0, 1)
    assert np.abs(inverted - encoder).mean() < np.abs(w - encoder).mean()
    with pytest.raises(Exception, match="refine needs the source's neutral"):
        r.invert(frames, refine=True)
    # (vertices, faces) pairs, as every API call takes them, give the same codes
    pairs = r.expression_codes([(f.vertices, f.faces) for f in frames],
                               source_neutral=(neutral.vertices, neutral.faces), refine=True)
    np.testing.assert_array_equal(pairs, z)
    one = r.expression_codes((frames[0].vertices, frames[0].faces),
                             source_neutral=(neutral.vertices, neutral.faces), refine=True)
    np.testing.assert_array_equal(one, z[0])


def test_fit_residuals_measure_what_the_weights_leave_on_the_source_rig(r, rig, weights):
    neutral = Mesh(rig.neutral, rig.faces)
    baked = r.source_rig(neutral).baked
    frames = [Mesh(f, rig.faces) for f in baked.evaluate(weights)]
    residual, motion = r.fit_residuals(frames, neutral, weights)
    # frames drawn by the rig itself: nothing left; the motion is the RMS displacement
    assert residual.shape == motion.shape == (3,) and residual.max() < 1e-4 * motion.min()
    np.testing.assert_allclose(motion, [np.sqrt(np.square(f.vertices - rig.neutral).sum(-1).mean())
                                        for f in frames], rtol=1e-5)
    # weights 0 leave the frame against the rig's own neutral (the decoder's output at zero
    # weights, which an untrained model puts off the source neutral)
    residual0, motion0 = r.fit_residuals(frames, neutral, np.zeros((3, 53)))
    np.testing.assert_allclose(residual0, [np.sqrt(np.square(f.vertices - baked.neutral).sum(-1).mean())
                                           for f in frames], rtol=1e-5)
    np.testing.assert_array_equal(motion0, motion)
    # invert's own weights on rig frames leave less than half of the motion unexplained
    w = r.invert(frames, source_neutral=neutral, refine=True)
    assert np.all(r.fit_residuals(frames, neutral, w)[0] < 0.5 * motion)
    with pytest.raises(RetargetError, match=r"weights of shape \(2, 53\) for 3 frame\(s\)"):
        r.fit_residuals(frames, neutral, weights[:2])
    with pytest.raises(RetargetError, match="needs the source's neutral"):
        r.fit_residuals(frames, None, weights)
    other = build_rig(sample_identity(1, split="test"), tessellate(n_vertices=300, kind="regular"))
    with pytest.raises(RetargetError, match="must share a topology"):
        r.fit_residuals(frames, Mesh(other.neutral, other.faces), weights)


def test_code_residuals_measure_what_the_codes_leave_on_the_source(r, rig, weights):
    neutral = Mesh(rig.neutral, rig.faces)
    z = r.weight_codes(weights, neutral)
    frames = [Mesh(f, rig.faces) for f in r.decode(neutral, z)]
    residual, motion = r.code_residuals(frames, neutral, z)
    # frames the codes draw on the source itself: nothing left
    assert residual.shape == motion.shape == (3,) and residual.max() < 1e-4 * motion.min()
    np.testing.assert_allclose(motion, [np.sqrt(np.square(f.vertices - rig.neutral).sum(-1).mean())
                                        for f in frames], rtol=1e-5)
    # transfer's refined codes explain more of rig frames than the encoder's alone, and with the
    # basis decoder leave what the weights-and-free-dims fit leaves
    rig_frames = [Mesh(f, rig.faces) for f in rig.evaluate(weights)]
    plain = r.code_residuals(rig_frames, neutral, r.expression_codes(rig_frames, neutral))[0]
    refined = r.code_residuals(rig_frames, neutral,
                               r.expression_codes(rig_frames, neutral, refine=True))[0]
    assert np.all(refined < plain)
    # a code of zeros leaves the frame against the decoder's own neutral, as fit_residuals does
    np.testing.assert_allclose(r.code_residuals(rig_frames, neutral, np.zeros((3, 128)))[0],
                               r.fit_residuals(rig_frames, neutral, np.zeros((3, 53)))[0], rtol=1e-4)
    with pytest.raises(RetargetError, match=r"codes of shape \(3, 53\) for 3 frame\(s\)"):
        r.code_residuals(rig_frames, neutral, weights)
    with pytest.raises(RetargetError, match="code_residuals needs the source's neutral"):
        r.code_residuals(rig_frames, None, z)


def test_refine_fits_on_one_blas_thread(r, rig, weights, monkeypatch):
    # OpenBLAS threads left spinning after a fit slow the next frame's torch encoder ~2.5x
    from threadpoolctl import threadpool_info

    def blas_threads():
        return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]

    before, seen = blas_threads(), []
    for name in ("fit", "fit_joint"):
        def spy(self, *args, _orig=getattr(SourceRig, name), **kwargs):
            seen.append(blas_threads())
            return _orig(self, *args, **kwargs)
        monkeypatch.setattr(SourceRig, name, spy)
    neutral = Mesh(rig.neutral, rig.faces)
    frames = [Mesh(f, rig.faces) for f in r.source_rig(neutral).baked.evaluate(weights)]
    r.invert(frames, source_neutral=neutral, refine=True)
    assert len(seen) == len(frames) and all(threads and set(threads) == {1} for threads in seen)
    assert blas_threads() == before                                  # restored afterwards


def test_estimate_neutral_is_the_median_of_the_frames_readings(r, rig, weights):
    frames = [Mesh(f, rig.faces) for f in rig.evaluate(weights)]
    est = r.estimate_neutral(frames)
    assert est.vertices.shape == rig.neutral.shape and np.array_equal(est.faces, rig.faces)
    # each frame minus its code decoded on the first frame as the identity; the median of those
    decoded = r.decode(r.prepare(frames[0]), r.encode(frames))
    readings = np.stack([f.vertices for f in frames]) - (decoded - frames[0].vertices)
    np.testing.assert_allclose(est.vertices, np.median(readings, 0), atol=1e-4)
    assert np.abs(est.vertices - frames[0].vertices).max() > 1e-4   # not a frame given back
    # at most max_frames of the take, evenly spaced: here the first and the last
    np.testing.assert_array_equal(r.estimate_neutral(frames, max_frames=2).vertices,
                                  r.estimate_neutral([frames[0], frames[2]]).vertices)
    # in the frames' own frame and units: millimetres, shifted, give the same neutral
    mm = r.estimate_neutral([Mesh(f.vertices * 10 + [5.0, -3.0, 2.0], f.faces) for f in frames])
    np.testing.assert_allclose(mm.vertices, est.vertices * 10 + [5.0, -3.0, 2.0], atol=1e-3)


def test_refine_steps_fit_the_free_dims(rig, weights):
    torch.manual_seed(0)
    model = NFSModel(NFSConfig.preset("tiny", neutral_channels=True))
    stepped = Retargeter(model, device="cpu", refine_steps=3)
    neutral = Mesh(rig.neutral, rig.faces)
    frames = [Mesh(f, rig.faces) for f in rig.evaluate(weights[:1])]
    z = stepped.expression_codes(frames, source_neutral=neutral, refine=True)
    assert np.abs(z[:, 53:]).max() > 0 and np.all(np.isfinite(z))
    again = stepped.expression_codes(frames, source_neutral=neutral, refine=True)
    np.testing.assert_array_equal(z, again)


def test_basis_decoder_fits_the_free_dims_exactly_on_its_own_rig(rig, weights):
    torch.manual_seed(0)
    model = NFSModel(NFSConfig.preset("tiny", decoder="basis", decoder_fourier=2,
                                      neutral_channels=True))
    r = Retargeter(model, device="cpu", stabilise=False)   # no refine_steps: a basis decoder needs
    # none; no stabilisation: the untrained rig's rest vertices are not at rest (see r above)
    r.REFINE_JOINT = False                     # the weights first, then the free dims
    neutral = Mesh(rig.neutral, rig.faces)
    src = r.source_rig(neutral)
    assert src.free_basis.shape == (model.cfg.code_dim - 53, 3 * len(rig.neutral))
    z = np.random.default_rng(2).normal(size=model.cfg.code_dim).astype(np.float32)
    z[:53] = weights[0]
    flat = lambda x: np.asarray(x, np.float64).reshape(-1)
    # the rig's columns are what the decoder does with each dim of z_GE
    decoded = r.decode(neutral, z)
    by_rig = rig.neutral + (z[:53] @ src.basis + z[53:] @ src.free_basis).reshape(-1, 3)
    np.testing.assert_allclose(decoded, by_rig, atol=1e-4 * np.abs(decoded - rig.neutral).max())
    frame = Mesh(decoded, rig.faces)
    out = r.expression_codes([frame], source_neutral=neutral, refine=True)[0]
    w, f = out[:53], out[53:]
    plain = src.fit(frame.vertices, np.clip(r.expression_codes([frame], neutral)[0, :53], 0, 1),
                    r.REFINE_PRIOR)
    np.testing.assert_array_equal(w, plain)                      # the weights are the plain fit's
    # f solves the ridge normal equations Fᵀ(F f − residual) + λ f = 0 (the weights held) ...
    resid = flat(frame.vertices - rig.neutral) - flat(w @ src.basis)
    F = src.free_basis.astype(np.float64)
    grad = F @ (F.T @ f - resid) + src.free_ridge * f
    assert np.abs(grad).max() < 1e-3 * np.abs(F @ resid).max()
    # ... so the frame is explained better than with the free dims at 0
    err = lambda code: np.square(flat(frame.vertices - rig.neutral)
                                 - flat(code[:53] @ src.basis + code[53:] @ src.free_basis)).sum()
    assert err(out) < 0.5 * err(np.concatenate([w, np.zeros_like(f)]))


def test_joint_fit_solves_weights_and_free_dims_together(rig, weights):
    torch.manual_seed(0)
    model = NFSModel(NFSConfig.preset("tiny", decoder="basis", decoder_fourier=2,
                                      neutral_channels=True))
    r = Retargeter(model, device="cpu", stabilise=False)   # as in the test above
    neutral = Mesh(rig.neutral, rig.faces)
    src = r.source_rig(neutral)
    frame = rig.evaluate(weights[:1])[0]             # not in the span of the tiny model's rig
    w0 = np.full(53, 0.5, np.float32)
    prior, sparsity = 1e-2, 0.01
    w, f = src.fit_joint(frame, w0, prior, sparsity)
    assert w.min() >= 0.0 and w.max() <= 1.0 and np.all(np.isfinite(f))
    A, F = src.basis.astype(np.float64), src.free_basis.astype(np.float64)
    b = (frame - rig.neutral).reshape(-1)
    lam = prior * np.trace(src.gram) / 53
    mu = sparsity * np.trace(src.gram) / 53

    def objective(w, f):
        return (np.square(w @ A + f @ F - b).sum() + lam * np.square(w - w0).sum() + mu * w.sum()
                + src.free_ridge * np.square(f).sum())

    # KKT: zero gradient in f; in w zero where free, pointing outwards at an active bound
    res = w @ A + f @ F - b
    gf = 2 * F @ res + 2 * src.free_ridge * f
    gw = 2 * A @ res + 2 * lam * (w - w0) + mu
    scale = np.abs(2 * A @ b).max()
    assert np.abs(gf).max() < 1e-3 * scale
    free = (w > 1e-6) & (w < 1 - 1e-6)
    assert np.abs(gw[free]).max(initial=0) < 1e-3 * scale
    assert np.all(gw[w <= 1e-6] > -1e-3 * scale) and np.all(gw[w >= 1 - 1e-6] < 1e-3 * scale)
    # at least as good as the weights first, then the free dims (what refine does by default)
    w_seq = src.fit(frame, w0, prior, sparsity)
    assert objective(w, f) <= objective(w_seq, src.fit_free(frame, w_seq)) + 1e-9 * scale
    # refine(joint=True) returns the same code
    z = r.encode([Mesh(frame, rig.faces)], source_neutral=neutral)
    out = r.refine([Mesh(frame, rig.faces)], neutral, z, prior, sparsity, joint=True)[0]
    np.testing.assert_allclose(out, np.concatenate(
        src.fit_joint(frame, np.clip(z[0, :53], 0, 1), prior, sparsity)), rtol=1e-6, atol=1e-6)


# ------------------------------------------------------------------------------- CLI and eval
@pytest.fixture(scope="module")
def files(tmp_path_factory, rig, weights):
    d = tmp_path_factory.mktemp("neutral_cli")
    tiny_checkpoint(d / "tiny.pt", neutral_channels=True)
    save_mesh(d / "neutral.obj", Mesh(rig.neutral, rig.faces))
    for t, f in enumerate(rig.evaluate(weights)):
        save_mesh(d / "seq" / f"frame_{t}.obj", Mesh(f, rig.faces))
    other = build_rig(sample_identity(1, split="test"), tessellate(n_vertices=300, kind="regular"))
    save_mesh(d / "other_neutral.obj", Mesh(other.neutral, other.faces))
    return d


def _cli(files, *argv) -> int:
    return main([str(a) for a in argv] + ["--checkpoint", str(files / "tiny.pt"), "--device", "cpu"])


def test_invert_and_transfer_refine_on_the_command_line(files, tmp_path):
    out = tmp_path / "w.csv"
    assert _cli(files, "invert", files / "seq", "-o", out, "--source-neutral",
                files / "neutral.obj", "--refine") == 0
    with open(out) as f:
        rows = list(csv.DictReader(f))
    values = np.array([[float(v) for k, v in row.items() if k not in ("frame", "time")]
                       for row in rows])
    assert len(rows) == 3 and values.min() >= 0 and values.max() <= 1
    assert _cli(files, "transfer", files / "seq" / "frame_0.obj", files / "neutral.obj", "-o",
                tmp_path / "t.obj", "--source-neutral", files / "neutral.obj", "--refine",
                "--refine-steps", "1") == 0
    assert (tmp_path / "t.obj").stat().st_size > 0


def _check_residuals_csv(path, n_frames: int) -> None:
    """A residuals CSV: one row per frame, residual ≥ 0, motion > 0, and their ratio."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    assert [r_["frame"] for r_ in rows] == [str(t) for t in range(n_frames)]
    for row in rows:
        residual, motion, share = (float(row[k]) for k in ("residual_rms", "motion_rms", "unexplained"))
        assert motion > 0 and residual >= 0 and share == pytest.approx(residual / motion, rel=1e-4)


def test_invert_writes_the_fits_residuals(files, tmp_path, capsys):
    out, res = tmp_path / "w.csv", tmp_path / "fit.csv"
    assert _cli(files, "invert", files / "seq", "-o", out, "--source-neutral", files / "neutral.obj",
                "--refine", "--residuals", res) == 0
    assert "median share unexplained" in capsys.readouterr().out
    _check_residuals_csv(res, 3)
    assert _cli(files, "invert", files / "seq", "-o", out, "--source-neutral", files / "neutral.obj",
                "--residuals", out) == 2
    assert "--residuals and -o name the same file" in capsys.readouterr().err
    # without a neutral there is no rig to measure on: refused before any work
    res.unlink()
    assert _cli(files, "invert", files / "seq", "-o", tmp_path / "w2.csv", "--residuals", res) == 2
    assert "--residuals needs --source-neutral" in capsys.readouterr().err and not res.exists()


def test_transfer_writes_the_codes_residuals(files, tmp_path, capsys):
    res = tmp_path / "fit.csv"
    assert _cli(files, "transfer", files / "seq", files / "neutral.obj", "-o", tmp_path / "out",
                "--source-neutral", files / "neutral.obj", "--refine", "--residuals", res) == 0
    assert "median share unexplained" in capsys.readouterr().out
    _check_residuals_csv(res, 3)
    # refused before any work: no neutral, or a residuals file that is not a CSV
    res.unlink()
    assert _cli(files, "transfer", files / "seq", files / "neutral.obj", "-o", tmp_path / "out2",
                "--residuals", res) == 2
    assert "--residuals needs --source-neutral" in capsys.readouterr().err
    assert _cli(files, "transfer", files / "seq", files / "neutral.obj", "-o", tmp_path / "out3",
                "--source-neutral", files / "neutral.obj", "--residuals", tmp_path / "fit.obj") == 2
    assert not res.exists() and not (tmp_path / "out2").exists() and not (tmp_path / "out3").exists()


def test_estimate_neutral_on_the_command_line(files, tmp_path, capsys):
    for command in (["invert", files / "seq", "-o", tmp_path / "w.csv"],
                    ["transfer", files / "seq", files / "neutral.obj", "-o", tmp_path / "out"]):
        capsys.readouterr()
        assert _cli(files, *command, "--estimate-neutral", "--refine") == 0
        out, err = capsys.readouterr()
        assert "estimated the source neutral from 3 of 3 frame(s)" in out
        assert "note:" not in err
    assert len(list((tmp_path / "out").glob("*.obj"))) == 3
    capsys.readouterr()                               # one frame: said, then done as asked
    assert _cli(files, "invert", files / "seq" / "frame_0.obj", "-o", tmp_path / "one.csv",
                "--estimate-neutral", "--refine") == 0
    assert "a take of varied expressions is needed" in capsys.readouterr().err


def test_transfer_and_invert_advise_the_neutral_and_refine(files, tmp_path, capsys):
    seq, neutral = files / "seq", files / "neutral.obj"
    for extra, fragment in (([], "no --source-neutral"),
                            (["--source-neutral", neutral], "without --refine"),
                            (["--source-neutral", neutral, "--refine"], None)):
        for i, command in enumerate((["invert", seq, "-o", tmp_path / f"w{len(extra)}.csv"],
                                     ["transfer", seq / "frame_0.obj", neutral, "-o",
                                      tmp_path / f"t{len(extra)}.obj"])):
            capsys.readouterr()
            assert _cli(files, *command, *extra) == 0
            notes = [l for l in capsys.readouterr().err.splitlines() if l.startswith("note: ")]
            assert notes == [] if fragment is None else (len(notes) == 1 and fragment in notes[0]), \
                (command[0], extra, notes)


@pytest.mark.parametrize("argv,fragment", [
    (["--refine"], "--refine needs --source-neutral"),
    (["--source-neutral", "NEUTRAL", "--estimate-neutral"], "either --source-neutral or --estimate-neutral"),
    (["--source-neutral", "NEUTRAL_OTHER"], "has 303 vertices, but the frames have 415"),
    (["--source-neutral", "NEUTRAL_OTHER", "--refine"], "has 303 vertices, but the frames have 415"),
    (["--source-neutral", "NEUTRAL", "--refine", "--refine-steps", "-1"], "--refine-steps must be"),
])
def test_bad_neutral_arguments_give_one_error_line(files, tmp_path, capsys, argv, fragment):
    argv = [{"NEUTRAL": files / "neutral.obj", "NEUTRAL_OTHER": files / "other_neutral.obj"}.get(a, a)
            for a in argv]
    for command in (["invert", files / "seq", "-o", tmp_path / "w.csv"],
                    ["transfer", files / "seq", files / "neutral.obj", "-o", tmp_path / "out"]):
        capsys.readouterr()
        assert _cli(files, *command, *argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: ") and fragment in err[0], err
        if "303" in fragment:
            assert err[0].startswith(f"error: {files / 'other_neutral.obj'}: ")
        assert not (tmp_path / "w.csv").exists() and not (tmp_path / "out").exists()


def test_eval_neutral_modes_make_a_row_each(files, tmp_path):
    out = tmp_path / "eval"
    assert main(["eval", "--config", str(TINY_EVAL), "--checkpoint", f"n={files / 'tiny.pt'}",
                 "--suite", "self", "inverse", "--neutral-modes", "none", "neutral", "refine",
                 "estimate", "--no-oracle", "--no-progress", "--out", str(out), "--device", "cpu"]) == 0
    res = json.loads((out / "eval.json").read_text())
    rows = {"n (no neutral)", "n (neutral)", "n (neutral + refine)", "n (estimated neutral + refine)"}
    assert set(res["methods"]) == rows | {"do nothing", "closest point"}
    inverse = {k: v for k, v in res["suites"]["inverse"]["methods"].items() if k in rows}
    assert set(inverse) == rows and all(0 <= m["weight_mae"] <= 1 for m in inverse.values())
    assert inverse["n (no neutral)"]["weight_mae"] != inverse["n (neutral)"]["weight_mae"]


def test_eval_estimates_a_takes_neutral_once(r, monkeypatch):
    """Mode "estimate": cases that share their frames (the ARKit rig's transfer and inversion)
    share one estimate; another take gets its own."""
    from retarget.evaluate import EvalData, NetworkMethod, load_eval_config

    calls = []
    estimate = r.estimate_neutral
    monkeypatch.setattr(r, "estimate_neutral", lambda frames: calls.append(1) or estimate(frames))
    data = EvalData(load_eval_config(TINY_EVAL))
    first, other = data.cases("self")[0], data.cases("inverse")[0]
    method = NetworkMethod("n", r, "estimate")
    a = method.invert(first)
    method.transfer(first)
    assert len(calls) == 1
    np.testing.assert_array_equal(method.invert(first), a)
    method.invert(other)
    assert len(calls) == 2


def test_eval_refuses_negative_refine_steps(files, tmp_path, capsys):
    assert main(["eval", "--config", str(TINY_EVAL), "--checkpoint", str(files / "tiny.pt"),
                 "--suite", "inverse", "--neutral-modes", "refine", "--refine-steps", "-2",
                 "--no-oracle", "--no-progress", "--device", "cpu"]) == 2
    assert capsys.readouterr().err.strip() == "error: --refine-steps must be >= 0, got -2"


def test_a_blind_encoder_reads_frames_without_the_neutral_but_not_the_estimate(rig, weights):
    """A model with a blind encoder reads a take without its neutral by it, with it by the
    neutral-aware encoder; estimate_neutral reads by the neutral-aware one (no-neutral flag)."""
    torch.manual_seed(0)
    model = NFSModel(NFSConfig.preset("tiny", neutral_channels=True, blind_encoder=True))
    r = Retargeter(model, device="cpu", stabilise=False)
    frames = [Mesh(f, rig.faces) for f in rig.evaluate(weights)]
    neutral = Mesh(rig.neutral, rig.faces)
    blind, shared = r.encode(frames), r.encode(frames, blind=False)
    with_neutral = r.encode(frames, source_neutral=neutral)
    estimate = r.estimate_neutral(frames).vertices
    with torch.no_grad():
        model.blind_encoder.last.bias += 0.5
    np.testing.assert_allclose(r.encode(frames), blind + 0.5, atol=1e-5)
    np.testing.assert_array_equal(r.encode(frames, blind=False), shared)
    np.testing.assert_array_equal(r.encode(frames, source_neutral=neutral), with_neutral)
    np.testing.assert_array_equal(r.estimate_neutral(frames).vertices, estimate)
    with torch.no_grad():
        model.expression_encoder.last.bias += 0.5
    assert np.abs(r.estimate_neutral(frames).vertices - estimate).max() > 1e-6
