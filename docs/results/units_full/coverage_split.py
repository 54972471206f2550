"""Split the real-rig per-shape table of `retarget eval` into jawOpen, the other shapes a
MakeHuman expression unit maps to (data_synth.makehuman.expressions.UNIT_TO_ICT) and the shapes
without a unit: the errors of the artist's one-hot ARKit shapes, summed over each group, as a
ratio to doing nothing on the same shapes (jawOpen alone is 39 % of the do-nothing error).

    python docs/results/units_full/coverage_split.py EVAL.json [EVAL.json ...] > OUT.md
"""
import json
import sys

from data_synth.facs import arkit_to_ict
from data_synth.makehuman.expressions import UNIT_TO_ICT

KEYS = {"real_to_real.mse_mm2": "real → real", "invert.rig_mse_mm2": "inversion (rig MSE)",
        "animate.mse_mm2": "animate from true weights"}


def split(path: str) -> list[str]:
    units = {s for v in UNIT_TO_ICT.values() for s in v}
    rig = json.load(open(path))["suites"]["real_rig"]
    base = rig["methods"]["do nothing"]["per_shape"]
    rows = []
    for method, entry in rig["methods"].items():
        if method in ("do nothing", "closest point") or "per_shape" not in entry:
            continue
        shapes = entry["per_shape"]
        for key, label in KEYS.items():
            if key.startswith("animate") and not method.endswith("(no neutral)"):
                continue                        # the same in every neutral mode
            cells = []
            for group in ("jawOpen", "unit", "none"):
                names = [n for n in shapes if key in shapes[n] and group == (
                    "jawOpen" if n == "jawOpen" else "unit" if set(arkit_to_ict(n)) <= units else "none")]
                err = sum(shapes[n][key] for n in names)
                cells.append(f"{err / sum(base[n][key] for n in names):.2f}× ({len(names)})")
            rows.append(f"| {method} | {label} | {' | '.join(cells)} |")
    return rows


if __name__ == "__main__":
    print("| model | ARKit rig, one-hot shapes | jawOpen | other shapes with a unit | shapes without |")
    print("| --- | --- | ---: | ---: | ---: |")
    for p in sys.argv[1:]:
        print("\n".join(split(p)))
