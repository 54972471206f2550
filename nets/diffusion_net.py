"""DiffusionNet (Sharp, Attaiki, Crane, Ovsjanikov 2022): discretisation-agnostic learning on surfaces.

The network is a stack of blocks acting on per-vertex features x (V, C):

1. learned-time spectral diffusion, per channel c with its own time t_c > 0:
   ``x_diffused = evecs @ (exp(-evals ⊗ t) * (evecs^T (mass * x)))``;
2. spatial gradient features: the tangent gradient ``g = gradX x_diffused + i gradY x_diffused``
   (a complex number per vertex and channel, in the vertex's tangent frame), a learned complex-linear
   map A across channels, and ``tanh(Re(g · conj(A g)))`` -- a dot product of the gradient with a
   rotated/scaled copy of itself, so independent of the arbitrary choice of tangent frame;
3. a per-vertex MLP on [x, x_diffused, gradient features] (3·width -> width -> width), added to x.

Operators (mass, evals, evecs, gradX, gradY) are precomputed by :mod:`nets.geometry` and passed to
``forward`` explicitly; nothing here depends on a device or on the mesh connectivity, so the same
weights run on any mesh, on the CPU or the GPU.

The NFS model uses three of these networks: the identity encoder (-> z_ID, ``outputs="global_mean"``),
the expression encoder (-> z_GE, ``"global_mean"``) and the skinning encoder (-> z_Skin, per vertex).
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

import torch
from torch import nn

from nets.geometry import TorchOperators

#: Diffusion times are initialised log-uniformly over this range, in squared canonical length units.
#: Canonical heads are 16 units wide (retarget.canonical), so heat spreads over sqrt(t) ≈ 0.2 to 6
#: units at the start: from a wrinkle to a whole cheek.
INITIAL_TIME_RANGE = (0.05, 40.0)


def spectral_diffusion(x: torch.Tensor, time: torch.Tensor, ops: TorchOperators) -> torch.Tensor:
    """Heat diffusion of each channel of x for its own time, in the truncated Laplace basis.

    x (V,C) float; time (C,) > 0 (squared length units); ops: mass (V,), evals (k,), evecs (V,k).
    Returns (V,C): ``evecs @ (exp(-evals[:, None] * time[None]) * (evecs.T @ (mass[:, None] * x)))``.
    """
    spectrum = ops.evecs.transpose(0, 1) @ (ops.mass[:, None] * x)            # (k,C)
    decay = torch.exp(-ops.evals[:, None] * time[None, :])                     # (k,C)
    return ops.evecs @ (decay * spectrum)


class _SparseMatmul(torch.autograd.Function):
    """y = A @ x for a constant sparse A whose transpose is given: the backward is the product
    A^T @ dy. PyTorch's own backward of ``sparse @ dense`` transposes A on every call (a sort of its
    indices), which took ~9 % of a CPU training step."""

    @staticmethod
    def forward(ctx, a: torch.Tensor, a_t: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        ctx.a_t = a_t
        return a @ x

    @staticmethod
    def backward(ctx, dy: torch.Tensor):
        return None, None, ctx.a_t @ dy if ctx.needs_input_grad[2] else None


def sparse_matmul(a: torch.Tensor, a_t: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """A @ x, A (N,M) a constant sparse matrix, a_t its transpose (M,N), x (M,C) -> (N,C)."""
    return _SparseMatmul.apply(a, a_t, x)


def tangent_gradient(x: torch.Tensor, ops: TorchOperators) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-vertex tangent-plane gradient of each channel: (gx, gy), each (V,C), in the vertex frames."""
    if ops.grad_xy is None:
        return ops.gradX @ x, ops.gradY @ x
    g = sparse_matmul(ops.grad_xy, ops.grad_xy_t, x)                           # (2V,C)
    return g[: x.shape[0]], g[x.shape[0]:]


def tanh(x: torch.Tensor) -> torch.Tensor:
    """tanh(x) as ``2 sigmoid(2x) - 1`` (the same function; within 2e-7 of torch.tanh in float32).

    PyTorch 2.13's CPU tanh takes 1.8 ms on a (11211, 64) float32 tensor on this project's machine
    (AVX-512), its sigmoid 0.2 ms; the whole expression 0.4 ms. It took 4 x 4 ms of a 125 ms
    inversion frame. Autograd-safe (no in-place op)."""
    return torch.sigmoid(2.0 * x) * 2.0 - 1.0


def gradient_features(gx: torch.Tensor, gy: torch.Tensor, a_re: torch.Tensor, a_im: torch.Tensor) -> torch.Tensor:
    """Rotation-invariant gradient features ``tanh(Re(g · conj(A g)))``.

    gx, gy (V,C): real and imaginary parts of the complex gradient g per channel.
    a_re, a_im (C,C): real and imaginary parts of the complex channel-mixing matrix A.
    Returns (V,C). Rotating every tangent frame by any angle multiplies g by a unit complex number per
    vertex, which cancels in g · conj(A g).
    """
    ag_re = gx @ a_re.T - gy @ a_im.T
    ag_im = gy @ a_re.T + gx @ a_im.T
    return tanh(gx * ag_re + gy * ag_im)


