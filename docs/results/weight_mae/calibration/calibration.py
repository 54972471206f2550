"""Study (not kept): the encoder's reading of a head's baked rig as a calibration of invert's fit
(docs/RESULTS.md, "The baked rig read back by the encoder").

If the baked shapes were a mix of the true ones, B̂ = M B (the in-span error of "What the weights'
error is made of"), the fit on B̂ would return v with w = Mᵀ v; the encoder, were it exact on
single shapes, would read M's rows from the baked one-hot frames (E ≈ M). This fits on the
calibrated shapes ((1 − a) I + a E)⁻¹ B̂, and, as an oracle, on the same with M fitted to the true
shapes by least squares. Cases from ``rig_span/cases.py --readings``:

    for s in 100 101 102 103 104; do python docs/results/weight_mae/rig_span/cases.py --seed $s --readings --out runs/calib/tuning$s.npz; done
    python docs/results/weight_mae/calibration/calibration.py runs/calib/tuning10{0,1,2,3,4}.npz
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "rig_span"))
from cases import SUITES, fit, load, row_kinds, weight_mae  # noqa: E402


def row(cases, name, weights_of) -> str:
    """Per suite: weight MAE over all rows (over the uniform rows)."""
    cells = []
    for suite in SUITES:
        errs, kinds = [], []
        for c in cases:
            if str(c["suite"]) == suite:
                errs.append(weight_mae(c, weights_of(c)))
                kinds.append(row_kinds(c))
        e, k = np.concatenate(errs), np.concatenate(kinds)
        cells.append(f"{e.mean():.4f} ({e[k == 'uniform'].mean():.3f})")
    return f"| {name} | " + " | ".join(cells) + " |"


def mixing(c) -> np.ndarray:
    """M (53, 53) with B̂ ≈ M B, least squares on the true shapes."""
    return np.linalg.lstsq(c["true"].T.astype(np.float64), c["A"].T.astype(np.float64), rcond=None)[0].T


def calibrated(c, a: float, oracle: bool) -> np.ndarray:
    if oracle and "E_true" not in c:                  # the ARKit rig: no 53 true ICT shapes
        return c["A"]
    m = mixing(c) if oracle else c["E"].astype(np.float64)
    return np.linalg.solve((1 - a) * np.eye(53) + a * m, c["A"].astype(np.float64))


def main(paths) -> None:
    cases = load(*paths)
    print("| shapes, fit | " + " | ".join(SUITES) + " |\n| --- |" + " ---: |" * len(SUITES))
    print(row(cases, "predicting 0", lambda c: np.zeros_like(c["w0"])))
    print(row(cases, "the encoder alone", lambda c: np.clip(c["w0"], 0, 1)))
    print(row(cases, "baked, bundled fit", fit))
    for a in (0.25, 0.5, 1.0):
        print(row(cases, f"oracle M, a = {a}", lambda c: fit(c, calibrated(c, a, True))))
    for a in (0.25, 0.5, 1.0):
        print(row(cases, f"encoder's E, a = {a}", lambda c: fit(c, calibrated(c, a, False))))
    ict = [c for c in cases if "E_true" in c]
    diag = lambda m: float(np.mean(np.diag(m)))  # noqa: E731
    print(f"\nmean diagonal over {len(ict)} ICT-rigged heads: E {np.mean([diag(c['E']) for c in ict]):.3f}, "
          f"E_true {np.mean([diag(c['E_true']) for c in ict]):.3f} (the encoder's weight for one true "
          f"shape at 1), M {np.mean([diag(mixing(c)) for c in ict]):.3f}")


if __name__ == "__main__":
    main(sys.argv[1:])
