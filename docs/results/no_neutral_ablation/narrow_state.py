"""The ``no_neutral`` ablation at the bundled run's budget (issue 10): a resumable training state
of the paper's expression encoder made from the bundled run's own state, so that one
``retarget train --resume`` continues both designs from the same model, optimizer moments, step,
learning-rate schedule, clock and random-generator state, on the same samples.

The model is narrowed by :func:`retarget.checkpoint.warm_start` (the neutral channels' columns of the
expression encoder's first layer dropped, the no-neutral flag's column folded into its bias: the
narrowed model computes what the neutral-aware one does without the neutral). AdamW's moments of
that weight keep the same columns; the bias's moments are kept as they are.

    mkdir -p runs/stage14     # stage 14's state, kept at commit 98177ce
    git show 98177ce:training/stage14/last.pt > runs/stage14/last.pt
    git show 98177ce:training/stage14/train_log.csv > runs/stage14/train_log.csv
    python docs/results/no_neutral_ablation/narrow_state.py runs/stage14 \
        configs/train/realistic_rig_heavy_no_neutral.yaml runs/ablation_no_neutral
    retarget train --config realistic_rig_heavy_no_neutral --seed 1 --steps 12000 --lr 1e-4 \
        --max-minutes 0 --out runs/ablation_no_neutral --resume --data-workers 1
"""
from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import torch

from nets.model import NFSModel
from retarget.checkpoint import load_checkpoint, model_from_checkpoint, save_checkpoint, warm_start
from retarget.train import load_config, model_cfg

FIRST = "expression_encoder.first.weight"


def narrow_state(state: dict, train_cfg: dict) -> dict:
    """A training state (``Trainer.state()``) of a neutral-aware model -> the same state for the
    model of ``train_cfg`` (the same design without the neutral channels)."""
    old = model_from_checkpoint(state, "state")
    new = NFSModel(model_cfg(train_cfg))
    report = warm_start(new, old)
    if report["narrowed"] != [FIRST] or report["fresh"] or report["widened"]:
        raise SystemExit(f"the two models differ beyond the neutral channels: {report}")
    names = [name for name, _ in old.named_parameters()]
    if names != [name for name, _ in new.named_parameters()]:
        raise SystemExit("the two models' parameters are not in the same order")
    optimizer = {"param_groups": state["optimizer"]["param_groups"],
                 "state": dict(state["optimizer"]["state"])}
    index = names.index(FIRST)
    width = new.expression_encoder.first.in_features
    optimizer["state"][index] = {k: (v[:, :width].clone() if v.dim() == 2 else v)
                                 for k, v in optimizer["state"][index].items()}
    return {**state, "model_config": new.cfg.to_dict(), "train_config": train_cfg,
            "model": new.state_dict(), "optimizer": optimizer}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run", type=Path, help="the neutral-aware run folder (last.pt, train_log.csv)")
    p.add_argument("config", help="the ablation's training config")
    p.add_argument("out", type=Path, help="new run folder for the ablation (must not exist)")
    args = p.parse_args()
    cfg = load_config(args.config)
    state = narrow_state(load_checkpoint(args.run / "last.pt"), cfg)
    args.out.mkdir(parents=True)
    save_checkpoint(args.out / "last.pt", state)
    shutil.copy(args.run / "train_log.csv", args.out / "train_log.csv")
    print(f"{args.out / 'last.pt'}: step {state['step']}, {sum(t.numel() for t in state['model'].values())} weights")


if __name__ == "__main__":
    torch.set_num_threads(1)
    main()
