"""Two models head by head on rig_by_style.py's per-seed files (docs/RESULTS.md, "L_rig on the
shapes as authored"): for the regular and the stylised heads, the geometric mean over heads of
model A's rig error and weight MAE over model B's, the standard error of the mean log ratio, and
on how many heads A is lower.

    python docs/results/authored_targets/paired.py A=a.json B=b1.json,b2.json [C=...]   # every pair against the last
"""
from __future__ import annotations

import json
import sys

import numpy as np

from retarget.metrics import standard_error


def load(spec: str) -> tuple[str, dict]:
    name, files = spec.split("=", 1)
    return name, {r["seed"]: r for f in files.split(",") for r in json.load(open(f))}


def main(argv: list[str]) -> None:
    models = [load(s) for s in argv]
    ref_name, ref = models[-1]
    print(f"| A ÷ {ref_name} | heads | rig error: geometric mean ratio ± s.e. (A lower on) | "
          "weight MAE: geometric mean ratio ± s.e. (A lower on) |")
    print("| --- | --- | ---: | ---: |")
    for name, rows in models[:-1]:
        for label, stylised in (("regular", False), ("stylised", True)):
            seeds = [s for s in rows if s in ref and rows[s]["stylised"] == stylised]
            cells = []
            for key in ("rig_median_rel", "weight_mae"):
                lr = np.log([rows[s][key] / ref[s][key] for s in seeds])
                cells.append(f"{np.exp(lr.mean()):.3f} ± {standard_error(lr):.3f} ({int((lr < 0).sum())} of {len(lr)})")
            print(f"| {name} | {label} | {cells[0]} | {cells[1]} |")


if __name__ == "__main__":
    main(sys.argv[1:])
