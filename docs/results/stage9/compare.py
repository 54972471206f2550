"""Side by side: the segment-averaged MSE (mm²; inverse suites: of the weights re-applied to the
rig, and their MAE; the ARKit rig's plain MSE, kept apart from the means) of several checkpoints in every suite and neutral mode of one eval.json (e.g.
``retarget eval --merge`` of runs on configs/eval/validation.yaml), each as a ratio to a reference
checkpoint, with the geometric mean of the ratios per mode and over all (the validation suites only).

    python docs/results/stage9/compare.py EVAL_JSON REFERENCE [CHECKPOINT ...]
"""
import json
import sys

import numpy as np

MODES = ("no neutral", "neutral", "neutral + refine")


def figures(suites: dict, name: str, mode: str) -> dict:
    """{suite: seg MSE} (and {suite + " MAE": weight MAE}) of method ``name (mode)``."""
    out = {}
    for suite, res in suites.items():
        m = res.get("methods", {}).get(f"{name} ({mode})")
        if suite == "real_rig" and m:   # the one artist rig: the test eval's too
            e = m["sampled"]
            out["ARKit rig (test) real->real"] = e["real_to_real"]["mse_mm2"]
            out["ARKit rig (test) invert"] = e["invert"]["rig_mse_mm2"]
            out["ARKit rig (test) invert MAE"] = e["invert"]["weight_mae"]
            continue
        if not m or "seg_mse_mm2" not in m:
            continue
        out[suite] = m["seg_mse_mm2"]
        if "weight_mae" in m:
            out[suite + " MAE"] = m["weight_mae"]
    return out


def main(path: str, reference: str, names: list[str]) -> None:
    suites = json.loads(open(path).read())["suites"]
    names = names or sorted({m.rsplit(" (", 1)[0] for s in suites.values() for m in s["methods"]
                             if m.endswith(")") and m.rsplit(" (", 1)[0] != reference})
    print("| suite | mode | " + reference + " | " + " | ".join(names) + " |")
    print("| --- | --- | ---: | " + " | ".join("---:" for _ in names) + " |")
    logs = {n: {m: [] for m in MODES} for n in names}
    for mode in MODES:
        ref = figures(suites, reference, mode)
        others = {n: figures(suites, n, mode) for n in names}
        for key, value in ref.items():
            cells = []
            for n in names:
                v = others[n].get(key)
                if v is None:
                    cells.append("—")
                    continue
                if not key.startswith("ARKit"):
                    logs[n][mode].append(np.log(v / value))
                cells.append(f"{v:.4g} ({v / value:.3f})")
            print(f"| {key} | {mode} | {value:.4g} | " + " | ".join(cells) + " |")
    for mode in MODES:
        print(f"| geometric mean of the ratios | {mode} | 1 | "
              + " | ".join(f"{np.exp(np.mean(logs[n][mode])):.3f}" if logs[n][mode] else "—"
                           for n in names) + " |")
    print("| geometric mean of the ratios | all | 1 | "
          + " | ".join(f"{np.exp(np.mean(sum(logs[n].values(), []))):.3f}" for n in names) + " |")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3:])
