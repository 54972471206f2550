"""Tessellations and crops of the MakeHuman head whose every vertex is a fixed linear combination
of base vertices, so identities, expressions and region labels carry over exactly.

A ``HeadTessellation`` holds a sparse matrix ``weights`` (V, 5472) over the base bust vertices
(the head's 4326 first; rows sum to 1, non-negative): any per-vertex quantity of the base head —
an identity's neutral, an expression delta — is ``weights @ quantity`` on this tessellation. Two
tessellations of one identity therefore give exact cross-topology ground truth: each is the same
linear rig evaluated through its own ``weights``.

Crops (as users have them): ``face`` (the face mask, no ears, scalp or neck), ``head`` (cut under
the jaw), ``head_neck`` (the shipped head cut, with the upper neck), ``bust`` (neck, shoulders and
upper chest). ``holes=True`` leaves the eyes and the mouth open; ``False`` closes them with the eye
sockets and the mouth cavity. Layouts: ``base`` (MakeHuman's quads split as shipped), ``flipped``
(each quad split along a random diagonal), ``subdivided`` (midpoint subdivision, 4x the faces per
level, up to the requested density), ``decimated`` (quadric edge collapse by fast-simplification
of the base or a subdivided mesh to the requested vertex count, each vertex snapped to a base or
subdivision vertex of its own collapse cluster) and ``jittered`` (decimated, then every vertex
slid inside one of its triangles by random barycentric weights).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from . import assets

CROPS = ("face", "head", "head_neck", "bust")
KINDS = ("base", "flipped", "subdivided", "decimated", "jittered")
HEAD_CUT = 61.5          # "head": keep faces with y + 0.3 z above this (cm), under the jaw
MIN_VERTICES, MAX_VERTICES = 200, 200_000


@dataclass
class HeadTessellation:
    """weights (V, 5472) sparse CSR, rows are convex combinations of base bust vertices;
    faces (F,3) int64 (wound outward); name: a readable description."""

    weights: sp.csr_matrix
    faces: np.ndarray
    name: str

    @property
    def n_vertices(self) -> int:
        return self.weights.shape[0]

    def apply(self, values: np.ndarray) -> np.ndarray:
        """Base per-vertex values (5472, ...) or (K, 5472, ...) -> on this tessellation, float32.
        Head-only values (4326, ...) are padded with zeros on the bust vertices."""
        values = np.asarray(values, np.float32)
        axis = 0 if values.shape[0] in (assets.N_HEAD, assets.N_BUST) else 1
        n = values.shape[axis]
        w = self.weights[:, :n] if n == assets.N_HEAD else self.weights
        if axis == 0:
            flat = values.reshape(n, -1)
            return np.asarray(w @ flat, np.float32).reshape(w.shape[0], *values.shape[1:])
        moved = np.moveaxis(values, 1, 0).reshape(n, -1)
        out = np.asarray(w @ moved, np.float32)
        return np.moveaxis(out.reshape(w.shape[0], values.shape[0], *values.shape[2:]), 0, 1)


def crop_faces(crop: str, holes: bool) -> np.ndarray:
    """Base bust triangles (F,3) int64 of one crop (module docstring)."""
    if crop not in CROPS:
        raise ValueError(f"crop must be one of {CROPS}, got {crop!r}")
    z = assets.heads()
    faces, part = z["bust_faces"].astype(np.int64), z["bust_face_part"]
    keep = part != 4 if crop != "bust" else np.ones(len(faces), bool)
    if holes:
        keep &= (part == 0) | (part == 4)
    v = z["bust_neutral"].astype(np.float64)
    corner = v[faces]                                            # (F,3,3)
    if crop == "head":
        keep &= np.all(corner[..., 1] + 0.3 * corner[..., 2] > HEAD_CUT, axis=1)
    elif crop == "face":
        x, y, zz = corner[..., 0], corner[..., 1], corner[..., 2]
        keep &= np.all((np.abs(x) < 6.3) & (y > 60.0) & (y < 80.5) &
                       (zz > 9.0 - 0.35 * np.maximum(0.0, 72.0 - y)), axis=1)
    return _largest_component(faces[keep])


def _largest_component(faces: np.ndarray) -> np.ndarray:
    """The faces of the largest edge-connected piece."""
    from scipy.sparse.csgraph import connected_components

    n = int(faces.max()) + 1
    rows = np.repeat(faces[:, 0], 2)
    cols = faces[:, 1:].reshape(-1)
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    face_label = label[faces[:, 0]]
    return faces[face_label == np.bincount(face_label).argmax()]


def _compact(weights: sp.csr_matrix, faces: np.ndarray):
    """Drop rows no face uses; re-index the faces."""
    used = np.unique(faces)
    remap = np.full(weights.shape[0], -1, np.int64)
    remap[used] = np.arange(len(used))
    return weights[used].tocsr(), remap[faces]


def _flip_quads(faces: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Re-split each quad (consecutive triangles 2k, 2k+1 sharing an edge) along the other diagonal
    with probability 1/2."""
    out = faces.copy()
    for k in range(0, len(faces) - 1, 2):
        a, b = faces[k], faces[k + 1]
        shared = np.intersect1d(a, b)
        if len(shared) != 2 or rng.random() < 0.5:
            continue
        pa = a[~np.isin(a, shared)][0]
        pb = b[~np.isin(b, shared)][0]
        i = int(np.where(a == pa)[0][0])
        s1, s2 = a[(i + 1) % 3], a[(i + 2) % 3]                 # a = (pa, s1, s2) in order
        out[k], out[k + 1] = (pa, s1, pb), (pa, pb, s2)
    return out


