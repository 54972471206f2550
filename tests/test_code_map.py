"""The code map (retarget.code_map): its least-squares fit and its gate, the Retargeter paths that
draw FACS weights through it (weight_codes, animate, bake, refine, invert), the checkpoint fields
and their fit at the end of training; tiny untrained models throughout."""
from pathlib import Path

import numpy as np
import pytest
import torch

from data_synth.identity import sample_identity
from data_synth.rig import build_rig
from data_synth.tessellate import tessellate
from nets.model import NFSConfig, NFSModel
from retarget import FACS_NAMES
from retarget.api import Retargeter, basis_shapes
from retarget.checkpoint import load_checkpoint, save_checkpoint
from retarget.code_map import (CodeMapFit, HeadMapFit, MapErrorFit, code_metric, fit_gate, gate_probability,
                               head_code_map, head_map_error)
from retarget.errors import RetargetError
from retarget.mesh import Mesh
from retarget.train import Trainer, load_config

from .test_api import tiny_checkpoint

ROOT = Path(__file__).resolve().parents[1]
TINY_TRAIN = ROOT / "configs" / "train" / "tiny.yaml"


@pytest.fixture(scope="module")
def rig():
    return build_rig(sample_identity(0, split="test"), tessellate(n_vertices=400, kind="regular"))


def basis_model(seed: int = 0) -> NFSModel:
    torch.manual_seed(seed)
    return NFSModel(NFSConfig.preset("tiny", decoder="basis", decoder_fourier=2, neutral_channels=True))


def random_map(code_dim: int, seed: int = 0) -> np.ndarray:
    """The paper's map [I; 0] plus a dense random part: every shape drawn by every code dim."""
    m = np.eye(code_dim, 53, dtype=np.float32)
    return m + 0.3 * np.random.default_rng(seed).normal(size=m.shape).astype(np.float32)


# ------------------------------------------------------------------------------- the fit
def test_the_fit_recovers_a_map_that_holds_on_every_head():
    rng = np.random.default_rng(0)
    dims = 60
    truth = rng.normal(size=(dims, 53))
    fit = CodeMapFit(dims)
    for h in range(3):
        x = rng.normal(size=(dims, 90 + 10 * h))
        b = truth.T @ x
        if h == 0:
            b[7] = 0.0                       # a shape this head's rig lacks
        b[11] = 0.0                          # a shape no head has
        fit.add(x, b)
    assert fit.count[7] == 2 and fit.count[11] == 0 and fit.count[0] == 3
    m = fit.solve(1e-9)
    keep = np.arange(53) != 11
    np.testing.assert_allclose(m[:, keep], truth[:, keep], atol=1e-4)
    np.testing.assert_array_equal(m[:, 11], np.eye(dims)[11])        # the paper's column kept
    # a heavy ridge pulls every column to the paper's map [I; 0]
    np.testing.assert_allclose(fit.solve(1e9), np.eye(dims, 53), atol=1e-6)


def test_each_heads_shape_counts_relative_to_its_size():
    """Two heads that disagree on shape 0 by a factor 3: the fit minimises the squared relative
    errors, (s − 1)² + (s − 3)²/9, at s = 1.2, not the plain squared errors (at their mean 2)."""
    x = np.zeros((53, 4))
    x[0, 0] = 1.0
    fit = CodeMapFit(53)
    for scale in (1.0, 3.0):
        b = np.zeros((53, 4))
        b[0, 0] = scale
        fit.add(x, b)
    assert fit.solve(1e-12)[0, 0] == pytest.approx(1.2, rel=1e-6)


# ------------------------------------------------------------------------------- the Retargeter
def test_weights_are_drawn_through_the_map(rig):
    model = basis_model()
    m = random_map(model.cfg.code_dim)
    r = Retargeter(model, device="cpu", code_map=m)
    neutral = Mesh(rig.neutral, rig.faces)
    w = np.random.default_rng(1).random((2, 53)).astype(np.float32)
    np.testing.assert_allclose(r.weight_codes(w, neutral), w @ m.T, rtol=1e-6)
    # bake: shape k is the decoder's drawing of the code M[:, k], and animate is the baked rig
    baked = r.bake(neutral)
    rows = basis_shapes(r.prepare(neutral), slice(None))                     # (128, V, 3)
    np.testing.assert_allclose(baked.deltas, np.tensordot(m.T, rows, 1), rtol=1e-4,
                               atol=1e-5 * np.abs(baked.deltas).max())
    scale = np.abs(baked.deltas).max()
    np.testing.assert_allclose(r.animate(neutral, w), baked.evaluate(w), atol=1e-4 * scale)
    # without the map the same model draws other shapes
    assert np.abs(Retargeter(model, device="cpu").bake(neutral).deltas - baked.deltas).max() > 0.1 * scale


