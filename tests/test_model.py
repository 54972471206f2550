"""Tests of nets.cnn and nets.model: shapes, per-vertex independence, chunking, gradients,
the no-skinning ablation, the code for FACS weights and the configuration round trip."""
import dataclasses
import functools

import numpy as np
import pytest
import torch
import trimesh

from nets import losses
from nets.geometry import compute_operators
from nets.model import NFSConfig, NFSModel, TargetCodes, weights_to_code


@functools.lru_cache(maxsize=None)
def _mesh_arrays(subdivisions: int, stretch: tuple):
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    verts = np.asarray(sphere.vertices) * stretch
    faces = np.asarray(sphere.faces, dtype=np.int64)
    return verts, faces, compute_operators(verts, faces, k=16)


def make_mesh(subdivisions=1, stretch=(1.0, 1.2, 0.9), device="cpu"):
    """An ellipsoid mesh: dict with verts (V,3), faces (F,3), feat (V,6), ops, img (1,2,32,32)."""
    verts, faces, ops = _mesh_arrays(subdivisions, tuple(stretch))
    v = torch.tensor(verts, dtype=torch.float32, device=device)
    f = torch.tensor(faces, device=device)
    feat = torch.cat([v, losses.vertex_normals(v, f)], dim=1)
    gen = torch.Generator().manual_seed(subdivisions)
    img = torch.rand(1, 2, 32, 32, generator=gen).to(device)
    return dict(verts=v, faces=f, feat=feat, ops=ops.to_torch(device), img=img)


def tiny_model(seed=0, **overrides):
    torch.manual_seed(seed)
    return NFSModel(NFSConfig.preset("tiny", **overrides)).eval()


def pair(model, src, tgt, **kw):
    c_src, c_tgt = model.image_code(torch.cat([src["img"], tgt["img"]]))
    return model.forward_pair(src["feat"], c_src, src["ops"], tgt["feat"], c_tgt, tgt["ops"], **kw)


def test_output_shapes_for_meshes_of_different_sizes():
    model = tiny_model()
    a, b = make_mesh(1), make_mesh(2, stretch=(0.8, 1.0, 1.1))
    assert model.image_code(torch.cat([a["img"], b["img"]])).shape == (2, 128)
    for src, tgt in ((a, b), (b, a)):
        out = pair(model, src, tgt)
        v = tgt["feat"].shape[0]
        assert out["z_ID"].shape == (128,) and out["z_GE"].shape == (128,)
        assert out["z_Skin"].shape == (v, 20) and out["z_LE"].shape == (v, 128)
        assert out["dv"].shape == (v, 3) and out["dv"].dtype == torch.float32
        assert ((out["z_Skin"] > 0) & (out["z_Skin"] < 1)).all()
        assert torch.isfinite(out["dv"]).all() and out["dv"].abs().max() > 0


def test_cnn_rejects_wrong_channels():
    with pytest.raises(ValueError, match="expects images"):
        tiny_model().image_code(torch.zeros(1, 3, 32, 32))


