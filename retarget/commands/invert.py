"""``retarget invert``: inverse rigging, mesh frame(s) -> 53 named FACS weights per frame."""
from __future__ import annotations

from ._common import (add_model_args, add_neutral_args, add_residuals_arg, add_smooth_arg,
                      check_neutral_args, check_residuals_arg, check_side_csv, estimated_neutral,
                      load_source_neutral, print_neutral_hint, print_notes, retargeter,
                      write_head_poses, write_residuals)

HELP = "inverse rigging: FRAMES (a mesh, folder or glob) -> a CSV of 53 named weights per frame"
EXAMPLE = """retarget invert "capture/*.obj" -o weights.csv
retarget invert capture/ -o weights_arkit.csv --names arkit --smooth one_euro
retarget invert capture/ -o weights.csv --source-neutral actor_neutral.obj --refine
retarget invert capture/ -o weights.csv --estimate-neutral --refine
retarget invert capture/ -o weights.csv --source-neutral actor_neutral.obj --refine --residuals fit.csv
retarget invert capture/ -o weights.csv --source-neutral actor_neutral.obj --refine --head-poses head.csv"""


def add_arguments(p):
    p.add_argument("frames", help="a mesh, a folder of frames, or a glob (quote it)")
    p.add_argument("-o", "--out", required=True, help="output CSV (one row per frame)")
    p.add_argument("--names", choices=("ict", "arkit"), default="ict", help="column names")
    add_residuals_arg(p, "the weights")
    p.add_argument("--head-poses", metavar="CSV",
                   help="also write each frame's head motion against the source neutral (or the "
                        "first frame): a unit quaternion qw qx qy qz and a translation tx ty tz "
                        "in the frames' units, frame = neutral rotated, then moved")
    add_neutral_args(p)
    add_smooth_arg(p)
    add_model_args(p, target=False)


def run(args) -> int:
    from ..io import check_output, load_sequence, sequence_files
    from ..weights_io import write_weights_csv

    check_neutral_args(args)
    inputs = sequence_files(args.frames)
    if args.source_neutral:
        inputs.append(args.source_neutral)
    check_output(args.out, inputs, formats=(".csv",))
    check_residuals_arg(args, inputs)
    if args.head_poses:
        check_side_csv(args.head_poses, "--head-poses", args, inputs, [("--residuals", args.residuals)])
    frames = load_sequence(args.frames, up=args.up, forward=args.forward, force=args.force)
    neutral = load_source_neutral(args, frames)
    print_neutral_hint(args)
    r = retargeter(args)
    neutral = estimated_neutral(args, r, frames, neutral)
    w = r.invert(frames, neutral, smooth=args.smooth, fps=args.fps, progress=True, refine=args.refine)
    print_notes(r, frames=frames, neutral=neutral, source_name=args.source_neutral or args.frames)
    write_weights_csv(args.out, w.reshape(len(frames), -1), names=args.names, fps=args.fps)
    print(f"wrote {len(frames)} frame(s) of 53 weights to {args.out}")
    if args.residuals:
        write_residuals(args.residuals, *r.fit_residuals(frames, neutral, w.reshape(len(frames), -1)))
    if args.head_poses:
        write_head_poses(args.head_poses, r.stabilise_frames(frames, neutral or frames[0])[1], args.fps)
    return 0