def test_refine_fits_the_mapped_rig_and_returns_its_codes(rig):
    model = basis_model()
    m = random_map(model.cfg.code_dim)
    # frames drawn from the untrained baked rig: not stabilised (tests/test_neutral.py, fixture r)
    r = Retargeter(model, device="cpu", stabilise=False)
    neutral = Mesh(rig.neutral, rig.faces)
    plain = r.source_rig(neutral).basis.copy()
    r.code_map = m                                   # drops the rig baked without the map
    src = r.source_rig(neutral)
    np.testing.assert_allclose(src.basis, r.bake(neutral).deltas.reshape(53, -1), rtol=1e-6)
    assert np.abs(src.basis - plain).max() > 0.1 * np.abs(plain).max()
    w_true = np.random.default_rng(2).uniform(0.2, 0.8, 53).astype(np.float32)
    frame = Mesh(src.baked.evaluate(w_true), rig.faces)
    z = r.encode([frame], source_neutral=neutral)
    w, f = r.refine_fit([frame], neutral, z, prior=1e-10, sparsity=0.0, joint=False)
    assert np.abs(w[0] - w_true).max() < 0.01           # the weights of the mapped rig (float32)
    np.testing.assert_allclose(f[0], src.fit_free(frame.vertices, w[0]), rtol=1e-5, atol=1e-6)
    # refine gives the code that draws them: M w with the free dims added
    code = r.refine([frame], neutral, z, prior=1e-10, sparsity=0.0, joint=False)
    expected = w @ m.T
    expected[:, 53:] += f
    np.testing.assert_allclose(code, expected, rtol=1e-5, atol=1e-6)
    # invert returns the fitted weights, not the code's first dims
    inv = r.invert([frame], source_neutral=neutral, refine=True)
    w_inv, _ = r.refine_fit([frame], neutral, z, r.REFINE_PRIOR_INVERT, r.REFINE_SPARSITY_INVERT,
                            r.REFINE_JOINT_INVERT, r.REFINE_REWEIGHT_INVERT, r.REFINE_BALANCE_INVERT,
                            r.REFINE_DENSE_INVERT)
    np.testing.assert_allclose(inv, np.clip(w_inv, 0, 1), rtol=1e-6)
    np.testing.assert_array_equal(r.invert_fit([frame], neutral, z), w_inv)
    sparse, _ = r.refine_fit([frame], neutral, z, r.REFINE_PRIOR_INVERT, r.REFINE_SPARSITY_INVERT,
                             r.REFINE_JOINT_INVERT, r.REFINE_REWEIGHT_INVERT, r.REFINE_BALANCE_INVERT)
    alike, _ = r.refine_fit([frame], neutral, z, r.REFINE_PRIOR_INVERT, r.REFINE_SPARSITY_INVERT,
                            r.REFINE_JOINT_INVERT, r.REFINE_REWEIGHT_INVERT, 0.0)
    assert r.REFINE_BALANCE_INVERT > 0 and np.abs(alike - sparse).max() > 1e-3   # the balance is used
    assert np.abs(sparse - w_inv).max() > 1e-3   # a frame of every shape is fitted again (dense)
    assert inv.shape == (1, 53) and r.invert(frame, source_neutral=neutral, refine=True).shape == (53,)


def test_a_bad_map_is_refused():
    model = basis_model()
    with pytest.raises(RetargetError, match=r"\(128, 53\)"):
        Retargeter(model, device="cpu", code_map=np.zeros((53, 53)))
    bad = np.eye(128, 53)
    bad[0, 0] = np.nan
    with pytest.raises(RetargetError, match="finite"):
        Retargeter(model, device="cpu", code_map=bad)
    torch.manual_seed(0)
    mlp = NFSModel(NFSConfig.preset("tiny"))
    with pytest.raises(RetargetError, match="basis"):
        Retargeter(mlp, device="cpu", code_map=np.eye(mlp.cfg.code_dim, 53))


