"""Tests of nets.losses: known values, invariances, and which parameters each NFS loss trains."""
import math

import numpy as np
import pytest
import torch

from nets import losses
from tests.test_model import make_mesh, pair, tiny_model


def grid(m=6):
    """Planar m x m grid in z = 0 (unit square), counter-clockwise seen from +z: verts, faces."""
    u, v = torch.meshgrid(torch.linspace(0, 1, m), torch.linspace(0, 1, m), indexing="ij")
    verts = torch.stack([u.ravel(), v.ravel(), torch.zeros(m * m)], dim=1)
    idx = torch.arange(m * m).reshape(m, m)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return verts, torch.cat([torch.stack([a, b, c], 1), torch.stack([a, c, d], 1)])


def rotation(axis, angle):
    """Rotation matrix (3,3) about a unit axis (Rodrigues)."""
    k = torch.tensor([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]],
                     dtype=torch.float32)
    return torch.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def test_vertex_loss_known_values():
    v = torch.randn(2, 50, 3)
    assert losses.vertex_loss(v, v) == 0
    d = torch.tensor([0.3, -1.0, 2.0])
    torch.testing.assert_close(losses.vertex_loss(v + d, v), d.pow(2).sum())


def test_vertex_normals_of_a_sphere_point_outwards():
    mesh = make_mesh(2, stretch=(1, 1, 1))
    n = losses.vertex_normals(mesh["verts"], mesh["faces"])
    radial = mesh["verts"] / mesh["verts"].norm(dim=1, keepdim=True)
    assert (n * radial).sum(1).min() > 0.99
    torch.testing.assert_close(n.norm(dim=1), torch.ones(len(n)))


def test_normal_loss_known_values():
    verts, faces = grid()
    assert losses.normal_loss(verts, verts, faces) == 0
    scaled = 3.0 * verts + torch.tensor([1.0, 2.0, 3.0])
    assert losses.normal_loss(scaled, verts, faces) < 1e-10  # normals ignore scale and translation
    theta = 0.4  # a rigid tilt turns every normal (0, 0, 1) by theta: |n - n_gt|² = 2 - 2 cos(theta)
    tilted = verts @ rotation((1.0, 0.0, 0.0), theta).T
    torch.testing.assert_close(losses.normal_loss(tilted, verts, faces),
                               torch.tensor(2 - 2 * math.cos(theta)))


def test_jacobian_loss_translation_rotation_and_shear():
    mesh = make_mesh(2)
    rest, faces = mesh["verts"], mesh["faces"]
    gt = rest + 0.05 * torch.randn_like(rest)
    t = torch.tensor([1.0, -2.0, 0.5])
    assert losses.jacobian_loss(gt, gt, rest, faces) == 0
    assert losses.jacobian_loss(gt + t, gt, rest, faces) < 1e-8  # zero for a pure translation
    pred = gt + 0.05 * torch.randn_like(rest)
    torch.testing.assert_close(losses.jacobian_loss(pred + t, gt, rest, faces),
                               losses.jacobian_loss(pred, gt, rest, faces), rtol=1e-4, atol=1e-6)
    # a rotation of the rest mesh has J = R on every face
    r = rotation((0.6, 0.0, 0.8), 0.7)
    j, valid = losses.deformation_gradients(rest @ r.T, rest, faces)
    assert valid.all()
    torch.testing.assert_close(j, r.expand_as(j), rtol=1e-4, atol=1e-4)


def test_jacobian_loss_of_an_in_plane_shear_is_k_squared():
    verts, faces = grid()
    k = 0.3
    sheared = verts.clone()
    sheared[:, 0] += k * verts[:, 1]  # J = [[1, k, 0], [0, 1, 0], [0, 0, 1]] on every face
    torch.testing.assert_close(losses.jacobian_loss(sheared, verts, verts, faces), torch.tensor(k * k))


