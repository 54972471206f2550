"""Vertex-clustering decimation: the proxy on which large meshes are encoded.

Vertices are snapped to a uniform grid; each occupied cell becomes one proxy vertex (the mean of its
vertices) and faces whose corners fall into three different cells are kept. The result may be
non-manifold, which the robust Laplacian of ``nets.geometry`` handles. Every original vertex knows its
proxy vertex, so per-vertex encoder outputs (z_Skin, ω_Skin) are carried back to full resolution, and
the frames of a large source sequence are reduced with the clusters of its reference mesh
(:func:`cluster_means`).
"""
from __future__ import annotations

import numpy as np

CELL_GROWTH = 1.15  # the grid cell grows by this factor until the proxy is small enough


def cluster_means(vertices: np.ndarray, cluster: np.ndarray) -> np.ndarray:
    """Proxy positions: vertices (V,3), cluster (V,) int64 in 0..P-1 -> (P,3) float64 cluster means."""
    v = np.asarray(vertices, np.float64)
    counts = np.bincount(cluster)
    return np.stack([np.bincount(cluster, weights=v[:, k], minlength=len(counts)) for k in range(3)],
                    axis=1) / counts[:, None]


def _grid_clusters(v: np.ndarray, lo: np.ndarray, cell: float) -> np.ndarray:
    """(V,) int64 cluster of each vertex: the rank of its occupied grid cell of side ``cell``."""
    keys = np.floor((v - lo) / cell).astype(np.int64)
    dims = keys.max(axis=0) + 1
    linear = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
    return np.unique(linear, return_inverse=True)[1].reshape(-1)


def cluster_decimate(vertices: np.ndarray, faces: np.ndarray, n_target: int
                     ) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """Decimate to at most ``n_target`` (>= 1) vertices (usually 40-100 % of it).

    vertices (V,3), faces (F,3). Returns ((proxy_vertices (P,3) float64, proxy_faces (G,3) int64),
    cluster (V,) int64 = the proxy vertex of each original vertex). Proxy faces are the original faces
    with three distinct clusters, duplicates removed, orientation kept.
    """
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    lo, hi = v.min(0), v.max(0)
    extent = max(float((hi - lo).max()), 1e-12)
    # a surface spanning a box of side s covers ~(s / cell)^2 cells: start there, then grow the cell
    cell = extent / np.sqrt(n_target)
    cluster = _grid_clusters(v, lo, cell)
    while cluster.max() >= n_target:  # ends: a cell wider than the mesh makes one cluster
        cell *= CELL_GROWTH
        cluster = _grid_clusters(v, lo, cell)
    pf = cluster[f]
    pf = pf[(pf[:, 0] != pf[:, 1]) & (pf[:, 1] != pf[:, 2]) & (pf[:, 0] != pf[:, 2])]
    _, first = np.unique(np.sort(pf, axis=1), axis=0, return_index=True)  # drop duplicate faces
    return (cluster_means(v, cluster), pf[np.sort(first)]), cluster