# ------------------------------------------------------------------------------- checkpoints
def test_the_checkpoints_map_is_loaded_and_checked(tmp_path):
    path = tiny_checkpoint(tmp_path / "basis.pt", decoder="basis", decoder_fourier=2)
    assert Retargeter.load(path, device="cpu").code_map is None
    state = load_checkpoint(path)
    m = random_map(128)
    state["code_map"] = torch.from_numpy(m)
    save_checkpoint(tmp_path / "mapped.pt", state)
    np.testing.assert_array_equal(Retargeter.load(tmp_path / "mapped.pt", device="cpu").code_map, m)
    state["code_map"] = torch.zeros(128, 52)
    save_checkpoint(tmp_path / "bad.pt", state)
    with pytest.raises(RetargetError, match=r"bad\.pt: the checkpoint's code_map"):
        Retargeter.load(tmp_path / "bad.pt", device="cpu")
    mlp = load_checkpoint(tiny_checkpoint(tmp_path / "mlp.pt"))
    mlp["code_map"] = torch.from_numpy(np.eye(128, 53, dtype=np.float32))
    save_checkpoint(tmp_path / "mlp_map.pt", mlp)
    with pytest.raises(RetargetError, match=r"mlp_map\.pt: .*basis-decoder"):
        Retargeter.load(tmp_path / "mlp_map.pt", device="cpu")


def test_training_fits_the_map_into_the_exported_model(tmp_path):
    cfg = load_config(TINY_TRAIN)
    cfg["train"]["steps"] = 2
    cfg["model"].update(decoder="basis", decoder_fourier=2)
    cfg["code_map"]["identities"] = 1
    trainer = Trainer(cfg, tmp_path / "run", progress=False)
    trainer.run()
    m = load_checkpoint(tmp_path / "run" / "model.pt")["code_map"].numpy()
    assert m.shape == (128, 53) and np.isfinite(m).all()
    assert np.abs(m - np.eye(128, 53)).max() > 1e-3      # fitted, not the paper's map
    assert "code_map" not in load_checkpoint(tmp_path / "run" / "last.pt")
    assert trainer.model.training                          # the fit leaves the model training
    again, gate, per_head, error = trainer.fit_code_map()
    np.testing.assert_allclose(again, m, rtol=1e-5, atol=1e-6)                   # deterministic
    assert gate is None and per_head is None and "code_map_gate" not in load_checkpoint(tmp_path / "run" / "model.pt")
    held = load_checkpoint(tmp_path / "run" / "model.pt")["code_map_error"].numpy()
    assert error.shape == held.shape == (1, 128, 128)                            # ungated: one moment
    np.testing.assert_allclose(error, held, rtol=1e-4, atol=1e-7)


def test_a_map_needs_the_basis_decoder_in_the_config(tmp_path):
    bad = tmp_path / "mlp_map.yaml"
    bad.write_text(f"base: {TINY_TRAIN}\ncode_map: {{identities: 2}}\n")
    with pytest.raises(RetargetError, match=r"mlp_map\.yaml: code_map needs the basis decoder"):
        load_config(bad)
    bad.write_text(f"base: {TINY_TRAIN}\nmodel: {{decoder: basis}}\ncode_map: {{ridge: 0}}\n")
    with pytest.raises(RetargetError, match=r"code_map\.ridge must be a number > 0"):
        load_config(bad)
    bad.write_text(f"base: {TINY_TRAIN}\nmodel: {{decoder: basis}}\ncode_map: {{gated: 1}}\n")
    with pytest.raises(RetargetError, match=r"code_map\.gated must be true or false"):
        load_config(bad)
    bad.write_text(f"base: {TINY_TRAIN}\nmodel: {{decoder: basis}}\ncode_map: {{features: -1}}\n")
    with pytest.raises(RetargetError, match=r"code_map\.features"):
        load_config(bad)


