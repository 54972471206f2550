"""Prepare (and bake a source rig on) test-split MakeHuman heads of every crop and four kinds of
tessellation, 1,500-3,500 vertices, turned by up to 25°, and print every failure (a robustness
sweep of ``Retargeter.prepare`` and the upright fit).

    OMP_NUM_THREADS=1 python docs/results/orientation/prepare_sweep.py 0 200 > docs/results/orientation/prepare_sweep.txt
"""
import sys
import time

import numpy as np
from retarget.api import Retargeter
from retarget.mesh import Mesh
from retarget.canonical import turn_matrix
from data_synth.makehuman import head_tessellation, sample_head_identity
from data_synth.makehuman.identity import head_neutral
first, last = int(sys.argv[1]), int(sys.argv[2])
r = Retargeter.load()
crops = ("face", "head", "head_neck", "bust")
kinds = ("base", "flipped", "decimated", "jittered")
turns = [(0, 0), (-20, 0), (20, 0), (0, 25), (-12, 10)]
fails = 0; n = 0; t0 = time.time()
for s in range(first, last):
    ident = sample_head_identity(s, "test")
    bust = head_neutral(ident, "bust")
    crop, kind = crops[s % 4], kinds[(s // 4) % 4]
    tess = head_tessellation(seed=s, n_vertices=1500 + 500 * (s % 5), kind=kind, crop=crop)
    v = tess.apply(bust).astype(np.float64)
    turn = turns[s % len(turns)]
    v = v @ turn_matrix(*turn).T
    n += 1
    try:
        r.prepare(Mesh(v, tess.faces))
        r.source_rig(Mesh(v, tess.faces))
    except Exception as e:
        fails += 1
        print(f"seed {s} crop {crop} kind {kind} turn {turn} V {len(v)}: {type(e).__name__}: {e}", flush=True)
print(f"{n} heads, {fails} failures, {time.time()-t0:.0f} s")
