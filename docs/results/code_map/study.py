"""The code map (``retarget.code_map``) on a checkpoint without one: fitted on training rigs, judged
on held-out inversion cases (issue 10).

Fits the map on ``--identities`` MakeHuman and as many procedural training heads (once; the
ridges share the normal equations), and for each ridge prints the baked shapes' median relative
error and inverse rigging's weight MAE with refine by kind of row (``breakdown.py``), beside the
checkpoint without a map and predicting 0, on the cases of ``--config`` (validation identities by
default). ``--save RIDGE`` writes a copy of the checkpoint holding the map of that ridge, for
``retarget eval``.

    OMP_NUM_THREADS=1 python docs/results/code_map/study.py --identities 24 --out docs/results/code_map/val_stage17.json --save 0.01 runs/code_map/stage17_map.pt
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "weight_mae"))
from breakdown import by_kind, inversion_rows, shape_errors  # noqa: E402

from retarget.api import Retargeter  # noqa: E402
from retarget.checkpoint import load_checkpoint, save_checkpoint  # noqa: E402
from retarget.code_map import CodeMapFit, decoder_rows, training_rigs  # noqa: E402
from retarget.evaluate import EvalData, NetworkMethod, load_eval_config  # noqa: E402


def report(name: str, r: Retargeter, data: EvalData, cfg: dict, results: dict) -> None:
    shapes = shape_errors(r, data)
    tables = {s: by_kind(rows) for s, rows in inversion_rows(NetworkMethod(name, r, "refine"), data, cfg).items()}
    results[name] = {"shape_errors": shapes, "inversion": tables}
    if "predict 0" not in results:
        results["predict 0"] = {s: {k: v["predict_0_mae"] for k, v in t.items()} for s, t in tables.items()}
        print("| variant | suite | shapes (median relative error) | MAE uniform / onehot / sparse / all | rig MSE (mm²) all |")
        print("| --- | --- | ---: | ---: | ---: |")
        for s, t in results["predict 0"].items():
            print(f"| predict 0 | {s} | — | " + " / ".join(f"{t[k]:.4f}" for k in ("uniform", "onehot", "sparse", "all") if k in t)
                  + f" | {tables[s]['all']['predict_0_rig']:.4g} |")
    for s, t in tables.items():
        print(f"| {name} | {s} | {shapes[s]['median']:.3f} | "
              + " / ".join(f"{t[k]['weight_mae']:.4f}" for k in ("uniform", "onehot", "sparse", "all") if k in t)
              + f" | {t['all']['rig_mse_mm2']:.4g} |", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    ap.add_argument("--config", default="configs/eval/validation.yaml")
    ap.add_argument("--identities", type=int, default=24)
    ap.add_argument("--seed", type=int, default=0, help="first training identity seed")
    ap.add_argument("--ridges", type=float, nargs="+", default=[0.003, 0.01, 0.03])
    ap.add_argument("--kinds", nargs="+", default=["makehuman", "procedural"],
                    help="which training heads the map is fitted on")
    ap.add_argument("--save", nargs=2, metavar=("RIDGE", "PATH"), default=None)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()

    r = Retargeter.load(args.checkpoint)
    if r.code_map is not None:
        raise SystemExit(f"{args.checkpoint} holds a code map already")
    t0 = time.time()
    fit = CodeMapFit(r.cfg.code_dim)
    for _, rig in training_rigs(args.identities, args.seed, r.cfg.n_segments, tuple(args.kinds)):
        fit.add(decoder_rows(r, rig)[0], rig.deltas.reshape(len(rig.deltas), -1))
    print(f"normal equations of {args.identities} identities ({', '.join(args.kinds)}): "
          f"{time.time() - t0:.0f} s", flush=True)

    cfg = load_eval_config(args.config)
    data = EvalData(cfg)
    results: dict = {}
    report("no map", r, data, cfg, results)
    for ridge in args.ridges:
        r.code_map = fit.solve(ridge)
        report(f"map, ridge {ridge}", r, data, cfg, results)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps({"args": vars(args), "results": results}, indent=1))
    if args.save:
        state = load_checkpoint(args.checkpoint)
        state["code_map"] = torch.from_numpy(fit.solve(float(args.save[0])))
        Path(args.save[1]).parent.mkdir(parents=True, exist_ok=True)
        save_checkpoint(Path(args.save[1]), state)
        print(f"wrote {args.save[1]}")


if __name__ == "__main__":
    main()