class DiffusionNetBlock(nn.Module):
    """Diffusion + spatial gradient features + per-vertex MLP, with a residual connection.

    width: channels C in and out. dropout: probability after the MLP's hidden layer.
    Parameters: ``log_time`` (C,) (t = exp(log_time) > 0), complex map ``A_re``/``A_im`` (C,C), the MLP.
    """

    def __init__(self, width: int, dropout: float = 0.0):
        super().__init__()
        low, high = (math.log(t) for t in INITIAL_TIME_RANGE)
        self.log_time = nn.Parameter(torch.linspace(low, high, width))
        self.A_re = nn.Linear(width, width, bias=False)
        self.A_im = nn.Linear(width, width, bias=False)
        self.mlp = nn.Sequential(
            nn.Linear(3 * width, width), nn.ReLU(), nn.Dropout(dropout), nn.Linear(width, width)
        )

    @property
    def diffusion_time(self) -> torch.Tensor:
        """(C,) diffusion time per channel, > 0."""
        return self.log_time.exp()

    def forward(self, x: torch.Tensor, ops: TorchOperators) -> torch.Tensor:
        """x (V,C) -> (V,C)."""
        x_diffused = spectral_diffusion(x, self.diffusion_time, ops)
        gx, gy = tangent_gradient(x_diffused, ops)
        grad_features = gradient_features(gx, gy, self.A_re.weight, self.A_im.weight)
        return x + self.mlp(torch.cat([x, x_diffused, grad_features], dim=-1))


class DiffusionNet(nn.Module):
    """Linear c_in -> width, ``n_blocks`` :class:`DiffusionNetBlock`, linear width -> c_out.

    outputs: ``"vertices"`` -> (V, c_out) per vertex; ``"global_mean"`` -> (c_out,), the area-weighted
    (mass-weighted) mean of the per-vertex outputs. last_activation: optional callable applied last
    (after the mean for ``"global_mean"``), e.g. ``torch.sigmoid`` for z_Skin in (0, 1).
    """

    OUTPUTS = ("vertices", "global_mean")

    def __init__(self, c_in: int, c_out: int, width: int = 128, n_blocks: int = 4, dropout: float = 0.0,
                 outputs: str = "vertices", last_activation: Callable[[torch.Tensor], torch.Tensor] | None = None):
        super().__init__()
        if outputs not in self.OUTPUTS:
            raise ValueError(f"DiffusionNet: outputs must be one of {self.OUTPUTS}, got {outputs!r}")
        self.outputs = outputs
        self.last_activation = last_activation
        self.first = nn.Linear(c_in, width)
        self.blocks = nn.ModuleList(DiffusionNetBlock(width, dropout) for _ in range(n_blocks))
        self.last = nn.Linear(width, c_out)

    def forward(self, x: torch.Tensor, ops: TorchOperators, constant: torch.Tensor | None = None,
                constant_at: int = 0) -> torch.Tensor:
        """x (V, c_in) on the operators' device and dtype -> (V, c_out) or (c_out,).

        ``constant`` (k,): input columns that are the same at every vertex (e.g. an image code),
        left out of x (then (V, c_in − k)); in the full input they are columns
        [constant_at, constant_at + k). The result is that of the full input, but the first layer
        multiplies only the per-vertex columns (the image code is 128 of the expression encoder's
        141 inputs)."""
        if x.shape[0] != ops.n_vertices:
            raise ValueError(f"DiffusionNet: {x.shape[0]} feature rows for a mesh of {ops.n_vertices} vertices")
        if constant is None:
            h = self.first(x)
        else:
            w, k = self.first.weight, constant.shape[0]
            if x.shape[1] + k != self.first.in_features:
                raise ValueError(f"DiffusionNet: {x.shape[1]} + {k} input columns for a first layer "
                                 f"of {self.first.in_features}")
            bias = torch.addmv(self.first.bias, w[:, constant_at:constant_at + k], constant)
            w_vertex = torch.cat([w[:, :constant_at], w[:, constant_at + k:]], dim=1)
            h = torch.addmm(bias, x, w_vertex.T)
        for block in self.blocks:
            h = block(h, ops)
        y = self.last(h)
        if self.outputs == "global_mean":
            y = (ops.mass[:, None] * y).sum(dim=0) / ops.mass.sum()
        return y if self.last_activation is None else self.last_activation(y)

    def forward_batch(self, xs: Sequence[torch.Tensor], ops_list: Sequence[TorchOperators]) -> list[torch.Tensor]:
        """Meshes of different sizes: ``[forward(x, ops) for x, ops in zip(xs, ops_list)]``."""
        if len(xs) != len(ops_list):
            raise ValueError(f"DiffusionNet: {len(xs)} feature arrays for {len(ops_list)} operator sets")
        return [self.forward(x, ops) for x, ops in zip(xs, ops_list)]
