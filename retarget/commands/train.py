"""``retarget train``: train the NFS network on procedural rigs from a YAML config, or fine-tune a
checkpoint on the user's own blendshape rig (``--rig``)."""
from __future__ import annotations

import sys
import warnings
from pathlib import Path

HELP = "train the network from a config (resumable; torchrun for several processes)"
EXAMPLE = """retarget train --config configs/train/default.yaml --out runs/default
retarget train --config configs/train/default.yaml --out runs/default --resume
retarget train --config realistic_rig --data-workers 4 --out runs/fast   # samples made by 4 processes
retarget train --config configs/train/no_bp.yaml --steps 1500 --max-minutes 0 --out runs/no_bp  # fixed step budget
torchrun --nproc_per_node 2 -m retarget.cli train --config configs/train/tiny.yaml --out runs/ddp
retarget train --rig my_rig.npz --init runs/default/model.pt --out runs/mine    # fine-tune
retarget train --config realistic --init runs/default/model.pt --init-partial --out runs/new  # new design, warm start
retarget train --rig ICT-FaceKit/FaceXModel --keep-vertices 0:11248 --init model.pt --out runs/ict"""


def add_arguments(p):
    p.add_argument("--config", help="training YAML: a file or a shipped name (default, no_skinning, "
                                    "...: configs/train/*.yaml); with --rig it defaults to "
                                    "finetune and the --init checkpoint's model")
    p.add_argument("--out", required=True, help="run folder: last.pt, model.pt, train_log.csv")
    p.add_argument("--resume", action="store_true", help="continue from OUT/last.pt if present")
    p.add_argument("--init", help="initialise the weights from this checkpoint (fine-tuning)")
    p.add_argument("--init-partial", action="store_true",
                   help="with --init and a --config whose model differs from the checkpoint's (a "
                        "new design): copy the weights whose names and shapes fit, widen the "
                        "expression encoder's input for the neutral channels, start the rest "
                        "fresh (listed)")
    p.add_argument("--init-fresh", nargs="+", metavar="MODULE", default=(),
                   help="with --init-partial: start these modules fresh even where they fit (e.g. "
                        "decoder: compare a new decoder with a trained one at the same budget)")
    p.add_argument("--rig", help="fine-tune on this blendshape rig: an npz (neutral, faces, names, "
                                 "deltas) or a folder (neutral.obj + one OBJ per ICT/ARKit shape, "
                                 "or ICT-FaceKit's FaceXModel)")
    p.add_argument("--keep-vertices", metavar="A:B",
                   help="use only the rig's vertices A..B-1 (e.g. the skin, without eyes and teeth)")
    p.add_argument("--strict", action="store_true",
                   help="refuse rig shapes that have no ICT or ARKit name (correctives, visemes, "
                        "ICT-FaceKit's PupilDilate_L/R, cheekRaiser_L/R) instead of leaving them "
                        "out with a one-line warning")
    p.add_argument("--rig-mix", type=float,
                   help="fraction of steps drawn from the rig, the rest procedural (default 0.5)")
    p.add_argument("--steps", type=int, help="override train.steps (>= 1)")
    p.add_argument("--lr", type=float, help="override optim.lr (the peak learning rate)")
    p.add_argument("--seed", type=int, help="override train.seed (samples, validation set, init)")
    p.add_argument("--max-minutes", type=float,
                   help="override train.max_minutes (0 = no time limit: the budget and the "
                        "learning-rate schedule follow --steps only, whatever else runs on the "
                        "machine)")
    p.add_argument("--data-workers", type=int, metavar="N",
                   help="override train.data_workers: N processes prepare the samples of the next "
                        "steps while the model trains (the same samples; 0 = in the training "
                        "process)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def training_config(args) -> tuple[dict, str]:
    """(config, its path) from the arguments: --config, or with --rig the fine-tuning config whose
    model is the --init checkpoint's; --rig, --keep-vertices, --strict, --rig-mix, --steps, --lr, --seed
    --max-minutes and --data-workers applied."""
    from ..config import find_config
    from ..errors import RetargetError
    from ..train import load_checkpoint, load_config

    if args.config is None:
        if not args.rig:
            raise RetargetError("--config is required (or --rig with --init to fine-tune)")
        if not args.init:
            raise RetargetError("--rig without --config needs --init CHECKPOINT (its model is "
                                "fine-tuned)")
        path = str(find_config("finetune", "train"))
        cfg = load_config(path)
        cfg["model"] = dict(load_checkpoint(args.init)["model_config"])
    else:
        path = str(find_config(args.config, "train"))
        cfg = load_config(path)
    if args.rig:
        cfg["data"]["rig"] = args.rig
    if args.keep_vertices is not None:
        cfg["data"]["keep_vertices"] = args.keep_vertices
    if args.strict:
        cfg["data"]["rig_strict"] = True
    if args.rig_mix is not None:
        if not 0 <= args.rig_mix <= 1:
            raise RetargetError(f"--rig-mix {args.rig_mix}: must be between 0 and 1")
        cfg["data"]["rig_mix"] = args.rig_mix
    if args.steps is not None:
        if args.steps < 1:
            raise RetargetError(f"--steps {args.steps}: must be at least 1")
        cfg["train"]["steps"] = args.steps
    if args.lr is not None:
        if not 0 < args.lr < float("inf"):
            raise RetargetError(f"--lr must be > 0, got {args.lr}")
        cfg["optim"]["lr"] = args.lr
    if args.seed is not None:
        if args.seed < 0:
            raise RetargetError(f"--seed {args.seed}: must be >= 0")
        cfg["train"]["seed"] = args.seed
    if args.max_minutes is not None:
        if not args.max_minutes >= 0 or args.max_minutes == float("inf"):
            raise RetargetError(f"--max-minutes must be >= 0, got {args.max_minutes}")
        cfg["train"]["max_minutes"] = args.max_minutes
    if args.data_workers is not None:
        if args.data_workers < 0:
            raise RetargetError(f"--data-workers {args.data_workers}: must be >= 0")
        cfg["train"]["data_workers"] = args.data_workers
    return cfg, path


def describe_warm_start(init: str, report: dict) -> str:
    """One paragraph for --init-partial: how many tensors were copied, widened, narrowed and
    started fresh (the fresh ones' module names)."""
    fresh = sorted({name.rsplit(".", 1)[0].split(".")[0] for name in report["fresh"]})
    narrowed = (f"{len(report['narrowed'])} narrowed ({', '.join(report['narrowed'])}), "
                if report["narrowed"] else "")
    return (f"warm start from {init}: {len(report['copied'])} tensors copied, "
            f"{len(report['widened'])} widened ({', '.join(report['widened']) or 'none'}), "
            f"{narrowed}{len(report['fresh'])} fresh ({', '.join(fresh) or 'none'})")


def run(args) -> int:
    from ..train import Trainer, check_run_folder, shutdown_distributed
    from ..user_rig import UnknownShapeWarning

    from ..errors import RetargetError

    if args.init_partial and not args.init:
        raise RetargetError("--init-partial needs --init CHECKPOINT (the weights to start from)")
    if args.init_fresh and not args.init_partial:
        raise RetargetError("--init-fresh needs --init-partial (it names modules not to copy)")
    out = Path(args.out)
    check_run_folder(out, args.resume)
    cfg, config_path = training_config(args)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UnknownShapeWarning)
        trainer = Trainer(cfg, out, config_path=config_path, init=args.init,
                          progress=not args.no_progress, init_partial=args.init_partial,
                          init_fresh=tuple(args.init_fresh))
    if trainer.rank == 0:
        for w in caught:  # e.g. the rig's shapes left out: one line, not a Python warning
            print(f"warning: {w.message}", file=sys.stderr)
    if trainer.rank == 0 and trainer.init_report is not None:
        print(describe_warm_start(args.init, trainer.init_report))
    if args.resume and trainer.resume():
        print(f"resumed {out / 'last.pt'} at step {trainer.step}")
    metrics = trainer.run()
    shutdown_distributed()
    if trainer.rank == 0:
        print(f"saved {out / 'model.pt'} (step {trainer.step})"
              + "".join(f", {k} {v:.4f}" for k, v in metrics.items()))
    return 0