def test_jacobian_loss_skips_degenerate_faces():
    verts, faces = grid()
    faces = torch.cat([faces, torch.tensor([[0, 0, 1]])])  # zero-area face
    pred = verts + 0.01 * torch.randn_like(verts)
    pred.requires_grad_(True)
    loss = losses.jacobian_loss(pred, verts, verts, faces)
    loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(pred.grad).all() and loss > 0


def test_decoder_loss_combines_the_three_terms():
    mesh = make_mesh(1)
    rest, faces = mesh["verts"], mesh["faces"]
    gt = rest + 0.1 * torch.randn_like(rest)
    pred = gt + 0.05 * torch.randn_like(rest)
    parts = losses.decoder_loss(pred, gt, rest, faces)
    torch.testing.assert_close(parts["L_dec"], 10 * parts["L_v"] + parts["L_n"] + parts["L_g"])
    assert all(parts[k] > 0 for k in ("L_v", "L_n", "L_g"))
    custom = losses.decoder_loss(pred, gt, rest, faces, lambda_v=1.0, lambda_n=0.0, lambda_g=2.0)
    torch.testing.assert_close(custom["L_dec"], parts["L_v"] + 2 * parts["L_g"])
    assert losses.decoder_loss(gt, gt, rest, faces)["L_dec"] == 0


def test_identity_and_expression_losses():
    w = torch.rand(3, 53)
    z = torch.cat([w, torch.zeros(3, 75)], dim=1)
    assert losses.expression_loss(z, w) == 0
    torch.testing.assert_close(losses.expression_loss(z + torch.cat([torch.ones(53), torch.zeros(75)]), w),
                               torch.tensor(53.0))
    ident = torch.randn(50)
    z_id = torch.cat([ident, torch.full((78,), 2.0)])
    torch.testing.assert_close(losses.identity_loss(z_id, ident), torch.tensor(4.0 * 78))
    with pytest.raises(ValueError):
        losses.identity_loss(torch.zeros(10), ident)


def test_blendshape_projection_loss_known_value():
    gen = torch.Generator().manual_seed(0)
    basis = torch.randn(53, 40, 3, generator=gen)
    w = torch.rand(53, generator=gen)
    z = torch.cat([w, torch.randn(75, generator=gen)])  # extra dims do not enter eq. 7
    assert losses.blendshape_projection_loss(z, w, basis) == 0
    z2 = z.clone()
    z2[26] += 0.5  # one weight off by 0.5 -> displacement 0.5 * B[26]
    expected = np.mean(np.sum((0.5 * basis[26].numpy()) ** 2, axis=1))
    torch.testing.assert_close(losses.blendshape_projection_loss(z2, w, basis),
                               torch.tensor(expected, dtype=torch.float32))


def test_segmentation_nll_and_code_range_known_values():
    labels = torch.tensor([0, 2, 1, 2])
    half = torch.full((4, 3), 0.5)
    torch.testing.assert_close(losses.segmentation_nll(half, labels), torch.tensor(3 * math.log(2)))
    good = torch.nn.functional.one_hot(labels, 3).float() * 0.998 + 0.001
    assert losses.segmentation_nll(good, labels) < 0.01
    z = torch.tensor([-0.5, 0.0, 0.5, 1.0, 1.5, 2.0])
    torch.testing.assert_close(losses.code_range_loss(z), torch.tensor((0.5 + 0.5 + 1.0) / 6))
    assert losses.code_range_loss(torch.rand(100)) == 0


def _grads(model, loss, prefix):
    model.zero_grad()
    loss.backward()
    return {n: None if p.grad is None else p.grad.clone()
            for n, p in model.named_parameters() if n.startswith(prefix)}


def _setup(seed=0):
    model = tiny_model(seed).train()
    mesh = make_mesh(1)
    v = mesh["feat"].shape[0]
    gen = torch.Generator().manual_seed(seed)
    basis, w = 0.1 * torch.randn(53, v, 3, generator=gen), torch.rand(53, generator=gen)
    return model, mesh, basis, w


