"""Code maps per head, predicted from the identity code z_ID: fitted on cached training heads
(``cache.py``), judged on held-out heads by the decoder's shapes' relative error (study, issue 10).

Each map is m_k(z) = A_k φ̃(z), φ̃ = [1, the first d whitened principal components of the training
heads' z_ID]; d = 0 is one map shared by every head (the bundled kind). A_k is the ridge
least-squares fit of Σ_h |X_hᵀ m_k(z_h) − B_hk|² / |B_hk|² over the training heads, pulled towards
the paper's map [e_k, 0, ...] by ``ridge`` × the mean diagonal of the normal equations. Printed:
the median over held-out heads and shapes of |X_hᵀ m_k − B_hk| / |B_hk|, beside the paper's map
e_k and each head's own best map (the oracle).

    python docs/results/code_map/head_maps/fit.py --train runs/head_maps/procedural_train.npz --test runs/head_maps/procedural_val.npz
"""
from __future__ import annotations

import argparse

import numpy as np


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


class Features:
    """φ̃(z) = [1, whitened principal components 1..d of the training heads' z_ID]."""

    def __init__(self, z, d):
        self.mean = z.mean(0)
        _, s, vt = np.linalg.svd(z - self.mean, full_matrices=False)
        self.proj = vt[:d].T / (s[:d] / np.sqrt(len(z)))

    def __call__(self, z):
        return np.c_[np.ones(len(z)), (z - self.mean) @ self.proj]


def fit_linear(train, feats, ridge):
    """A (53, dims, 1 + d): the ridge fit of m_k(z) = A_k φ̃(z) (module docstring)."""
    phi = feats(train["z_id"])                                  # (H, p)
    g, c, n = train["gram"], train["cross"], train["norm2"]
    h, dims, _ = g.shape
    p = phi.shape[1]
    a = np.zeros((53, dims, p))
    outer = (phi[:, :, None] * phi[:, None, :]).reshape(h, -1)  # (H, p²)
    for k in range(53):
        use = n[:, k] > 0
        target = np.zeros((dims, p)); target[k, 0] = 1.0
        if not use.any():
            a[k] = target
            continue
        w = 1.0 / n[use, k]
        # normal matrix over vec(A) ordered (dims, p): Σ_h w_h G_h ⊗ φ̃φ̃ᵀ
        big = ((outer[use] * w[:, None]).T @ g[use].reshape(use.sum(), -1))     # (p², dims²)
        big = big.reshape(p, p, dims, dims).transpose(2, 0, 3, 1).reshape(dims * p, dims * p)
        rhs = np.einsum("h,hi,ha->ia", w, c[use, :, k], phi[use]).reshape(-1)
        lam = ridge * np.trace(big) / (dims * p)
        sol = np.linalg.solve(big + lam * np.eye(dims * p), rhs + lam * target.reshape(-1))
        a[k] = sol.reshape(dims, p)
    return a


def maps_of(a, feats, z):
    """(H, dims, 53) maps of heads with codes z."""
    return np.einsum("kip,hp->hik", a, feats(z))


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
        feats = Features(train["z_id"], d)
        for ridge in args.ridges:
            a = fit_linear(train, feats, ridge)
            e = relative_errors(maps_of(a, feats, test["z_id"]), test)
            et = relative_errors(maps_of(a, feats, train["z_id"]), train)
            print(f"| d = {d}, ridge {ridge:g} | {np.nanmedian(e):.4f} | {np.nanmean(e):.4f} | {np.nanmedian(et):.4f} |", flush=True)


if __name__ == "__main__":
    main()
