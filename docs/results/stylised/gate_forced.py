"""Is the code map's gate what fails the stylised heads? (docs/RESULTS.md, "Stylised heads").

The bundled model gives each head its code map as far as the gate on its identity code calls it
MakeHuman-like (``retarget.code_map``); some stylised heads get p well under 1. For each stylised
identity of the split (seeds ``--seeds A B``; rig_by_style.head_case: head with neck, 2,000
vertices, the artist's ARKit shapes), the baked rig's median relative error and invert's weight
MAE (neutral + refine, 12 frames of the eval's mixed sampler) with the gate as bundled and with
p forced to 1 (the MakeHuman map on every head), beside predicting 0:

    python docs/results/stylised/gate_forced.py --split val --seeds 0 150 > docs/results/stylised/gate_forced_val.md
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from data_synth.makehuman import sample_head_identity
from retarget.api import Retargeter
from retarget.code_map import gate_probability
from retarget.metrics import standard_error

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "weight_mae"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from breakdown import baked_and_true  # noqa: E402
from rig_by_style import head_case  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", default="val")
    ap.add_argument("--seeds", type=int, nargs=2, default=(0, 150))
    args = ap.parse_args()
    r = Retargeter.load()
    gates = {"bundled gate": r.code_map_gate.copy(),
             "p = 1": np.r_[np.zeros(len(r.code_map_gate) - 1), 60.0].astype(np.float32)}
    print("| seed | gate p | rig error: bundled gate | p = 1 | weight MAE: bundled gate | p = 1 | predicting 0 |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    rows = []
    for s in range(*args.seeds):
        if not sample_head_identity(s, args.split).stylised:
            continue
        _, rig, neutral, w, frames = head_case(s, args.split)
        row = [gate_probability(gates["bundled gate"], r.prepare(neutral).codes.z_id.numpy())]
        for gate in gates.values():
            r.code_map_gate = gate                               # drops the rigs baked so far
            baked, true, norm = baked_and_true(r, rig)
            row += [float(np.median(np.linalg.norm(baked - true, axis=1) / norm)),
                    float(np.abs(r.invert(frames, source_neutral=neutral, refine=True) - w).mean())]
        p, rig_g, mae_g, rig_1, mae_1 = row
        rows.append((p, rig_g, rig_1, mae_g, mae_1, float(np.abs(w).mean())))
        print(f"| {s} | {p:.3f} | {rig_g:.3f} | {rig_1:.3f} | {mae_g:.4f} | {mae_1:.4f} | {rows[-1][-1]:.4f} |",
              flush=True)
    a = np.array(rows)
    for name, sel in (("all stylised", np.ones(len(a), bool)), ("gate p < 0.95", a[:, 0] < 0.95)):
        m = a[sel]
        if not len(m):
            continue
        se = [float("nan") if e is None else e for e in (standard_error(m[:, 3]), standard_error(m[:, 4]))]
        print(f"| {name} ({len(m)}) | | median {np.median(m[:, 1]):.3f} | {np.median(m[:, 2]):.3f} | "
              f"{m[:, 3].mean():.4f} ± {se[0]:.4f} | "
              f"{m[:, 4].mean():.4f} ± {se[1]:.4f} | {m[:, 5].mean():.4f} |")


if __name__ == "__main__":
    main()