# ------------------------------------------------------------------------------- the gate
def test_the_gate_tells_two_kinds_of_codes_apart_and_moves_the_map():
    rng = np.random.default_rng(0)
    centre = rng.normal(size=128)
    a = centre + 0.3 * rng.normal(size=(20, 128))          # "MakeHuman-like" codes
    b = -centre + 0.3 * rng.normal(size=(20, 128))
    gate = fit_gate(np.r_[a, b], np.r_[np.ones(20, bool), np.zeros(20, bool)])
    assert gate.shape == (129,) and gate.dtype == np.float32
    held_a = centre + 0.3 * rng.normal(size=128)
    held_b = -centre + 0.3 * rng.normal(size=128)
    assert gate_probability(gate, held_a) > 0.95 and gate_probability(gate, held_b) < 0.05
    m = random_map(128)
    eye = np.eye(128, 53, dtype=np.float32)
    np.testing.assert_array_equal(head_code_map(m, None, held_b), m)      # no gate: the map itself
    p = gate_probability(gate, held_b)
    np.testing.assert_allclose(head_code_map(m, gate, held_b), eye + p * (m - eye), rtol=1e-6)
    assert np.abs(head_code_map(m, gate, held_b) - eye).max() < 0.05 * np.abs(m - eye).max()
    assert np.abs(head_code_map(m, gate, held_a) - m).max() < 0.05 * np.abs(m - eye).max()


def test_a_gated_map_is_drawn_by_each_heads_own_probability(rig, tmp_path):
    model = basis_model()
    neutral = Mesh(rig.neutral, rig.faces)
    m = random_map(model.cfg.code_dim)
    r = Retargeter(model, device="cpu", code_map=m)
    z_id = r.prepare(neutral).codes.z_id.numpy()
    # a gate whose probability for this head is 1/4: logit = −ln 3
    gate = np.r_[np.zeros(128), -np.log(3.0)].astype(np.float32)
    gate[:128] = 1e-3 * z_id / max(np.linalg.norm(z_id) ** 2, 1e-12)
    gate[128] -= float(gate[:128] @ z_id)
    r.code_map_gate = gate
    eye = np.eye(128, 53, dtype=np.float32)
    head = r.head_code_map(r.prepare(neutral))
    np.testing.assert_allclose(head, eye + 0.25 * (m - eye), rtol=1e-4, atol=1e-6)
    w = np.random.default_rng(1).random(53).astype(np.float32)
    np.testing.assert_allclose(r.weight_codes(w, neutral), head @ w, rtol=1e-5, atol=1e-6)
    baked = r.bake(neutral)
    rows = basis_shapes(r.prepare(neutral), slice(None))
    np.testing.assert_allclose(baked.deltas, np.tensordot(head.T, rows, 1), rtol=1e-4,
                               atol=1e-5 * np.abs(baked.deltas).max())
    # the checkpoint carries the gate; a gate without a map, or of another size, is refused
    path = tiny_checkpoint(tmp_path / "basis.pt", decoder="basis", decoder_fourier=2)
    state = load_checkpoint(path)
    state["code_map"] = torch.from_numpy(m)
    state["code_map_gate"] = torch.from_numpy(gate)
    save_checkpoint(tmp_path / "gated.pt", state)
    np.testing.assert_array_equal(Retargeter.load(tmp_path / "gated.pt", device="cpu").code_map_gate, gate)
    del state["code_map"]
    save_checkpoint(tmp_path / "gate_only.pt", state)
    with pytest.raises(RetargetError, match=r"gate_only\.pt: the checkpoint's code_map_gate"):
        Retargeter.load(tmp_path / "gate_only.pt", device="cpu")
    with pytest.raises(RetargetError, match=r"\(129,\)"):
        r.code_map_gate = np.zeros(128)


def test_training_fits_a_gated_map(tmp_path):
    cfg = load_config(TINY_TRAIN)
    cfg["train"]["steps"] = 1
    cfg["model"].update(decoder="basis", decoder_fourier=2)
    cfg["code_map"].update(identities=1, gated=True)
    Trainer(cfg, tmp_path / "run", progress=False).run()
    state = load_checkpoint(tmp_path / "run" / "model.pt")
    assert state["code_map"].shape == (128, 53) and state["code_map_gate"].shape == (129,)
    assert state["code_map_error"].shape == (2, 128, 128)      # MakeHuman and procedural heads
    r = Retargeter.load(tmp_path / "run" / "model.pt", device="cpu")
    assert r.code_map_gate is not None and np.isfinite(r.code_map_gate).all()
    eig = np.linalg.eigvalsh(r.code_map_error.astype(np.float64))
    assert (eig > -1e-6 * eig.max()).all()                       # second moments: no negative direction


