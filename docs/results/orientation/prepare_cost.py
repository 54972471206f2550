"""What turning heads upright costs a target's preparation (docs/RESULTS.md, "Heads that do not
face +z"): ``Retargeter.prepare`` of an 11,000-vertex MakeHuman test head (head and neck) with and
without ``upright``, warm (operators cached, median of 3), and ``upright_rotation`` and
``upright_fit`` alone.

    OMP_NUM_THREADS=1 python docs/results/orientation/prepare_cost.py
"""
from __future__ import annotations

import time

import numpy as np


def median_seconds(fn, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    from data_synth.makehuman import (base_head_rig, build_head_rig, head_tessellation,
                                      sample_head_identity)
    from retarget.api import Retargeter
    from retarget.canonical import upright_face_model, upright_fit, upright_rotation
    from retarget.mesh import Mesh

    t0 = time.perf_counter()
    upright_face_model()
    print(f"loading the face model (once per process): {time.perf_counter() - t0:.3f} s")
    tess = head_tessellation(seed=0, n_vertices=11000, kind="decimated", crop="head_neck")
    rig = build_head_rig(base_head_rig(sample_head_identity(0, "test"), "arkit"), tess, 6)
    mesh = Mesh(rig.neutral.astype(np.float64), rig.faces, "head")
    for upright in (False, True):
        r = Retargeter.load(device="cpu", upright=upright)
        r.prepare(mesh)                                     # operators computed and cached
        print(f"prepare, {mesh.n_vertices:,} vertices, upright={upright}: "
              f"{median_seconds(lambda: r.prepare(mesh)):.3f} s")
    print(f"upright_rotation alone (settles on an upright head): "
          f"{median_seconds(lambda: upright_rotation(mesh.vertices, mesh.faces)):.3f} s")
    print(f"upright_fit alone (every start): "
          f"{median_seconds(lambda: upright_fit(mesh.vertices, mesh.faces)):.3f} s")


if __name__ == "__main__":
    main()
