"""Invert's fit weighed by the rig's expected error, offline (docs/RESULTS.md, "Invert's fit weighed
by the rig's expected error"): on the inversion cases of docs/results/weight_mae/rig_span/cases.py,
each case's rig gets the metric of ``retarget.code_map.code_metric`` from the checkpoint's error
moments (``code_map_error``, each head's by its gate probability) and ρ, and the bundled fit
(``Retargeter.REFINE_INVERT_FITS[True]``) runs on it through ``SourceRig.fit``. Prints one markdown
row per ρ ("plain": no metric) of the weight MAE per suite (uniform rows in brackets), after a
line with the moments' traces; with ``--swap`` the MakeHuman and procedural moments are given to
the wrong heads (a control); with ``--against`` another checkpoint, how far its code map and gate
are from this one's (the largest difference of an entry).

    python docs/results/weight_mae/metric/sweep.py --checkpoint retarget/checkpoints/default.pt runs/decstudy/s23_10{0,1,2,3,4}.npz
    python docs/results/weight_mae/metric/sweep.py --checkpoint retarget/checkpoints/default.pt runs/decstudy/val_s23.npz --rho plain 10 5 3
    git show d86a049~1:retarget/checkpoints/default.pt > runs/stage23.pt
    python docs/results/weight_mae/metric/sweep.py --checkpoint retarget/checkpoints/default.pt --against runs/stage23.pt
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "rig_span"))
from cases import SUITES, load, row_kinds, weight_mae  # noqa: E402


def weighed_fit(case: dict, sigma: np.ndarray | None, rho: float | None) -> np.ndarray:
    """Invert's bundled fit of every frame of ``case`` on its baked rig A, weighed by the metric of
    error moment ``sigma`` (dims, dims) and ``rho`` (None: plain) -> weights (T, 53)."""
    from retarget.api import Retargeter, SourceRig, _gram
    from retarget.code_map import code_metric

    a = np.ascontiguousarray(case["A"], np.float32)
    rig = SourceRig(None, SimpleNamespace(neutral=np.asarray(case["neutral"], np.float32)), a, _gram(a))
    if rho is not None:
        rig.fit_basis, rig.fit_gram = code_metric(case["X"], a, sigma, rho)
    fit = Retargeter.REFINE_INVERT_FITS[True]
    return np.array([rig.fit(frame, np.clip(w0, 0.0, 1.0), *fit)
                     for frame, w0 in zip(case["frames"], case["w0"])])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*")
    ap.add_argument("--checkpoint", required=True, help="the model the cases were dumped with")
    ap.add_argument("--rho", nargs="*", default=["plain", "100", "10", "5", "3", "1", "0.3"])
    ap.add_argument("--swap", action="store_true", help="each head the other kind's moment")
    ap.add_argument("--against", help="another checkpoint whose code map and gate to compare")
    args = ap.parse_args()
    from retarget.checkpoint import checkpoint_code_map, load_checkpoint
    from retarget.code_map import head_map_error

    code_map, gate, _, error = checkpoint_code_map(load_checkpoint(args.checkpoint))
    if error is None:
        raise SystemExit(f"{args.checkpoint}: no code_map_error")
    print(f"<!-- traces of the moments: {', '.join(f'{np.trace(e):.3f}' for e in error)} -->")
    if args.against:
        other_map, other_gate, _, _ = checkpoint_code_map(load_checkpoint(args.against))
        print(f"<!-- against {args.against}: code map {np.abs(code_map - other_map).max():.2e}, "
              f"gate {np.abs(gate - other_gate).max():.2e} -->")
    if args.swap:
        error = error[::-1]
    if not args.cases:
        return
    cases = load(*args.cases)
    sigmas = [head_map_error(error, gate, c["z_id"]) for c in cases]
    print("| ρ | " + " | ".join(SUITES) + " |\n| --- |" + " ---: |" * len(SUITES))
    for rho in args.rho:
        value = None if rho == "plain" else float(rho)
        cells = []
        for suite in SUITES:
            errs, kinds = [], []
            for c, sigma in zip(cases, sigmas):
                if str(c["suite"]) == suite:
                    errs.append(weight_mae(c, weighed_fit(c, sigma, value)))
                    kinds.append(row_kinds(c))
            e, k = np.concatenate(errs), np.concatenate(kinds)
            cells.append(f"{e.mean():.4f} ({e[k == 'uniform'].mean():.3f})")
        print(f"| {rho} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