# ------------------------------------------------------------------------------- the commands
def test_animate_and_export_rig_on_the_command_line_draw_through_the_map(rig, tmp_path):
    from retarget.cli import main
    from retarget.io import load_mesh, save_mesh

    path = tiny_checkpoint(tmp_path / "basis.pt", decoder="basis", decoder_fourier=2)
    state = load_checkpoint(path)
    m = random_map(128)
    state["code_map"] = torch.from_numpy(m)
    save_checkpoint(tmp_path / "mapped.pt", state)
    save_mesh(tmp_path / "neutral.obj", Mesh(rig.neutral, rig.faces))
    (tmp_path / "w.json").write_text('{"jawOpen": 0.8, "eyeBlink_L": 0.5}')

    def animate(checkpoint, out):
        assert main(["animate", str(tmp_path / "neutral.obj"), "--weights", str(tmp_path / "w.json"),
                     "-o", str(out), "--checkpoint", str(checkpoint), "--device", "cpu"]) == 0
        return load_mesh(out).vertices

    mapped, plain = animate(tmp_path / "mapped.pt", tmp_path / "a.obj"), animate(path, tmp_path / "b.obj")
    assert main(["animate", str(tmp_path / "neutral.obj"), "--weights", str(tmp_path / "w.json"), "-o",
                 str(tmp_path / "c.obj"), "--checkpoint", str(tmp_path / "mapped.pt"), "--device", "cpu",
                 "--no-code-map"]) == 0
    np.testing.assert_array_equal(load_mesh(tmp_path / "c.obj").vertices, plain)   # the map left out
    r = Retargeter.load(tmp_path / "mapped.pt", device="cpu")
    w = {"jawOpen": 0.8, "eyeBlink_L": 0.5}
    expected = r.animate(load_mesh(tmp_path / "neutral.obj"), w)
    scale = np.abs(expected - rig.neutral).max()
    np.testing.assert_allclose(mapped, expected, atol=1e-4 * scale + 1e-5)
    assert np.abs(mapped - plain).max() > 0.05 * scale
    # the exported rig's morph targets are the mapped shapes
    from pygltflib import GLTF2

    assert main(["export-rig", str(tmp_path / "neutral.obj"), "-o", str(tmp_path / "rig.glb"),
                 "--checkpoint", str(tmp_path / "mapped.pt"), "--device", "cpu"]) == 0
    gltf = GLTF2().load(str(tmp_path / "rig.glb"))
    assert len(gltf.meshes[0].primitives[0].targets) == 53
    baked = r.bake(load_mesh(tmp_path / "neutral.obj"))
    jaw = FACS_NAMES.index("jawOpen")
    acc = gltf.accessors[gltf.meshes[0].primitives[0].targets[jaw]["POSITION"]]
    assert acc.max is not None and np.allclose(acc.max, baked.deltas[jaw].max(0), atol=1e-4 * scale + 1e-5)
    unmapped = Retargeter.load(path, device="cpu").bake(load_mesh(tmp_path / "neutral.obj"))
    assert not np.allclose(acc.max, unmapped.deltas[jaw].max(0), atol=0.01 * scale)


def test_load_can_leave_the_checkpoints_map_out(rig, tmp_path):
    path = tiny_checkpoint(tmp_path / "basis.pt", decoder="basis", decoder_fourier=2)
    state = load_checkpoint(path)
    state["code_map"] = torch.from_numpy(random_map(128))
    save_checkpoint(tmp_path / "mapped.pt", state)
    r = Retargeter.load(tmp_path / "mapped.pt", device="cpu", code_map=None)
    assert r.code_map is None
    w = np.random.default_rng(0).random(53).astype(np.float32)
    np.testing.assert_array_equal(r.weight_codes(w, Mesh(rig.neutral, rig.faces)),
                                  np.r_[w, np.zeros(75, np.float32)])


