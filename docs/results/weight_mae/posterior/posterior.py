"""Invert's weights as the posterior mean or median instead of the maximum (docs/RESULTS.md,
"Inverse rigging's weights as a posterior mean"): offline on the cases of
docs/results/weight_mae/rig_span/cases.py.

Invert's fit (``SourceRig.fit``) returns the minimiser over the box [0,1]^53 of
E(w) = |A w − b|² + λ|w − w0|² + Σ μ_k w_k, a truncated Gaussian's mode. Where the frame leaves
directions of w undetermined (the rows that move every shape at once), the mode sits on the box's
faces, a weight at exactly 0 or 1. The mean (or the per-weight median) of exp(−E(w) / (2 τ s)) on
the box, s = mean diag(AᵀA), is what minimises the expected squared (absolute) error if the
residual were noise of that size; τ → 0 gives the mode back. It is computed by Gibbs sampling
(each weight in turn from its truncated normal conditional), started at the mode, all frames of a
case at once.

    python docs/results/weight_mae/posterior/posterior.py runs/fitstudy/tuning10{0,1,2,3,4}.npz
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.special import ndtr, ndtri

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "rig_span"))
from cases import SUITES, _bounded, load, row_kinds, weight_mae  # noqa: E402


def problem(case: dict, prior=0.01, sparsity=0.002, reweight=(0.02, 0.05, 2)):
    """The bundled fit's quadratic: (P (53,53) = AᵀA + λI, q (T,53) = Aᵀb + λ w0 − μ/2 with the
    last reweighted pass's μ, the modes (T,53), s = mean diag(AᵀA))."""
    a = np.asarray(case["A"], np.float64)
    gram = a @ a.T
    s = np.trace(gram) / len(gram)
    ridge = prior * s + 1e-12
    p = gram + ridge * np.eye(len(gram))
    chol = np.linalg.cholesky(p).T
    modes, qs = [], []
    for frame, w0 in zip(case["frames"], case["w0"]):
        h = a @ (frame - case["neutral"]).reshape(-1).astype(np.float64) + ridge * np.clip(w0, 0, 1)
        mu = np.full(len(h), sparsity)
        w = _bounded(chol, h, mu, s)
        if reweight:
            m, eps, passes = reweight
            for _ in range(passes):
                mu = m * eps / (w + eps)
                w = _bounded(chol, h, mu, s)
        modes.append(w)
        qs.append(h - 0.5 * mu * s)
    return p, np.array(qs), np.array(modes), s


def gibbs(p, q, start, temperature: float, sweeps: int, burn: int, rng) -> np.ndarray:
    """Samples (sweeps − burn, T, K) of the density ∝ exp(−(wᵀPw − 2qᵀw) / (2 temperature)) on
    [0,1]^K for each row of q (T,K), by systematic-scan Gibbs from ``start`` (T,K)."""
    w = np.array(start, np.float64)
    diag = np.diag(p)
    sd = np.sqrt(temperature / diag)
    out = []
    for sweep in range(sweeps):
        for k in range(len(diag)):
            mean = (q[:, k] - w @ p[:, k] + diag[k] * w[:, k]) / diag[k]
            lo, hi = ndtr((0.0 - mean) / sd[k]), ndtr((1.0 - mean) / sd[k])
            u = lo + (hi - lo) * rng.random(len(mean))
            z = ndtri(np.clip(u, 1e-12, 1 - 1e-12))
            w[:, k] = np.clip(mean + sd[k] * z, 0.0, 1.0)
        if sweep >= burn:
            out.append(w.copy())
    return np.array(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--temperatures", type=float, nargs="+", default=[1e-4, 3e-4, 1e-3, 3e-3])
    ap.add_argument("--sweeps", type=int, default=200)
    ap.add_argument("--burn", type=int, default=50)
    args = ap.parse_args()
    cases = load(*args.cases)
    rng = np.random.default_rng(0)
    names = ["predicting 0", "mode (bundled fit)"]
    for t in args.temperatures:
        names += [f"mean, τ = {t:g}", f"median, τ = {t:g}"]
    errs = {n: {s: [] for s in SUITES} for n in names}
    kinds = {s: [] for s in SUITES}
    fitted = {s: [] for s in SUITES}
    for c in cases:
        suite = str(c["suite"])
        p, q, modes, s = problem(c)
        kinds[suite].append(row_kinds(c))
        errs["predicting 0"][suite].append(weight_mae(c, np.zeros_like(modes)))
        errs["mode (bundled fit)"][suite].append(weight_mae(c, modes))
        fitted[suite].append((modes, c["gt"]))
        for t in args.temperatures:
            draws = gibbs(p, q, modes, t * s, args.sweeps, args.burn, rng)
            errs[f"mean, τ = {t:g}"][suite].append(weight_mae(c, draws.mean(0)))
            errs[f"median, τ = {t:g}"][suite].append(weight_mae(c, np.median(draws, 0)))
    print("| weights | " + " | ".join(SUITES) + " |")
    print("| --- | " + " | ".join("---:" for _ in SUITES) + " |")
    for n in names:
        cells = []
        for suite in SUITES:
            if not errs[n][suite]:
                cells.append("—")
                continue
            e, k = np.concatenate(errs[n][suite]), np.concatenate(kinds[suite])
            cells.append(f"{e.mean():.4f} (u {e[k == 'uniform'].mean():.3f}, "
                         f"o {e[k == 'onehot'].mean():.3f}, s {e[k == 'sparse'].mean():.3f})")
        print(f"| {n} | " + " | ".join(cells) + " |")
    print()
    print(mode_bias(fitted, kinds))


def mode_bias(fitted: dict, kinds: dict) -> str:
    """On the uniform rows of the ICT-rigged suites, the mode's weights: the share at 0 and at 1,
    the mean signed error, and per shape the slope of the fitted weight against the true one
    (least squares with an intercept; median over the 53 shapes) -> a markdown table."""
    lines = ["| uniform rows, the mode | at 0 | at 1 | mean signed error | median slope per shape |",
             "| --- | ---: | ---: | ---: | ---: |"]
    for suite in SUITES[:2]:
        if not fitted[suite]:
            continue
        u = np.concatenate(kinds[suite]) == "uniform"
        w = np.concatenate([m for m, _ in fitted[suite]])[u]
        gt = np.concatenate([g for _, g in fitted[suite]])[u]
        slopes = [np.polyfit(gt[:, k], w[:, k], 1)[0] for k in range(w.shape[1])]
        lines.append(f"| {suite} | {(w <= 1e-6).mean():.3f} | {(w >= 1 - 1e-6).mean():.3f} | "
                     f"{(w - gt).mean():.4f} | {np.median(slopes):.2f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
