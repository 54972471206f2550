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

A *per-head* map goes further: each head's map is linear in the whitened principal components of
its identity code, M(z) = M_0 + Σ_j φ_j(z) S_j, φ(z) = Pᵀ (z − μ) (d of them; ``HeadMapFit``,
checkpoint ``code_map`` = M_0 and ``code_map_per_head`` = (features [μ; Pᵀ] (d + 1, code_dim),
slopes S (d, code_dim, 53))), fitted on both kinds of heads or, gated, on the MakeHuman heads
and given to each head as the gate says. Not bundled (docs/RESULTS.md, "Code maps per head"): on
held-out MakeHuman validation heads it takes the shapes' relative error from 0.252 (one map) to
0.242 with d = 16 (each head's own best map: 0.203), which helps the realistic heads' weights a
little and costs the procedural heads'; most of what is left is the mesh's, not the identity's:
one head on three crops has identity codes further apart than two heads on one.

What no map removes is each head's own error, and that has a shape too: the code error
Δ_hk = m*_hk − M_h[:, k] of training head h's shape k (m*_hk the code that draws its true shape
best, M_h the map the head gets) falls on some code directions far more than on others, and
differently on MakeHuman and procedural heads. Its second moment Σ = E[Δ Δᵀ] (code_dim,
code_dim), one per kind of head when the map is gated (``MapErrorFit``, checkpoint
``code_map_error``), lets invert's fit weigh each direction of a frame's code by how far the
head's rig can be trusted there (``code_metric``; docs/RESULTS.md, "Invert's fit weighed by the
rig's expected error").
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


def check_per_head(per_head, cfg) -> tuple[np.ndarray, np.ndarray] | None:
    """A per-head map's (features (d + 1, code_dim), slopes (d, code_dim, 53)) as float32 arrays
    (None stays None); ValueError unless both are finite, of those shapes, with d >= 1."""
    if per_head is None:
        return None
    try:
        features, slopes = (np.asarray(a, np.float32) for a in per_head)
    except (TypeError, ValueError):
        raise ValueError("a per-head code map is a pair (features, slopes) of arrays") from None
    d = slopes.shape[0] if slopes.ndim else 0
    if (features.shape != (d + 1, cfg.code_dim) or slopes.shape != (d, cfg.code_dim, N_FACS) or d < 1
            or not (np.isfinite(features).all() and np.isfinite(slopes).all())):
        raise ValueError(f"a per-head code map needs finite features (d + 1, {cfg.code_dim}) and "
                         f"slopes (d, {cfg.code_dim}, {N_FACS}), d >= 1; got {features.shape} and "
                         f"{slopes.shape}")
    return features, slopes


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


def check_map_error(error, cfg) -> np.ndarray | None:
    """The code map's error moments (K, code_dim, code_dim), K = 1 or 2 (``MapErrorFit``), as a
    float32 array (None stays None); ValueError unless finite, of that shape and symmetric."""
    if error is None:
        return None
    e = np.asarray(error, np.float32)
    if (e.ndim != 3 or e.shape[0] not in (1, 2) or e.shape[1:] != (cfg.code_dim, cfg.code_dim)
            or not np.isfinite(e).all()
            or not np.allclose(e, e.transpose(0, 2, 1), atol=1e-6 * max(float(np.abs(e).max()), 1e-30))):
        raise ValueError(f"a code map's error must be a finite symmetric (K, {cfg.code_dim}, "
                         f"{cfg.code_dim}) array, K = 1 or 2; got shape {e.shape}")
    return e


