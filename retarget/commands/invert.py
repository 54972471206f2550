"""``retarget invert``: inverse rigging, mesh frame(s) -> 53 named FACS weights per frame."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..errors import RetargetError
from ._common import (add_model_args, add_neutral_args, add_smooth_arg, check_neutral_args,
                      estimated_neutral, load_source_neutral, print_neutral_hint, retargeter)

HELP = "inverse rigging: FRAMES (a mesh, folder or glob) -> a CSV of 53 named weights per frame"
EXAMPLE = """retarget invert "capture/*.obj" -o weights.csv
retarget invert capture/ -o weights_arkit.csv --names arkit --smooth one_euro
retarget invert capture/ -o weights.csv --source-neutral actor_neutral.obj --refine
retarget invert capture/ -o weights.csv --estimate-neutral --refine
retarget invert capture/ -o weights.csv --source-neutral actor_neutral.obj --refine --residuals fit.csv"""


def add_arguments(p):
    p.add_argument("frames", help="a mesh, a folder of frames, or a glob (quote it)")
    p.add_argument("-o", "--out", required=True, help="output CSV (one row per frame)")
    p.add_argument("--names", choices=("ict", "arkit"), default="ict", help="column names")
    p.add_argument("--residuals", metavar="CSV",
                   help="also write how well the weights explain each frame on the source's rig "
                        "(RMS residual and motion in the frames' units, and their ratio, the share "
                        "left unexplained); needs --source-neutral or --estimate-neutral")
    add_neutral_args(p)
    add_smooth_arg(p)
    add_model_args(p)


def run(args) -> int:
    from ..io import check_output, load_sequence, sequence_files
    from ..weights_io import write_weights_csv

    check_neutral_args(args)
    if args.residuals and not (args.source_neutral or args.estimate_neutral):
        raise RetargetError("--residuals needs --source-neutral (the source's neutral mesh) or "
                            "--estimate-neutral: the residual is measured on the source's rig")
    inputs = sequence_files(args.frames)
    if args.source_neutral:
        inputs.append(args.source_neutral)
    check_output(args.out, inputs, formats=(".csv",))
    if args.residuals:
        check_output(args.residuals, inputs, formats=(".csv",))
        if Path(args.residuals).resolve() == Path(args.out).resolve():
            raise RetargetError(f"{args.residuals}: --residuals and -o name the same file; give "
                                "the residuals their own")
    frames = load_sequence(args.frames, up=args.up, forward=args.forward, force=args.force)
    neutral = load_source_neutral(args, frames)
    print_neutral_hint(args)
    r = retargeter(args)
    neutral = estimated_neutral(args, r, frames, neutral)
    w = r.invert(frames, neutral, smooth=args.smooth, fps=args.fps, progress=True, refine=args.refine)
    write_weights_csv(args.out, w.reshape(len(frames), -1), names=args.names, fps=args.fps)
    print(f"wrote {len(frames)} frame(s) of 53 weights to {args.out}")
    if args.residuals:
        residual, motion = r.fit_residuals(frames, neutral, w.reshape(len(frames), -1))
        share = write_residuals_csv(args.residuals, residual, motion)
        worst = np.argsort(-share)[:3]
        print(f"wrote the fit's residuals to {args.residuals}: median share unexplained "
              f"{np.median(share):.3f}; worst frames "
              + ", ".join(f"{i} ({share[i]:.3f})" for i in worst))
    return 0


def write_residuals_csv(path, residual: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """Write frame, residual_rms, motion_rms, unexplained (residual ÷ motion; 0 for a frame that
    does not move and is matched) as CSV, atomically -> the unexplained shares (T,)."""
    from ..io import atomic_output

    still = np.where(residual > 0, np.inf, 0.0)
    share = np.where(motion > 0, residual / np.maximum(motion, 1e-12), still)
    with atomic_output(path) as tmp, open(tmp, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["frame", "residual_rms", "motion_rms", "unexplained"])
        for t, row in enumerate(zip(residual, motion, share)):
            out.writerow([str(t)] + [f"{x:.6g}" for x in row])
    return share
