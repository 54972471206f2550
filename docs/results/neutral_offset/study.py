"""Study: does subtracting the code of the source's neutral help the neutral mode?

The bundled encoder, given the source's neutral, reads the neutral itself as a small expression
(on the ARKit rig's head mouthClose 0.22, ...), which decodes to a floor of spurious motion. A
variant encodes the neutral as a frame once and subtracts alpha times its code from every frame's
code (z - alpha z(neutral)). Run on the tuning set (configs/eval/study.yaml, seed 100), neutral
mode, beside alpha = 0 (the bundled behaviour):

    OMP_NUM_THREADS=1 python docs/results/neutral_offset/study.py CHECKPOINT OUT.json
"""
import json
import sys

import numpy as np

from retarget.api import Retargeter
from retarget.evaluate import DoNothingMethod, Evaluation, NetworkMethod, load_eval_config

ALPHAS = (0.0, 0.5, 1.0)
SUITES = ("self", "real_rig", "head_self", "head_cross_identity")


class OffsetRetargeter(Retargeter):
    """A Retargeter whose ``encode`` with a source neutral subtracts alpha z(neutral)."""
    alpha = 0.0

    def encode(self, frames, source_neutral=None, progress=False):
        z = super().encode(frames, source_neutral, progress)
        if source_neutral is None or self.alpha == 0.0:
            return z
        return z - self.alpha * super().encode(source_neutral, source_neutral)


def main(checkpoint: str, out: str) -> None:
    cfg = load_eval_config("configs/eval/study.yaml")
    cfg["seed"] = 100
    results, data = {}, None
    for alpha in ALPHAS:
        r = OffsetRetargeter.load(checkpoint)
        r.alpha = alpha
        name = f"alpha {alpha}"
        ev = Evaluation(cfg, [NetworkMethod(name, r, "neutral")] + ([DoNothingMethod()] if data is None else []),
                        progress=False, data=data)
        data = ev.data
        for s, v in ev.run(SUITES)["suites"].items():
            results.setdefault(s, {}).update(v["methods"])
        for s in SUITES:
            e = results[s][name]
            e = e["sampled"]["real_to_real"]["mse_mm2"] if s == "real_rig" else e["seg_mse_mm2"]
            print(f"{name}  {s}: {e:.4g}", flush=True)
        with open(out, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