def test_invert_fits_with_the_settings_tuned_with_or_without_a_map():
    model = basis_model()
    r = Retargeter(model, device="cpu")
    fits = Retargeter.REFINE_INVERT_FITS

    def fit_of(obj):
        return (obj.REFINE_PRIOR_INVERT, obj.REFINE_SPARSITY_INVERT, obj.REFINE_REWEIGHT_INVERT,
                obj.REFINE_BALANCE_INVERT, obj.REFINE_DENSE_INVERT)

    assert fit_of(r) == fits[False]
    r.code_map = random_map(model.cfg.code_dim)
    assert fit_of(r) == fits[True]
    assert fits[True] == fit_of(Retargeter)
    assert fits[True] != fits[False]
    r.code_map = None
    assert fit_of(r) == fits[False]


# ------------------------------------------------------------------------------- per head
def test_the_per_head_fit_recovers_maps_linear_in_the_identity_code():
    """Heads whose true map is M_0 + Σ_j φ_j(z) S_j: the fit finds each held-out head's map, and
    with d = 0 features it cannot (one map for all)."""
    rng = np.random.default_rng(0)
    dims = 60
    m0 = np.eye(dims, 53) + 0.2 * rng.normal(size=(dims, 53))
    slope = rng.normal(size=(2, dims, 53))
    basis = rng.normal(size=(2, dims))                     # the codes vary in a 2-d subspace

    def head(seed):
        r = np.random.default_rng(seed)
        coeffs = r.normal(size=2)
        z = 3.0 + coeffs @ basis
        truth = m0 + np.tensordot(coeffs, slope, 1)
        x = r.normal(size=(dims, 80))
        return z, truth, x, truth.T @ x

    fit = HeadMapFit()
    for h in range(30):
        z, _, x, b = head(h)
        fit.add(x, b, z)
    m, per_head = fit.solve(8, 1e-10)
    features, slopes = per_head
    assert features.shape == (3, dims) and slopes.shape == (2, dims, 53)   # only 2 components span
    z, truth, _, _ = head(100)
    np.testing.assert_allclose(head_code_map(m, None, z, per_head), truth, atol=1e-3)
    shared = fit.solve(0, 1e-10)[0]
    assert np.abs(shared - truth).max() > 0.1


def test_a_per_head_map_travels_in_the_checkpoint_and_is_drawn_per_head(rig, tmp_path):
    path = tiny_checkpoint(tmp_path / "basis.pt", decoder="basis", decoder_fourier=2)
    state = load_checkpoint(path)
    m = random_map(128)
    rng = np.random.default_rng(3)
    features = np.r_[rng.normal(size=(1, 128)), 0.1 * rng.normal(size=(2, 128))].astype(np.float32)
    slopes = (0.05 * rng.normal(size=(2, 128, 53))).astype(np.float32)
    state["code_map"] = torch.from_numpy(m)
    state["code_map_features"], state["code_map_slopes"] = torch.from_numpy(features), torch.from_numpy(slopes)
    save_checkpoint(tmp_path / "per_head.pt", state)
    r = Retargeter.load(tmp_path / "per_head.pt", device="cpu")
    neutral = Mesh(rig.neutral, rig.faces)
    z = r.prepare(neutral).codes.z_id.numpy().astype(np.float64)
    expected = m + np.tensordot(features[1:] @ (z - features[0]), slopes, 1)
    np.testing.assert_allclose(r.head_code_map(r.prepare(neutral)), expected, rtol=1e-4, atol=1e-5)
    w = np.random.default_rng(1).random(53).astype(np.float32)
    np.testing.assert_allclose(r.weight_codes(w, neutral), expected @ w, rtol=1e-4, atol=1e-5)
    # with a gate, the per-head map is drawn as far as the gate says: here p = 1/4
    gate = np.r_[np.zeros(128), -np.log(3.0)].astype(np.float32)
    r.code_map_gate = gate
    eye = np.eye(128, 53)
    np.testing.assert_allclose(r.head_code_map(r.prepare(neutral)), eye + 0.25 * (expected - eye),
                               rtol=1e-4, atol=1e-5)
    # a half-given or misshapen per-head map is refused, naming the file
    del state["code_map_slopes"]
    save_checkpoint(tmp_path / "half.pt", state)
    with pytest.raises(RetargetError, match=r"half\.pt: the checkpoint's per-head code map"):
        Retargeter.load(tmp_path / "half.pt", device="cpu")
    state["code_map_slopes"] = torch.zeros(2, 128, 52)
    save_checkpoint(tmp_path / "bad.pt", state)
    with pytest.raises(RetargetError, match=r"bad\.pt: the checkpoint's per-head code map"):
        Retargeter.load(tmp_path / "bad.pt", device="cpu")
    with pytest.raises(RetargetError, match="per-head code map"):
        r.code_map_per_head = (features, slopes[:1])
    with pytest.raises(RetargetError, match="per-head code map"):
        r.code_map_per_head = (features, np.float32(1.0))       # not an array of slopes at all


