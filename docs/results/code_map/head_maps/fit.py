"""Code maps per head, predicted from the identity code z_ID: fitted on cached training heads
(``cache.py``), judged on held-out heads by the decoder's shapes' relative error (study, issue 10).

Each map is m_k(z) = A_k φ̃(z), φ̃ = [1, the first d whitened principal components of the training
heads' z_ID]; d = 0 is one map shared by every head (the bundled kind). A_k is the ridge
least-squares fit of Σ_h |X_hᵀ m_k(z_h) − B_hk|² / |B_hk|² over the training heads, pulled towards
the paper's map [e_k, 0, ...] by ``ridge`` × the mean diagonal of the normal equations
(``retarget.code_map.HeadMapFit``, the fit ``retarget train`` makes with ``code_map.features``). Printed:
the median over held-out heads and shapes of |X_hᵀ m_k − B_hk| / |B_hk|, beside the paper's map
e_k and each head's own best map (the oracle).

    python docs/results/code_map/head_maps/fit.py --train runs/head_maps/procedural_train.npz --test runs/head_maps/procedural_val.npz
"""
from __future__ import annotations

import argparse

import numpy as np

from retarget.code_map import HeadMapFit, head_code_map


def load(paths):
    parts = [np.load(p) for p in paths]
    return {k: np.concatenate([p[k] for p in parts]) for k in ("z_id", "gram", "cross", "norm2")}


def relative_errors(maps, data):
    """(H, 53) |Xᵀ m_k − B_k| / |B_k| of maps (H, dims, 53) on heads ``data`` (nan where B_k = 0)."""
    g, c, n = data["gram"], data["cross"], data["norm2"]
    quad = np.einsum("hik,hij,hjk->hk", maps, g, maps)
    lin = np.einsum("hik,hik->hk", maps, c)
    err2 = np.maximum(quad - 2 * lin + n, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.sqrt(err2 / n), np.nan)


def fit_map(train, d, ridge):
    """(M_0, per-head (features, slopes) or None): ``retarget.code_map.HeadMapFit`` on the cached
    heads ``train``, d whitened principal components of z_ID (0: one map), ridge ``ridge``."""
    fit = HeadMapFit()
    for z, g, c, n in zip(train["z_id"], train["gram"], train["cross"], train["norm2"]):
        fit.add_normal_equations(z, g, c, n)
    return fit.solve(d, ridge)


def maps_of(m0, per_head, z):
    """(H, dims, 53) the maps (``retarget.code_map.head_code_map``, no gate) of heads with codes z."""
    return np.stack([head_code_map(m0, None, z_h, per_head) for z_h in z]).astype(np.float64)


def oracle(data, ridge=1e-6):
    g, c = data["gram"], data["cross"]
    dims = g.shape[1]
    lam = ridge * np.trace(g, axis1=1, axis2=2)[:, None, None] / dims
    return np.linalg.solve(g + lam * np.eye(dims), c)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", nargs="+", required=True)
    ap.add_argument("--test", nargs="+", required=True)
    ap.add_argument("--dims", type=int, nargs="+", default=[0, 4, 8, 16, 32])
    ap.add_argument("--ridges", type=float, nargs="+", default=[0.001, 0.01, 0.1])
    ap.add_argument("--max-train", type=int, default=0)
    args = ap.parse_args()
    train, test = load(args.train), load(args.test)
    if args.max_train:
        train = {k: v[:args.max_train] for k, v in train.items()}
    dims = train["gram"].shape[1]
    eye = np.broadcast_to(np.eye(dims, 53), (len(test["z_id"]), dims, 53))
    print(f"{len(train['z_id'])} training heads, {len(test['z_id'])} held-out heads")
    print("| map | median relative error (held out) | mean | median on training heads |")
    print("| --- | ---: | ---: | ---: |")
    rows = [("paper's map e_k", eye, np.broadcast_to(np.eye(dims, 53), (len(train["z_id"]), dims, 53))),
            ("each head's best (oracle)", oracle(test), oracle(train))]
    for name, m, mt in rows:
        e, et = relative_errors(m, test), relative_errors(mt, train)
        print(f"| {name} | {np.nanmedian(e):.4f} | {np.nanmean(e):.4f} | {np.nanmedian(et):.4f} |", flush=True)
    for d in args.dims:
        for ridge in args.ridges:
            m0, per_head = fit_map(train, d, ridge)
            e = relative_errors(maps_of(m0, per_head, test["z_id"]), test)
            et = relative_errors(maps_of(m0, per_head, train["z_id"]), train)
            print(f"| d = {d}, ridge {ridge:g} | {np.nanmedian(e):.4f} | {np.nanmean(e):.4f} | {np.nanmedian(et):.4f} |", flush=True)


if __name__ == "__main__":
    main()
