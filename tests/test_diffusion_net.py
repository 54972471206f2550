"""Tests of nets.diffusion_net: shapes, pooling, gradients, discretisation agnosticism, invariances."""
import numpy as np
import pytest
import torch
import trimesh

from nets.diffusion_net import DiffusionNet, gradient_features, spectral_diffusion, tanh
from nets.geometry import compute_operators


def mesh_inputs(verts, faces, k=32, device="cpu"):
    """Features [position, unit normal] (V,6) float32 and TorchOperators of a mesh."""
    ops = compute_operators(verts, faces, k=k).to_torch(device)
    normals = trimesh.Trimesh(verts, faces, process=False).vertex_normals
    x = torch.tensor(np.concatenate([verts, normals], axis=1), dtype=torch.float32, device=device)
    return x, ops


def sphere(subdivisions, scale=(1.0, 1.0, 1.0)):
    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(s.vertices) * np.asarray(scale), np.asarray(s.faces)


@pytest.fixture(scope="module")
def spheres():
    return [mesh_inputs(*sphere(2)), mesh_inputs(*sphere(3))]


def test_output_shapes_for_meshes_of_different_sizes(spheres):
    torch.manual_seed(0)
    per_vertex = DiffusionNet(6, 5, width=16, n_blocks=2, last_activation=torch.sigmoid)
    outs = per_vertex.forward_batch([x for x, _ in spheres], [ops for _, ops in spheres])
    assert [tuple(o.shape) for o in outs] == [(162, 5), (642, 5)]
    assert all(o.dtype == torch.float32 and (o > 0).all() and (o < 1).all() for o in outs)
    pooled = DiffusionNet(6, 7, width=16, n_blocks=2, outputs="global_mean")
    assert [tuple(o.shape) for o in pooled.forward_batch([x for x, _ in spheres], [o for _, o in spheres])] == [(7,), (7,)]
    with pytest.raises(ValueError):
        DiffusionNet(6, 7, outputs="max")
    with pytest.raises(ValueError):
        per_vertex(spheres[0][0], spheres[1][1])


def test_global_mean_is_mass_weighted_mean_of_vertex_outputs():
    x, ops = mesh_inputs(*sphere(2, scale=(1.5, 1.0, 0.6)))
    torch.manual_seed(1)
    per_vertex = DiffusionNet(6, 4, width=16, n_blocks=2)
    pooled = DiffusionNet(6, 4, width=16, n_blocks=2, outputs="global_mean")
    pooled.load_state_dict(per_vertex.state_dict())
    y = per_vertex(x, ops)
    expected = (ops.mass[:, None] * y).sum(0) / ops.mass.sum()
    torch.testing.assert_close(pooled(x, ops), expected)
    assert not torch.allclose(expected, y.mean(0), atol=1e-4)  # the ellipsoid's areas are not uniform


def test_gradients_reach_every_parameter():
    x, ops = mesh_inputs(*sphere(2, scale=(1.5, 1.0, 0.6)))
    torch.manual_seed(2)
    net = DiffusionNet(6, 3, width=8, n_blocks=2)
    net(x, ops).square().sum().backward()
    for name, p in net.named_parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all() and p.grad.abs().max() > 0, name


def test_diffusion_is_exact_heat_flow_on_eigenfunctions():
    x, ops = mesh_inputs(*sphere(3))
    time = torch.tensor([0.0, 0.1, 0.5])
    f = ops.evecs[:, [0, 2, 5]]  # eigenvalues 0, 2, 6 on the unit sphere
    out = spectral_diffusion(f, time, ops)
    torch.testing.assert_close(out, f * torch.exp(-ops.evals[[0, 2, 5]] * time), atol=1e-4, rtol=1e-4)


def test_gradient_features_invariant_to_tangent_frame_rotation():
    torch.manual_seed(3)
    gx, gy = torch.randn(50, 6), torch.randn(50, 6)
    a_re, a_im = torch.randn(6, 6), torch.randn(6, 6)
    angle = torch.rand(50, 1) * 6.3
    rx, ry = gx * angle.cos() - gy * angle.sin(), gx * angle.sin() + gy * angle.cos()
    torch.testing.assert_close(gradient_features(rx, ry, a_re, a_im), gradient_features(gx, gy, a_re, a_im))


