"""The classical baselines of ``retarget eval``.

:func:`closest_point_transfer` is the peer to beat: each target vertex takes the displacement of
the nearest source vertex once both heads are canonicalised, with no correspondence given. For the
jobs that start from weights (driving a mesh from FACS weights, inverse rigging) its peer is a
template rig carried onto the mesh the same way (:func:`closest_point_rig`) and, for inverse
rigging, weights fitted to each frame on it by bounded least squares (:func:`fit_rig_weights`).

The rest of this module is the oracle: displacement transfer through a known (u, v)
correspondence (Noh & Neumann 2001 style, with the correspondence given instead of fitted).

Every procedural tessellation samples the same (u, v) parameter domain, so each target vertex can
be located in a triangle of the source tessellation's (u, v) mesh; the source's per-vertex
displacement (frame − neutral) is interpolated there with barycentric weights and added to the
target neutral. Target vertices outside every source triangle (e.g. a full head onto a face crop, or
near hole boundaries) take the displacement of the nearest source vertex in (u, v).

It is an oracle because it is told the dense correspondence that real meshes do not come with; it
is exact for self-retargeting (same identity, same tessellation) and close to exact across
tessellations of one identity, and it ignores how expressions adapt to identity.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

CANDIDATE_TRIANGLES = 8   # nearest triangle centroids tried per query point
INSIDE_TOLERANCE = 1e-9   # barycentric coordinates >= -tol count as inside
CHUNK = 65536             # query points located per vectorised batch


def barycentric_2d(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of 2D points in 2D triangles.

    points (..., 2), tri (..., 3, 2) float64 -> (..., 3); rows sum to 1. Degenerate triangles give
    -inf coordinates (never chosen as containing).
    """
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    v0, v1, v2 = b - a, c - a, points - a
    det = v0[..., 0] * v1[..., 1] - v1[..., 0] * v0[..., 1]
    safe = np.where(np.abs(det) > 1e-300, det, np.nan)
    l1 = (v2[..., 0] * v1[..., 1] - v1[..., 0] * v2[..., 1]) / safe
    l2 = (v0[..., 0] * v2[..., 1] - v2[..., 0] * v0[..., 1]) / safe
    out = np.stack([1.0 - l1 - l2, l1, l2], axis=-1)
    return np.where(np.isnan(out), -np.inf, out)


def locate(src_uv: np.ndarray, src_faces: np.ndarray, query_uv: np.ndarray):
    """Find the source triangle containing each query point in (u, v).

    src_uv (Vs,2), src_faces (Fs,3) int, query_uv (Q,2). Returns (face (Q,) int64, bary (Q,3)
    float64, inside (Q,) bool); for points outside every candidate triangle ``face`` and ``bary``
    describe the best candidate and ``inside`` is False.
    """
    src_uv = np.asarray(src_uv, np.float64)
    query_uv = np.asarray(query_uv, np.float64)
    corners = src_uv[src_faces]                                    # (Fs,3,2)
    k = min(CANDIDATE_TRIANGLES, len(src_faces))
    tree = cKDTree(corners.mean(axis=1))
    face = np.empty(len(query_uv), np.int64)
    bary = np.empty((len(query_uv), 3))
    for start in range(0, len(query_uv), CHUNK):
        q = query_uv[start:start + CHUNK]
        _, cand = tree.query(q, k=k)
        cand = cand.reshape(len(q), k)
        b = barycentric_2d(q[:, None, :], corners[cand])          # (n,k,3)
        best = b.min(axis=-1).argmax(axis=1)
        rows = np.arange(len(q))
        face[start:start + len(q)] = cand[rows, best]
        bary[start:start + len(q)] = b[rows, best]
    return face, bary, bary.min(axis=1) >= -INSIDE_TOLERANCE


def uv_transfer_matrix(src_uv: np.ndarray, src_faces: np.ndarray,
                       tgt_uv: np.ndarray) -> sp.csr_matrix:
    """The linear map from source to target per-vertex values through (u, v).

    Returns a (Vt, Vs) float64 CSR matrix whose rows hold the barycentric weights of the source
    triangle containing each target vertex's (u, v), or a single 1 at the nearest source vertex for
    target vertices outside the source's domain. Rows sum to 1.
    """
    src_faces = np.asarray(src_faces, np.int64)
    face, bary, inside = locate(src_uv, src_faces, tgt_uv)
    n_t, n_s = len(tgt_uv), len(src_uv)
    cols = src_faces[face]                                         # (Vt,3)
    vals = np.clip(bary, 0.0, None)
    vals /= np.maximum(vals.sum(axis=1, keepdims=True), 1e-300)
    if not inside.all():
        _, nearest = cKDTree(np.asarray(src_uv, np.float64)).query(np.asarray(tgt_uv)[~inside])
        cols[~inside] = nearest[:, None]
        vals[~inside] = [1.0, 0.0, 0.0]
    rows = np.repeat(np.arange(n_t), 3)
    return sp.csr_matrix((vals.ravel(), (rows, cols.ravel())), shape=(n_t, n_s))


