"""``retarget export-rig``: a 53-shape rig for any mesh (optionally animated), as glTF or UsdSkel."""
from __future__ import annotations

import sys

from ._common import add_model_args, print_notes, read_weights_file, retargeter, rotation

HELP = ("export a 53-shape blendshape rig (GLB morph targets or UsdSkel blend shapes, ICT names) for "
        "the neutral TGT")
EXAMPLE = """retarget export-rig character_neutral.obj -o character_rig.glb
retarget export-rig character_neutral.obj -o take01.glb --weights take01_livelink.csv --names arkit
retarget export-rig character_neutral.obj -o take01.usda --weights take01_livelink.csv  # UsdSkel"""


def add_arguments(p):
    p.add_argument("target", help="target neutral mesh (any topology)")
    p.add_argument("-o", "--out", required=True,
                   help="output .glb, or .usd/.usda/.usdc (UsdSkel; needs pip install 'retarget[usd]')")
    p.add_argument("--weights", help="optional weights file: adds a weight animation")
    p.add_argument("--clamp", action="store_true", help="clip weights to [0, 1] instead of warning")
    p.add_argument("--names", choices=("ict", "arkit"), default="ict",
                   help="morph target names (arkit: 52 ARKit shapes, the two halves of browInnerUp "
                        "and cheekPuff summed)")
    add_usd_arg(p)
    add_model_args(p)


def add_usd_arg(p) -> None:
    p.add_argument("--meters-per-unit", type=float, default=0.01,
                   help="USD outputs: the stage's metersPerUnit, one unit of the target mesh in metres "
                        "(default 0.01: centimetres, the project's units)")


def run(args) -> int:
    from ..errors import RetargetError
    from ..io import check_output, load_mesh
    from ..usd import is_usd_path

    if not args.out.lower().endswith(".glb") and not is_usd_path(args.out):
        raise RetargetError(f"{args.out}: the rig is written as .glb, or as USD (.usd, .usda, .usdc)")
    inputs = [args.target] + ([args.weights] if args.weights else [])
    if is_usd_path(args.out):
        check_usd_output(args, inputs)
    else:
        check_output(args.out, inputs)
    track = read_weights_file(args.weights, args.clamp) if args.weights else None
    target = load_mesh(args.target, up=args.up, forward=args.forward, force=args.force)
    r = retargeter(args)
    tgt = r.prepare(target)
    print_notes(r, tgt, args.target)
    rig = r.bake(tgt)
    names, anim = write_rig(args.out, rig, target.faces, track, args, args.names)
    print(f"wrote {args.out}: {len(names)} {'blend shapes' if is_usd_path(args.out) else 'morph targets'} "
          f"on {target.n_vertices} vertices" + (f", {len(anim)} animated frames" if anim is not None else ""))
    return 0


def check_usd_output(args, inputs) -> None:
    """Before any work: usd-core is installed, ``--meters-per-unit`` is positive, OUT is no input."""
    import math

    from ..errors import RetargetError
    from ..io import check_output
    from ..usd import require_usd

    require_usd(args.out)
    if not (math.isfinite(args.meters_per_unit) and args.meters_per_unit > 0):
        raise RetargetError(f"--meters-per-unit {args.meters_per_unit:g}: must be a positive number")
    check_output(args.out, inputs)


def usd_frame(args):
    """(R (3,3), up_axis): a USD rig is written as ``v @ R`` in the input files' axes when their up
    is +y or +z, the two up axes a USD stage can declare, else in the project frame (+y up)."""
    import numpy as np

    back = rotation(args)  # project frame -> the file's axes; its row 1 is the file's up
    for axis, up in (("Y", (0, 1, 0)), ("Z", (0, 0, 1))):
        if np.array_equal(back[1], up):
            return back, axis
    print("note: USD declares +y or +z up only; the rig is written +y up, +z forward", file=sys.stderr)
    return np.eye(3), "Y"


def write_rig(out, rig, faces, track, args, names: str = "ict"):
    """Write a BakedRig (project frame) and the optional weight track to OUT, a .glb or a USD file,
    in the input files' axes (see ``usd_frame`` for USD). names: "ict" (53 shapes) or "arkit" (51,
    see ``arkit_rig``). Returns (shape names, (T,K) animated weights or None)."""
    from data_synth.facs import FACS_NAMES
    from ..glb import write_rig_glb
    from ..usd import is_usd_path, write_rig_usd

    shape_names, deltas, anim = list(FACS_NAMES), rig.deltas, None if track is None else track.weights
    if names == "arkit":
        shape_names, deltas, anim = arkit_rig(deltas, anim)
    fps = track.fps if track and track.fps else 30.0
    if is_usd_path(out):
        back, up_axis = usd_frame(args)
        write_rig_usd(out, rig.neutral @ back, faces, deltas @ back, shape_names, animation=anim, fps=fps,
                      up_axis=up_axis, meters_per_unit=args.meters_per_unit)
    else:
        back = rotation(args)  # project frame -> the file's axes
        write_rig_glb(out, rig.neutral @ back, faces, deltas @ back, shape_names, animation=anim, fps=fps)
    return shape_names, anim


def arkit_rig(deltas, anim):
    """ICT (53,V,3) shapes -> ARKit names: browInnerUp / cheekPuff = sum of both halves (one ARKit
    weight drives both ICT halves); tongueOut omitted. anim (T,53) -> (T,51)."""
    import numpy as np
    from data_synth.facs import ARKIT_NAMES, FACS_INDEX, arkit_to_ict
    names, shapes, cols = [], [], []
    for a in ARKIT_NAMES:
        ict = arkit_to_ict(a)
        if not ict:
            continue
        idx = [FACS_INDEX[n] for n in ict]
        names.append(a)
        shapes.append(deltas[idx].sum(0))
        cols.append(idx)
    out_anim = None if anim is None else np.stack([anim[:, i].mean(1) for i in cols], axis=1)
    return names, np.stack(shapes), out_anim