def _subdivide(weights: sp.csr_matrix, faces: np.ndarray):
    """One level of midpoint subdivision: each triangle -> 4; new vertices are edge midpoints."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    uniq, inverse = np.unique(edges, axis=0, return_inverse=True)
    n = weights.shape[0]
    mid = n + inverse.reshape(3, -1).T                           # (F,3): midpoints of 01, 12, 20
    half = sp.csr_matrix((np.full(2 * len(uniq), 0.5),
                          (np.repeat(np.arange(len(uniq)), 2), uniq.reshape(-1))),
                         shape=(len(uniq), n))
    new_w = sp.vstack([weights, half @ weights]).tocsr()
    a, b, c = faces.T
    ab, bc, ca = mid.T
    new_f = np.concatenate([np.c_[a, ab, ca], np.c_[ab, b, bc], np.c_[ca, bc, c], np.c_[ab, bc, ca]])
    return new_w, new_f


def _decimate(weights: sp.csr_matrix, faces: np.ndarray, positions: np.ndarray, n_target: int):
    """Quadric edge collapse to about ``n_target`` vertices; each kept vertex is the member of its
    collapse cluster nearest the optimal position (so it stays a row of ``weights``)."""
    import fast_simplification

    reduction = float(np.clip(1.0 - n_target / len(positions), 0.0, 0.99))
    if reduction <= 0.0:
        return weights, faces
    _, _, collapses = fast_simplification.simplify(positions, faces, target_reduction=reduction,
                                                   return_collapses=True)
    points, new_faces, mapping = fast_simplification.replay_simplification(positions, faces,
                                                                          collapses)
    dist = np.linalg.norm(positions - points[mapping], axis=1)
    order = np.lexsort((dist, mapping))                        # by cluster, nearest first
    first = np.r_[True, mapping[order][1:] != mapping[order][:-1]]
    rep = np.empty(len(points), np.int64)
    rep[mapping[order][first]] = order[first]
    new_faces = np.asarray(new_faces, np.int64)
    area = np.linalg.norm(np.cross(*(positions[rep[new_faces[:, i]]] - positions[rep[new_faces[:, 0]]]
                                     for i in (1, 2))), axis=1)
    return weights[rep].tocsr(), new_faces[area > 1e-12]


def _jitter(weights: sp.csr_matrix, faces: np.ndarray, rng: np.random.Generator,
            amount: float = 0.3) -> sp.csr_matrix:
    """Slide each vertex inside one random incident triangle: new = (1-s-t) self + s b + t c."""
    n = weights.shape[0]
    owner = np.full(n, -1, np.int64)
    order = rng.permutation(len(faces))
    owner[faces[order].reshape(-1)] = np.repeat(order, 3)
    rows, cols, vals = [], [], []
    for v in range(n):
        f = faces[owner[v]]
        others = f[f != v]
        s, t = rng.uniform(0, amount, size=2) / 2
        rows += [v, v, v]
        cols += [v, int(others[0]), int(others[1])]
        vals += [1 - s - t, s, t]
    mix = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    return (mix @ weights).tocsr()


def head_tessellation(n_vertices: int = 5000, kind: str = "decimated", crop: str = "head_neck",
                      holes: bool = True, seed: int = 0) -> HeadTessellation:
    """One tessellation of a crop of the MakeHuman head (module docstring).

    n_vertices: the density asked for (``decimated`` / ``jittered`` reach it within a few %,
    ``subdivided`` takes the first level at or above it; ignored by ``base`` / ``flipped``).
    Deterministic in its arguments."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    if not MIN_VERTICES <= n_vertices <= MAX_VERTICES:
        raise ValueError(f"n_vertices must be in [{MIN_VERTICES}, {MAX_VERTICES}], got {n_vertices}")
    rng = np.random.default_rng([int(seed), KINDS.index(kind), CROPS.index(crop), int(holes), 77])
    faces = crop_faces(crop, holes)
    weights, faces = _compact(sp.identity(assets.N_BUST, format="csr"), faces)
    if kind == "flipped":
        faces = _flip_quads(faces, rng)
    if kind in ("subdivided", "decimated", "jittered"):
        stop = n_vertices if kind == "subdivided" else 1.3 * n_vertices
        while weights.shape[0] < stop:
            weights, faces = _subdivide(weights, faces)
    if kind in ("decimated", "jittered"):
        positions = np.asarray(weights @ assets.heads()["bust_neutral"].astype(np.float64))
        weights, faces = _decimate(weights, faces, positions, n_vertices)
        weights, faces = _compact(weights, faces)
    if kind == "jittered":
        weights = _jitter(weights, faces, rng)
    weights.eliminate_zeros()
    name = f"mh_{crop}_{kind}_{weights.shape[0]}v{'_holes' if holes else '_closed'}"
    return HeadTessellation(weights.tocsr(), np.ascontiguousarray(faces, np.int64), name)