def test_decoding_a_vertex_subset_equals_full_decode_rows():
    model = tiny_model()
    src, tgt = make_mesh(1), make_mesh(2)
    full = pair(model, src, tgt)
    rows = torch.randperm(tgt["feat"].shape[0], generator=torch.Generator().manual_seed(1))[:37]
    sub = pair(model, src, tgt, vertex_subset=rows)
    assert sub["dv"].shape == (37, 3) and sub["z_LE"].shape == (37, 128)
    torch.testing.assert_close(sub["dv"], full["dv"][rows], rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(sub["z_LE"], full["z_LE"][rows])
    # the same through decode() directly
    c = model.image_code(tgt["img"])[0]
    dv_rows = model.decode(tgt["feat"][rows], c, full["z_ID"], full["z_LE"][rows])
    torch.testing.assert_close(dv_rows, full["dv"][rows], rtol=1e-5, atol=1e-6)


def test_chunked_decode_equals_unchunked():
    model = tiny_model()
    src, tgt = make_mesh(1), make_mesh(2)
    out = pair(model, src, tgt)
    c = model.image_code(tgt["img"])[0]
    whole = model.decode(tgt["feat"], c, out["z_ID"], out["z_LE"])
    for chunk in (1, 7, 64, 10_000):
        torch.testing.assert_close(model.decode(tgt["feat"], c, out["z_ID"], out["z_LE"], chunk=chunk),
                                   whole, rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError, match="chunk"):
        model.decode(tgt["feat"], c, out["z_ID"], out["z_LE"], chunk=0)
    # through decode_target, with z_LE formed per chunk from cached or uncached ω_Skin
    codes = model.encode_target(tgt["feat"], c, tgt["ops"])
    lean = TargetCodes(codes.z_id, codes.z_skin, None)
    rows = torch.arange(5, tgt["feat"].shape[0], 2)
    for target_codes in (codes, lean):
        torch.testing.assert_close(model.decode_target(tgt["feat"], c, target_codes, out["z_GE"], chunk=9),
                                   whole, rtol=1e-4, atol=1e-5)
        torch.testing.assert_close(model.decode_target(tgt["feat"], c, target_codes, out["z_GE"], rows, 9),
                                   whole[rows], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("use_skinning", [True, False])
def test_batched_decode_equals_the_decoder_on_the_concatenated_input(use_skinning):
    """decode_many folds the c and z_ID columns of the first layer into a bias: the same Δv as the
    paper's decoder on [v, c, z_ID, z_LE], for every one of S codes."""
    model = tiny_model(use_skinning=use_skinning)
    tgt = make_mesh(2)
    c = model.image_code(tgt["img"])[0]
    codes = model.encode_target(tgt["feat"], c, tgt["ops"])
    z_ge = torch.rand(3, 128, generator=torch.Generator().manual_seed(0))
    rows = torch.arange(3, tgt["feat"].shape[0], 3)
    batched = model.decode_target(tgt["feat"], c, codes, z_ge, rows, chunk=11)
    assert batched.shape == (3, len(rows), 3)
    for s in range(3):
        z_le = model.local_code(codes, z_ge[s], rows)
        z_le = z_le.expand(len(rows), -1) if z_le.dim() == 1 else z_le
        x = torch.cat([tgt["feat"][rows], c.expand(len(rows), -1), codes.z_id.expand(len(rows), -1),
                       z_le], dim=1)
        torch.testing.assert_close(batched[s], model.decoder(x), rtol=1e-4, atol=1e-5)
        torch.testing.assert_close(batched[s], model.decode_target(tgt["feat"], c, codes, z_ge[s], rows))
    with pytest.raises(ValueError, match="decode_many"):
        model.decode_many(tgt["feat"], c, codes.z_id, torch.zeros(2, 5, 128))


def test_group_encodes_target_once_and_matches_pairs(monkeypatch):
    model = tiny_model()
    tgt = make_mesh(2)
    sources = [make_mesh(1), make_mesh(1, stretch=(1.1, 1.0, 1.0)), make_mesh(2, stretch=(1, 1, 1))]
    imgs = model.image_code(torch.cat([tgt["img"]] + [s["img"] for s in sources]))
    calls = []
    original = model.encode_skinning
    monkeypatch.setattr(model, "encode_skinning", lambda *a: calls.append(1) or original(*a))
    out = model.forward_group(tgt["feat"], imgs[0], tgt["ops"], [s["feat"] for s in sources],
                              list(imgs[1:]), [s["ops"] for s in sources])
    assert len(calls) == 1
    v = tgt["feat"].shape[0]
    assert out["z_GE"].shape == (3, 128) and out["dv"].shape == (3, v, 3)
    assert out["z_LE"].shape == (3, v, 128)
    for i, s in enumerate(sources):
        single = model.forward_pair(s["feat"], imgs[i + 1], s["ops"], tgt["feat"], imgs[0], tgt["ops"])
        torch.testing.assert_close(out["dv"][i], single["dv"])
    assert (out["dv"][0] - out["dv"][1]).abs().max() > 1e-6  # different sources, different output


def total_loss(model, src, tgt, w_gt, id_gt, basis, labels):
    """Eq. 9 (ICT branch) on one pair whose source and target share the rig ``basis``."""
    out = pair(model, src, tgt)
    c_tgt = model.image_code(tgt["img"])[0]
    gt = tgt["verts"] + losses.blend(w_gt, basis)
    pred = tgt["verts"] + out["dv"]
    codes = model.encode_target(tgt["feat"], c_tgt, tgt["ops"])
    loss = (losses.decoder_loss(pred, gt, tgt["verts"], tgt["faces"])["L_dec"]
            + losses.identity_loss(out["z_ID"], id_gt) + losses.expression_loss(out["z_GE"], w_gt)
            + losses.blendshape_projection_loss(out["z_GE"], w_gt, basis)
            + losses.blendshape_reconstruction_loss(model, tgt["feat"], c_tgt, codes, out["z_GE"], basis))
    if model.cfg.use_skinning:
        loss = loss + losses.segmentation_nll(out["z_Skin"], labels)
    return loss


def rig_targets(v, seed=0):
    gen = torch.Generator().manual_seed(seed)
    return dict(w_gt=torch.rand(53, generator=gen), id_gt=torch.randn(50, generator=gen),
                basis=0.05 * torch.randn(53, v, 3, generator=gen),
                labels=torch.randint(0, 20, (v,), generator=gen))


@pytest.mark.parametrize("use_skinning", [True, False])
def test_gradients_reach_every_parameter(use_skinning):
    model = tiny_model(use_skinning=use_skinning).train()
    src, tgt = make_mesh(1), make_mesh(1, stretch=(1, 1, 1))
    total_loss(model, src, tgt, **rig_targets(tgt["feat"].shape[0])).backward()
    missing = [n for n, p in model.named_parameters() if p.grad is None or not p.grad.abs().sum() > 0]
    assert not missing, f"no gradient for {missing}"


def test_no_skinning_ablation_has_no_skinning_parameters_and_decodes():
    model = tiny_model(use_skinning=False)
    assert not [n for n, _ in model.named_parameters() if "skinning" in n]
    full = sum(p.numel() for p in tiny_model().parameters())
    assert sum(p.numel() for p in model.parameters()) < full
    src, tgt = make_mesh(1), make_mesh(2)
    out = pair(model, src, tgt)
    assert out["z_Skin"] is None and out["z_LE"] is None and out["dv"].shape == (tgt["feat"].shape[0], 3)
    c = model.image_code(tgt["img"])[0]
    broadcast = out["z_GE"].expand(tgt["feat"].shape[0], -1)
    torch.testing.assert_close(model.decode(tgt["feat"], c, out["z_ID"], broadcast), out["dv"])
    with pytest.raises(ValueError, match="use_skinning=False"):
        model.encode_skinning(tgt["feat"], c, tgt["ops"])


def test_weights_to_code_and_driving_from_weights():
    w = torch.rand(4, 5, 53)
    z = weights_to_code(w)
    assert z.shape == (4, 5, 128)
    assert torch.equal(z[..., :53], w) and not z[..., 53:].any()
    with pytest.raises(ValueError):
        weights_to_code(torch.zeros(129))
    model = tiny_model()
    tgt = make_mesh(1)
    c = model.image_code(tgt["img"])[0]
    codes = model.encode_target(tgt["feat"], c, tgt["ops"])
    dv = model.decode_target(tgt["feat"], c, codes, weights_to_code(w[0, 0]))
    expected = model.decode(tgt["feat"], c, codes.z_id, model.skinning_block(codes.z_skin, z[0, 0]))
    torch.testing.assert_close(dv, expected)


def test_config_round_trip_and_unknown_keys(tmp_path):
    for name in ("paper", "cpu", "tiny"):
        cfg = NFSConfig.preset(name)
        path = tmp_path / f"{name}.pt"
        torch.save({"config": cfg.to_dict()}, path)
        assert NFSConfig.from_dict(torch.load(path, weights_only=True)["config"]) == cfg
    assert NFSConfig.preset("paper").enc_width == 256 and NFSConfig.preset("tiny").enc_blocks == 1
    assert NFSConfig.preset("cpu", n_segments=6).n_segments == 6
    with pytest.raises(ValueError, match="unknown keys.*'widht'"):
        NFSConfig.from_dict({**NFSConfig().to_dict(), "widht": 3})
    # a retired key of older checkpoints (the bundled one has n_identity) is dropped
    assert NFSConfig.from_dict({**NFSConfig().to_dict(), "n_identity": 50}) == NFSConfig()
    with pytest.raises(ValueError, match="unknown NFSConfig preset"):
        NFSConfig.preset("huge")
    with pytest.raises(ValueError, match="use_skinning"):
        NFSConfig(use_skinning=1)
    with pytest.raises(ValueError, match="n_facs"):
        NFSConfig(code_dim=32)


def test_input_validation():
    model = tiny_model()
    tgt = make_mesh(1)
    c = model.image_code(tgt["img"])[0]
    with pytest.raises(ValueError, match="vertex features"):
        model.encode_identity(tgt["feat"][:, :3], c, tgt["ops"])
    with pytest.raises(ValueError, match="image code"):
        model.encode_identity(tgt["feat"], c[None], tgt["ops"])
    with pytest.raises(ValueError, match="z_code"):
        model.decode(tgt["feat"], c, torch.zeros(128), torch.zeros(5, 128))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu():
    model = tiny_model()
    src, tgt = make_mesh(1), make_mesh(2)
    cpu = pair(model, src, tgt)
    cuda = pair(model.cuda(), make_mesh(1, device="cuda"), make_mesh(2, device="cuda"))
    assert cuda["dv"].is_cuda
    torch.testing.assert_close(cuda["dv"].cpu(), cpu["dv"], rtol=1e-3, atol=1e-4)


def test_row_group_norm_equals_group_norm_forward_and_backward():
    from nets.cnn import RowGroupNorm
    torch.manual_seed(0)
    fast, ref = RowGroupNorm(4, 32), torch.nn.GroupNorm(4, 32)
    with torch.no_grad():
        fast.weight.uniform_(0.5, 1.5), fast.bias.uniform_(-1, 1)
    ref.load_state_dict(fast.state_dict())
    x = torch.randn(50, 32, requires_grad=True)
    y_fast, y_ref = fast(x), ref(x)
    torch.testing.assert_close(y_fast, y_ref, rtol=1e-4, atol=1e-5)
    g_fast = torch.autograd.grad((y_fast ** 3).sum(), [x, fast.weight, fast.bias])
    g_ref = torch.autograd.grad((y_ref ** 3).sum(), [x, ref.weight, ref.bias])
    for a, b in zip(g_fast, g_ref):
        torch.testing.assert_close(a, b, rtol=1e-3, atol=1e-4)
    img = torch.randn(2, 32, 5, 5)                # the CNN's 4D inputs take nn.GroupNorm's path
    torch.testing.assert_close(fast(img), ref(img))


def test_preset_benchmark_reports_each_preset_and_size():
    from nets.model import benchmark_presets
    rows = benchmark_presets(["tiny"], [200, 400], repeats=1)
    assert [(r["preset"], r["n_vertices"]) for r in rows] == [("tiny", 196), ("tiny", 400)]
    assert rows[0]["n_params"] == sum(p.numel() for p in tiny_model().parameters())
    assert all(r["forward_ms"] > 0 and r["backward_ms"] > 0 for r in rows)


# ------------------------------------------------------------------------------- basis decoder
def _basis_target(use_skinning=True, seed=0):
    model = tiny_model(seed, decoder="basis", decoder_fourier=3, use_skinning=use_skinning)
    tgt = make_mesh(2)
    c = model.image_code(tgt["img"])[0]
    return model, tgt, c


@pytest.mark.parametrize("use_skinning", [True, False])
def test_basis_decoder_is_a_rig_linear_in_z_ge(use_skinning):
    model, tgt, c = _basis_target(use_skinning)
    codes = model.encode_target(tgt["feat"], c, tgt["ops"])
    v = tgt["feat"].shape[0]
    assert codes.basis.shape == (v, 3, 128)
    gen = torch.Generator().manual_seed(1)
    z1, z2 = torch.rand(128, generator=gen), torch.rand(128, generator=gen)
    dv = lambda z: model.decode_target(tgt["feat"], c, codes, z)
    torch.testing.assert_close(dv(2.0 * z1 - 0.5 * z2), 2.0 * dv(z1) - 0.5 * dv(z2),
                               rtol=1e-4, atol=1e-5)
    assert dv(torch.zeros(128)).abs().max() == 0 and dv(z1).abs().max() > 0
    # Δv = M(x)ᵀ z_LE: the cached rig, M computed per chunk, and decode_many on z_LE all agree
    lean = model.encode_target(tgt["feat"], c, tgt["ops"], basis=False)
    assert lean.basis is None
    z = torch.stack([z1, z2])
    full = model.decode_target(tgt["feat"], c, codes, z)
    rows = torch.tensor([5, 0, 17, 3])
    torch.testing.assert_close(model.decode_target(tgt["feat"], c, lean, z, chunk=7), full,
                               rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(model.decode_target(tgt["feat"], c, lean, z, rows, chunk=3),
                               full[:, rows], rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(
        model.decode_many(tgt["feat"], c, codes.z_id, model.local_code(lean, z), z_skin=lean.z_skin),
        full, rtol=1e-4, atol=1e-5)
    if use_skinning:   # z_LE = ω_Skin ⊙ z_GE: ω_Skin is what makes the code local
        omega = codes.omega_skin
        torch.testing.assert_close(
            model.decode(tgt["feat"], c, codes.z_id, omega * z1, z_skin=codes.z_skin), full[0],
            rtol=1e-4, atol=1e-5)
        with pytest.raises(ValueError, match="needs z_Skin"):
            model.decode(tgt["feat"], c, codes.z_id, omega * z1)
    # chunked preparation of the rig equals the whole
    chunked = model.with_basis(tgt["feat"], c, dataclasses.replace(lean, omega_skin=None), chunk=10)
    torch.testing.assert_close(chunked.basis, codes.basis, rtol=1e-4, atol=1e-6)


def test_basis_decoder_gradients_reach_every_trained_part():
    model, tgt, c_tgt = _basis_target()
    model.train()
    src = make_mesh(1)
    c_src, c_tgt = model.image_code(torch.cat([src["img"], tgt["img"]]))
    out = model.forward_pair(src["feat"], c_src, src["ops"], tgt["feat"], c_tgt, tgt["ops"],
                             vertex_subset=torch.arange(0, 40))
    assert out["dv"].shape == (40, 3) and out["z_LE"].shape == (40, 128)
    out["dv"].square().mean().backward()
    for part in ("decoder", "skinning_mlp", "skinning_encoder", "identity_encoder",
                 "expression_encoder", "cnn"):
        grads = [p.grad for n, p in model.named_parameters() if n.startswith(part)]
        assert grads and all(g is not None for g in grads), part
        assert sum(g.abs().sum() for g in grads) > 0, part


def test_decoder_field_defaults_to_mlp_for_old_checkpoints():
    old = {k: v for k, v in NFSConfig().to_dict().items() if k not in ("decoder", "decoder_fourier")}
    assert NFSConfig.from_dict(old).decoder == "mlp"
    assert NFSModel(NFSConfig.from_dict(old)).decoder[-1].out_features == 3
    assert NFSModel(NFSConfig.preset("tiny", decoder="basis")).decoder[-1].out_features == 3 * 128
    with pytest.raises(ValueError, match="decoder: expected one of"):
        NFSConfig(decoder="linear")
    with pytest.raises(ValueError, match="decoder_fourier: expected an int in 0..16"):
        NFSConfig(decoder_fourier=-1)
    # the MLP decoder keeps no rig
    model = tiny_model()
    tgt = make_mesh(1)
    c = model.image_code(tgt["img"])[0]
    assert model.encode_target(tgt["feat"], c, tgt["ops"]).basis is None
