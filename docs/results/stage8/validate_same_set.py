"""Checkpoints on one validation set: the 16 held-out cases of a training config's validation
(``retarget.train.validate``: self-retargeting without the neutral, the same cases and weights as
the training log's ``val_*`` columns of a run of that config with seed 1). A run with
``partial_macro_share`` draws its validation heads with that share too, so its logged curve is on
another set; this puts models of both configs on the same one.

    OMP_NUM_THREADS=2 python docs/results/stage8/validate_same_set.py CONFIG NAME=CHECKPOINT [...]
"""
import sys

import torch

from retarget.checkpoint import load_checkpoint, model_from_checkpoint
from retarget.train import load_config, validate
from retarget.training_data import validation_entries


def main(config: str, specs: list[str]) -> None:
    cfg = load_config(config)
    models = {name: model_from_checkpoint(load_checkpoint(path), path)
              for name, path in (s.split("=", 1) for s in specs)}
    model_cfg = next(iter(models.values())).cfg
    val_set = validation_entries(cfg["data"], model_cfg, 1)
    print(f"validation set of {config} (seed 1): {sum(len(w) for _, w in val_set)} cases")
    for name, model in models.items():
        torch.manual_seed(0)
        r = validate(model, val_set, torch.device("cpu"))
        print(f"{name}: " + ", ".join(f"{k} {v:.4f}" for k, v in r.items()), flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
