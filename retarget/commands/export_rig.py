"""``retarget export-rig``: a 53-morph-target glTF rig for any mesh (optionally animated)."""
from __future__ import annotations

from ._common import add_model_args, read_weights_file, retargeter, rotation

HELP = "export a 53-shape blendshape rig (GLB morph targets with ICT names) for the neutral TGT"
EXAMPLE = """retarget export-rig character_neutral.obj -o character_rig.glb
retarget export-rig character_neutral.obj -o take01.glb --weights take01_livelink.csv --names arkit"""


def add_arguments(p):
    p.add_argument("target", help="target neutral mesh (any topology)")
    p.add_argument("-o", "--out", required=True, help="output .glb")
    p.add_argument("--weights", help="optional weights file: adds a weight animation")
    p.add_argument("--clamp", action="store_true", help="clip weights to [0, 1] instead of warning")
    p.add_argument("--names", choices=("ict", "arkit"), default="ict",
                   help="morph target names (arkit: 52 ARKit shapes, the two halves of browInnerUp "
                        "and cheekPuff summed)")
    add_model_args(p)


def run(args) -> int:
    from data_synth.facs import FACS_NAMES
    from ..errors import RetargetError
    from ..glb import write_rig_glb
    from ..io import check_output, load_mesh

    if not args.out.lower().endswith(".glb"):
        raise RetargetError(f"{args.out}: the rig is written as .glb")
    inputs = [args.target] + ([args.weights] if args.weights else [])
    check_output(args.out, inputs)
    track = read_weights_file(args.weights, args.clamp) if args.weights else None
    target = load_mesh(args.target, up=args.up, forward=args.forward, force=args.force)
    rig = retargeter(args).bake(target)
    back = rotation(args)  # project frame -> the file's axes
    neutral, deltas = rig.neutral @ back, rig.deltas @ back
    names, anim = list(FACS_NAMES), None if track is None else track.weights
    if args.names == "arkit":
        names, deltas, anim = arkit_rig(deltas, anim)
    write_rig_glb(args.out, neutral, target.faces, deltas, names, animation=anim,
                  fps=(track.fps if track and track.fps else 30.0))
    print(f"wrote {args.out}: {len(names)} morph targets on {target.n_vertices} vertices"
          + (f", {len(anim)} animated frames" if anim is not None else ""))
    return 0


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
