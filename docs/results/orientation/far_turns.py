"""Turns beyond the reach of ``retarget.canonical.upright_fit`` (its starts span ±20° of pitch and
±25° of yaw): how far off its reading is and whether ``upright_rotation`` turns the artist's ARKit
head (docs/RESULTS.md, "Heads that do not face +z"). A mesh given with the wrong axes reads as a
turn of 90° or 180°.

    OMP_NUM_THREADS=1 python docs/results/orientation/far_turns.py > docs/results/orientation/far_turns.md
"""
from __future__ import annotations

import numpy as np

TURNS = ((-90.0, 0.0), (90.0, 0.0), (0.0, 90.0), (0.0, 180.0), (35.0, 0.0), (-35.0, 0.0),
         (0.0, 40.0), (0.0, -40.0))


def main() -> None:
    from data_synth.makehuman import assets
    from retarget.canonical import rotation_angle, turn_matrix, upright_fit, upright_rotation

    a = assets.arkit()
    v, f = a["neutral"].astype(np.float64), a["faces"]
    print("| pitch, yaw (°) | reading off by (°) | face-model RMS | upright_rotation | left over after it (°) |")
    print("| --- | ---: | ---: | --- | ---: |")
    for pitch, yaw in TURNS:
        turn = turn_matrix(pitch, yaw)
        rotation, rms = upright_fit(v @ turn.T, f)
        chosen = upright_rotation(v @ turn.T, f)
        after = rotation_angle(turn) if chosen is None else rotation_angle(chosen @ turn)
        print(f"| {pitch:+g}, {yaw:+g} | {rotation_angle(rotation @ turn):.1f} | {rms:.3f} | "
              f"{'left as it is' if chosen is None else 'turned'} | {after:.1f} |")


if __name__ == "__main__":
    main()
