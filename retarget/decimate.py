"""Vertex-clustering decimation: the proxy on which large meshes are encoded.

Vertices are snapped to a uniform grid; each occupied cell becomes one proxy vertex (the mean of its
vertices) and faces whose corners fall into three different cells are kept. The result may be
non-manifold, which the robust Laplacian of ``nets.geometry`` handles. Every original vertex knows its
proxy vertex, so per-vertex encoder outputs (z_Skin, ω_Skin) are carried back to full resolution.
"""
from __future__ import annotations

import numpy as np


def cluster_decimate(vertices: np.ndarray, faces: np.ndarray, n_target: int
                     ) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """Decimate to about ``n_target`` vertices (never more).

    vertices (V,3), faces (F,3). Returns ((proxy_vertices (P,3) float64, proxy_faces (G,3) int64),
    cluster (V,) int64 = the proxy vertex of each original vertex).
    """
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    lo, hi = v.min(0), v.max(0)
    extent = max(float((hi - lo).max()), 1e-12)
    # a surface of V vertices in a box of side s: cells ~ (s / cell)^2; start there, then shrink
    cell = extent / np.sqrt(n_target)
    for _ in range(40):
        keys = np.floor((v - lo) / cell).astype(np.int64)
        _, cluster, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        if len(counts) <= n_target:
            break
        cell *= 1.15
    cluster = cluster.reshape(-1)
    proxy = np.zeros((len(counts), 3))
    np.add.at(proxy, cluster, v)
    proxy /= counts[:, None]
    pf = cluster[f]
    pf = pf[(pf[:, 0] != pf[:, 1]) & (pf[:, 1] != pf[:, 2]) & (pf[:, 0] != pf[:, 2])]
    _, first = np.unique(np.sort(pf, axis=1), axis=0, return_index=True)  # drop duplicate faces
    return (proxy, pf[np.sort(first)]), cluster
