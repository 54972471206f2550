"""What a face frame that misses the nose tip costs (docs/RESULTS.md, "The face frame's nose tip").

The face frame takes the front-most point of the head window for the nose tip. On a head whose
lips, chin or brow lie further forward than its nose, or whose nose lies below the window, it
takes that instead, and the network sees the face shifted by centimetres. For each validation
identity (``sample_head_identity(seed, "val")``; head and neck, decimated, 2,000 vertices, the
artist's ARKit shapes: ``docs/results/stylised/rig_by_style.py``'s cases) this measures, with the
bundled model (taken as it faces, ``upright=False``), the baked shapes' median relative error and
invert's weight MAE with the neutral and refine, twice: with the frame as fitted, and with the
frame given the true nose tip (``fit_face_frame(nose=)``: the front-most point within 3 % of the
window's depth of the MakeHuman base head's nose-tip vertex, moved with the identity), an oracle
no user mesh has. Also how far each frame's nose tip lies from the true one (face widths).

    OMP_NUM_THREADS=1 python docs/results/face_frame/nose_tip.py --seeds 0 150 --out docs/results/face_frame/nose_tip_fitted.json
    OMP_NUM_THREADS=1 python docs/results/face_frame/nose_tip.py --seeds 0 150 --oracle --out docs/results/face_frame/nose_tip_oracle.json
    python docs/results/face_frame/nose_tip.py --summary docs/results/face_frame/nose_tip_fitted.json docs/results/face_frame/nose_tip_oracle.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from data_synth.makehuman import head_neutral
from retarget import canonical

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "stylised"), str(ROOT / "weight_mae"), str(ROOT / "face_frame")]
from breakdown import baked_and_true  # noqa: E402
from nose_finder import nose_tip_vertex  # noqa: E402
from rig_by_style import head_case  # noqa: E402


def measure(seeds, oracle: bool) -> list[dict]:
    from retarget.api import Retargeter

    fit = canonical.fit_face_frame
    hint = {}
    if oracle:
        canonical.fit_face_frame = lambda v, f: fit(v, f, nose=hint["tip"][:2])
    r = Retargeter.load(None, upright=False)
    tip_vertex = nose_tip_vertex()
    rows = []
    for s in seeds:
        ident, rig, neutral, w, frames = head_case(s, "val")
        hint["tip"] = head_neutral(ident, "bust")[tip_vertex]
        point, width = canonical.fit_face_frame(rig.neutral.astype(np.float64), rig.faces)
        baked, true, norm = baked_and_true(r, rig)
        inv = r.invert(frames, source_neutral=neutral, refine=True)
        rows.append({"seed": s, "stylised": bool(ident.stylised),
                     "tip_off": float(np.hypot(*(point[:2] - hint["tip"][:2])) / width),
                     "rig_median_rel": float(np.median(np.linalg.norm(baked - true, axis=1) / norm)),
                     "weight_mae": float(np.abs(inv - w).mean()), "predict_0_mae": float(np.abs(w).mean())})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def summary(fitted: list[dict], oracle: list[dict], names=("frame as fitted", "true nose tip")) -> None:
    """Tables of two runs' files (``names``: what each run's frame was)."""
    o = {r["seed"]: r for r in oracle}
    print(f"| heads | count | frame's tip > 0.05 face widths off (first) | weight MAE: {names[0]} | "
          f"{names[1]} | predicting 0 | rig error (median): {names[0]} / {names[1]} |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, keep in (("regular", False), ("stylised", True), ("all", None)):
        sel = [r for r in fitted if keep is None or r["stylised"] == keep]
        a = np.array([r["weight_mae"] for r in sel])
        b = np.array([o[r["seed"]]["weight_mae"] for r in sel])
        print(f"| {name} | {len(sel)} | {sum(r['tip_off'] > 0.05 for r in sel)} | {a.mean():.4f} | "
              f"{b.mean():.4f} | {np.mean([r['predict_0_mae'] for r in sel]):.4f} | "
              f"{np.median([r['rig_median_rel'] for r in sel]):.3f} / "
              f"{np.median([o[r['seed']]['rig_median_rel'] for r in sel]):.3f} |")
    print()
    print(f"| head | stylised | frame's tip off (face widths, first) | weight MAE: {names[0]} → {names[1]} | "
          f"rig error: {names[0]} → {names[1]} |")
    print("| ---: | --- | ---: | ---: | ---: |")
    for r in fitted:
        q = o[r["seed"]]
        if r["tip_off"] > 0.05 or abs(r["weight_mae"] - q["weight_mae"]) > 1e-9:
            print(f"| {r['seed']} | {'yes' if r['stylised'] else 'no'} | {r['tip_off']:.2f} | "
                  f"{r['weight_mae']:.4f} → {q['weight_mae']:.4f} | "
                  f"{r['rig_median_rel']:.3f} → {q['rig_median_rel']:.3f} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs=2, metavar=("FIRST", "END"))
    ap.add_argument("--oracle", action="store_true", help="give the frame the true nose tip")
    ap.add_argument("--out", help="JSON of the per-seed figures")
    ap.add_argument("--summary", nargs=2, metavar=("FITTED", "ORACLE"))
    ap.add_argument("--names", nargs=2, default=("frame as fitted", "true nose tip"),
                    help="what the two summarised runs' frames were")
    args = ap.parse_args()
    if args.summary:
        return summary(*(json.load(open(p)) for p in args.summary), names=args.names)
    rows = measure(range(*args.seeds), args.oracle)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