def displacement_transfer(transfer: sp.csr_matrix, src_neutral: np.ndarray,
                          src_frames: np.ndarray, tgt_neutral: np.ndarray) -> np.ndarray:
    """Target frames = target neutral + interpolated source displacements.

    transfer: (Vt,Vs) from :func:`uv_transfer_matrix`; src_neutral (Vs,3), src_frames (T,Vs,3) or
    (Vs,3), tgt_neutral (Vt,3), all in the same units (cm for procedural rigs).
    Returns (T,Vt,3) or (Vt,3) float64 in those units.
    """
    frames = np.asarray(src_frames, np.float64)
    single = frames.ndim == 2
    disp = frames.reshape(-1, *frames.shape[-2:]) - np.asarray(src_neutral, np.float64)
    out = np.stack([tgt_neutral + transfer @ d for d in disp])
    return out[0] if single else out


def closest_point_transfer(src_neutral: np.ndarray, src_faces: np.ndarray, src_frames: np.ndarray,
                           tgt_neutral: np.ndarray, tgt_faces: np.ndarray,
                           frame: str = "face", upright: bool = False) -> np.ndarray:
    """The closest-point displacement-transfer baseline: what a technical artist tries first in a
    DCC tool once the two heads are aligned.

    Both neutrals are canonicalised on their own (``retarget.canonical.Canonicaliser``, frame kind
    ``frame``: "face" aligns the faces whatever the crop, "bbox" the bounding boxes); each target
    vertex takes the displacement (frame − neutral) of the nearest source vertex in the canonical
    frame, converted from the source's units to canonical units and then to the target's units.
    It needs the source neutral (displacements are measured from it), no correspondence and no
    (u, v); on one mesh (self-retargeting) it is exact. ``upright``: a tilted head is turned
    upright before its frame is fitted, as ``Retargeter`` does (``retarget.canonical.upright_rotation``).

    src_neutral (Vs,3), src_faces (Fs,3), src_frames (T,Vs,3) or (Vs,3) in the source's units;
    tgt_neutral (Vt,3), tgt_faces (Ft,3) in the target's units (any units and offsets).
    Returns (T,Vt,3) or (Vt,3) float64 target frames in the target's units.
    """
    from .canonical import Canonicaliser, upright_rotation

    src_canon, tgt_canon = (
        Canonicaliser.fit(v, name, kind=frame, faces=f,
                          rotation=upright_rotation(np.asarray(v, np.float64), f) if upright else None)
        for v, f, name in ((src_neutral, src_faces, "source"), (tgt_neutral, tgt_faces, "target")))
    _, nearest = cKDTree(src_canon.to_canonical(src_neutral)).query(tgt_canon.to_canonical(tgt_neutral))
    frames = np.asarray(src_frames, np.float64)
    disp = (frames - np.asarray(src_neutral, np.float64))[..., nearest, :]
    return np.asarray(tgt_neutral, np.float64) + tgt_canon.displacement_from_canonical(
        src_canon.displacement_to_canonical(disp))


def closest_point_rig(template_neutral: np.ndarray, template_faces: np.ndarray,
                      template_deltas: np.ndarray, tgt_neutral: np.ndarray, tgt_faces: np.ndarray,
                      frame: str = "face") -> np.ndarray:
    """A template blendshape rig carried onto a target neutral by :func:`closest_point_transfer`
    (each shape taken as a frame): what a technical artist with an ARKit head tries first to rig
    another head.

    template_neutral (Vs,3), template_faces (Fs,3), template_deltas (K,Vs,3) in the template's
    units; tgt_neutral (Vt,3), tgt_faces (Ft,3) in the target's. Returns the target's shapes
    (K,Vt,3) float64, in the target's units."""
    neutral = np.asarray(template_neutral, np.float64)
    frames = neutral + np.asarray(template_deltas, np.float64)
    return closest_point_transfer(neutral, template_faces, frames, tgt_neutral, tgt_faces,
                                  frame=frame) - np.asarray(tgt_neutral, np.float64)


def fit_rig_weights(deltas: np.ndarray, neutral: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Inverse rigging on a known rig, the plain way: the weights w in [0,1] minimising
    |neutral + Σ_k w_k deltas_k − frame|² for each frame, by bounded least squares
    (``retarget.api.box_least_squares``) on the K×K reduced system, with a ridge of 1e-9 of the
    Gram matrix's mean diagonal only to keep it positive definite.

    deltas (K,V,3), neutral (V,3), frames (T,V,3) or (V,3), one unit. Returns (T,K) or (K,) float64."""
    from .api import _gram, _ridge_factor, box_least_squares

    a = np.asarray(deltas, np.float64).reshape(len(deltas), -1)              # (K, 3V)
    frames = np.asarray(frames, np.float64)
    single = frames.ndim == 2
    b = (frames.reshape(-1, *np.shape(neutral)) - np.asarray(neutral, np.float64)).reshape(
        -1, a.shape[1])                                                       # (T, 3V)
    chol, _ = _ridge_factor(_gram(a), 1e-9)
    out = np.array([box_least_squares(chol, h) for h in b @ a.T])
    return out[0] if single else out
