"""The starting point of the bundled stage 21's run (issue 10, docs/RESULTS.md, "Stage 21": blind_b,
and the study's blind_b_lr and blind_joint): stage 19 with a blind encoder
(``NFSConfig.blind_encoder``) that is the ``no_neutral`` ablation's expression encoder at the same
budget (training/ablation_no_neutral_19), instead of stage 19's own encoder read without the
neutral (what ``retarget train --init-partial`` gives). An inference checkpoint, for
``retarget train --init``:

    git show 1c60070:retarget/checkpoints/default.pt > runs/stage19.pt
    python docs/results/blind_encoder/assemble.py runs/stage19.pt \
        training/ablation_no_neutral_19/last.pt configs/train/realistic_rig_authored_blind.yaml \
        runs/blind_abl_init.pt
"""
from __future__ import annotations

import argparse
from pathlib import Path

from nets.model import NFSModel
from retarget.checkpoint import (CHECKPOINT_FORMAT, load_checkpoint, model_from_checkpoint,
                                 save_checkpoint, warm_start)
from retarget.train import load_config, model_cfg


def assemble(base: NFSModel, ablation: NFSModel, train_cfg: dict) -> NFSModel:
    """The model of ``train_cfg`` with ``base``'s weights and ``ablation``'s expression encoder as
    its blind encoder (the two encoders must be of one shape)."""
    if ablation.cfg.neutral_channels:
        raise SystemExit("the ablation's expression encoder reads the neutral channels")
    model = NFSModel(model_cfg(train_cfg))
    report = warm_start(model, base)
    if report["fresh"] or report["widened"]:
        raise SystemExit(f"the model differs from the base beyond the blind encoder: {report}")
    model.blind_encoder.load_state_dict(ablation.expression_encoder.state_dict())
    return model


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("base", type=Path, help="the neutral-aware model (stage 19)")
    p.add_argument("ablation", type=Path, help="the no_neutral ablation's checkpoint")
    p.add_argument("config", help="the blind-encoder training config")
    p.add_argument("out", type=Path, help="the assembled checkpoint (must not exist)")
    args = p.parse_args()
    if args.out.exists():
        raise SystemExit(f"{args.out}: exists; choose another file")
    cfg = load_config(args.config)
    base = model_from_checkpoint(load_checkpoint(args.base), args.base)
    ablation = model_from_checkpoint(load_checkpoint(args.ablation), args.ablation)
    model = assemble(base, ablation, cfg)
    save_checkpoint(args.out, {"format": CHECKPOINT_FORMAT, "model_config": model.cfg.to_dict(),
                               "train_config": cfg, "model": model.state_dict()})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
