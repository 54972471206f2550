"""The code map: which code z_GE draws each FACS shape, learned from training rigs (issue 10).

The basis decoder draws a code z (128,) on a target as Δv = Xᵀ z, X (128, 3V) its rig on that
target (``TargetCodes.basis``). The paper drives it from FACS weights with z = [w, 0], so FACS shape
k is X's row k. Part of how those rows miss the true shapes is the same on every head: the decoder
mixes its shapes up in a fixed way, and draws parts of them through the free dims. The code map M
(128, 53) undoes that part: shape k is drawn by the code M[:, k], so weights w by z = M w
(``Retargeter.weight_codes``), and the rig that ``bake``, ``animate``, ``export-rig`` and
``--refine`` use is Mᵀ X instead of X[:53].

M is fitted once, after training, on the true shapes B (53, 3V) of training heads (procedural and
MakeHuman rigs of training identities, shapes as authored): per shape k, ridge least squares
towards the paper's map e_k,

    M[:, k] = argmin_m  Σ_h |X_hᵀ m − B_hk|² / |B_hk|²  +  λ_k |m − e_k|²,

each head's shape weighted by its own size (the fit aims at the relative error), λ_k = ``ridge`` ·
mean diag(Σ_h X_h X_hᵀ / |B_hk|²). It is data (a tensor in the checkpoint, ``code_map``), learned
from shapes only: it knows nothing of how any weights are drawn.
"""
from __future__ import annotations

import numpy as np

from data_synth.facs import N_FACS

#: MakeHuman training heads: tessellations the rigs are drawn on (data_synth.makehuman.head_tessellation)
HEAD_TESSELLATIONS = ({"n_vertices": 3000, "kind": "decimated", "crop": "head_neck"},
                      {"n_vertices": 2500, "kind": "decimated", "crop": "head"},
                      {"n_vertices": 2000, "kind": "jittered", "crop": "bust"})
#: procedural training heads: tessellations (data_synth.tessellate.tessellate)
UV_TESSELLATIONS = ({"n_vertices": 2500, "kind": "adaptive", "region": "full"},
                    {"n_vertices": 2000, "kind": "jittered", "region": "full"},
                    {"n_vertices": 1800, "kind": "regular", "region": "face"})


class CodeMapFit:
    """The normal equations of the code map, accumulated head by head: per shape k, G_k = Σ_h
    X_h X_hᵀ / |B_hk|² (dims, dims), c_k = Σ_h X_h B_hkᵀ / |B_hk|² (dims,), over the heads with
    |B_hk| > 0 (``count`` (53,))."""

    def __init__(self, dims: int):
        self.gram = np.zeros((N_FACS, dims, dims))
        self.cross = np.zeros((N_FACS, dims))
        self.count = np.zeros(N_FACS, np.int64)

    def add(self, x: np.ndarray, b: np.ndarray) -> None:
        """One head: x (dims, n) the decoder's rig rows (every code dim's shape, flattened), b (53, n)
        the true shapes in the same units and frame (a shape the rig lacks is all zero)."""
        x = np.asarray(x, np.float64)
        b = np.asarray(b, np.float64)
        gram, norm2 = x @ x.T, (b ** 2).sum(1)
        for k in np.flatnonzero(norm2 > 0):
            self.gram[k] += gram / norm2[k]
            self.cross[k] += x @ b[k] / norm2[k]
            self.count[k] += 1

    def solve(self, ridge: float) -> np.ndarray:
        """M (dims, 53) float32 (module docstring); a shape no head had keeps e_k."""
        dims = self.gram.shape[1]
        m = np.zeros((dims, N_FACS))
        for k in range(N_FACS):
            e = np.eye(dims)[k]
            if self.count[k] == 0:
                m[:, k] = e
                continue
            lam = ridge * np.trace(self.gram[k]) / dims
            m[:, k] = np.linalg.solve(self.gram[k] + lam * np.eye(dims), self.cross[k] + lam * e)
        return m.astype(np.float32)


def decoder_rows(r, rig) -> np.ndarray:
    """The basis decoder's rig on ``rig``'s neutral, every code dim's shape: (code_dim, 3V) in the
    rig's units (``Retargeter.prepare``; whatever code map ``r`` holds is not applied)."""
    from .api import basis_shapes
    from .mesh import Mesh

    target = r.prepare(Mesh(rig.neutral, rig.faces))
    if target.codes.basis is None:
        raise ValueError("a code map needs the basis decoder")
    return basis_shapes(target, slice(None)).reshape(r.cfg.code_dim, -1)


def training_rigs(identities: int, seed: int = 0, n_segments: int = 20,
                  kinds: tuple[str, ...] = ("makehuman", "procedural")):
    """Rigs of training identities with their shapes as authored, for each identity seed
    ``seed`` ... ``seed + identities − 1``: a MakeHuman head (the artist's ARKit shapes by deformation
    transfer; kind "makehuman") and a procedural head (kind "procedural"), of the ``kinds`` asked
    for, each on one of ``HEAD_TESSELLATIONS`` / ``UV_TESSELLATIONS`` in turn. Yields the rigs."""
    from data_synth.identity import sample_identity
    from data_synth.makehuman import base_head_rig, build_head_rig, head_tessellation, sample_head_identity
    from data_synth.rig import build_rig
    from data_synth.tessellate import tessellate

    for i in range(identities):
        s = seed + i
        if "makehuman" in kinds:
            base = base_head_rig(sample_head_identity(s, "train"), "arkit")
            spec = HEAD_TESSELLATIONS[i % len(HEAD_TESSELLATIONS)]
            yield build_head_rig(base, head_tessellation(seed=s, **spec), n_segments)
        if "procedural" in kinds:
            spec = UV_TESSELLATIONS[i % len(UV_TESSELLATIONS)]
            yield build_rig(sample_identity(s, "train"), tessellate(seed=s, **spec), n_segments)


def fit_code_map(r, rigs, ridge: float = 0.01) -> np.ndarray:
    """The code map M (code_dim, 53) float32 of the model of Retargeter ``r`` fitted on ``rigs``
    (objects with ``neutral`` (V,3), ``faces`` and ``deltas`` (53,V,3), e.g. ``training_rigs``)."""
    fit = CodeMapFit(r.cfg.code_dim)
    for rig in rigs:
        fit.add(decoder_rows(r, rig), np.asarray(rig.deltas).reshape(len(rig.deltas), -1))
    return fit.solve(ridge)