def _encode(model, mesh):
    out = pair(model, mesh, mesh)
    c = model.image_code(mesh["img"])[0]
    return out, c, model.encode_target(mesh["feat"], c, mesh["ops"])


def test_blendshape_projection_loss_trains_the_expression_encoder_only():
    model, mesh, basis, w = _setup()
    out, _, _ = _encode(model, mesh)
    grads = _grads(model, losses.blendshape_projection_loss(out["z_GE"], w, basis), "")
    assert all(g is not None and g.abs().sum() > 0 for n, g in grads.items()
               if n.startswith("expression_encoder"))
    assert all(g is None for n, g in grads.items() if n.startswith("decoder"))
    # and it changes the expression encoder's gradient of the expression loss
    out, _, _ = _encode(model, mesh)
    base = _grads(model, losses.expression_loss(out["z_GE"], w), "expression_encoder")
    out, _, _ = _encode(model, mesh)
    both = _grads(model, losses.expression_loss(out["z_GE"], w)
                  + losses.blendshape_projection_loss(out["z_GE"], w, basis), "expression_encoder")
    assert any((base[n] - both[n]).abs().max() > 1e-6 for n in base)


def test_blendshape_reconstruction_loss_trains_the_decoder_not_the_expression_encoder():
    model, mesh, basis, w = _setup()
    out, c, codes = _encode(model, mesh)
    l_br = losses.blendshape_reconstruction_loss(model, mesh["feat"], c, codes, out["z_GE"], basis)
    grads = _grads(model, l_br, "")
    assert all(g is None for n, g in grads.items() if n.startswith("expression_encoder"))
    assert all(g is not None and g.abs().sum() > 0 for n, g in grads.items() if n.startswith("decoder"))
    # it changes the decoder's gradient of the vertex loss
    gt = losses.blend(w, basis)
    out, c, codes = _encode(model, mesh)
    base = _grads(model, losses.vertex_loss(out["dv"], gt), "decoder")
    out, c, codes = _encode(model, mesh)
    both = _grads(model, losses.vertex_loss(out["dv"], gt) + losses.blendshape_reconstruction_loss(
        model, mesh["feat"], c, codes, out["z_GE"], basis), "decoder")
    assert any((base[n] - both[n]).abs().max() > 1e-6 for n in base)


