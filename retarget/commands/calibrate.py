"""``retarget calibrate``: compare the procedural expressions with a real ARKit rig (magnitude,
area moved, main direction) and print the markdown table and a summary."""
from __future__ import annotations

HELP = "compare the procedural FACS shapes with a real ARKit rig (table + summary)"
EXAMPLE = """retarget calibrate
retarget calibrate --rig ../shared/rigs/makehuman_arkit.npz --out docs/calibration_table.md"""


def add_arguments(p):
    from ..calibrate import DEFAULT_RIG

    p.add_argument("--rig", default=str(DEFAULT_RIG),
                   help="real ARKit rig npz (default: the packaged MakeHuman ARKit rig)")
    p.add_argument("--n-vertices", type=int, default=12000,
                   help="vertices of the procedural head (default 12000)")
    p.add_argument("--out", help="also write the table and summary to this markdown file")


def run(args) -> int:
    import json

    from ..calibrate import compare, markdown_table, summary
    from ..io import atomic_output

    rows = compare(args.rig, n_vertices=args.n_vertices)
    table = markdown_table(rows)
    s = summary(rows)
    text = (f"{table}\n\n{s['magnitude_within_0.5_2x']}/{s['n_shapes']} shapes within 0.5-2x of the "
            f"real magnitude, {s['direction_cosine_gt_0.7']}/{s['n_shapes']} with direction cosine > 0.7.\n"
            f"outside the magnitude band: {', '.join(s['outside_band']) or '-'}\n"
            f"direction cosine <= 0.7: {', '.join(s['misaligned']) or '-'}\n")
    print(text)
    if args.out:
        with atomic_output(args.out) as tmp:
            with open(tmp, "w") as f:
                f.write(text)
        print(json.dumps({"written": str(args.out)}))
    return 0
