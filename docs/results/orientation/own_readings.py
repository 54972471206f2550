"""What a head's own shape reads, turned and cropped (docs/RESULTS.md, "Heads that do not face
+z"): ``upright_fit``'s pitch and yaw-and-roll on test head 0 of the orientation study (head and
neck, 5,000 vertices) upright and pitched ±10°; the angle between the readings of the four
crops (face, head, head_neck, bust; 2,000 vertices) of test heads 0-3; and the weights eval's
head 19 (configs/eval/weights.yaml), a stylised head.

    OMP_NUM_THREADS=1 python docs/results/orientation/own_readings.py > docs/results/orientation/own_readings.md
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from orientation import turn  # noqa: E402


def main() -> None:
    from data_synth.makehuman import (base_head_rig, build_head_rig, head_tessellation,
                                      sample_head_identity)
    from data_synth.makehuman.tessellate import CROPS
    from retarget.canonical import pitch_and_side, rotation_angle, upright_fit

    rig = build_head_rig(base_head_rig(sample_head_identity(0, "test"), "arkit"), head_tessellation(
        seed=0, n_vertices=5000, kind="decimated", crop="head_neck"), 6)
    centre = 0.5 * (rig.neutral.min(0) + rig.neutral.max(0))
    print("| test head 0 pitched | reads pitch (°) | yaw and roll (°) | RMS |\n| ---: | ---: | ---: | ---: |")
    for deg in (0, -10, 10):
        rotation, rms = upright_fit(turn(rig.neutral, "x", deg, centre), rig.faces)
        print(f"| {deg:+d}° | {pitch_and_side(rotation)[0]:.1f} | {pitch_and_side(rotation)[1]:.1f} | "
              f"{rms:.3f} |")
    print("\n| test head | largest angle between two crops' readings (°) | face crop to the others (°) |"
          "\n| ---: | ---: | ---: |")
    for seed in range(4):
        base = base_head_rig(sample_head_identity(seed, "test"), "arkit")
        reads = []
        for crop in CROPS:
            r = build_head_rig(base, head_tessellation(seed=seed, n_vertices=2000, kind="decimated",
                                                       crop=crop), 6)
            reads.append(upright_fit(r.neutral.astype(np.float64), r.faces)[0])
        angles = [[rotation_angle(a @ b.T) for b in reads] for a in reads]
        face = CROPS.index("face")
        print(f"| {seed} | {np.max(angles):.2f} | {max(a for i, a in enumerate(angles[face]) if i != face):.2f} |")
    from retarget.evaluate import EvalData, load_eval_config

    head = EvalData(load_eval_config("weights")).head_rig(19)
    rotation, rms = upright_fit(head.neutral.astype(np.float64), head.faces)
    pitch, side = pitch_and_side(rotation)
    print(f"\nThe weights eval's head 19 reads {pitch:.1f}° of pitch, {side:.1f}° of yaw and roll, "
          f"RMS {rms:.3f}.")


if __name__ == "__main__":
    main()
