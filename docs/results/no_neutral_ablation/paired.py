"""Two methods of one eval.json compared case by case: is a suite's difference more than the
choice of cases moves it?

For every suite where both methods have each case's MSE (``case_mse_mm2``; the ARKit rig: each
frame's, ``frame_mse_mm2`` / ``frame_rig_mse_mm2``), the ratio B ÷ A of each case, their
geometric mean and its standard error (of the mean log ratio, shown as a factor), and the pooled
ratio of the suite's MSE for reference. A suite is marked when the geometric mean is more than two
standard errors from 1. Cases where either method's error is exactly 0 (e.g. the ARKit rig's
inversion of a frame fitted exactly) have no ratio and are left out of the geometric mean; the
cases column then says how many were kept. Markdown on stdout.

    python docs/results/no_neutral_ablation/paired.py EVAL_JSON "A (no neutral)" "B (no neutral)"
"""
from __future__ import annotations

import json
import sys

import numpy as np

from retarget.metrics import standard_error


def paired_rows(suites: dict, a: str, b: str) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(row name, A's per-case errors, B's) for every suite and ARKit part both methods have."""
    rows = []
    for suite, res in suites.items():
        ma, mb = res.get("methods", {}).get(a), res.get("methods", {}).get(b)
        if not ma or not mb:
            continue
        if suite == "real_rig":
            for part, key in (("real_to_real", "frame_mse_mm2"), ("invert", "frame_rig_mse_mm2")):
                ea, eb = ma["sampled"].get(part, {}).get(key), mb["sampled"].get(part, {}).get(key)
                if ea and eb:
                    rows.append((f"ARKit rig {part} (frames)", np.array(ea), np.array(eb)))
        elif "case_mse_mm2" in ma and "case_mse_mm2" in mb:
            rows.append((suite, np.array(ma["case_mse_mm2"]), np.array(mb["case_mse_mm2"])))
    return rows


def main(path: str, a: str, b: str) -> None:
    suites = json.loads(open(path).read())["suites"]
    rows = paired_rows(suites, a, b)
    if not rows:
        sys.exit(f"{path}: no suite has per-case errors of both {a!r} and {b!r}")
    print(f"| suite | cases | pooled MSE ratio | geometric mean of the case ratios × / ÷ s.e. | "
          f"cases worse |\n| --- | ---: | ---: | ---: | ---: |")
    print(f"<!-- ratios are {b} ÷ {a} -->")
    for name, ea, eb in rows:
        if len(ea) != len(eb):
            sys.exit(f"{path}: {name}: {len(ea)} cases of {a!r} against {len(eb)} of {b!r}")
        kept = (ea > 0) & (eb > 0)
        log = np.log(eb[kept] / ea[kept])
        se = standard_error(log)
        se = float("nan") if se is None else se
        cell = f"{np.exp(log.mean()):.3f} × / ÷ {np.exp(se):.3f}"
        if abs(log.mean()) > 2 * se:
            cell = f"**{cell}**"
        cases = f"{len(log)}" if kept.all() else f"{len(log)} of {len(ea)} (the rest 0)"
        print(f"| {name} | {cases} | {eb.mean() / ea.mean():.3f} | {cell} | "
              f"{int((log > 0).sum())} of {len(log)} |")


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(*sys.argv[1:])
