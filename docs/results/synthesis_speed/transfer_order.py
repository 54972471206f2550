"""Deformation transfer's sparse factorisation, timed: SuperLU with its default column order
(COLAMD, partial pivoting) against the symmetric order and diagonal pivots that
``data_synth.makehuman.transfer`` uses for its SPD anchored Laplacian, on the source rigs of
``base_head_rig`` (the ARKit and unit shapes of training identities 0..N-1). Prints the seconds of
each over all rigs and the largest difference of their outputs (cm). The factor cache of
``transfer`` (``FACTOR_CACHE_BYTES``) is switched off, so that every shape is factorised.

    OMP_NUM_THREADS=1 python docs/results/synthesis_speed/transfer_order.py --identities 4
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.sparse.linalg import splu

import data_synth.makehuman.expressions as expressions
import data_synth.makehuman.transfer as transfer
from data_synth.makehuman import base_head_rig, sample_head_identity


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--identities", type=int, default=4)
    args = ap.parse_args()
    transfer.FACTOR_CACHE_BYTES = 0
    calls = []   # the arguments of every deformation_transfer call base_head_rig makes
    solve = transfer.deformation_transfer
    expressions.deformation_transfer = lambda *a: (calls.append(a), solve(*a))[1]
    for seed in range(args.identities):
        for kind in ("arkit", "units"):
            base_head_rig(sample_head_identity(seed, "train", 0.15, 0.3), kind, None)
    seconds = {"symmetric order (used)": 0.0, "default order": 0.0}
    largest = 0.0
    for a in calls:
        t = time.perf_counter()
        used = solve(*a)
        seconds["symmetric order (used)"] += time.perf_counter() - t
        transfer.splu = lambda m, **_: splu(m)   # SuperLU's defaults
        try:
            t = time.perf_counter()
            default = solve(*a)
            seconds["default order"] += time.perf_counter() - t
        finally:
            transfer.splu = splu
        largest = max(largest, float(np.abs(used - default).max()))
    for name, s in seconds.items():
        print(f"{name}: {s:.2f} s for {len(calls)} rigs")
    print(f"largest difference of the outputs: {largest:.1e} cm")


if __name__ == "__main__":
    main()
