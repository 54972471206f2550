"""Deformation transfer with its factorisations kept (``data_synth.makehuman.transfer``,
``FACTOR_CACHE_BYTES``) against factorising every shape anew, on the ARKit rigs of training
identities 0..N-1 (``identity_expressions``, as ``base_head_rig`` calls it). Prints the seconds per
identity of each (the cached run's first identity, which fills the cache, apart), whether the
outputs are bit-identical, and the cache's size.

    OMP_NUM_THREADS=1 python docs/results/synthesis_speed/transfer_cache.py --identities 6
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import data_synth.makehuman.transfer as transfer
from data_synth.makehuman import assets, head_neutral, sample_head_identity
from data_synth.makehuman.expressions import identity_expressions


def timed(neutrals, races) -> tuple[list[float], list[np.ndarray]]:
    seconds, outputs = [], []
    for neutral, race in zip(neutrals, races):
        t = time.perf_counter()
        outputs.append(identity_expressions(neutral, race, "arkit")[0])
        seconds.append(time.perf_counter() - t)
    return seconds, outputs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--identities", type=int, default=6)
    args = ap.parse_args()
    idents = [sample_head_identity(s, "train", 0.15, 0.3) for s in range(args.identities)]
    neutrals = [head_neutral(i)[:assets.N_HEAD] for i in idents]
    races = [i.macros["race"] for i in idents]
    limit = transfer.FACTOR_CACHE_BYTES
    transfer.FACTOR_CACHE_BYTES = 0
    fresh, out_fresh = timed(neutrals, races)
    transfer.FACTOR_CACHE_BYTES = limit
    cached, out_cached = timed(neutrals, races)
    same = all(np.array_equal(a, b) for a, b in zip(out_fresh, out_cached))
    size = sum(b for _, b in transfer._factors.values()) / 2**20
    print(f"factorising every shape: {np.median(fresh):.3f} s per identity (median of {len(fresh)})")
    print(f"factorisations kept: first identity {cached[0]:.3f} s, then {np.median(cached[1:]):.3f} s "
          f"per identity (median of {len(cached) - 1})")
    print(f"bit-identical shapes: {same}; cache: {len(transfer._factors)} factorisations, {size:.0f} MB")


if __name__ == "__main__":
    main()
