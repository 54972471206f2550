"""The face frame of MakeHuman busts against that of the same heads cut at the neck (docs/RESULTS.md,
"A bust's face frame").

For each identity of a split, the head is tessellated as a bust and as a head with its neck
(decimated, 2,000 vertices) and ``retarget.canonical.fit_face_frame`` is fitted to each; a bust
whose face width is more than 10 % off its head's is counted, with the largest ratio.

    python docs/results/face_frame/bust_scan.py --split test --identities 100
    python docs/results/face_frame/bust_scan.py --split test --rig 19 30 39   # and the model's rig

``--rig``: for those seeds instead, the median over the 53 FACS shapes of the relative error
|B̂_k − B_k| / |B_k| of the bundled model's baked rig (``Retargeter.source_rig``) on the bust and on
the head with its neck.
"""
from __future__ import annotations

import argparse

import numpy as np

from data_synth.makehuman import base_head_rig, build_head_rig, head_tessellation, sample_head_identity
from retarget.canonical import fit_face_frame


def crop_rigs(split: str, seed: int) -> dict:
    """{"head_neck", "bust"}: the identity's rig (ARKit shapes) on each crop."""
    base = base_head_rig(sample_head_identity(seed, split), "arkit")
    return {crop: build_head_rig(base, head_tessellation(seed=seed, n_vertices=2000, kind="decimated",
                                                         crop=crop), 6)
            for crop in ("head_neck", "bust")}


def rig_errors(split: str, seeds) -> None:
    from retarget.api import Retargeter
    from retarget.mesh import Mesh

    r = Retargeter.load()
    for s in seeds:
        out = []
        for crop, rig in crop_rigs(split, s).items():
            baked = r.source_rig(Mesh(rig.neutral, rig.faces)).baked.deltas.reshape(53, -1)
            true = np.asarray(rig.deltas).reshape(53, -1)
            norm = np.linalg.norm(true, axis=1)
            rel = np.linalg.norm(baked - true, axis=1)[norm > 0] / norm[norm > 0]
            out.append(f"{crop} {np.median(rel):.3f}")
        print(f"{split} seed {s}: baked rig's median relative error: " + ", ".join(out))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", default="test")
    ap.add_argument("--identities", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0, help="first identity seed")
    ap.add_argument("--rig", type=int, nargs="*", default=None, help="seeds whose baked rig to measure")
    args = ap.parse_args()
    if args.rig:
        return rig_errors(args.split, args.rig)
    ratios = []
    for s in range(args.seed, args.seed + args.identities):
        width = {crop: fit_face_frame(rig.neutral.astype(np.float64), rig.faces)[1]
                 for crop, rig in crop_rigs(args.split, s).items()}
        ratios.append(width["bust"] / width["head_neck"])
    ratios = np.array(ratios)
    off = np.flatnonzero(np.abs(ratios - 1) > 0.1)
    print(f"{args.split} identities {args.seed}..{args.seed + args.identities - 1}: busts whose face "
          f"width is >10 % off their head's: {len(off)} of {len(ratios)} "
          f"(seeds {[int(args.seed + i) for i in off]}); bust/head width ratio min {ratios.min():.3f}, "
          f"median {np.median(ratios):.3f}, max {ratios.max():.3f}")


if __name__ == "__main__":
    main()
