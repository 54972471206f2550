"""Frames that move many shapes, fitted again without the pull towards 0 (docs/RESULTS.md, "Frames
that move many shapes: fitted again without the pull towards 0"): ``SourceRig.fit``'s ``dense``,
offline on the inversion cases of docs/results/weight_mae/rig_span/cases.py.

Invert's fit pulls each weight towards 0 (an L1 pull, reweighted twice) so that a frame of a few
shapes is not explained by small weights spread over all of them. On a frame that moves most of
the 53 shapes at once the same pull only shrinks weights the frame needs. With ``dense`` = (count,
threshold, prior, balance) a frame whose fitted weights have more than ``count`` above
``threshold`` is fitted again without the L1 pull. Prints one markdown row per setting: the
weight MAE per suite over all rows (the uniform rows, all 53 shapes at U(0, 1), in brackets),
the then bundled prior, sparsity, reweighting and balance for the first fit (``FIRST``: before
retune.py retuned them). "Choosing by the truth"
takes, frame by frame, whichever of the sparse fit and the L1-free one (prior 0.01, balance 0.5)
is nearer the true weights: what a perfect detector of dense frames would give.

    python docs/results/weight_mae/dense/dense.py runs/fitstudy/tuning10{0,1,2,3,4}.npz
    python docs/results/weight_mae/dense/dense.py runs/fitstudy/val_large.npz
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "rig_span"))
from cases import SUITES, api_fit, load, table_row, weight_mae  # noqa: E402

#: the first fit as this study ran it: invert's before the retune of retune.py (prior, sparsity,
#: reweight, balance)
FIRST = (0.01, 0.002, (0.02, 0.05, 2), 0.5)
COUNTS = (10, 15, 20, 25, 30)
SECOND = ((0.01, 0.5), (0.01, 0.25), (0.03, 0.5))


def fitted(case: dict, dense: tuple = ()) -> np.ndarray:
    """Invert's fit of every frame of ``case`` on its baked rig, with ``dense`` -> (T, 53)."""
    return api_fit(case, *FIRST, dense=dense)


def by_the_truth(case: dict) -> np.ndarray:
    """Per frame, the sparse fit or the L1-free one (prior 0.01, balance 0.5), whichever has the
    lower weight MAE against the true weights -> (T, 53)."""
    sparse, free = fitted(case), fitted(case, (-1, 0.0, 0.01, 0.5))
    better = weight_mae(case, free) < weight_mae(case, sparse)
    return np.where(better[:, None], free, sparse)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+")
    cases = load(*ap.parse_args().cases)
    print("| fit | " + " | ".join(SUITES) + " |")
    print("| --- | " + " | ".join("---:" for _ in SUITES) + " |")
    print(table_row(cases, "predicting 0", zero=True), flush=True)
    print(table_row(cases, "no second fit (the fit before)", fit_fn=lambda c, _: fitted(c)),
          flush=True)
    print(table_row(cases, "every frame fitted without the L1 pull (prior 0.01, balance 0.5)",
                    fit_fn=lambda c, _: fitted(c, (-1, 0.0, 0.01, 0.5))), flush=True)
    print(table_row(cases, "choosing by the truth", fit_fn=lambda c, _: by_the_truth(c)), flush=True)
    for count in COUNTS:
        for prior, balance in SECOND:
            dense = (count, 0.05, prior, balance)
            print(table_row(cases, f"more than {count} above 0.05: prior {prior}, balance {balance}",
                            fit_fn=lambda c, _, d=dense: fitted(c, d)), flush=True)


if __name__ == "__main__":
    main()
