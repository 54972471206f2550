"""Is the baked rig's error one of scale or of direction, and is it the same on training
identities as on held-out ones? (issue 10)

For each inversion case's source (procedural ``inverse``, realistic ``head_inverse``) the decoder's
baked one-hot shapes B̂_k on the source neutral are compared with that identity's true shapes B_k
(flattened (V·3,) displacements, mm): the gain a_k = <B̂_k, B_k> / |B̂_k|² (B_k ≈ a_k B̂_k at best),
the cosine of the angle between them, the relative error |B̂_k − B_k| / |B_k|, and the relative
error left after the best scale, sqrt(1 − cos²). Medians over shapes and identities; identities of
the ``val`` split (configs/eval/validation.yaml) and, for the same draw, of the ``train`` split.

    python docs/results/weight_mae/shape_direction.py > docs/results/weight_mae/shape_direction.md
"""
from __future__ import annotations

import argparse

import numpy as np

from breakdown import baked_and_true
from retarget.api import Retargeter
from retarget.evaluate import EvalData, load_eval_config


def shape_stats(r: Retargeter, data: EvalData, suite: str) -> dict:
    """Medians of the gain, cosine, relative error and scaled relative error (see the module doc)
    over the shapes of the suite's sources, and the spread of each shape's gain across identities
    (median over shapes of std / |mean|)."""
    gains, cos, rel = [], [], []
    for case in data.cases(suite):
        b, t, n = baked_and_true(r, case.source)
        dot = (b * t).sum(1)
        gains.append(dot / np.maximum((b * b).sum(1), 1e-20))
        cos.append(dot / np.maximum(np.linalg.norm(b, axis=1) * n, 1e-20))
        rel.append(np.linalg.norm(b - t, axis=1) / n)
    g, c, e = (np.concatenate(x) for x in (gains, cos, rel))
    spread = np.stack(gains)
    return {"gain": np.median(g), "cos": np.median(c), "rel": np.median(e),
            "rel_scaled": np.median(np.sqrt(np.clip(1 - c ** 2, 0, None))),
            "gain_spread": np.median(spread.std(0) / np.abs(spread.mean(0)))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    ap.add_argument("--splits", nargs="*", default=["val", "train"])
    args = ap.parse_args()
    r = Retargeter.load(args.checkpoint)
    print(f"{args.checkpoint}; configs/eval/validation.yaml's cases, identities of each split\n")
    print("| split | suite | gain a (median) | cosine (median) | relative error | after the best scale | gain spread across identities |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
    for split in args.splits:
        cfg = load_eval_config("configs/eval/validation.yaml")
        cfg["split"] = split          # "train": the training identities, for this study only
        data = EvalData(cfg)
        for suite in ("inverse", "head_inverse"):
            s = shape_stats(r, data, suite)
            print(f"| {split} | {suite} | {s['gain']:.3f} | {s['cos']:.3f} | {s['rel']:.3f} | "
                  f"{s['rel_scaled']:.3f} | {s['gain_spread']:.3f} |", flush=True)


if __name__ == "__main__":
    main()
