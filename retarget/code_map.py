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

What it learns on MakeHuman heads does not suit procedural heads, and a map of procedural heads
does not help them (their rigs' errors are each head's own). A *gated* map is fitted on the
MakeHuman heads only, with a gate: a logistic regression on the identity code z_ID that tells a
MakeHuman-like head from a procedural one (``fit_gate``, checkpoint ``code_map_gate``). Each head
gets [I; 0] + p (M − [I; 0]), p the gate's probability for its z_ID (``head_code_map``): M on
heads like the realistic training heads, the paper's map on heads unlike them.
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


def check_code_map(code_map, cfg) -> np.ndarray | None:
    """A code map (code_dim, 53) for a model of config ``cfg`` as a float32 array (None stays
    None); ValueError unless it is finite, of that shape and the model's decoder is the basis
    decoder (the map is a linear change of its rig)."""
    if code_map is None:
        return None
    m = np.asarray(code_map, np.float32)
    if m.shape != (cfg.code_dim, N_FACS) or not np.isfinite(m).all() or cfg.decoder != "basis":
        raise ValueError(f"a code map must be a finite ({cfg.code_dim}, {N_FACS}) array of a "
                         f"basis-decoder model; got shape {m.shape} for decoder {cfg.decoder!r}")
    return m


def check_gate(gate, cfg) -> np.ndarray | None:
    """A code map's gate (code_dim + 1,) as a float32 array (None stays None); ValueError unless
    it is finite and of that shape."""
    if gate is None:
        return None
    g = np.asarray(gate, np.float32)
    if g.shape != (cfg.code_dim + 1,) or not np.isfinite(g).all():
        raise ValueError(f"a code map gate must be a finite ({cfg.code_dim + 1},) array; got shape "
                         f"{g.shape}")
    return g


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


def decoder_rows(r, rig) -> tuple[np.ndarray, np.ndarray]:
    """The basis decoder's rig on ``rig``'s neutral, every code dim's shape, (code_dim, 3V) in the
    rig's units, and the head's identity code z_ID (code_dim,) (``Retargeter.prepare``; whatever
    code map ``r`` holds is not applied)."""
    from .api import basis_shapes
    from .mesh import Mesh

    target = r.prepare(Mesh(rig.neutral, rig.faces))
    if target.codes.basis is None:
        raise ValueError("a code map needs the basis decoder")
    return (basis_shapes(target, slice(None)).reshape(r.cfg.code_dim, -1),
            target.codes.z_id.detach().cpu().numpy().astype(np.float64))


def fit_gate(z_ids: np.ndarray, is_makehuman: np.ndarray, ridge: float = 1.0,
             steps: int = 50) -> np.ndarray:
    """The gate of a code map: p(the head is MakeHuman-like | z_ID) = σ(a·z_ID + b), by ridge
    logistic regression (Newton steps on standardised codes, ``ridge`` on the weights) on the
    identity codes z_ids (N, code_dim) of training heads labelled ``is_makehuman`` (N,) bool.
    Returns [a, b] (code_dim + 1,) float32 in the raw codes' units."""
    x = np.asarray(z_ids, np.float64)
    y = np.asarray(is_makehuman, np.float64)
    mean, scale = x.mean(0), x.std(0) + 1e-6
    z = np.c_[(x - mean) / scale, np.ones(len(x))]
    w = np.zeros(z.shape[1])
    reg = ridge * np.eye(len(w))
    reg[-1, -1] = 0.0                                   # the bias is not pulled to 0
    for _ in range(steps):
        p = 1.0 / (1.0 + np.exp(-z @ w))
        hess = (z * (p * (1 - p))[:, None]).T @ z + reg + 1e-9 * np.eye(len(w))
        w -= np.linalg.solve(hess, z.T @ (p - y) + reg @ w)
    a = w[:-1] / scale
    return np.r_[a, w[-1] - a @ mean].astype(np.float32)


def gate_probability(gate: np.ndarray, z_id) -> float:
    """p = σ(a·z_ID + b) of a gate [a, b] (``fit_gate``) for one head's z_ID (code_dim,)."""
    logit = float(np.dot(np.asarray(gate[:-1], np.float64), np.asarray(z_id, np.float64)) + gate[-1])
    return float(1.0 / (1.0 + np.exp(-np.clip(logit, -60.0, 60.0))))


def head_code_map(code_map: np.ndarray, gate: np.ndarray | None, z_id) -> np.ndarray:
    """The code map of one head (code_dim, 53) float32: ``code_map`` itself without a gate, else
    the paper's map [I; 0] moved by p = ``gate_probability`` towards it: [I; 0] + p (M − [I; 0])."""
    if gate is None:
        return code_map
    eye = np.eye(*code_map.shape, dtype=np.float32)
    return (eye + gate_probability(gate, z_id) * (code_map - eye)).astype(np.float32)


def training_rigs(identities: int, seed: int = 0, n_segments: int = 20,
                  kinds: tuple[str, ...] = ("makehuman", "procedural")):
    """Rigs of training identities with their shapes as authored, for each identity seed
    ``seed`` ... ``seed + identities − 1``: a MakeHuman head (the artist's ARKit shapes by deformation
    transfer; kind "makehuman") and a procedural head (kind "procedural"), of the ``kinds`` asked
    for, each on one of ``HEAD_TESSELLATIONS`` / ``UV_TESSELLATIONS`` in turn. Yields (kind, rig)."""
    from data_synth.identity import sample_identity
    from data_synth.makehuman import base_head_rig, build_head_rig, head_tessellation, sample_head_identity
    from data_synth.rig import build_rig
    from data_synth.tessellate import tessellate

    for i in range(identities):
        s = seed + i
        if "makehuman" in kinds:
            base = base_head_rig(sample_head_identity(s, "train"), "arkit")
            spec = HEAD_TESSELLATIONS[i % len(HEAD_TESSELLATIONS)]
            yield "makehuman", build_head_rig(base, head_tessellation(seed=s, **spec), n_segments)
        if "procedural" in kinds:
            spec = UV_TESSELLATIONS[i % len(UV_TESSELLATIONS)]
            yield "procedural", build_rig(sample_identity(s, "train"), tessellate(seed=s, **spec), n_segments)


def fit_code_map(r, identities: int, seed: int = 0, ridge: float = 0.01,
                 gated: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """The code map of the model of Retargeter ``r`` on ``training_rigs(identities, seed)``: (M
    (code_dim, 53) float32, gate (code_dim + 1,) float32 or None). Ungated, M is fitted on both
    kinds of heads and drawn on every head. Gated, M is fitted on the MakeHuman heads only and
    the gate (``fit_gate``) on both kinds' identity codes, so that each head gets M as far as it
    is MakeHuman-like and the paper's map otherwise (``head_code_map``)."""
    fit = CodeMapFit(r.cfg.code_dim)
    z_ids, labels = [], []
    for kind, rig in training_rigs(identities, seed, r.cfg.n_segments):
        rows, z_id = decoder_rows(r, rig)
        makehuman = kind == "makehuman"
        if makehuman or not gated:
            fit.add(rows, np.asarray(rig.deltas).reshape(len(rig.deltas), -1))
        z_ids.append(z_id)
        labels.append(makehuman)
    return fit.solve(ridge), (fit_gate(np.array(z_ids), np.array(labels)) if gated else None)
