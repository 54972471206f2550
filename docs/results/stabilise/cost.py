"""What stabilisation costs (docs/RESULTS.md, "Frames that move as a whole"): on the bench's
11k-vertex procedural head, one frame per call, invert with the neutral with and without
``Retargeter(stabilise=...)``, each with and without refine (median ms a frame over REPEATS
alternating rounds of FRAMES frames), and ``stabilise_frames`` alone; then on the bench's
100k-vertex head, the first call with a new neutral (whose rest vertices come from its proxy's
rig) with and without stabilisation, the peak resident memory, and what a 9-degree turn leaves.

    OMP_NUM_THREADS=2 python docs/results/stabilise/cost.py
"""
from __future__ import annotations

import resource
import time

import numpy as np

FRAMES = 30
REPEATS = 3


def main() -> None:
    from scipy.spatial.transform import Rotation

    from retarget.api import Retargeter
    from retarget.bench import procedural_head
    from retarget.mesh import Mesh

    r = Retargeter.load()
    head = procedural_head(11_000)
    rng = np.random.default_rng(0)
    frames = [Mesh(head.vertices + rng.normal(size=head.vertices.shape) * 0.001, head.faces)
              for _ in range(FRAMES)]
    r.invert(frames[0], source_neutral=head, refine=True)              # bake and cache first
    times = {(s, f): [] for s in (True, False) for f in (False, True)}
    for _ in range(REPEATS):
        for stabilise, refine in times:
            r.stabilise = stabilise
            t = time.perf_counter()
            for f in frames:
                r.invert(f, source_neutral=head, refine=refine)
            times[(stabilise, refine)].append((time.perf_counter() - t) / FRAMES * 1e3)
    r.stabilise = True
    print(f"11k vertices ({head.n_vertices}), one frame per call, median of {REPEATS} x {FRAMES}:")
    for (stabilise, refine), v in times.items():
        print(f"  invert{' --refine' if refine else ''}, stabilise={stabilise}: "
              f"{np.median(v):.1f} ms a frame")
    t = time.perf_counter()
    for f in frames:
        r.stabilise_frames(f, head)
    print(f"  stabilise_frames alone: {(time.perf_counter() - t) / FRAMES * 1e3:.2f} ms a frame")

    big = procedural_head(100_000)
    frame = Mesh(big.vertices + 0.001, big.faces)
    for stabilise in (True, False):
        r = Retargeter.load(stabilise=stabilise)
        t = time.perf_counter()
        r.encode(frame, source_neutral=big)
        print(f"{big.n_vertices} vertices: first encode with a new neutral, stabilise={stabilise}: "
              f"{time.perf_counter() - t:.2f} s")
        if stabilise:
            print(f"  peak resident memory so far: "
                  f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6:.2f} GB")
            q = Rotation.from_rotvec([0.05, 0.1, 0.0]).as_matrix()
            turned = Mesh(big.vertices @ q.T + [0.5, 0.0, 0.2], big.faces)
            t = time.perf_counter()
            (out,), (motion,) = r.stabilise_frames(turned, big)
            print(f"  stabilise a {motion.angle_degrees():.1f}-degree turn: "
                  f"{(time.perf_counter() - t) * 1e3:.1f} ms; largest error left "
                  f"{np.abs(out.vertices - big.vertices).max():.1e} (units of the head, cm)")


if __name__ == "__main__":
    main()
