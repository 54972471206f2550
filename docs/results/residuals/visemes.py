"""How much of each frame `retarget invert --residuals` reports unexplained, on the artist's ARKit
rig (makehuman_arkit.npz, centimetres): frames its own shapes make (three ARKit shapes at 0.3-1
each, 12 frames, seed 0) against its visemes, which the artist sculpted apart from the 52 ARKit
shapes (viseme_sil, the rest pose, left out). The bundled model, the rig's neutral as the source
neutral, refine; beside it what weights 0 leave (doing nothing: the frame against the rig's
neutral) and what the artist's own 52 shapes leave (bounded least squares in [0, 1] on the true
shapes: a network with the performer's exact rig would report this). The last columns are what
`retarget transfer --residuals` reports: the codes transfer sends (neutral and refine: the weights
and the free dims fitted together) drawn back on the rig's neutral.

    python docs/results/residuals/visemes.py
"""
import numpy as np
from scipy.optimize import lsq_linear

from retarget.api import Retargeter
from retarget.mesh import Mesh

d = np.load("data_synth/makehuman/data/makehuman_arkit.npz", allow_pickle=True)
neutral_v, faces, deltas = d["neutral"], d["faces"], d["deltas"]
rng = np.random.default_rng(0)
weights = np.zeros((12, len(deltas)))
for t in range(12):
    k = rng.choice(len(deltas), 3, replace=False)
    weights[t, k] = rng.uniform(0.3, 1.0, 3)
moving = [i for i, n in enumerate(d["viseme_names"]) if np.abs(d["viseme_deltas"][i]).max() > 0]
takes = {"ARKit shapes (12 frames)": [Mesh(neutral_v + np.tensordot(w, deltas, 1), faces) for w in weights],
         f"visemes ({len(moving)})": [Mesh(neutral_v + d["viseme_deltas"][i], faces) for i in moving]}
a = deltas.reshape(len(deltas), -1).T.astype(np.float64)           # (3V, 52) the true shapes


def true_rig_share(frame: Mesh) -> float:
    b = (frame.vertices - neutral_v).reshape(-1)
    w = lsq_linear(a, b, bounds=(0.0, 1.0)).x
    return float(np.linalg.norm(a @ w - b) / np.linalg.norm(b))


r = Retargeter.load()
neutral = Mesh(neutral_v, faces)
print("| frames | share unexplained, bundled model: median | min | max | weights 0: median | the artist's own shapes: median | max | motion RMS, median (cm) | transfer's codes: median | max |")
print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
for name, frames in takes.items():
    w = r.invert(frames, source_neutral=neutral, refine=True)
    residual, motion = r.fit_residuals(frames, neutral, w)
    share = residual / motion
    nothing = r.fit_residuals(frames, neutral, np.zeros_like(w))[0] / motion
    own = np.array([true_rig_share(f) for f in frames])
    sent = r.code_residuals(frames, neutral, r.expression_codes(frames, neutral, refine=True))[0] / motion
    print(f"| {name} | {np.median(share):.3f} | {share.min():.3f} | {share.max():.3f} | "
          f"{np.median(nothing):.3f} | {np.median(own):.3f} | {own.max():.3f} | {np.median(motion):.3f} | "
          f"{np.median(sent):.3f} | {sent.max():.3f} |")
names = [str(d["viseme_names"][i]) for i in moving]
print("\nvisemes, bundled model (the artist's shapes), worst first: "
      + ", ".join(f"{n} {s:.3f} ({o:.3f})" for n, s, o in sorted(zip(names, share, own), key=lambda x: -x[1])))
