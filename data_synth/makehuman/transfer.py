"""Deformation transfer (Sumner & Popovic 2004) of blendshapes between heads of one topology.

Each source shape's per-face deformation gradient S_f (3x3, from the triangle's two edges and its
scaled normal, neutral -> shape) is applied to the target's triangle edges, and the target's vertex
offsets are the least-squares fit of those deformed edges (a Poisson problem on the edge graph),
anchored where the source does not move. The matrix of each shape's solve depends on the topology
and on which vertices that shape anchors, not on either head, so its factorisation is kept and
reused for every later identity carried from the same source shapes (``FACTOR_CACHE_BYTES``). On
the source's own neutral it reproduces the source shapes exactly.
"""
from __future__ import annotations

import hashlib
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import SuperLU, splu

ANCHOR_CM = 1e-3      # a vertex that a source shape moves by less than this is anchored for it
ANCHOR_WEIGHT = 100.0  # anchor weight, relative to one edge equation
# Factorisations kept per process, least recently used dropped first. The 53 ARKit shapes on the
# 4,326-vertex MakeHuman head hold about 115 MB (docs/results/synthesis_speed/transfer_cache.txt);
# rigs whose source shapes change with the identity (MakeHuman's expression units, by race) miss
# and replace them.
FACTOR_CACHE_BYTES = 256 * 2**20
_factors: OrderedDict[bytes, tuple[SuperLU, int]] = OrderedDict()


def _frames(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(...,F,3,3) columns [e1, e2, n / sqrt|n|] per face (Sumner's fourth-vertex frame)."""
    a, b, c = (verts[..., faces[:, i], :] for i in range(3))
    e1, e2 = b - a, c - a
    n = np.cross(e1, e2)
    n = n / np.sqrt(np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12))
    return np.stack([e1, e2, n], axis=-1)


def _edge_matrix(faces: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """(3F, V) signed incidence of each face's edges (b-a, c-a, c-b)."""
    f = len(faces)
    rows = np.repeat(np.arange(3 * f), 2)
    ends = np.stack([faces[:, [0, 1]], faces[:, [0, 2]], faces[:, [1, 2]]], axis=1).reshape(-1, 2)
    cols = ends.reshape(-1)
    vals = np.tile([-1.0, 1.0], 3 * f)
    return sp.csr_matrix((vals, (rows, cols)), shape=(3 * f, n_vertices))


def _factor_bytes(lu: SuperLU) -> int:
    """Approximate memory of a SuperLU factorisation: values and indices of L and U."""
    return 12 * (lu.L.nnz + lu.U.nnz) + 16 * lu.shape[0]


def anchored_factor(laplacian: sp.csc_matrix, anchored: np.ndarray, topology: bytes) -> SuperLU:
    """The factorisation of laplacian + ANCHOR_WEIGHT diag(anchored), from the cache when the same
    ``topology`` key (a digest of the faces) and anchored set (V,) bool were factorised before."""
    key = topology + hashlib.blake2b(np.packbits(anchored).tobytes(), digest_size=16).digest()
    hit = _factors.get(key)
    if hit is not None:
        _factors.move_to_end(key)
        return hit[0]
    # symmetric positive definite: a symmetric fill-reducing order and diagonal pivots
    # (docs/results/synthesis_speed/transfer_order.py: 18 % faster than SuperLU's defaults)
    lu = splu((laplacian + sp.diags(ANCHOR_WEIGHT * anchored.astype(np.float64))).tocsc(),
              permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    size = _factor_bytes(lu)
    if size <= FACTOR_CACHE_BYTES:
        _factors[key] = (lu, size)
        while sum(b for _, b in _factors.values()) > FACTOR_CACHE_BYTES:
            _factors.popitem(last=False)
    return lu


def deformation_transfer(src_neutral: np.ndarray, src_deltas: np.ndarray, tgt_neutral: np.ndarray,
                         faces: np.ndarray) -> np.ndarray:
    """Carry shapes from one neutral to another of the same topology.

    src_neutral, tgt_neutral (V,3) cm; src_deltas (K,V,3) cm; faces (F,3) int.
    Returns the target's deltas (K,V,3) float32 cm. For each shape, the vertices it does not move
    (by more than ANCHOR_CM) are held at zero, which also fixes the translation of the solve.
    """
    src_neutral = np.asarray(src_neutral, np.float64)
    tgt_neutral = np.asarray(tgt_neutral, np.float64)
    src_deltas = np.asarray(src_deltas, np.float64)
    faces = np.asarray(faces, np.int64)
    n_v = len(tgt_neutral)
    frame_src = _frames(src_neutral, faces)                                 # (F,3,3)
    inv_src = np.linalg.pinv(frame_src)
    grads = _frames(src_neutral[None] + src_deltas, faces) @ inv_src[None]   # (K,F,3,3) S_f
    tgt_edges = _frames(tgt_neutral, faces)[..., :2]                         # (F,3,2)
    want = grads @ tgt_edges[None]                                           # (K,F,3,2)
    want = np.stack([want[..., 0], want[..., 1], want[..., 1] - want[..., 0]], axis=2)  # (K,F,3e,3)
    a = _edge_matrix(faces, n_v)
    laplacian = (a.T @ a).tocsc()
    topology = hashlib.blake2b(np.int64(n_v).tobytes() + faces.tobytes(), digest_size=16).digest()
    rest = a @ tgt_neutral                                                   # (3F,3)
    out = np.zeros((len(src_deltas), n_v, 3), np.float32)
    for k, delta in enumerate(src_deltas):
        anchored = np.abs(delta).max(axis=1) < ANCHOR_CM
        if anchored.all():
            continue
        lu = anchored_factor(laplacian, anchored, topology)
        out[k] = lu.solve(np.ascontiguousarray(a.T @ (want[k].reshape(-1, 3) - rest)))
    return out
