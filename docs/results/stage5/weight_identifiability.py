"""How accurate must a rig's shapes be for bounded least squares to recover its weights?

The artist's ARKit rig (data_synth/makehuman/data/makehuman_arkit.npz) driven by 12 sparse random
weight vectors (each weight in [0, 1], active with probability 0.3); the weights fitted back by
bounded least squares in [0, 1] on the rig's own shapes, exact or perturbed by independent noise
of a given share of each shape's mean square. Prints the shape norms and the weight MAE per share.
    python docs/results/stage5/weight_identifiability.py
"""
import numpy as np
from scipy.optimize import lsq_linear

rig = np.load("data_synth/makehuman/data/makehuman_arkit.npz")
shapes = rig["deltas"].reshape(len(rig["names"]), -1).astype(np.float64)     # (52, 3V), cm
rng = np.random.default_rng(0)
weights = rng.random((12, len(shapes))) * (rng.random((12, len(shapes))) < 0.3)
frames = weights @ shapes
norms = np.sqrt((shapes ** 2).sum(1))
print(f"shape norms (cm): min {norms.min():.3f} ({rig['names'][norms.argmin()]}), "
      f"median {np.median(norms):.3f}, max {norms.max():.3f}")
for share in (0.0, 0.01, 0.05, 0.2):
    mae = []
    for w, x in zip(weights, frames):
        noise = rng.standard_normal(shapes.shape) * np.sqrt(share * (shapes ** 2).mean(1, keepdims=True))
        fit = lsq_linear((shapes + noise).T, x, bounds=(0.0, 1.0)).x
        mae.append(np.abs(fit - w).mean())
    print(f"shapes perturbed by {share:.2f} of their mean square: weight MAE {np.mean(mae):.4f}")