def normal_equations(x: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One head's normal equations for the map's fits: G = X Xᵀ (dims, dims), C = X Bᵀ (dims, 53)
    and n = |B_k|² (53,), float64, from x (dims, n) the decoder's rig rows and b (53, n) the true
    shapes (a shape the rig lacks is all zero)."""
    x, b = np.asarray(x, np.float64), np.asarray(b, np.float64)
    return x @ x.T, x @ b.T, (b ** 2).sum(1)


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
        self.add_normal_equations(*normal_equations(x, b))

    def add_normal_equations(self, gram, cross, norm2) -> None:
        """One head by its ``normal_equations``: G (dims, dims), C (dims, 53), n (53,)."""
        for k in np.flatnonzero(norm2 > 0):
            self.gram[k] += gram / norm2[k]
            self.cross[k] += cross[:, k] / norm2[k]
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


class HeadMapFit:
    """The per-head code map's fit (module docstring), head by head: each head's identity code
    z_ID and its normal equations G = X Xᵀ (dims, dims), C = X Bᵀ (dims, 53), n = |B_k|² (53,)
    are kept; ``solve`` fits, per shape k, m_k(z) = A_k φ̃(z), φ̃ = [1, φ(z)], by ridge least
    squares of Σ_h |X_hᵀ m_k(z_h) − B_hk|² / n_hk, pulled towards the paper's map [e_k, 0, ...]."""

    def __init__(self):
        self.z_ids, self.grams, self.crosses, self.norms = [], [], [], []

    def add(self, x: np.ndarray, b: np.ndarray, z_id: np.ndarray) -> None:
        """One head: x (dims, n) the decoder's rig rows, b (53, n) the true shapes (a shape the rig
        lacks is all zero), z_id (dims,) its identity code."""
        self.add_normal_equations(z_id, *normal_equations(x, b))

    def add_normal_equations(self, z_id, gram, cross, norm2) -> None:
        """One head by what the fit keeps of it: z_id (dims,), G (dims, dims), C (dims, 53),
        n (53,) (class docstring; e.g. cached once for many fits)."""
        self.z_ids.append(np.asarray(z_id, np.float64))
        self.grams.append(np.asarray(gram, np.float64))
        self.crosses.append(np.asarray(cross, np.float64))
        self.norms.append(np.asarray(norm2, np.float64))

    def solve(self, features: int,
              ridge: float) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
        """(M_0 (dims, 53), (features [μ; Pᵀ] (d + 1, dims), slopes (d, dims, 53))) float32 with
        d = ``features`` whitened principal components of the heads' identity codes (fewer when
        the heads span fewer; None for the pair when they span none); ridge λ_k = ``ridge`` × the
        mean diagonal of shape k's normal equations."""
        z, g = np.array(self.z_ids), np.array(self.grams)
        c, n = np.array(self.crosses), np.array(self.norms)
        heads, dims = z.shape
        mean = z.mean(0)
        _, sv, vt = np.linalg.svd(z - mean, full_matrices=False)
        d = int(min(features, np.sum(sv > 1e-9 * max(sv[0], 1e-300))))
        proj = vt[:d].T / (sv[:d] / np.sqrt(heads))                  # (dims, d): whitened
        phi = np.c_[np.ones(heads), (z - mean) @ proj]               # (H, p)
        p = d + 1
        outer = (phi[:, :, None] * phi[:, None, :]).reshape(heads, -1)
        a = np.zeros((N_FACS, dims, p))
        for k in range(N_FACS):
            target = np.zeros((dims, p))
            target[k, 0] = 1.0
            use = n[:, k] > 0
            if not use.any():
                a[k] = target
                continue
            w = 1.0 / n[use, k]
            normal = (outer[use] * w[:, None]).T @ g[use].reshape(int(use.sum()), -1)   # (p², dims²)
            normal = normal.reshape(p, p, dims, dims).transpose(2, 0, 3, 1).reshape(dims * p, dims * p)
            rhs = np.einsum("h,hi,ha->ia", w, c[use, :, k], phi[use]).reshape(-1)
            lam = ridge * np.trace(normal) / (dims * p)
            a[k] = np.linalg.solve(normal + lam * np.eye(dims * p),
                                   rhs + lam * target.reshape(-1)).reshape(dims, p)
        m0 = a[:, :, 0].T.astype(np.float32)
        if d == 0:                                                   # one map: nothing per head
            return m0, None
        slopes = a[:, :, 1:].transpose(2, 1, 0)                      # (d, dims, 53)
        return m0, (np.r_[mean[None], proj.T].astype(np.float32), slopes.astype(np.float32))


class MapErrorFit:
    """The second moment of the code map's error on training heads (module docstring), head by
    head: its normal equations G = X Xᵀ (dims, dims), C = X Bᵀ (dims, 53), |B_k|² (53,), its
    identity code and its group (0: MakeHuman, 1: procedural) are kept, since the map each head
    gets is known only once the map and its gate are fitted."""

    def __init__(self):
        self.heads = []

    def add(self, x: np.ndarray, b: np.ndarray, z_id: np.ndarray, group: int) -> None:
        """One head: x (dims, n) the decoder's rig rows, b (53, n) the true shapes (a shape the rig
        lacks is all zero), z_id (dims,) its identity code, group 0 or 1."""
        self.add_normal_equations(*normal_equations(x, b), z_id, group)

    def add_normal_equations(self, gram, cross, norm2, z_id, group: int) -> None:
        """One head by its ``normal_equations`` G, C, n, its identity code and its group."""
        self.heads.append((gram, cross, norm2, np.asarray(z_id, np.float64), int(group)))

    def solve(self, code_map: np.ndarray, gate: np.ndarray | None = None,
              per_head: tuple | None = None, groups: int = 1) -> np.ndarray:
        """Σ (groups, dims, dims) float32: per group, the mean over its heads h and their shapes k
        (|B_hk| > 0) of Δ Δᵀ, Δ = m*_hk − M_h[:, k], m*_hk = (G_h + ε I)⁻¹ C_h[:, k] (ε = 10⁻⁶ of
        G_h's mean diagonal) and M_h = ``head_code_map(code_map, gate, z_ID, per_head)``. With one
        group every head counts in it."""
        dims = len(code_map)
        sums, counts = np.zeros((groups, dims, dims)), np.zeros(groups)
        for gram, cross, norm2, z_id, group in self.heads:
            g = min(group, groups - 1)
            eps = 1e-6 * np.trace(gram) / dims
            best = np.linalg.solve(gram + eps * np.eye(dims), cross)              # (dims, 53)
            delta = (best - head_code_map(code_map, gate, z_id, per_head))[:, norm2 > 0]
            sums[g] += delta @ delta.T
            counts[g] += delta.shape[1]
        if not counts.all():
            raise ValueError("a code map's error needs heads of every group")
        return (sums / counts[:, None, None]).astype(np.float32)


def head_map_error(error: np.ndarray, gate: np.ndarray | None, z_id) -> np.ndarray:
    """The code map's error moment Σ (code_dim, code_dim) float64 of one head for its identity
    code z_id: the one moment, or with two (MakeHuman, procedural) and a gate p Σ_0 + (1 − p) Σ_1,
    p = ``gate_probability``."""
    error = np.asarray(error, np.float64)
    if len(error) == 1 or gate is None:
        return error[0]
    p = gate_probability(gate, z_id)
    return p * error[0] + (1.0 - p) * error[1]


def code_metric(code_basis: np.ndarray, basis: np.ndarray, error: np.ndarray,
                rho: float) -> tuple[np.ndarray, np.ndarray]:
    """Invert's fit weighed by the rig's expected error (module docstring; ``SourceRig.fit``).

    A frame b (3V,) is read through its code c = G⁻¹ X b (G = X Xᵀ, X = ``code_basis`` (dims, 3V)
    the decoder's rig on the head), and the rig's 53 shapes ``basis`` A (53, 3V) = Mᵀ X through
    their codes M = G⁻¹ X Aᵀ. The plain fit's |Aᵀw − b|² is, within the rig's span,
    (c − M w)ᵀ G (c − M w). If the head's true shapes are drawn by codes M + Δ, Δ's columns of
    second moment Σ = ``error`` (dims, dims), the frame's code misses M w by Δ w, and adding
    white noise in vertex space (variance ∝ ``rho``) the residual's covariance is
    C = Σ + ρ' G⁻¹, ρ' = rho · tr Σ / tr G⁻¹. The fit weighs it by W = C⁻¹ (scaled to G's
    trace, so the fit's pulls keep their size; rho → ∞ gives the plain fit):

        |w|² terms:  Mᵀ W M (53, 53),    the frame's term:  Mᵀ W G⁻¹ X b = Q b.

    Returns (Q (53, 3V) float32, Mᵀ W M (53, 53) float64); for a mesh of fewer coordinates than
    code dims (3V < dims, X's rows not independent) the plain (A, A Aᵀ)."""
    from scipy.linalg import cho_factor, cho_solve

    x = np.asarray(code_basis, np.float64)
    a = np.asarray(basis, np.float64)
    if x.shape[1] < len(x):
        return np.asarray(basis, np.float32), a @ a.T
    gram = x @ x.T
    g = cho_factor(gram + 1e-10 * np.trace(gram) / len(gram) * np.eye(len(gram)))
    m = cho_solve(g, x @ a.T)                                           # (dims, 53)
    g_inv = cho_solve(g, np.eye(len(gram)))
    sigma = np.asarray(error, np.float64)
    cov = sigma + rho * np.trace(sigma) / np.trace(g_inv) * g_inv
    w = np.linalg.inv(0.5 * (cov + cov.T))
    w *= np.trace(gram) / np.trace(w)
    p = cho_solve(g, w @ m).T                                           # Mᵀ W G⁻¹ (53, dims)
    fit_gram = m.T @ w @ m
    return (p @ x).astype(np.float32), 0.5 * (fit_gram + fit_gram.T)


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


def head_code_map(code_map: np.ndarray, gate: np.ndarray | None, z_id,
                  per_head: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The code map of one head (code_dim, 53) float32 for its identity code z_id (code_dim,): the
    map M, ``code_map`` itself or, with ``per_head`` (features, slopes), M_0 + Σ_j φ_j S_j,
    φ = features[1:] (z − features[0]) (``HeadMapFit``); with a gate, the paper's map [I; 0] moved
    by p = ``gate_probability`` towards it: [I; 0] + p (M − [I; 0])."""
    if per_head is not None:
        features, slopes = per_head
        phi = features[1:].astype(np.float64) @ (np.asarray(z_id, np.float64) - features[0])
        code_map = (code_map + np.tensordot(phi, slopes, axes=1)).astype(np.float32)
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


def fit_code_map(r, identities: int, seed: int = 0, ridge: float = 0.01, gated: bool = False,
                 features: int = 0) -> tuple[np.ndarray, np.ndarray | None, tuple | None, np.ndarray]:
    """The code map of the model of Retargeter ``r`` on ``training_rigs(identities, seed)``: (M
    (code_dim, 53) float32, gate (code_dim + 1,) float32 or None, per-head (features, slopes) or
    None). Ungated, M is fitted on both kinds of heads and drawn on every head. Gated, M is fitted
    on the MakeHuman heads only and the gate (``fit_gate``) on both kinds' identity codes, so that
    each head gets M as far as it is MakeHuman-like and the paper's map otherwise. With
    ``features`` d > 0, M is a per-head map (``HeadMapFit``) fitted on the same heads. The fourth
    item is the map's error moment on the same heads (``MapErrorFit``): (2, code_dim, code_dim),
    MakeHuman and procedural heads apart, when gated, else (1, code_dim, code_dim)."""
    fit = HeadMapFit() if features else CodeMapFit(r.cfg.code_dim)
    errors = MapErrorFit()
    z_ids, labels = [], []
    for kind, rig in training_rigs(identities, seed, r.cfg.n_segments):
        rows, z_id = decoder_rows(r, rig)
        makehuman = kind == "makehuman"
        normal = normal_equations(rows, np.asarray(rig.deltas).reshape(len(rig.deltas), -1))
        errors.add_normal_equations(*normal, z_id, 0 if makehuman else 1)
        if makehuman or not gated:
            if features:
                fit.add_normal_equations(z_id, *normal)
            else:
                fit.add_normal_equations(*normal)
        z_ids.append(z_id)
        labels.append(makehuman)
    gate = fit_gate(np.array(z_ids), np.array(labels)) if gated else None
    m, per_head = fit.solve(features, ridge) if features else (fit.solve(ridge), None)
    return m, gate, per_head, errors.solve(m, gate, per_head, 2 if gated else 1)
