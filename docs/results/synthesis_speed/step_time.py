"""Where a training step's time goes on one thread: the network's compute (forward, backward,
optimizer) on 20 prepared groups of a config, and making a step's sample in steady state (the
pool already filled, 40 later steps). Prints seconds per step of each.

    RETARGET_NO_CACHE=1 OMP_NUM_THREADS=1 python docs/results/synthesis_speed/step_time.py --config realistic_rig_authored
"""
from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np
import torch

from retarget.config import find_config
from retarget.train import Trainer, group_losses, load_config


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="realistic_rig_authored")
    ap.add_argument("--init", default="retarget/checkpoints/default.pt")
    args = ap.parse_args()
    cfg = load_config(find_config(args.config, "train"))
    cfg["train"].update(seed=1, steps=100000, max_minutes=0, data_workers=0)
    cfg["optim"]["lr"] = 2e-5
    with tempfile.TemporaryDirectory() as out:
        tr = Trainer(cfg, out, init=args.init, progress=False)
    groups = [tr.pool.sample(s) for s in range(40)]            # fills the pool first

    def step(s: int) -> None:
        rng = np.random.default_rng([1, s, 0, 1])
        losses = group_losses(tr.model, groups[s], cfg["loss"], cfg["data"]["decode_faces"], rng,
                              tr.device)
        tr.opt.zero_grad(set_to_none=True)
        losses["total"].backward()
        torch.nn.utils.clip_grad_norm_(tr.model.parameters(), cfg["optim"]["grad_clip"])
        tr.opt.step()

    for s in range(5):                                        # warm-up
        step(s)
    t = time.perf_counter()
    for s in range(5, 25):
        step(s)
    print(f"network compute: {(time.perf_counter() - t) / 20:.3f} s per step (20 steps)")
    t = time.perf_counter()
    for s in range(40, 80):
        tr.pool.sample(s)
    print(f"making a step's sample, steady state: {(time.perf_counter() - t) / 40:.3f} s per step "
          f"(40 steps)")


if __name__ == "__main__":
    main()
