"""What ``retarget.canonical.upright_fit`` reads on heads that are upright: how far from facing +z
it finds them (pitch, and yaw and roll together) and how well its face model fits, per kind of
head (150 MakeHuman heads of each split, crops, procedural heads), and how many
``upright_rotation`` would turn (docs/RESULTS.md, "Heads that do not face +z"). The thresholds
UPRIGHT_MIN_PITCH, UPRIGHT_MIN_SIDE and UPRIGHT_MAX_RMS lie above what these read.

    OMP_NUM_THREADS=1 python docs/results/orientation/upright_reads.py > docs/results/orientation/upright_reads.md
"""
from __future__ import annotations

import numpy as np


def readings(vertices, faces) -> tuple[float, float, float, bool]:
    """(pitch °, yaw-and-roll °, face-model RMS, turned by upright_rotation)."""
    from retarget.canonical import pitch_and_side, upright_fit, upright_rotation

    vertices = np.asarray(vertices, np.float64)
    rotation, rms = upright_fit(vertices, faces)
    return (*pitch_and_side(rotation), rms, upright_rotation(vertices, faces) is not None)


def main() -> None:
    from data_synth.identity import sample_identity
    from data_synth.makehuman import (assets, base_head_rig, build_head_rig, head_tessellation,
                                      sample_head_identity)
    from data_synth.makehuman.identity import head_neutral
    from data_synth.makehuman.tessellate import CROPS
    from data_synth.rig import build_rig
    from data_synth.tessellate import tessellate

    faces = assets.heads()["full_faces"]
    groups: dict[str, list] = {}
    for split in ("train", "val", "test"):
        for seed in range(150):
            ident = sample_head_identity(seed, split)
            kind = "stylised" if ident.stylised else "regular"
            groups.setdefault(f"MakeHuman {kind}, {split}", []).append(
                readings(head_neutral(ident, "head"), faces))
    for crop in CROPS:
        for seed in range(4):
            tess = head_tessellation(seed=seed, n_vertices=2000, kind="decimated", crop=crop)
            rig = build_head_rig(base_head_rig(sample_head_identity(seed, "test"), "arkit"), tess, 6)
            groups.setdefault(f"MakeHuman test heads, {crop} crop (2,000 vertices)", []).append(
                readings(rig.neutral, rig.faces))
    for seed in range(12):
        rig = build_rig(sample_identity(seed, split="test"), tessellate(2500, "adaptive", region="full", seed=0))
        groups.setdefault("procedural test heads", []).append(readings(rig.neutral, rig.faces))
    from retarget.canonical import UPRIGHT_MAX_RMS

    print("| heads | count | pitch: median / max (°) | yaw and roll: median / max (°) | "
          "face-model RMS: min / median / max | fit (RMS ≤ gate) | pitch / yaw and roll of those: "
          "max (°) | turned |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for name, rows in groups.items():
        r = np.array(rows, np.float64)
        fit = r[r[:, 2] <= UPRIGHT_MAX_RMS]
        fit_max = f"{fit[:, 0].max():.1f} / {fit[:, 1].max():.1f}" if len(fit) else "—"
        print(f"| {name} | {len(r)} | {np.median(r[:, 0]):.1f} / {r[:, 0].max():.1f} | "
              f"{np.median(r[:, 1]):.1f} / {r[:, 1].max():.1f} | {r[:, 2].min():.3f} / "
              f"{np.median(r[:, 2]):.3f} / {r[:, 2].max():.3f} | {len(fit)} | {fit_max} | "
              f"{int(r[:, 3].sum())} |")


if __name__ == "__main__":
    main()
