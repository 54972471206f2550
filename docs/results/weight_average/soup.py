"""Two fine-tunes of one network averaged weight by weight (docs/RESULTS.md, "Averaging the
bundled model with a fine-tune"): θ = (1 − α) θ_A + α θ_B over every floating-point tensor of the
two models (integer buffers from A), with the code map refitted on the averaged network as
``retarget train`` fits it at export (``retarget.code_map.fit_code_map`` with the code_map section
of B's training config). A and B must have the same model config.

    python docs/results/weight_average/soup.py A.pt B.pt --alpha 0.5 --out runs/soup50.pt
"""
from __future__ import annotations

import argparse

import torch

from retarget.api import Retargeter
from retarget.checkpoint import load_checkpoint, model_from_checkpoint, put_code_map, save_checkpoint
from retarget.code_map import fit_code_map


def average(a: dict, b: dict, alpha: float) -> dict:
    """The state dicts a and b (same keys and shapes) mixed as (1 − alpha) a + alpha b."""
    if a.keys() != b.keys():
        raise SystemExit("the two checkpoints hold different networks")
    return {k: ((1 - alpha) * a[k] + alpha * b[k]) if a[k].is_floating_point() else a[k].clone()
            for k in a}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--alpha", type=float, required=True, help="B's share, in [0, 1]")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    sa, sb = load_checkpoint(args.a), load_checkpoint(args.b)
    if sa["model_config"] != sb["model_config"]:
        raise SystemExit(f"{args.a} and {args.b} have different model configs")
    state = {k: sb[k] for k in ("format", "model_config", "train_config", "step")}
    state["model"] = average(sa["model"], sb["model"], args.alpha)
    model = model_from_checkpoint(state, args.out)
    c = sb["train_config"]["code_map"]
    if c["identities"]:
        put_code_map(state, *fit_code_map(Retargeter(model, torch.device("cpu")), c["identities"],
                                          c["seed"], c["ridge"], c["gated"]))
    save_checkpoint(args.out, state)
    print(f"wrote {args.out} (alpha {args.alpha})")


if __name__ == "__main__":
    main()