def test_blendshape_reconstruction_loss_known_value_and_subset():
    model, mesh, basis, w = _setup()
    model.eval()
    out, c, codes = _encode(model, mesh)
    z = out["z_GE"].detach()
    dv = model.decode_target(mesh["feat"], c, codes, z)
    expected = losses.vertex_loss(dv, losses.blend(z[:53], basis))
    torch.testing.assert_close(
        losses.blendshape_reconstruction_loss(model, mesh["feat"], c, codes, z, basis), expected)
    rows = torch.arange(0, mesh["feat"].shape[0], 3)
    expected_rows = losses.vertex_loss(dv[rows], losses.blend(z[:53], basis)[rows])
    torch.testing.assert_close(losses.blendshape_reconstruction_loss(
        model, mesh["feat"], c, codes, torch.stack([z, z]), basis, rows), expected_rows,
        rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("decoder", ["mlp", "basis"])
def test_rig_loss_is_zero_on_the_decoders_own_one_hot_shapes_and_trains_the_decoder(decoder):
    model = tiny_model(0, decoder=decoder)
    mesh = make_mesh(1)
    c = model.image_code(mesh["img"])[0]
    codes = model.encode_target(mesh["feat"], c, mesh["ops"])
    one_hot = torch.eye(model.cfg.code_dim)[:53]                      # [e_k, 0]
    own = model.decode_target(mesh["feat"], c, codes, one_hot).detach()   # (53, V, 3)
    assert losses.rig_loss(model, mesh["feat"], c, codes, own) < 1e-10
    other = own.clone()
    other[7] += torch.tensor([0.0, 0.2, 0.0])                  # shape 7 of the rig moved by 0.2
    # mean over 53 shapes of |0.2|² on every vertex of shape 7
    torch.testing.assert_close(losses.rig_loss(model, mesh["feat"], c, codes, other),
                               torch.tensor(0.04 / 53), rtol=1e-4, atol=1e-7)
    rows, shapes = torch.arange(0, mesh["feat"].shape[0], 2), torch.tensor([7, 9])
    torch.testing.assert_close(losses.rig_loss(model, mesh["feat"], c, codes, other, rows, shapes),
                               torch.tensor(0.04 / 2), rtol=1e-4, atol=1e-7)
    # relative (τ): shape 7's error over its own size in the rig, against the rig's mean size
    size = other.pow(2).sum(-1).mean(-1)
    weight = size.mean() / (size[7] + 0.05 * size.mean())
    torch.testing.assert_close(losses.rig_loss(model, mesh["feat"], c, codes, other, relative=0.05),
                               0.04 * weight / 53, rtol=1e-4, atol=1e-7)
    # a shape the rig draws far smaller than the decoder: its error weighs up to 1/τ times more
    k = int(own.pow(2).sum(-1).mean(-1).argmin())
    tiny = own.clone()
    tiny[k] *= 0.05
    plain = losses.rig_loss(model, mesh["feat"], c, codes, tiny)
    relative = losses.rig_loss(model, mesh["feat"], c, codes, tiny, relative=0.05)
    assert 10 * plain < relative <= 20 * plain * (1 + 1e-4)
    model.train()
    codes = model.encode_target(mesh["feat"], c, mesh["ops"])
    grads = _grads(model, losses.rig_loss(model, mesh["feat"], c, codes, 0.1 * other), "")
    assert all(g is None for n, g in grads.items() if n.startswith("expression_encoder"))
    assert any(g is not None and g.abs().sum() > 0 for n, g in grads.items() if n.startswith("decoder"))


def test_solve_loss_is_the_ridge_weights_error_on_the_decoders_own_rig_and_trains_the_decoder():
    """On the decoder's own one-hot shapes the ridge solve gives the weights back (up to its
    shrinkage, which vanishes with λ); a rig whose shape 7 is drawn as shape 9 costs the weights
    of both; the loss reaches the decoder. The decoder: a linear rig of 200 random vertices."""

    class Rig(torch.nn.Module):
        cfg = type("C", (), {"code_dim": 60})()

        def __init__(self):
            super().__init__()
            self.decoder = torch.nn.Parameter(torch.randn(60, 200, 3, generator=torch.Generator().manual_seed(1)))

        def decode_target(self, feat, c, codes, z, rows=None):
            shapes = self.decoder if rows is None else self.decoder[:, rows]
            return torch.einsum("sk,kvd->svd", z, shapes)

    model = Rig()
    own = model.decoder[:53].detach().clone()
    w = torch.rand(4, 53, generator=torch.Generator().manual_seed(0))
    exact = losses.solve_loss(model, None, None, None, own, w, ridge=1e-9)
    assert exact < 1e-4
    assert losses.solve_loss(model, None, None, None, own, w, ridge=0.1) > 10 * exact
    swapped = own.clone()
    swapped[7] = own[9]                                   # the true rig's shape 7 is the decoder's 9
    off = losses.solve_loss(model, None, None, None, swapped, w, ridge=1e-9)
    # frames w B draw 9 with w_7 + w_9 and 7 not at all: those two weights are off by w_7 each
    torch.testing.assert_close(off, 2 * w[:, 7].mean() / 53, rtol=1e-3, atol=1e-5)
    rows = torch.arange(0, 200, 2)
    assert losses.solve_loss(model, None, None, None, own, w, rows, ridge=1e-9) < 1e-4
    loss = losses.solve_loss(model, None, None, None, swapped, w)
    loss.backward()
    assert model.decoder.grad[:53].abs().sum() > 0 and not model.decoder.grad[53:].any()
