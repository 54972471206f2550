"""How many frames ``Retargeter.estimate_neutral`` needs: the artist's ARKit rig of the default
eval config (its 12 sampled expressions, as in ``retarget eval``'s real_rig suite), self-retargeted
from the first T frames of the take with no neutral, with the neutral estimated from those T
frames (then ``refine``), and with the rig's true neutral (then ``refine``); MSE in mm² against
the rig's exact frames, and the estimate's own error (mean squared distance to the true neutral).

    OMP_NUM_THREADS=1 python docs/results/estimate_neutral/take_length.py [CHECKPOINT] > docs/results/estimate_neutral/take_length.md
"""
import sys

import numpy as np

from retarget.api import Retargeter
from retarget.evaluate import EvalData, load_eval_config
from retarget.mesh import Mesh
from retarget.metrics import squared_errors_mm2

LENGTHS = (1, 2, 3, 4, 6, 8, 12)


def main(checkpoint=None) -> None:
    case = EvalData(load_eval_config(None)).real_cases()["sampled"]["real_to_real"]
    r = Retargeter.load(checkpoint, device="cpu")
    faces, truth = case.source.faces, Mesh(case.source.neutral, case.source.faces)
    target = r.prepare(Mesh(case.target.neutral, case.target.faces))
    frames = [Mesh(f, faces) for f in case.source_frames]

    def error(z, t):
        return float(squared_errors_mm2(r.decode(target, z.reshape(t, -1)), case.gt[:t]).mean())

    print("| frames T | do nothing | no neutral | estimated neutral + refine | true neutral + refine "
          "| estimate vs true neutral (mm²) |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: |")
    for t in LENGTHS:
        take = frames[:t]
        est = r.estimate_neutral(take)
        nothing = float(squared_errors_mm2(np.repeat(case.target.neutral[None], t, 0), case.gt[:t]).mean())
        row = [nothing, error(r.expression_codes(take), t),
               error(r.expression_codes(take, source_neutral=est, refine=True), t),
               error(r.expression_codes(take, source_neutral=truth, refine=True), t),
               float(np.square(est.vertices - truth.vertices).sum(-1).mean() * 100)]
        print(f"| {t} | " + " | ".join(f"{x:.4g}" for x in row) + " |")


if __name__ == "__main__":
    main(*sys.argv[1:])
