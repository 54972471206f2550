"""What the inverted weights' error is made of: the baked rig's error inside and outside the
decoder's span, and four ways of fitting (docs/RESULTS.md, "What the weights' error is made of").

Reads case files of ``cases.py`` (the bundled model's inversion cases) and prints markdown tables:
1. the baked shapes' median relative error |B̂_k − B_k| / |B_k|, and the least error any shapes in
   the span of the decoder's 128-dim rig X of that head could have (B_k projected on X's rows);
2. invert's fit (weight MAE, and of the uniform rows) on the baked shapes, on those best in-span
   shapes (a per-head code map no head's data but its true shapes can give) and on the true
   shapes, each with the bundled fit and with weaker priors;
3. per-vertex weights in the fit (weighted least squares): 1 / (1 + c q_v / mean q), q_v = Σ_k
   |B̂_k(v)|², the residual's expected variance where many shapes move a vertex;
4. with ``--zmap N``: a code map that depends on the head, M(z_ID) = M_0 + L φ(z_ID) (φ: the
   first d whitened principal components of the identity code), fitted as the bundled map is
   (``retarget.code_map``) on the MakeHuman training heads of seeds 0..N−1, d = 0 (the bundled
   map for N = 48), 4 and 8.

    python docs/results/weight_mae/rig_span/rig_span.py runs/rig_span/tuning10{0,1,2,3,4}.npz --zmap 96
    python docs/results/weight_mae/rig_span/rig_span.py runs/rig_span/val.npz --parts 3
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cases import SUITES, load, table_row  # noqa: E402

HEADER = "| fit | procedural | realistic heads | ARKit rig |\n| --- | ---: | ---: | ---: |"


def in_span(case: dict, shapes=None) -> np.ndarray:
    """``shapes`` (K, 3V) (default: the case's true shapes) projected on the rows of the head's
    decoder rig X: (K, 3V)."""
    q, _ = np.linalg.qr(np.asarray(case["X"], np.float64).T)
    t = np.asarray(case["true"] if shapes is None else shapes, np.float64)
    return (t @ q) @ q.T


def shape_errors(cases) -> None:
    print("| suite | baked shapes | best in the decoder's span |\n| --- | ---: | ---: |")
    for suite in SUITES:
        baked, best = [], []
        for c in (c for c in cases if str(c["suite"]) == suite):
            a, t = np.asarray(c["A"], np.float64), np.asarray(c["true"], np.float64)
            if suite == "real_rig":                       # ARKit shapes against sums of ICT shapes
                m = c["arkit_ict"]
                keep = m.sum(1) > 0
                a, t = (m @ a)[keep], t[keep]
            p = in_span(c, t)
            n = np.linalg.norm(t, axis=1)
            ok = n > 0
            baked.append(np.median(np.linalg.norm(a - t, axis=1)[ok] / n[ok]))
            best.append(np.median(np.linalg.norm(p - t, axis=1)[ok] / n[ok]))
        print(f"| {suite} | {np.mean(baked):.3f} | {np.mean(best):.3f} |")


def oracle_fits(cases) -> None:
    weak = {"bundled fit": {}, "prior 0.001, no L1": dict(prior=0.001, sparsity=0.0, reweight=()),
            "prior 0.0001, no L1": dict(prior=1e-4, sparsity=0.0, reweight=())}
    ict = [c for c in cases if str(c["suite"]) != "real_rig"]
    print("| shapes, fit | procedural | realistic heads |\n| --- | ---: | ---: |")
    print(table_row(ict, "predicting 0", suites=SUITES[:2], zero=True))
    for shapes, of in (("baked", None), ("best in span", in_span), ("true", lambda c: c["true"])):
        for name, args in weak.items():
            print(table_row(ict, f"{shapes}, {name}", of, suites=SUITES[:2], **args), flush=True)


def vertex_weighted(cases) -> None:
    print(HEADER)
    print(table_row(cases, "predicting 0", zero=True))
    print(table_row(cases, "bundled fit"))
    for c_ in (0.3, 0.5, 1.0):
        for case in cases:
            a = np.asarray(case["A"], np.float64)
            q = (a.reshape(len(a), -1, 3) ** 2).sum((0, 2))
            case["vw"] = 1.0 / (1.0 + c_ * q / q.mean())
        print(table_row(cases, f"vertex weights, c = {c_}", vertex_weights=lambda c: c["vw"]), flush=True)


def zmap(cases, identities: int) -> None:
    import torch

    from retarget.api import Retargeter
    from retarget.code_map import decoder_rows, training_rigs

    r = Retargeter.load()
    heads = []                          # (gram X Xᵀ, cross X Bᵀ, |B_k|², z_ID) per MakeHuman head
    for kind, rig in training_rigs(identities, 0, r.cfg.n_segments, kinds=("makehuman",)):
        x, z = decoder_rows(r, rig)
        x = x.astype(np.float64)
        b = np.asarray(rig.deltas, np.float64).reshape(len(rig.deltas), -1)
        heads.append((x @ x.T, x @ b.T, (b ** 2).sum(1), z))
    gram, cross, norm2, z = (np.array(v) for v in zip(*heads))
    bundled = torch.load(str(Path(__file__).resolve().parents[4] / "retarget/checkpoints/default.pt"),
                         weights_only=True)["code_map"].numpy()
    print(HEADER)
    print(table_row(cases, "bundled map (48 heads, gated)"))
    mh = [c for c in cases if str(c["suite"]) != "inverse"]
    for d in (0, 4, 8):
        theta, mean, std, proj = fit_zmap(gram, cross, norm2, z, d, ridge=0.01)
        for c in mh:
            psi = np.r_[1.0, ((np.asarray(c["z_id"], np.float64) - mean) / std) @ proj]
            c["A_z"] = (theta @ psi) @ np.asarray(c["X"], np.float64)
        if d == 0 and identities == 48:
            print(f"(the map of 48 heads, d = 0, against the bundled one: max |difference| "
                  f"{np.abs(theta[:, :, 0].T - bundled).max():.1e})")
        row = table_row(mh, f"map of {identities} heads, d = {d}", lambda c: c["A_z"], suites=SUITES[1:])
        print(row.replace(" | ", " | — | ", 1), flush=True)


def fit_zmap(gram, cross, norm2, z, d, ridge):
    """Θ (53, 128, d+1) with M(z)[:, k] = Θ_k [1, φ(z)], fitted per shape k like
    ``CodeMapFit`` (each head's shape weighted by 1/|B_hk|², ridge towards [e_k, 0])."""
    mean, std = z.mean(0), z.std(0) + 1e-6
    zs = (z - mean) / std
    if d:
        _, s, vt = np.linalg.svd(zs, full_matrices=False)
        proj = vt[:d].T / s[:d] * np.sqrt(len(zs))
    else:
        proj = np.zeros((z.shape[1], 0))
    psi = np.c_[np.ones(len(zs)), zs @ proj]
    dims, q = gram.shape[1], d + 1
    theta = np.zeros((norm2.shape[1], dims, q))
    for k in range(norm2.shape[1]):
        ok = norm2[:, k] > 0
        a = 1.0 / norm2[ok, k]
        h = np.einsum("h,hj,hl,hab->jalb", a, psi[ok], psi[ok], gram[ok], optimize=True).reshape(q * dims, -1)
        rhs = np.einsum("h,hj,ha->ja", a, psi[ok], cross[ok, :, k]).reshape(-1)
        target = np.zeros((q, dims))
        target[0, k] = 1.0
        lam = ridge * np.trace(h[:dims, :dims]) / dims
        theta[k] = np.linalg.solve(h + lam * np.eye(len(h)), rhs + lam * target.reshape(-1)).reshape(q, dims).T
    return theta, mean, std, proj


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--parts", type=int, nargs="*", default=[1, 2, 3])
    ap.add_argument("--zmap", type=int, default=0, help="part 4 on this many training identities")
    args = ap.parse_args()
    cases = load(*args.cases)
    for part, run in ((1, shape_errors), (2, oracle_fits), (3, vertex_weighted)):
        if part in args.parts:
            print(f"\n**{part}.**")
            run(cases)
    if args.zmap:
        print("\n**4.**")
        zmap(cases, args.zmap)


if __name__ == "__main__":
    main()