def test_discretisation_agnostic_global_output():
    coarse = mesh_inputs(*sphere(3))
    fine = mesh_inputs(*sphere(4))
    ellipsoid = mesh_inputs(*sphere(3, scale=(1.3, 1.0, 0.8)))
    torch.manual_seed(4)
    net = DiffusionNet(6, 16, width=32, n_blocks=2, outputs="global_mean")
    with torch.no_grad():
        z_coarse, z_fine, z_ellipsoid = (net(x, ops) for x, ops in (coarse, fine, ellipsoid))
    same_surface = (z_coarse - z_fine).norm()
    other_surface = (z_coarse - z_ellipsoid).norm()
    assert same_surface < 0.1 * other_surface, (same_surface, other_surface)


def test_rotation_invariance_with_invariant_features():
    verts, faces = sphere(2, scale=(1.4, 1.0, 0.7))
    q, _ = np.linalg.qr(np.random.default_rng(5).normal(size=(3, 3)))
    torch.manual_seed(5)
    net = DiffusionNet(1, 4, width=16, n_blocks=2)
    outs = []
    for v in (verts, verts @ q.T):
        ops = compute_operators(v, faces, k=24).to_torch()
        radius = torch.tensor(np.linalg.norm(v - v.mean(0), axis=1)[:, None], dtype=torch.float32)
        with torch.no_grad():
            outs.append(net(radius, ops))
    torch.testing.assert_close(outs[0], outs[1], atol=1e-4, rtol=1e-3)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu():
    verts, faces = sphere(2)
    x_cpu, ops_cpu = mesh_inputs(verts, faces)
    x_gpu, ops_gpu = mesh_inputs(verts, faces, device="cuda")
    torch.manual_seed(6)
    net = DiffusionNet(6, 3, width=16, n_blocks=2)
    expected = net(x_cpu, ops_cpu)
    out = net.to("cuda")(x_gpu, ops_gpu)
    out.sum().backward()
    torch.testing.assert_close(out.cpu(), expected, atol=1e-4, rtol=1e-4)


def test_sparse_matmul_with_a_given_transpose_matches_the_dense_product_and_its_gradient():
    from nets.diffusion_net import sparse_matmul
    gen = torch.Generator().manual_seed(0)
    dense = torch.randn(7, 5, generator=gen, dtype=torch.float64) * (torch.rand(7, 5, generator=gen) < 0.4)
    x = torch.randn(5, 3, generator=gen, dtype=torch.float64, requires_grad=True)
    a, a_t = dense.to_sparse_csr(), dense.T.contiguous().to_sparse_csr()
    torch.testing.assert_close(sparse_matmul(a, a_t, x), dense @ x)
    assert torch.autograd.gradcheck(lambda v: sparse_matmul(a, a_t, v), (x,))


def test_tanh_through_the_sigmoid_matches_torch_tanh_and_its_gradient():
    x = torch.linspace(-30.0, 30.0, 20001, dtype=torch.float32, requires_grad=True)
    y = tanh(x)
    torch.testing.assert_close(y, torch.tanh(x), atol=3e-7, rtol=0)
    (g,) = torch.autograd.grad(y.sum(), x)
    torch.testing.assert_close(g, 1.0 - torch.tanh(x.detach()) ** 2, atol=1e-6, rtol=0)


def test_constant_columns_give_the_result_of_the_full_input_and_its_gradients(spheres):
    x, ops = spheres[0]
    torch.manual_seed(0)
    net = DiffusionNet(6 + 5 + 2, 8, width=16, n_blocks=2, outputs="global_mean")
    code = torch.randn(5, requires_grad=True)
    extra = torch.randn(x.shape[0], 2)
    full = net(torch.cat([x, code.expand(x.shape[0], -1), extra], 1), ops)
    split = net(torch.cat([x, extra], 1), ops, constant=code, constant_at=6)
    torch.testing.assert_close(split, full, atol=1e-5, rtol=1e-5)
    g_full = torch.autograd.grad(full.sum(), [code, net.first.weight, net.first.bias])
    g_split = torch.autograd.grad(split.sum(), [code, net.first.weight, net.first.bias])
    for a, b in zip(g_split, g_full):
        torch.testing.assert_close(a, b, atol=1e-4, rtol=1e-4)
    with pytest.raises(ValueError, match="input columns"):
        net(x, ops, constant=code, constant_at=6)
