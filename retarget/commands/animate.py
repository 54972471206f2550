"""``retarget animate``: drive a target mesh from FACS weights, without building a rig."""
from __future__ import annotations

from ._common import (add_model_args, output_paths, print_notes, read_weights_file, retargeter,
                      write_frames)
from .export_rig import add_usd_arg, check_usd_output, write_rig

HELP = "drive the neutral TGT from FACS weights (ICT/ARKit CSV, Live Link Face CSV, JSON)"
EXAMPLE = """retarget animate character_neutral.obj --weights take01_livelink.csv -o take01.glb
retarget animate character_neutral.obj --weights smile.json -o smile.obj
retarget animate scan.ply --weights weights.csv -o frames/ --baked --clamp
retarget animate character_neutral.obj --weights take01_livelink.csv -o take01.usdc  # UsdSkel rig + take"""


def add_arguments(p):
    p.add_argument("target", help="target neutral mesh (any topology)")
    p.add_argument("--weights", required=True, help="weights: .csv (ICT/ARKit names or Live Link Face) or .json")
    p.add_argument("-o", "--out", required=True,
                   help="output .obj/.ply (one frame), .glb, a folder, or .usd/.usda/.usdc: the baked "
                        "rig (as --baked) with the weights as a UsdSkel animation")
    p.add_argument("--clamp", action="store_true", help="clip weights to [0, 1] instead of warning")
    p.add_argument("--baked", action="store_true",
                   help="decode the 53 shapes once and blend them linearly (fast, approximate)")
    p.add_argument("--format", choices=("obj", "ply"), default="obj", help="frame files in a folder")
    add_usd_arg(p)
    add_model_args(p)


def run(args) -> int:
    from ..io import load_mesh
    from ..usd import is_usd_path

    inputs, usd = [args.target, args.weights], is_usd_path(args.out)
    if usd:
        check_usd_output(args, inputs)
    track = read_weights_file(args.weights, args.clamp)
    if not usd:
        output_paths(args.out, len(track.weights), inputs, args.format)
    target = load_mesh(args.target, up=args.up, forward=args.forward, force=args.force)
    if not usd:   # the size of the take, before any work
        output_paths(args.out, len(track.weights), inputs, args.format, target.n_vertices,
                     len(target.faces), args.force)
    r = retargeter(args)
    tgt = r.prepare(target)
    print_notes(r, tgt, args.target)

    n = len(track.weights)
    if usd:
        names, _ = write_rig(args.out, r.bake(tgt), target.faces, track, args)
        print(f"wrote {args.out}: {len(names)} blend shapes on {target.n_vertices} vertices, {n} animated "
              f"frame(s)")
        return 0
    verts = (r.bake(tgt).evaluate(track.weights) if args.baked
             else r.iter_animate(tgt, track.weights, progress=True))
    written = write_frames(args.out, verts, target.faces, inputs, args, fps=track.fps or 30.0,
                           n_frames=n)
    print(f"wrote {n} frame(s) to {written[0] if len(written) == 1 else args.out}")
    return 0
