"""The floor: what a checkpoint makes of a face that does not move. Each head's neutral is given
as the source frame and transferred onto itself, without and with its neutral. The MSE in mm²
against the unmoved neutral is printed, with the largest FACS weight the encoder reads.

Heads, all on the skin cut of the ARKit rig (3,386 vertices, eyes and mouth open):
- the ARKit rig's own neutral, which is MakeHuman's raw base mesh (no macro targets);
- MakeHuman's default human (every macro at its default, ethnicity 1/3 each) with its macro
  targets scaled by s = 1 (as every training head has them) down to 0 (the raw base mesh);
- the eval's first three realistic test heads (``EvalData.head_rig``; their own crop).

    OMP_NUM_THREADS=2 python docs/results/floor/floor.py NAME=CHECKPOINT [NAME=CHECKPOINT ...]
"""
import sys

import numpy as np

from data_synth.facs import FACS_NAMES
from data_synth.makehuman import assets
from data_synth.makehuman.identity import HeadIdentity, category_values, head_neutral, macro_weights
from retarget.api import Retargeter
from retarget.evaluate import EvalData, RealRig, load_eval_config, real_rig_path
from retarget.mesh import Mesh

MACRO_SCALES = (1.0, 0.5, 0.25, 0.1, 0.0)


def default_human(scale: float) -> np.ndarray:
    """The default human's head (4326,3) cm with its macro targets times ``scale``."""
    z = assets.heads()
    vals = category_values(gender=0.5, age=0.5, muscle=0.5, weight=0.5, height=0.5,
                           proportions=0.5, race=np.full(3, 1 / 3))
    w = np.zeros(len(z["target_names"]), np.float32)
    w[z["macro_target"]] = macro_weights(z["macro_vars"], vals) * scale
    extra = macro_weights(z["bust_extra_macro_vars"], vals) * scale
    return head_neutral(HeadIdentity(w, extra, {}, 0, "test", False))


def heads() -> list[tuple[str, np.ndarray, np.ndarray]]:
    cfg = load_eval_config()
    rig = RealRig.load(real_rig_path(cfg))
    out = [("ARKit rig (raw base mesh)", rig.neutral, rig.faces)]
    out += [(f"default human, macros x{s}", default_human(s)[:len(rig.neutral)], rig.faces)
            for s in MACRO_SCALES]
    data = EvalData(cfg)
    out += [(f"test head {i}", data.head_rig(i).neutral, data.head_rig(i).faces) for i in range(3)]
    return out


def floor(r: Retargeter, vertices: np.ndarray, faces: np.ndarray) -> list[str]:
    neutral = Mesh(np.asarray(vertices, np.float32), faces)
    cells = []
    for given in (None, neutral):
        z = r.encode(neutral, source_neutral=given)
        mse = float((((r.decode(neutral, z) - vertices) * 10.0) ** 2).sum(-1).mean())
        k = int(np.argmax(z[:53]))
        cells.append(f"{mse:.3f} ({FACS_NAMES[k]} {z[k]:.2f})")
    return cells


if __name__ == "__main__":
    print("| model | head | no neutral: mm² (largest weight) | with its neutral |")
    print("| --- | --- | --- | --- |")
    for arg in sys.argv[1:]:
        name, path = arg.split("=", 1)
        r = Retargeter.load(path)
        for label, v, f in heads():
            print(f"| {name} | {label} | " + " | ".join(floor(r, v, f)) + " |", flush=True)
