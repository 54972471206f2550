"""Which baked shapes, and which face segments, carry the realistic heads' rig error.

For the four validation heads (``overfit_rig.HELD_OUT_TESSELLATION``, shapes as authored): the 12
worst and 8 best shapes by relative error |B̂_k − B_k| / |B_k| (mean over the heads), and each
segment's share of the squared error (each shape's error relative to its size, summed over the
segment's vertices).

  OMP_NUM_THREADS=1 python docs/results/weight_mae/overfit/shape_and_segment_errors.py [CHECKPOINT]
"""
import sys

import numpy as np
import torch

from data_synth.facs import FACS_INDEX
from overfit_rig import HELD_OUT_TESSELLATION, head_entry
from retarget.checkpoint import load_checkpoint, model_from_checkpoint

names = sorted(FACS_INDEX, key=FACS_INDEX.get)
path = sys.argv[1] if len(sys.argv) > 1 else "retarget/checkpoints/default.pt"
m = model_from_checkpoint(load_checkpoint(path), path)
m.eval()
rel_all = []; seg_err = {}
for i in range(4):
    e = head_entry(m, i, "val", False, HELD_OUT_TESSELLATION)
    f, img, o = e.mesh.torch_inputs("cpu")
    with torch.no_grad():
        codes = m.encode_target(f, m.image_code(img)[0], o)
    baked = codes.basis[:, :, :53].permute(2, 0, 1).numpy(); true = e.basis
    size = np.linalg.norm(true.reshape(53, -1), axis=1)
    rel = np.linalg.norm((baked - true).reshape(53, -1), axis=1) / np.maximum(size, 1e-12)
    rel_all.append(rel)
    err_v = ((baked - true) ** 2).sum(-1) / np.maximum(size[:, None] ** 2, 1e-12)   # (53,V) share of each shape's |B|^2
    segs = e.rig.segments
    for s in np.unique(segs):
        seg_err.setdefault(e.rig.segment_names[s], []).append(err_v[:, segs == s].sum(1).mean())
rel = np.mean(rel_all, 0)
order = np.argsort(rel)
print("worst:", [(names[k], round(float(rel[k]), 2)) for k in order[::-1][:12]])
print("best:", [(names[k], round(float(rel[k]), 2)) for k in order[:8]])
tot = sum(np.mean(v) for v in seg_err.values())
print("squared error share by segment:", sorted(((k, round(float(np.mean(v) / tot), 3)) for k, v in seg_err.items()), key=lambda t: -t[1]))
