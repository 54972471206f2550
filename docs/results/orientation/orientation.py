"""How straight a head must face the camera: the bundled model on the artist's ARKit rig
(``makehuman_arkit.npz``) turned about x (pitch: + looks down) or y (yaw: + turns to its left,
+x) before it is given to the network (docs/RESULTS.md, "Heads that do not face +z").

Everything is turned alike (the neutral, the frames, the target): without ``Retargeter``'s
uprighting (--no-upright) the network sees a head that is not upright in the +y up, +z forward
frame it was trained on (training turns heads by at most ``augment.rotate_deg`` = 3°). Per angle: self-retargeting (frame -> the same turned neutral) MSE in
mm² without the neutral, with it, and with refine; invert's weight MAE with the neutral and refine
(ARKit weights, as the eval's real_rig suite); doing nothing (MSE of the neutral, MAE of predicting
0); and where the face frame puts the face point (the nose tip) against the true nose tip, the
front-most vertex of the upright neutral, in mm. Then cross-identity: the upright ARKit head's
frames, with its neutral and refine, onto a MakeHuman test head turned (its rig carrying the same
weights is the exact GT), beside doing nothing and closest-point displacement transfer (turned
upright too, unless --no-upright). Closest point is exact on self-retargeting, so it has no row
there.

    OMP_NUM_THREADS=1 python docs/results/orientation/orientation.py --no-upright --out docs/results/orientation/no_upright.md
    OMP_NUM_THREADS=1 python docs/results/orientation/orientation.py --out docs/results/orientation/upright.md
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ANGLES = (-20, -15, -10, -5, 0, 5, 10, 15, 20)


def turn(points: np.ndarray, axis: str, degrees: float, centre: np.ndarray) -> np.ndarray:
    """points (..., 3) turned about the ``axis`` ("x": pitch, "y": yaw) line through ``centre``."""
    from retarget.canonical import turn_matrix

    rot = turn_matrix(degrees, 0.0) if axis == "x" else turn_matrix(0.0, degrees)
    return (np.asarray(points, np.float64) - centre) @ rot.T + centre


def mse_mm2(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean over frames and vertices of the squared distance, cm -> mm²."""
    return float(100.0 * np.square(pred - gt).sum(-1).mean())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default=None, help="default: the bundled model")
    ap.add_argument("--frames", type=int, default=12, help="frames of the eval's mixed sampler")
    ap.add_argument("--angles", type=float, nargs="+", default=ANGLES)
    ap.add_argument("--axes", nargs="+", default=["x", "y"], choices=["x", "y"])
    ap.add_argument("--no-upright", action="store_true", help="Retargeter(upright=False): the "
                    "meshes are taken as they face")
    ap.add_argument("--out", type=Path, default=None, help="markdown table (also printed)")
    args = ap.parse_args(argv)

    from data_synth.sampling import sample_weights
    from retarget.api import Retargeter
    from retarget.canonical import Canonicaliser
    from retarget.evaluate import RealRig, arkit_ict_matrix, ict_to_arkit_weights
    from retarget.io import atomic_output
    from retarget.mesh import Mesh

    from data_synth.makehuman import (base_head_rig, build_head_rig, head_tessellation,
                                      sample_head_identity)
    from retarget.oracle import closest_point_transfer

    repo = Path(__file__).resolve().parents[3]
    rig = RealRig.load(repo / "data_synth/makehuman/data/makehuman_arkit.npz")
    m = arkit_ict_matrix(rig.names)
    used = m.sum(1) > 0
    w_ict = sample_weights(np.random.default_rng(0), args.frames, mode="mixed").astype(np.float32)
    a = ict_to_arkit_weights(w_ict, m).astype(np.float32)
    frames0 = rig.evaluate(a).astype(np.float64)                          # (T,V,3) cm
    neutral0 = rig.neutral.astype(np.float64)
    centre = 0.5 * (neutral0.min(0) + neutral0.max(0))
    nose = int(np.argmax(neutral0[:, 2]))
    other = build_head_rig(base_head_rig(sample_head_identity(0, "test"), "arkit"), head_tessellation(
        seed=0, n_vertices=5000, kind="decimated", crop="head_neck"), 6)   # the cross-identity target
    other_gt0 = other.evaluate(a @ m).astype(np.float64)                    # the same ICT weights
    other_centre = 0.5 * (other.neutral.min(0) + other.neutral.max(0))
    source = Mesh(neutral0, rig.faces, "source neutral")
    source_frames = [Mesh(f, rig.faces, "frame") for f in frames0]
    r = Retargeter.load(args.checkpoint, upright=not args.no_upright)
    kind = r.cfg.canonical

    rows = []
    for axis in args.axes:
        for deg in args.angles:
            if axis == "y" and deg == 0 and "x" in args.axes:
                continue                                                  # the same head twice
            neutral_v = turn(neutral0, axis, deg, centre)
            frames_v = turn(frames0, axis, deg, centre)
            neutral = Mesh(neutral_v, rig.faces, "neutral")
            frames = [Mesh(f, rig.faces, "frame") for f in frames_v]
            canon = Canonicaliser.fit(neutral_v, kind=kind, faces=rig.faces)
            point = canon.from_canonical(np.zeros(3) + (0 if kind == "bbox" else 1) *
                                         np.array([0.0, 1.1, 10.3]))
            target = r.prepare(neutral)
            r.clear_source_cache()            # each angle is another performer of one topology
            row = {"axis": axis, "deg": deg,
                   "point_mm": float(10 * np.linalg.norm(point - neutral_v[nose])),
                   "nothing": mse_mm2(neutral_v[None], frames_v)}
            for mode, kw in (("none", {}), ("neutral", {"source_neutral": neutral}),
                             ("refine", {"source_neutral": neutral, "refine": True})):
                row[mode] = mse_mm2(r.transfer(frames, target, **kw), frames_v)
            other_v = turn(other.neutral, axis, deg, centre=other_centre)   # the target turned,
            other_gt = turn(other_gt0, axis, deg, centre=other_centre)      # the source upright
            row["cross_nothing"] = mse_mm2(other_v[None], other_gt)
            row["cross_closest"] = mse_mm2(closest_point_transfer(
                neutral0, rig.faces, frames0, other_v, other.faces, upright=not args.no_upright), other_gt)
            row["cross_refine"] = mse_mm2(r.transfer(source_frames, Mesh(other_v, other.faces, "target"),
                                                     source_neutral=source, refine=True), other_gt)
            w = r.invert(frames, source_neutral=neutral, refine=True)
            row["mae"] = float(np.abs(ict_to_arkit_weights(w, m) - a)[:, used].mean())
            row["mae0"] = float(np.abs(a)[:, used].mean())
            rows.append(row)
            print(row, flush=True)

    lines = ["| turn | face point from the nose tip (mm) | do nothing | no neutral | neutral | "
             "neutral + refine | invert MAE (neutral + refine) | predicting 0 |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for row in rows:
        name = f"{'pitch' if row['axis'] == 'x' else 'yaw'} {row['deg']:+g}°"
        lines.append(f"| {name} | {row['point_mm']:.1f} | {row['nothing']:.4g} | {row['none']:.4g} | "
                     f"{row['neutral']:.4g} | {row['refine']:.4g} | {row['mae']:.4f} | {row['mae0']:.4f} |")
    lines += ["", "Cross-identity: the upright ARKit head's frames (with its neutral) onto test head 0 "
              "(head and neck, 5,000 vertices, the artist's shapes carried over) turned; exact GT.", "",
              "| target turn | do nothing | closest point | neutral + refine |", "| --- | ---: | ---: | ---: |"]
    for row in rows:
        name = f"{'pitch' if row['axis'] == 'x' else 'yaw'} {row['deg']:+g}°"
        lines.append(f"| {name} | {row['cross_nothing']:.4g} | {row['cross_closest']:.4g} | "
                     f"{row['cross_refine']:.4g} |")
    table = "\n".join(lines) + "\n"
    print(table)
    if args.out:
        with atomic_output(args.out) as tmp:
            Path(tmp).write_text(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
