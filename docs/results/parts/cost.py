"""What telling a mesh's parts apart costs (docs/RESULTS.md, "Heads with eyes and teeth"):
``retarget.mesh.face_part`` on icospheres of 10k-655k vertices (one part: the check every target
and source neutral now pays), and on the same with a small second part (an icosphere four subdivisions
coarser, 0.4 % of the vertices: the welding pass runs too); median of 5 runs, warm.

    OMP_NUM_THREADS=1 python docs/results/parts/cost.py > docs/results/parts/cost.md
"""
from __future__ import annotations

import time

import numpy as np
import trimesh

from retarget.mesh import Mesh, face_part


def seconds(mesh: Mesh) -> float:
    face_part(mesh)
    runs = []
    for _ in range(5):
        t = time.perf_counter()
        face_part(mesh)
        runs.append(time.perf_counter() - t)
    return float(np.median(runs))


def main():
    print("| vertices | one part | with a small second part |")
    print("| ---: | ---: | ---: |")
    for sub in (5, 7, 8):
        s = trimesh.creation.icosphere(subdivisions=sub)
        one = Mesh(s.vertices * 10.0, s.faces)
        eye = trimesh.creation.icosphere(subdivisions=max(1, sub - 4))
        two = Mesh(np.concatenate([one.vertices, eye.vertices * 0.5]),
                   np.concatenate([one.faces, eye.faces + one.n_vertices]))
        print(f"| {one.n_vertices:,} | {seconds(one):.3f} s | {seconds(two):.3f} s |")


if __name__ == "__main__":
    main()