def test_training_fits_a_per_head_map(tmp_path):
    cfg = load_config(TINY_TRAIN)
    cfg["train"]["steps"] = 1
    cfg["model"].update(decoder="basis", decoder_fourier=2)
    cfg["code_map"].update(identities=2, features=2, ridge=0.001, gated=True)
    Trainer(cfg, tmp_path / "run", progress=False).run()
    state = load_checkpoint(tmp_path / "run" / "model.pt")
    assert state["code_map_features"].shape[1] == 128 and state["code_map_slopes"].shape[1:] == (128, 53)
    assert state["code_map_gate"].shape == (129,)
    r = Retargeter.load(tmp_path / "run" / "model.pt", device="cpu")
    assert r.code_map_per_head is not None and r.code_map_gate is not None


# ------------------------------------------------------------------------------- the map's error
def test_the_maps_error_moment_is_that_of_the_codes_each_head_misses_by():
    rng = np.random.default_rng(5)
    dims, n = 6, 40
    m = np.eye(dims, 53) + 0.1 * rng.normal(size=(dims, 53))
    fit, deltas = MapErrorFit(), {0: [], 1: []}
    for h in range(6):
        x = rng.normal(size=(dims, n))
        delta = rng.normal(size=(dims, 53)) * (0.3 if h % 2 else 0.05)
        b = (m + delta).T @ x
        b[7] = 0.0                                     # a shape this rig lacks: not counted
        fit.add(x, b, rng.normal(size=dims), h % 2)
        deltas[h % 2].append(np.delete(delta, 7, axis=1))
    two = fit.solve(m.astype(np.float32), groups=2)
    for g in (0, 1):
        d = np.concatenate(deltas[g], axis=1)
        np.testing.assert_allclose(two[g], d @ d.T / d.shape[1], rtol=1e-3, atol=1e-6)
    assert np.trace(two[1]) > 10 * np.trace(two[0])
    one = fit.solve(m.astype(np.float32), groups=1)
    np.testing.assert_allclose(one[0], (two[0] + two[1]) / 2, rtol=1e-3, atol=1e-6)
    # a head gets the moment of its kind as far as the gate says it is of that kind
    gate = np.r_[np.zeros(dims), -np.log(3.0)]                  # p = 1/4 for every head
    np.testing.assert_allclose(head_map_error(two, gate, np.zeros(dims)), 0.25 * two[0] + 0.75 * two[1],
                               rtol=1e-5)
    np.testing.assert_array_equal(head_map_error(one, gate, np.zeros(dims)), one[0].astype(np.float64))


