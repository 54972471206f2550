"""Invert's pulls in proportion to each shape (docs/RESULTS.md, "Invert's pulls in proportion to
each shape"): ``SourceRig.fit`` with its ``balance`` β, offline on the inversion cases of
docs/results/weight_mae/rig_span/cases.py.

The fit pulls weight k towards the encoder's estimate with λ s_k and towards 0 with μ s_k, s_k =
m^(1−β) |B̂_k|^(2β) (``retarget.api.pull_scales``). β = 0 was the bundled fit: every weight pulled
with the mean shape's size m, so a small shape (a brow, an eye look, the nose) is held at the
encoder's estimate by a pull many times what it adds to the frame. Prints one markdown row per
setting: the weight MAE per suite over all rows (the uniform rows in brackets), the then bundled
sparsity and reweighting throughout.

    python docs/results/weight_mae/balance/balance.py runs/fitstudy/tuning10{0,1,2,3,4}.npz --grid
    python docs/results/weight_mae/balance/balance.py runs/fitstudy/val_large.npz
    python docs/results/weight_mae/balance/balance.py runs/fitstudy/val_large.npz --shapes

``--shapes``: instead, per ICT-rigged suite, the mean absolute error of each shape's weight with
β = 0.5 against β = 0 (prior 0.01): the shapes that gain and lose most, and the eye looks'
mean against the others'.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "rig_span"))
from cases import SUITES, api_fit, load, table_row  # noqa: E402


#: invert's fit as this study ran it (before section "Frames that move many shapes" retuned it)
PRIOR, SPARSITY, REWEIGHT = 0.01, 0.002, (0.02, 0.05, 2)


def fitted(case: dict, prior: float, balance: float) -> np.ndarray:
    """Invert's fit of every frame of ``case`` on its baked rig -> weights (T, 53)."""
    return api_fit(case, prior, SPARSITY, REWEIGHT, balance)


def row(cases, name: str, prior: float | None = None, balance: float = 0.0) -> str:
    """A markdown row (``cases.table_row``): per suite the MAE over all rows (uniform rows) of the
    fit, or of predicting 0 when ``prior`` is None."""
    return table_row(cases, name, zero=prior is None,
                     fit_fn=lambda case, shapes: fitted(case, prior, balance))


def shape_changes(cases, suite: str, balance: float = 0.5, shown: int = 8) -> str:
    """Markdown lines for ``--shapes``: per-shape MAE of the weights, β = 0 -> ``balance``."""
    from data_synth.facs import FACS_NAMES

    prior = PRIOR
    before, after = [], []
    for c in cases:
        if str(c["suite"]) == suite:
            before.append(np.abs(fitted(c, prior, 0.0) - c["gt"]))
            after.append(np.abs(fitted(c, prior, balance) - c["gt"]))
    e0, e1 = np.concatenate(before).mean(0), np.concatenate(after).mean(0)
    order = np.argsort(e1 - e0)
    looks = np.array([n.startswith("eyeLook") for n in FACS_NAMES])

    def listed(ks):
        return ", ".join(f"{FACS_NAMES[k]} {e0[k]:.3f} → {e1[k]:.3f}" for k in ks)

    return (f"- {suite}, most worse: {listed(order[::-1][:shown])}\n"
            f"- {suite}, most better: {listed(order[:shown])}\n"
            f"- {suite}, the eye looks {e0[looks].mean():.4f} → {e1[looks].mean():.4f}, the other "
            f"shapes {e0[~looks].mean():.4f} → {e1[~looks].mean():.4f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--grid", action="store_true", help="priors 0.003, 0.01, 0.03 for each balance")
    ap.add_argument("--shapes", action="store_true", help="per-shape changes, β 0 -> 0.5")
    args = ap.parse_args()
    cases = load(*args.cases)
    if args.shapes:
        print("\n".join(shape_changes(cases, suite) for suite in SUITES[:2]))
        return
    priors = (0.003, 0.01, 0.03) if args.grid else (PRIOR,)
    print("| fit | " + " | ".join(SUITES) + " |")
    print("| --- | " + " | ".join("---:" for _ in SUITES) + " |")
    print(row(cases, "predicting 0"), flush=True)
    for balance in (0.0, 0.25, 0.5, 0.75, 1.0):
        for prior in priors:
            print(row(cases, f"balance {balance:g}, prior {prior:g}", prior, balance), flush=True)


if __name__ == "__main__":
    main()
