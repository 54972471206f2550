"""Transfer a frame (with the source's neutral and refine) onto, and invert a frame of, test-split
heads of other kinds than ``prepare_sweep.py``'s: procedural heads of three tessellations and two
regions, subdivided MakeHuman crops, turned by up to 40°; print every failure (a robustness sweep).

    OMP_NUM_THREADS=1 python docs/results/orientation/transfer_sweep.py 6 156 > docs/results/orientation/transfer_sweep_6_156.txt
"""
import sys
import time

import numpy as np
from retarget.api import Retargeter
from retarget.mesh import Mesh
from retarget.canonical import turn_matrix
from data_synth.identity import sample_identity
from data_synth.rig import build_rig
from data_synth.tessellate import tessellate
from data_synth.makehuman import head_tessellation, sample_head_identity, build_head_rig
first, last = int(sys.argv[1]), int(sys.argv[2])
r = Retargeter.load()
turns = [(0, 0), (-35, 0), (35, 0), (0, -40), (15, 30), (-8, -8)]
regions = ("full", "face"); ukinds = ("regular", "jittered", "adaptive")
fails = 0; n = 0; t0 = time.time()
src = build_head_rig(sample_head_identity(0, "val"), head_tessellation(seed=0, n_vertices=2000, kind="decimated", crop="head"))
frame = src.evaluate(np.random.default_rng(0).random(53) * 0.5)
for s in range(first, last):
    turn = turns[s % len(turns)]
    if s % 2:
        rig = build_rig(sample_identity(s, "test"), tessellate(seed=s, n_vertices=800 + 300 * (s % 7), kind=ukinds[s % 3], region=regions[(s // 3) % 2]))
        what = f"procedural {ukinds[s % 3]} {regions[(s // 3) % 2]}"
    else:
        crop = ("face", "head", "head_neck", "bust")[(s // 2) % 4]
        rig = build_head_rig(sample_head_identity(s, "test"), head_tessellation(seed=s, n_vertices=1200, kind="subdivided", crop=crop))
        what = f"makehuman subdivided {crop}"
    v = rig.neutral.astype(np.float64) @ turn_matrix(*turn).T
    n += 1
    try:
        tgt = Mesh(v, rig.faces)
        r.transfer([Mesh(frame, src.faces)], tgt, source_neutral=Mesh(src.neutral, src.faces), refine=True)
        r.invert([Mesh(v, rig.faces)], source_neutral=tgt, refine=True)
    except Exception as e:
        fails += 1
        print(f"seed {s} {what} turn {turn} V {len(v)}: {type(e).__name__}: {e}", flush=True)
print(f"{n} cases, {fails} failures, {time.time()-t0:.0f} s")
