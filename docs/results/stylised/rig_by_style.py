"""How far off the bundled model's rig is on stylised heads against the others (docs/RESULTS.md,
"Stylised heads").

For each test identity (``sample_head_identity(seed, "test")``; ``--split val`` for validation
identities, ``--checkpoint`` for another model than the bundled one: 15 % are drawn stylised, every
range of their macros and modifiers widened 2.5 times), the head with its neck (decimated, 2,000
vertices, the artist's ARKit shapes carried by deformation transfer) is baked by the bundled model
on its own neutral (``Retargeter.source_rig``) and the median over the 53 shapes of
|B̂_k − B_k| / |B_k| is taken; also invert's weight MAE with the neutral and refine on 12 frames of
random weights (eval's mixed sampler, seeded by the identity), beside predicting 0. Per-seed lines (``--out``, JSON)
and a markdown summary (``--summary`` over one or more of those files):

    python docs/results/stylised/rig_by_style.py --seeds 0 40 --out runs/stylised/a.json
    python docs/results/stylised/rig_by_style.py --summary runs/stylised/a.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from data_synth.makehuman import base_head_rig, build_head_rig, head_tessellation, sample_head_identity
from data_synth.sampling import sample_weights
from retarget.metrics import standard_error

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "weight_mae"))
from breakdown import baked_and_true  # noqa: E402


def head_case(seed: int, split: str):
    """Identity ``seed`` of ``split``: (its HeadIdentity, its rig on the head with neck (decimated,
    2,000 vertices, the artist's ARKit shapes), the neutral as a Mesh, 12 weight rows (12, 53) of
    the eval's mixed sampler seeded by the identity (0 on shapes the rig lacks), their frames)."""
    from retarget.mesh import Mesh

    ident = sample_head_identity(seed, split)
    rig = build_head_rig(base_head_rig(ident, "arkit"), head_tessellation(
        seed=seed, n_vertices=2000, kind="decimated", crop="head_neck"), 6)
    w = sample_weights(np.random.default_rng([seed, 77]), 12, mode="mixed").astype(np.float32)
    w[:, ~rig.deltas.any(axis=(1, 2))] = 0.0               # shapes the rig lacks
    return ident, rig, Mesh(rig.neutral, rig.faces), w, [Mesh(f, rig.faces) for f in rig.evaluate(w)]


def measure(seeds, split: str = "test", checkpoint: str | None = None) -> list[dict]:
    from retarget.api import Retargeter

    r = Retargeter.load(checkpoint)
    out = []
    for s in seeds:
        ident, rig, neutral, w, frames = head_case(s, split)
        baked, true, norm = baked_and_true(r, rig)
        rel = np.linalg.norm(baked - true, axis=1) / norm
        inv = r.invert(frames, source_neutral=neutral, refine=True)
        out.append({"seed": s, "stylised": ident.stylised, "rig_median_rel": float(np.median(rel)),
                    "weight_mae": float(np.abs(inv - w).mean()), "predict_0_mae": float(np.abs(w).mean())})
        print(json.dumps(out[-1]), flush=True)
    return out


def summary(rows: list[dict]) -> None:
    print("| heads | count | rig error: median | quartiles | max | weight MAE (neutral + refine): mean ± s.e. | predicting 0 |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, keep in (("regular", False), ("stylised", True)):
        sel = [r_ for r_ in rows if r_["stylised"] == keep]
        if not sel:
            continue
        e = np.array([r_["rig_median_rel"] for r_ in sel])
        m = np.array([r_["weight_mae"] for r_ in sel])
        se = standard_error(m)
        q1, q3 = np.percentile(e, [25, 75])
        print(f"| {name} | {len(sel)} | {np.median(e):.3f} | {q1:.3f}–{q3:.3f} | {e.max():.3f} | "
              f"{m.mean():.4f} ± {float('nan') if se is None else se:.4f} | "
              f"{np.mean([r_['predict_0_mae'] for r_ in sel]):.4f} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs=2, metavar=("FIRST", "END"), help="seeds FIRST..END-1")
    ap.add_argument("--split", default="test", help="test (default) or val (choosing models)")
    ap.add_argument("--checkpoint", help="default: the bundled model")
    ap.add_argument("--out", help="JSON of the per-seed figures")
    ap.add_argument("--summary", nargs="+", help="JSON files of --out to summarise")
    args = ap.parse_args()
    if args.summary:
        rows = [r_ for p in args.summary for r_ in json.load(open(p))]
        return summary(rows)
    rows = measure(range(*args.seeds), args.split, args.checkpoint)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
