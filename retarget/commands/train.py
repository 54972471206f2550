"""``retarget train``: train the NFS network on procedural rigs from a YAML config."""
from __future__ import annotations

from pathlib import Path

HELP = "train the network from a config (resumable; torchrun for several processes)"
EXAMPLE = """retarget train --config configs/train/default.yaml --out runs/default
retarget train --config configs/train/default.yaml --out runs/default --resume
torchrun --nproc_per_node 2 -m retarget.cli train --config configs/train/tiny.yaml --out runs/ddp"""


def add_arguments(p):
    p.add_argument("--config", required=True, help="training YAML (configs/train/*.yaml)")
    p.add_argument("--out", required=True, help="run folder: last.pt, model.pt, train_log.csv")
    p.add_argument("--resume", action="store_true", help="continue from OUT/last.pt if present")
    p.add_argument("--init", help="initialise the weights from this checkpoint (fine-tuning)")
    p.add_argument("--steps", type=int, help="override train.steps")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args) -> int:
    from ..train import Trainer, load_config

    cfg = load_config(args.config)
    if args.steps is not None:
        cfg["train"]["steps"] = args.steps
    out = Path(args.out)
    if (out / "last.pt").exists() and not args.resume:
        from ..errors import RetargetError
        raise RetargetError(f"{out}: already holds a run (last.pt); pass --resume to continue it "
                            f"or choose another --out")
    trainer = Trainer(cfg, out, config_path=args.config, init=args.init,
                      progress=not args.no_progress)
    if args.resume and trainer.resume():
        print(f"resumed {out / 'last.pt'} at step {trainer.step}")
    metrics = trainer.run()
    if trainer.rank == 0:
        print(f"saved {out / 'model.pt'} (step {trainer.step})"
              + "".join(f", {k} {v:.4f}" for k, v in metrics.items()))
    return 0
