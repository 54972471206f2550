"""Can the bundled decoder draw realistic rigs? A capacity and learnability check of the baked shapes.

Starting from a checkpoint, fit the model by L_rig alone (all 53 one-hot shapes, every vertex,
relative weighting τ = 0.05 as in training) to the rigs of a few MakeHuman training identities
(``--identities``, one rig per step in turn), and print every ``--every`` steps the baked shapes'
median relative error |B̂_k − B_k| / |B_k| over the shapes each rig has: on the fitted rigs and on
held-out validation heads (``--held-out``: the validation eval's heads, shapes as authored, 3,000
vertices, the eval's tessellation seed); and two controls that tell what a fit carries over: the
first fitted identity on the held-out heads' tessellation ("same_head_other_mesh") and four
other training identities on the fitted tessellation ("other_heads_same_mesh"). One fitted identity is the capacity check (can this
decoder draw one realistic rig at all?); several, with the held-out heads, the learnability check
(does drawing rigs carry over to unseen heads?).

Arms (--train): "all" = every parameter; "decoder" = the decoder MLP only (target encoders, CNN and
skinning block frozen). --unstyled takes the fitted identities' shapes as authored instead of with
the random per-rig style that training rigs get (``data_synth.makehuman.expressions.style_shapes``).
--descriptor F warm-starts a model with F skinning descriptor channels (``NFSConfig.skin_descriptor``,
zero decoder columns: the same model at step 0). --oracle-template (with --descriptor ≥ 3) puts each
head's true template positions (``training_data.template_positions``) into the first three
descriptor channels instead of the encoder's: how far the rig gets with a perfect correspondence.
--steps 0 only measures.

  OMP_NUM_THREADS=1 python docs/results/weight_mae/overfit/overfit_rig.py --train all --lr 1e-3 --steps 600 --identities 7
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np
import torch

from data_synth.makehuman import base_head_rig, build_head_rig, head_tessellation, sample_head_identity
from nets.losses import TEMPLATE_SPAN, rig_loss
from nets.model import NFSModel
from retarget.checkpoint import load_checkpoint, model_from_checkpoint, warm_start
from retarget.training_data import prepare_rig

HELD_OUT_TESSELLATION = {"n_vertices": 3000, "kind": "decimated", "crop": "head_neck", "seed": 0}


def head_entry(model, seed: int, split: str, style: bool, tess: dict):
    """A prepared MakeHuman rig (``training_data.Entry``) of identity ``seed`` of ``split``."""
    base = base_head_rig(sample_head_identity(seed, split), "arkit", seed if style else None)
    return prepare_rig(build_head_rig(base, head_tessellation(**tess), model.cfg.n_segments),
                       model.cfg)


def use_true_template(model) -> dict:
    """Make ``model.encode_skinning`` write the true template positions of ``holder["entry"]`` into
    descriptor channels 0-2 (as (0, 1) values, ``nets.losses.descriptor_template``'s inverse)."""
    holder, n_seg, encode = {}, model.cfg.n_segments, model.encode_skinning

    def encode_skinning(feat, c, ops):
        z = encode(feat, c, ops)
        t = torch.from_numpy(0.5 + holder["entry"].template / TEMPLATE_SPAN).to(z)
        return torch.cat([z[:, :n_seg], t, z[:, n_seg + 3:]], dim=1)

    model.encode_skinning = encode_skinning
    return holder


ORACLE: dict | None = None   # set by --oracle-template: the entry whose template is used


def median_error(model, entry) -> float:
    """Median over the shapes the rig has (|B_k| > 0) of |B̂_k − B_k| / |B_k|."""
    if ORACLE is not None:
        ORACLE["entry"] = entry
    t_feat, t_img, t_ops = entry.mesh.torch_inputs("cpu")
    basis = torch.from_numpy(entry.basis)
    with torch.no_grad():
        codes = model.encode_target(t_feat, model.image_code(t_img)[0], t_ops)
        baked = codes.basis[:, :, :53].permute(2, 0, 1)                    # (53, V, 3)
    size = basis.flatten(1).norm(dim=1)
    keep = size > 0
    return float(np.median(((baked[keep] - basis[keep]).flatten(1).norm(dim=1) / size[keep]).numpy()))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    ap.add_argument("--train", choices=("all", "decoder"), default="all")
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--every", type=int, default=50)
    ap.add_argument("--identities", type=int, nargs="+", default=[7],
                    help="seeds of the MakeHuman training identities to fit")
    ap.add_argument("--held-out", type=int, default=4, help="validation heads measured (0 = none)")
    ap.add_argument("--tessellation", default="decimated:2500:head_neck", help="kind:n_vertices:crop")
    ap.add_argument("--unstyled", action="store_true", help="fitted shapes as authored (no per-rig style)")
    ap.add_argument("--descriptor", type=int, default=0,
                    help="warm-start a model with this many skinning descriptor channels "
                         "(NFSConfig.skin_descriptor) from the checkpoint")
    ap.add_argument("--oracle-template", action="store_true",
                    help="the true template positions in descriptor channels 0-2 (needs --descriptor >= 3)")
    ap.add_argument("--batch", type=int, default=1,
                    help="heads per optimizer step (L_rig averaged over them; the training run has 1)")
    ap.add_argument("--tau", type=float, default=0.05)
    ap.add_argument("--out", default=None, help="write the curve as JSON here")
    args = ap.parse_args()
    torch.manual_seed(0)

    state = load_checkpoint(args.checkpoint)
    model = model_from_checkpoint(state, args.checkpoint)
    if args.descriptor:
        wide = NFSModel(dataclasses.replace(model.cfg, skin_descriptor=args.descriptor))
        warm_start(wide, model)
        model = wide
    if args.oracle_template:
        if args.descriptor < 3:
            raise SystemExit("--oracle-template needs --descriptor 3 or more")
        global ORACLE
        ORACLE = use_true_template(model)
    kind, n, crop = args.tessellation.split(":")
    fit = [head_entry(model, i, "train", not args.unstyled,
                      {"n_vertices": int(n), "kind": kind, "crop": crop, "seed": 3})
           for i in args.identities]
    held = [head_entry(model, i, "val", False, HELD_OUT_TESSELLATION) for i in range(args.held_out)]
    controls = {
        "same_head_other_mesh": [head_entry(model, args.identities[0], "train", not args.unstyled,
                                            HELD_OUT_TESSELLATION)],
        "other_heads_same_mesh": [head_entry(model, i, "train", not args.unstyled,
                                             {"n_vertices": int(n), "kind": kind, "crop": crop,
                                              "seed": 3})
                                  for i in range(1000, 1004)]}

    if args.train == "decoder":
        for p in model.parameters():
            p.requires_grad_(False)
        for p in model.decoder.parameters():
            p.requires_grad_(True)
    opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=args.lr)
    curve = []
    t0 = time.time()
    for step in range(args.steps + 1):
        if step % args.every == 0 or step == args.steps:
            model.eval()
            row = {"step": step, "fitted": float(np.mean([median_error(model, e) for e in fit]))}
            if held:
                row["held_out"] = float(np.mean([median_error(model, e) for e in held]))
            for name, entries in controls.items():
                row[name] = float(np.mean([median_error(model, e) for e in entries]))
            row["seconds"] = round(time.time() - t0, 1)
            curve.append(row)
            print(json.dumps(row), flush=True)
            model.train()
        if step == args.steps:
            break
        opt.zero_grad()
        for b in range(args.batch):
            entry = fit[(step * args.batch + b) % len(fit)]
            if ORACLE is not None:
                ORACLE["entry"] = entry
            t_feat, t_img, t_ops = entry.mesh.torch_inputs("cpu")
            c_t = model.image_code(t_img)[0]
            codes = model.encode_target(t_feat, c_t, t_ops, basis=False)
            present = np.ones(53, bool) if entry.present is None else entry.present
            loss = rig_loss(model, t_feat, c_t, codes, torch.from_numpy(entry.basis), None,
                            torch.from_numpy(np.flatnonzero(present)), args.tau)
            (loss / args.batch).backward()
        opt.step()
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"args": vars(args), "curve": curve}, f, indent=1)


if __name__ == "__main__":
    main()
