"""Can the skinning encoder learn a dense correspondence? L_corr alone, at a high learning rate.

Widens a checkpoint to ``--descriptor`` skinning descriptor channels (``NFSConfig.skin_descriptor``,
zero rows: the model is unchanged) and trains the skinning encoder alone by L_corr + L_nll (the
segments kept) on the neutrals of MakeHuman training heads, one head per step on the training
config's MakeHuman tessellations in turn, with Adam at ``--lr``. Prints every ``--every`` steps the
RMS distance (canonical units; a face is about 16 wide) between the template point the channels
give and the true one, on the training heads of the last steps and on the four validation heads
(the validation eval's meshes), and the segment accuracy. ``--out`` saves the widened model with
the trained encoder as a checkpoint (``model_config`` + ``model``), e.g. as ``--init`` of a run.

  OMP_NUM_THREADS=1 python docs/results/weight_mae/overfit/descriptor_pretrain.py --steps 600 --out runs/descriptor_pretrained.pt
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np
import torch

from nets.losses import correspondence_loss, segmentation_nll
from nets.model import NFSModel
from overfit_rig import HELD_OUT_TESSELLATION, head_entry
from retarget.checkpoint import (CHECKPOINT_FORMAT, load_checkpoint, model_from_checkpoint,
                                 save_checkpoint, warm_start)
from retarget.train import load_config


def measure(model, entries) -> tuple[float, float]:
    """(RMS template distance in canonical units, segment accuracy) over ``entries``."""
    n_seg = model.cfg.n_segments
    d2, acc = [], []
    with torch.no_grad():
        for e in entries:
            feat, img, ops = e.mesh.torch_inputs("cpu")
            z = model.encode_skinning(feat, model.image_code(img)[0], ops)
            d2.append(float(correspondence_loss(z[:, n_seg:n_seg + 3], torch.from_numpy(e.template))))
            acc.append(float((z[:, :n_seg].argmax(1).numpy() == e.rig.segments).mean()))
    return float(np.sqrt(np.mean(d2))), float(np.mean(acc))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    ap.add_argument("--config", default="configs/train/realistic_rig_corr.yaml",
                    help="its data.makehuman.tessellations are the training meshes")
    ap.add_argument("--descriptor", type=int, default=16)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--every", type=int, default=100)
    ap.add_argument("--heads", type=int, default=48, help="training heads (seeds 100, 101, ...)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    torch.manual_seed(0)

    old = model_from_checkpoint(load_checkpoint(args.checkpoint), args.checkpoint)
    model = NFSModel(dataclasses.replace(old.cfg, skin_descriptor=args.descriptor))
    warm_start(model, old)
    specs = load_config(args.config)["data"]["makehuman"]["tessellations"]
    train = [head_entry(model, 100 + i, "train", False, {**specs[i % len(specs)], "seed": 3})
             for i in range(args.heads)]
    held = [head_entry(model, i, "val", False, HELD_OUT_TESSELLATION) for i in range(4)]
    opt = torch.optim.Adam(model.skinning_encoder.parameters(), lr=args.lr)
    n_seg = model.cfg.n_segments
    t0 = time.time()
    for step in range(args.steps + 1):
        if step % args.every == 0:
            rms_train, _ = measure(model, train[:8])
            rms_held, acc_held = measure(model, held)
            print(json.dumps({"step": step, "rms_train": round(rms_train, 3),
                              "rms_held_out": round(rms_held, 3),
                              "segment_accuracy_held_out": round(acc_held, 3),
                              "seconds": round(time.time() - t0, 1)}), flush=True)
        if step == args.steps:
            break
        e = train[step % len(train)]
        feat, img, ops = e.mesh.torch_inputs("cpu")
        with torch.no_grad():
            c = model.image_code(img)[0]
        z = model.encode_skinning(feat, c, ops)
        loss = (correspondence_loss(z[:, n_seg:n_seg + 3], torch.from_numpy(e.template))
                + segmentation_nll(z[:, :n_seg], torch.from_numpy(e.rig.segments)))
        opt.zero_grad()
        loss.backward()
        opt.step()
    if args.out:
        save_checkpoint(args.out, {"format": CHECKPOINT_FORMAT, "model_config": model.cfg.to_dict(),
                                   "model": model.state_dict(), "step": 0})


if __name__ == "__main__":
    main()
