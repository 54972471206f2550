"""How accurate must the source's baked rig be for inverse rigging's weights to reach a weight MAE
of 0.05 (issue 10)? The baked rig B̂ of the bundled model is moved towards each identity's true
shapes B: B(α) = B + α (B̂ − B), α = 1 the decoder's own rig, α = 0 the true one; the frames of
the inversion cases are then fitted on B(α) exactly as ``invert --refine`` fits them on B̂
(``SourceRig.fit`` with the encoder's weights as the prior), with the bundled priors and with
weaker ones (``FITS``), and the MAE reported by kind of expression (``breakdown.py``). Tuning set
(configs/eval/study.yaml, seed 100).

    python docs/results/weight_mae/rig_accuracy.py > docs/results/weight_mae/rig_accuracy.md
"""
from __future__ import annotations

import numpy as np

from breakdown import KINDS, row_kind
from retarget.api import BakedRig, Retargeter, SourceRig
from retarget.evaluate import EvalData, load_eval_config
from retarget.mesh import Mesh

ALPHAS = (1.0, 0.75, 0.5, 0.25, 0.1, 0.0)
#: name -> (prior, sparsity, reweight) of ``SourceRig.fit``; None: the bundled invert's
FITS = {"bundled": None, "prior 0.01": (0.01, 0.02, (0.1, 0.05, 2)), "prior 1e-3": (1e-3, 0.0, ()),
        "prior 1e-5": (1e-5, 0.0, ())}


def main():
    cfg = load_eval_config("configs/eval/study.yaml")
    cfg["seed"] = 100
    data = EvalData(cfg)
    r = Retargeter.load("retarget/checkpoints/default.pt")
    print("| suite | α | baked shapes' median relative error | fit | "
          + " | ".join(f"{k} MAE" for k in KINDS + ("all",)) + " |")
    print("| --- | ---: | ---: | --- |" + " ---: |" * (len(KINDS) + 1))
    for suite in ("inverse", "head_inverse"):
        prepared = []
        for case in data.cases(suite):
            neutral = Mesh(case.source.neutral, case.source.faces)
            frames = [Mesh(f, case.source.faces) for f in case.source_frames]
            w0 = np.clip(r.invert(frames, source_neutral=neutral), 0.0, 1.0)   # the encoder's
            prepared.append((case, w0, r.source_rig(neutral).baked))
        for alpha in ALPHAS:
            rigs, rels = [], []
            for case, w0, baked in prepared:
                true = case.source.deltas.astype(np.float32)
                deltas = true + alpha * (baked.deltas - true)
                norm = np.linalg.norm(true.reshape(53, -1), axis=1)
                keep = norm > 0
                rels.append(np.median(np.linalg.norm((deltas - true).reshape(53, -1), axis=1)[keep]
                                      / norm[keep]))
                rigs.append(SourceRig.make(None, BakedRig(case.source.neutral.astype(np.float32), deltas)))
            for name, fit in FITS.items():
                prior, sparsity, reweight = fit or (r.REFINE_PRIOR_INVERT, r.REFINE_SPARSITY_INVERT,
                                                    r.REFINE_REWEIGHT_INVERT)
                kinds, maes = [], []
                for (case, w0, _), rig in zip(prepared, rigs):
                    for frame, prior_w, gt in zip(case.source_frames, w0, case.source_weights):
                        w = rig.fit(frame, prior_w, prior, sparsity, reweight)
                        kinds.append(row_kind(gt))
                        maes.append(np.abs(w - gt).mean())
                kinds, maes = np.array(kinds), np.array(maes)
                cells = [f"{maes[kinds == k].mean():.4f}" if (kinds == k).any() else "—" for k in KINDS]
                print(f"| {suite} | {alpha} | {np.mean(rels):.3f} | {name} | " + " | ".join(cells)
                      + f" | {maes.mean():.4f} |", flush=True)


if __name__ == "__main__":
    main()
