"""How far apart are realistic heads' rigs, against how far the network's baked rig is from them?

For the four validation heads (shapes as authored), the median over shapes of the relative error
|B̂_k − B_k| / |B_k| of:
- the bundled model's baked rig on the head's own neutral (3,000 decimated vertices, as the eval);
- the average rig of 24 training heads, in vertex correspondence (MakeHuman's base mesh layout,
  3,386 vertices), and the nearest of those 24 rigs: what a predictor that knew where each vertex
  lies on the face could start from;
- closest-point transfer in the face frame from each of three training heads (6,000 jittered
  vertices): what a predictor that drew shapes by canonical position alone would get.
All rigs in each head's canonical units (the face frame), so the heads' sizes do not count.

  OMP_NUM_THREADS=1 python docs/results/weight_mae/overfit/rig_baselines.py
"""
from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial import cKDTree

from retarget.checkpoint import load_checkpoint, model_from_checkpoint

from overfit_rig import HELD_OUT_TESSELLATION, head_entry, median_error

BASE_LAYOUT = {"n_vertices": 3386, "kind": "base", "crop": "head_neck", "seed": 0}
DENSE = {"n_vertices": 6000, "kind": "jittered", "crop": "head_neck", "seed": 1}


def median_relative(pred: np.ndarray, true: np.ndarray) -> float:
    """Median over the shapes with |B_k| > 0 of |pred_k − B_k| / |B_k|; both (53, V, 3)."""
    size = np.linalg.norm(true.reshape(len(true), -1), axis=1)
    keep = size > 0
    err = np.linalg.norm((pred - true).reshape(len(true), -1), axis=1)
    return float(np.median(err[keep] / size[keep]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    args = ap.parse_args()
    model = model_from_checkpoint(load_checkpoint(args.checkpoint), args.checkpoint)
    model.eval()
    train = [head_entry(model, i, "train", False, BASE_LAYOUT) for i in range(100, 124)]
    mean = np.mean([e.basis for e in train], 0)
    dense = [head_entry(model, i, "train", False, DENSE) for i in (100, 101, 102)]
    print("| validation head | baked rig (model) | average of 24 training rigs | nearest training rig "
          "| closest point in the face frame (3 training heads) |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for i in range(4):
        on_eval = head_entry(model, i, "val", False, HELD_OUT_TESSELLATION)
        on_base = head_entry(model, i, "val", False, BASE_LAYOUT)
        closest = []
        for src in dense:
            _, idx = cKDTree(src.mesh.feat[:, :3]).query(on_eval.mesh.feat[:, :3])
            closest.append(median_relative(src.basis[:, idx], on_eval.basis))
        print(f"| {i} | {median_error(model, on_eval):.3f} | {median_relative(mean, on_base.basis):.3f} | "
              f"{min(median_relative(t.basis, on_base.basis) for t in train):.3f} | "
              f"{' / '.join(f'{c:.3f}' for c in closest)} |")


if __name__ == "__main__":
    main()
