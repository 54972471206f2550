"""Invert's fit retuned around the dense second fit (docs/RESULTS.md, "Frames that move many
shapes"): the first fit's prior and reweighted L1 pull, and the second fit's balance, offline on the
inversion cases of docs/results/weight_mae/rig_span/cases.py. Candidates from a grid on the tuning
set's procedural and realistic heads (prior 0.003 / 0.01 / 0.03, sparsity 0.002 / 0.005,
reweighted L1 0.02 / 0.05, balance 0.25 / 0.5 / 0.75, the second fit's balance 0.25 / 0.5 / 0.75
and prior 0.003 / 0.01: the best of each kind of head below). Prints one markdown row per
candidate: the weight MAE per suite over all rows (uniform rows in brackets), and with ``--kinds``
the one-hot and sparse rows' MAE too. With ``--bundled``, only the row of the fit a model with a
code map gets now (``Retargeter.REFINE_INVERT_FITS[True]``): how section "Stage 22" compares the
cases of several models under one fit.

    python docs/results/weight_mae/dense/retune.py runs/fitstudy/tuning10{0,1,2,3,4}.npz
    python docs/results/weight_mae/dense/retune.py runs/fitstudy/val_large.npz
    python docs/results/weight_mae/dense/retune.py runs/fitstudy/val_large.npz --kinds
    python docs/results/weight_mae/dense/retune.py runs/decstudy/long10{0,1,2,3,4}.npz --bundled
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "rig_span"))
from cases import SUITES, api_fit, load, table_row  # noqa: E402

#: name -> (prior, sparsity, reweighted L1 μ_max, balance, the second fit's prior, its balance)
CANDIDATES = {
    "bundled: prior 0.01, reweight 0.02, second fit balance 0.25": (0.01, 0.002, 0.02, 0.5, 0.01, 0.25),
    "reweight 0.05": (0.01, 0.002, 0.05, 0.5, 0.01, 0.25),
    "prior 0.003": (0.003, 0.002, 0.02, 0.5, 0.01, 0.25),
    "prior 0.003, reweight 0.05 (best of the realistic heads)": (0.003, 0.002, 0.05, 0.5, 0.01, 0.25),
    "prior 0.003, reweight 0.05, second fit balance 0.5 (best of the procedural heads)": (0.003, 0.002, 0.05, 0.5, 0.01, 0.5),
}


def fitted(case: dict, prior, sparsity, mu, balance, dense_prior, dense_balance) -> np.ndarray:
    """Invert's fit of every frame of ``case`` with these settings -> (T, 53)."""
    return api_fit(case, prior, sparsity, (mu, 0.05, 2), balance,
                   (20, 0.05, dense_prior, dense_balance))


def one_hot_and_sparse(errors: np.ndarray, kinds: np.ndarray) -> str:
    """A ``table_row`` cell for ``--kinds``: the MAE of the one-hot / sparse rows."""
    return f"{errors[kinds == 'onehot'].mean():.4f} / {errors[kinds == 'sparse'].mean():.4f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--kinds", action="store_true", help="the one-hot / sparse rows' MAE instead")
    ap.add_argument("--bundled", action="store_true", help="only the fit invert uses now")
    args = ap.parse_args()
    cases = load(*args.cases)
    fits = {name: (lambda c, _, s=settings: fitted(c, *s)) for name, settings in CANDIDATES.items()}
    if args.bundled:
        from retarget.api import Retargeter

        fits = {"bundled fit": lambda c, _: api_fit(c, *Retargeter.REFINE_INVERT_FITS[True])}
    print(f"| fit{' (one-hot / sparse rows)' if args.kinds else ''} | " + " | ".join(SUITES) + " |")
    print("| --- | " + " | ".join("---:" for _ in SUITES) + " |")
    if not args.kinds:
        print(table_row(cases, "predicting 0", zero=True), flush=True)
    for name, fit_fn in fits.items():
        print(table_row(cases, name, fit_fn=fit_fn, cell=one_hot_and_sparse if args.kinds else None),
              flush=True)


if __name__ == "__main__":
    main()
