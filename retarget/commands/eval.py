"""``retarget eval``: the accuracy suites of DESIGN.md section 6 (``retarget.evaluate``)."""
from __future__ import annotations

HELP = ("accuracy suites (procedural, real rig, realistic heads, canonical frame) as tables, with "
        "do-nothing and closest-point baseline rows")
EXAMPLE = """retarget eval --out results/eval
retarget eval --checkpoint full=runs/full/model.pt no_skinning=runs/noskin/model.pt \\
    --suite cross_identity cross_topology --heatmaps results/heatmaps --out results/eval
retarget eval --config configs/eval/tiny.yaml --checkpoint runs/tiny/model.pt
retarget eval --merge results/a/eval.json results/b/eval.json --out results/all   # one table
retarget eval --checkpoint runs/neutral/model.pt --neutral-modes none neutral refine --out results/n"""


def add_arguments(p):
    from ..evaluate import NEUTRAL_MODES, SUITES

    p.add_argument("--checkpoint", action="extend", nargs="+", metavar="[NAME=]PATH",
                   help="checkpoint(s) to evaluate, a table row each (e.g. the model and its "
                        "ablations); default: the bundled retarget/checkpoints/default.pt")
    p.add_argument("--suite", action="extend", nargs="+", choices=SUITES, metavar="NAME",
                   help=f"run only these suites ({', '.join(SUITES)}); default: all")
    p.add_argument("--neutral-modes", nargs="+", choices=tuple(NEUTRAL_MODES), default=["neutral"],
                   metavar="MODE", help="a row per checkpoint and mode: none (the source's neutral "
                   "not given), neutral (given: the default), refine (given, plus "
                   "analysis-by-synthesis on the source's baked rig)")
    p.add_argument("--refine-steps", type=int, default=0, metavar="N",
                   help="mode refine, MLP decoder: then N gradient steps on the free dims of z_GE "
                        "(default 0; a basis decoder always solves them exactly)")
    p.add_argument("--config", help="eval config overriding configs/eval/default.yaml "
                                    "(fixed seeds and sizes)")
    p.add_argument("--out", help="folder for eval.json and eval.md")
    p.add_argument("--heatmaps", metavar="DIR", help="write per-vertex error PNGs (YlOrRd, fixed mm scale)")
    p.add_argument("--real-rig", help="the real ARKit rig npz (overrides real_rig.path)")
    p.add_argument("--no-oracle", action="store_true",
                   help="leave out the (u,v) displacement-transfer oracle row")
    p.add_argument("--device", help="torch device (default: cuda when present, else cpu)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--merge", nargs="+", metavar="EVAL_JSON",
                   help="evaluate nothing: put the methods of these eval.json files (same eval "
                        "config) into one table, written to --out")


def run(args) -> int:
    from pathlib import Path

    from ..evaluate import (SUITES, ClosestPointMethod, DoNothingMethod, Evaluation, OracleMethod,
                            load_eval_config, network_methods, parse_checkpoints, real_rig_path,
                            to_markdown, write_heatmaps, write_results)

    if args.merge:
        from ..evaluate import merge_results

        results = merge_results(args.merge)
        markdown = to_markdown(results)
        print(markdown)
        for path in write_results(args.out, "eval", results, markdown) if args.out else ():
            print(f"wrote {path}")
        return 0
    from ..errors import RetargetError

    cfg = load_eval_config(args.config)
    suites = list(args.suite or SUITES)
    if args.real_rig:
        cfg["real_rig"]["path"] = str(Path(args.real_rig).resolve())
    elif not args.suite and not real_rig_path(cfg).is_file():
        # e.g. a real_rig.path that does not exist here: run the rest
        print(f"note: {real_rig_path(cfg)} not found, the real_rig suite is left out "
              f"(pass --real-rig RIG.npz to run it)")
        suites.remove("real_rig")
    checkpoints = parse_checkpoints(args.checkpoint)
    if args.refine_steps < 0:
        raise RetargetError(f"--refine-steps must be >= 0, got {args.refine_steps}")
    methods = ([DoNothingMethod()]
               + network_methods(checkpoints, list(dict.fromkeys(args.neutral_modes)), args.device,
                                 args.refine_steps)
               + [ClosestPointMethod()])
    if not args.no_oracle:
        methods.append(OracleMethod())
    evaluation = Evaluation(cfg, methods, progress=not args.no_progress)
    results = evaluation.run(suites)
    results["checkpoints"] = {name: str(path) for name, path in checkpoints}
    markdown = to_markdown(results)
    print(markdown)
    if args.out:
        for path in write_results(args.out, "eval", results, markdown):
            print(f"wrote {path}")
    if args.heatmaps:
        h = cfg["heatmaps"]
        for path in write_heatmaps(evaluation.samples, args.heatmaps, h["vmax_mm"], h["size"]):
            print(f"wrote {path}")
    return 0
