"""A head cut along its UV seams (as glTF files hold one: the vertices on a seam twice): the bundled
model on the artist's ARKit head split along a seam down the back of the head, that and a seam
around each ear, or around the front of the face (a face island), each side of a seam with its own
copies of the vertices on it; 24 frames of the eval's mixed weights (seed 7), self-retargeting
(plain MSE over every vertex, mm²) and inversion, against the unsplit head; "seam gap": how far
apart the two copies of a seam vertex end up (a crack in the result). docs/RESULTS.md, "Heads
with eyes and teeth".

    OMP_NUM_THREADS=2 python docs/results/parts/seams.py > docs/results/parts/seams.txt
"""
import numpy as np
from retarget.api import Retargeter
from retarget.mesh import Mesh
from retarget.evaluate import RealRig, arkit_ict_matrix, ict_to_arkit_weights
from data_synth.sampling import sample_weights
rig = RealRig.load('../shared/rigs/makehuman_arkit.npz')
m = arkit_ict_matrix(rig.names)
w53 = sample_weights(np.random.default_rng(7), 24, mode="mixed").astype(np.float32)
a = ict_to_arkit_weights(w53, m).astype(np.float32)
frames = rig.evaluate(a)
v, f = rig.neutral.astype(np.float64), rig.faces
def split(v, f, side):
    """faces with side True get their own copies of the vertices they share with the others"""
    shared = np.intersect1d(f[side], f[~side])
    new = np.arange(len(v)); new[shared] = len(v) + np.arange(len(shared))
    f2 = np.where(side[:, None], new[f], f)
    return np.concatenate([np.arange(len(v)), shared]), f2
c = v[f].mean(1)
cuts = {
 "back seam": (c[:, 0] < 0) & (c[:, 2] < 2.0),
 "back + ears": None,
 "face island": (c[:, 2] > 8.0) & (np.abs(c[:, 0]) < 6.5),
}
ear = (np.abs(c[:, 0]) > 6.8) & (c[:, 1] > 66) & (c[:, 1] < 76) & (np.abs(c[:, 2] - 2) < 4)
r = Retargeter.load(None)
src = [Mesh(x, f) for x in frames]
base_t = r.transfer(src, Mesh(v, f), source_neutral=Mesh(v, f), refine=True)
def mse(pred, idx): return float((((pred - frames[:, idx]) * 10) ** 2).sum(-1).mean())
whole = np.arange(len(v))
print("unsplit: do nothing %.3f, self (neutral+refine) %.3f, no neutral %.3f" % (mse(np.broadcast_to(v, frames.shape), whole), mse(base_t, whole), mse(r.transfer(src, Mesh(v, f)), whole)))
inv0 = r.invert(src, source_neutral=Mesh(v, f), refine=True)
print("unsplit invert MAE %.4f (predicting 0: %.4f)" % (np.abs(ict_to_arkit_weights(inv0, m) - a)[:, m.sum(1) > 0].mean(), np.abs(a)[:, m.sum(1) > 0].mean()))
for name, side in cuts.items():
    idx, f2 = (None, None)
    if name == "back + ears":
        idx, f2 = split(v, f, cuts["back seam"])
        v2 = v[idx]
        idx2, f3 = split(v2, f2, ear)
        idx, f2 = idx[idx2], f3
    else:
        idx, f2 = split(v, f, side)
    v2 = v[idx]
    tgt = Mesh(v2, f2); sf = [Mesh(x[idx], f2) for x in frames]
    t = r.transfer(sf, tgt, source_neutral=tgt, refine=True)
    t0 = r.transfer(sf, tgt)
    inv = r.invert(sf, source_neutral=tgt, refine=True)
    gap = float(np.abs(t[:, len(v):] - t[:, idx[len(v):]]).max()) * 10 if len(idx) > len(v) else 0
    print("%-12s +%d vertices: do nothing %.3f, self (neutral+refine) %.3f, no neutral %.3f, invert MAE %.4f, seam gap up to %.2f mm" % (name, len(idx) - len(v), mse(np.broadcast_to(v2, (len(frames),) + v2.shape), idx), mse(t, idx), mse(t0, idx), np.abs(ict_to_arkit_weights(inv, m) - a)[:, m.sum(1) > 0].mean(), gap), flush=True)
