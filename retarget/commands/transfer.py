"""``retarget transfer``: clone the expression(s) of a source mesh or sequence onto a target."""
from __future__ import annotations

from ._common import (add_model_args, add_neutral_args, add_residuals_arg, add_smooth_arg,
                      check_neutral_args, check_residuals_arg, estimated_neutral,
                      load_source_neutral, output_paths, print_neutral_hint, print_notes, retargeter,
                      write_frames, write_residuals)

HELP = "clone expression(s) of SRC (a mesh, a folder or a glob of frames) onto the neutral TGT"
EXAMPLE = """retarget transfer actor/frame_0001.obj character_neutral.obj -o smile.obj
retarget transfer "capture/*.obj" character_neutral.obj -o out_frames/ --smooth savgol
retarget transfer capture/ character_neutral.obj -o performance.glb --source-neutral actor_neutral.obj
retarget transfer capture/ character_neutral.obj -o out/ --source-neutral actor_neutral.obj --refine
retarget transfer capture/ character_neutral.obj -o out/ --estimate-neutral --refine
retarget transfer capture/ character_neutral.obj -o out/ --source-neutral actor_neutral.obj --refine --residuals fit.csv
retarget transfer capture/ character_neutral.obj -o out/ --source-neutral actor_neutral.obj --refine --head-motion"""


def add_arguments(p):
    p.add_argument("source", help="source expression mesh, folder of frames, or glob (quote it)")
    p.add_argument("target", help="target neutral mesh (any topology)")
    p.add_argument("-o", "--out", required=True, help="output .obj/.ply (one frame), .glb, or a folder")
    add_neutral_args(p)
    add_residuals_arg(p, "the codes sent to the target")
    p.add_argument("--head-motion", action="store_true",
                   help="carry the source frames' head motion (turning, moving as a whole against "
                        "the source neutral, or the first frame) onto the target; by default it is "
                        "removed and the target shows the expression alone")
    p.add_argument("--format", choices=("obj", "ply"), default="obj", help="frame files in a folder")
    add_smooth_arg(p)
    add_model_args(p)


def run(args) -> int:
    from ..errors import RetargetError
    from ..io import load_mesh, load_sequence, sequence_files

    check_neutral_args(args)
    if args.head_motion and args.no_stabilise:
        raise RetargetError("--head-motion needs the head motion that stabilisation finds: drop "
                            "--no-stabilise")
    inputs = sequence_files(args.source) + [args.target]
    if args.source_neutral:
        inputs.append(args.source_neutral)
    frames = load_sequence(args.source, up=args.up, forward=args.forward, force=args.force)
    output_paths(args.out, len(frames), inputs, args.format)
    check_residuals_arg(args, inputs)
    target = load_mesh(args.target, up=args.up, forward=args.forward, force=args.force)
    output_paths(args.out, len(frames), inputs, args.format, target.n_vertices,   # the take's
                 len(target.faces), args.force)                                   # size, up front
    neutral = load_source_neutral(args, frames)
    print_neutral_hint(args)
    r = retargeter(args)
    neutral = estimated_neutral(args, r, frames, neutral)
    tgt = r.prepare(target)
    z, gaze = r.expression(frames, neutral, smooth=args.smooth, fps=args.fps, progress=True,
                           refine=args.refine)
    z = z.reshape(-1, z.shape[-1])
    print_notes(r, tgt, args.target, frames, neutral, args.source_neutral or args.source)
    results = r.iter_decode(tgt, z, progress=True, gaze=gaze.reshape(-1, 2, 2))
    if args.head_motion:
        results = r.carry_head_motion(frames, neutral, tgt, results)
    written = write_frames(args.out, results, target.faces, inputs, args, fps=args.fps, n_frames=len(z))
    print(f"wrote {len(frames)} frame(s) on {target.n_vertices} target vertices to "
          f"{written[0] if len(written) == 1 else args.out}")
    if args.residuals:
        write_residuals(args.residuals, *r.code_residuals(frames, neutral, z))
    return 0