def test_weighing_the_fit_by_the_rigs_expected_error_reads_weights_closer():
    rng = np.random.default_rng(0)
    dims, n = 12, 90
    x = rng.normal(size=(dims, n)) * np.linspace(0.3, 3.0, dims)[:, None]
    m = np.eye(dims, 53)[:, :8] + 0.2 * rng.normal(size=(dims, 8))
    a = m.T @ x                                                         # the baked rig (8 shapes)
    # the head's true shapes miss the baked ones along a few code directions only
    u = np.linalg.qr(rng.normal(size=(dims, 3)))[0]
    sigma = u @ np.diag([1.0, 0.5, 0.25]) @ u.T * 0.05
    q, gram = code_metric(x, a, sigma, rho=1.0)
    assert q.shape == a.shape and gram.shape == (8, 8)
    np.testing.assert_allclose(gram, gram.T, atol=1e-12)
    plain_err, weighed_err = [], []
    for _ in range(200):
        delta = np.linalg.cholesky(sigma + 1e-12 * np.eye(dims)) @ rng.normal(size=(dims, 8))
        w = rng.uniform(0, 1, 8)
        b = ((m + delta) @ w) @ x                                       # a frame of the true shapes
        plain_err.append(np.abs(np.linalg.solve(a @ a.T, a @ b) - w).mean())
        weighed_err.append(np.abs(np.linalg.solve(gram, q @ b) - w).mean())
    assert np.mean(weighed_err) < 0.5 * np.mean(plain_err)
    # with much white noise beside the rig's error the fit is the plain one
    q_inf, gram_inf = code_metric(x, a, sigma, rho=1e9)
    np.testing.assert_allclose(q_inf, a, rtol=1e-4, atol=1e-6 * np.abs(a).max())
    np.testing.assert_allclose(gram_inf, a @ a.T, rtol=1e-4, atol=1e-6 * np.abs(a @ a.T).max())
    # a mesh of fewer coordinates than code dims: the rig's rows are not independent, plain fit
    q_few, gram_few = code_metric(x[:, :9], a[:, :9], sigma, rho=1.0)
    np.testing.assert_allclose(q_few, a[:, :9], rtol=1e-6)
    np.testing.assert_allclose(gram_few, a[:, :9] @ a[:, :9].T, rtol=1e-10)


def test_invert_weighs_its_fit_when_the_model_holds_the_maps_error(rig, tmp_path):
    model = basis_model()
    neutral = Mesh(rig.neutral, rig.faces)
    m = random_map(model.cfg.code_dim)
    r = Retargeter(model, device="cpu", code_map=m, stabilise=False)
    assert r.source_rig(neutral).fit_basis is None                      # no error held: plain
    sigma = np.stack([np.eye(128), 2 * np.eye(128)]).astype(np.float32)
    sigma[:, 60:, 60:] *= 10.0
    r.code_map_error = sigma
    src = r.source_rig(neutral)
    code_basis = basis_shapes(r.prepare(neutral), slice(None))
    q, gram = code_metric(code_basis.reshape(128, -1), src.basis, sigma[0], r.REFINE_METRIC_RHO)
    np.testing.assert_allclose(src.fit_basis, q, rtol=1e-3, atol=1e-4 * np.abs(q).max())
    w_true = np.random.default_rng(3).uniform(0.0, 0.3, 53).astype(np.float32)
    frame = Mesh(src.baked.evaluate(w_true), rig.faces)
    z = r.encode([frame], source_neutral=neutral)
    weighed = r.invert_fit([frame], neutral, z)
    # a frame the baked rig draws exactly is read alike by either fit
    np.testing.assert_allclose(weighed[0], w_true, atol=0.02)
    r.code_map = None                               # the moments are the map's: none without it
    assert r.source_rig(neutral).fit_basis is None
    r.code_map = m
    assert r.source_rig(neutral).fit_basis is not None
    r.REFINE_METRIC_RHO = None
    r.code_map_error = sigma                                            # drops the rig: plain again
    assert r.source_rig(neutral).fit_basis is None
    # the checkpoint carries the moments; a bad one is refused naming the file
    path = tiny_checkpoint(tmp_path / "basis.pt", decoder="basis", decoder_fourier=2)
    state = load_checkpoint(path)
    state["code_map"] = torch.from_numpy(m)
    state["code_map_error"] = torch.from_numpy(sigma)
    save_checkpoint(tmp_path / "with_error.pt", state)
    np.testing.assert_array_equal(Retargeter.load(tmp_path / "with_error.pt", device="cpu").code_map_error,
                                  sigma)
    state["code_map_error"] = torch.zeros(2, 128, 127)
    save_checkpoint(tmp_path / "bad_error.pt", state)
    with pytest.raises(RetargetError, match=r"bad_error\.pt: the checkpoint's code_map_error"):
        Retargeter.load(tmp_path / "bad_error.pt", device="cpu")
    with pytest.raises(RetargetError, match="symmetric"):
        r.code_map_error = np.triu(np.ones((1, 128, 128), np.float32))
