"""Inverse rigging's weights with code maps predicted per head (``fit.py``'s linear maps in z_ID),
against the checkpoint's own map (study, issue 10).

Fits m_k(z) = A_k φ̃(z) on the cached training heads (``cache.py``) for each (d, ridge) asked, puts
it in place of the checkpoint's map (``Retargeter.code_map_per_head``: every head's map from its
own z_ID, no gate), and runs
invert's fit with refine on the inversion cases of ``--config`` (``breakdown.py``), printing the
weight MAE by kind of row and the baked shapes' median relative error per suite.

    OMP_NUM_THREADS=1 python docs/results/code_map/head_maps/mae.py --train runs/head_maps/*_train.npz --models 0:0.01 8:0.01
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parents[1] / "weight_mae"))
from breakdown import by_kind, inversion_rows, shape_errors  # noqa: E402
from fit import fit_map, load  # noqa: E402

from retarget.api import Retargeter  # noqa: E402
from retarget.evaluate import EvalData, NetworkMethod, load_eval_config  # noqa: E402


def report(name, r, data, cfg, results):
    shapes = shape_errors(r, data)
    tables = {s: by_kind(rows) for s, rows in inversion_rows(NetworkMethod(name, r, "refine"), data, cfg).items()}
    results[name] = {"shape_errors": shapes, "inversion": tables}
    for s, t in tables.items():
        print(f"| {name} | {s} | {shapes[s]['median']:.3f} | "
              + " / ".join(f"{t[k]['weight_mae']:.4f}" for k in ("uniform", "onehot", "sparse", "all") if k in t)
              + f" | {t['all']['predict_0_mae']:.4f} | {t['all']['rig_mse_mm2']:.4g} |", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    ap.add_argument("--config", default="docs/results/weight_mae/validation_large.yaml")
    ap.add_argument("--train", nargs="+", required=True)
    ap.add_argument("--models", nargs="*", default=[], help="d:ridge of each map to try")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    cfg = load_eval_config(args.config)
    data = EvalData(cfg)
    train = load(args.train)
    r = Retargeter.load(args.checkpoint)
    results: dict = {}
    print("| map | suite | shapes (median relative error) | weight MAE uniform / onehot / sparse / all | predicting 0 | rig MSE (mm²) |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    report("bundled (gated map)", r, data, cfg, results)
    for spec in args.models:
        d, ridge = spec.split(":")
        m0, per_head = fit_map(train, int(d), float(ridge))
        r.code_map, r.code_map_gate, r.code_map_per_head = m0, None, per_head
        report(f"per head, d = {d}, ridge {ridge}", r, data, cfg, results)
        if args.out:
            Path(args.out).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
