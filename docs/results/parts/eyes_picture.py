"""The picture of docs/results/parts/eyes.png: the artist's ARKit head given eyeballs with a cornea
bulge (a separate part in front of each), lashes, teeth and a tongue (eyes.py's parts), driven to a
look to the face's left and up (``eyeLookOut_L``, ``eyeLookIn_R`` 1, ``eyeLookUp_L`` / ``_R``
0.6) with the eyes at rest (``turn_eyes=False``, ``--still-parts``) and turned (the default);
front views of the eyes (docs/RESULTS.md, "Eyeballs that turn with the gaze").

    OMP_NUM_THREADS=2 python docs/results/parts/eyes_picture.py
"""
from __future__ import annotations

import sys

import numpy as np
import trimesh

from data_synth.facs import FACS_INDEX
from data_synth.makehuman.segmentation import EYE, MOUTH
from retarget.api import Retargeter
from retarget.evaluate import RealRig
from retarget.mesh import Mesh
from retarget.render import contact_sheet, render_frontal, save_png

sys.path.insert(0, "docs/results/parts")
from eyes import EYE_BACK, EYE_RADIUS, assemble, head_parts  # noqa: E402

OUT = "docs/results/parts/eyes.png"
CENTRE = np.array([0.0, 72.8, 12.0])                       # cm, between the eyes
BOX = np.array([[-5.0, -2.0, -7.0], [5.0, 2.0, 7.0]])      # the framed box around CENTRE


def cornea(eye: np.ndarray):
    """A cornea bulge: the front cap of a 0.65 cm sphere standing 0.2 cm proud of the eyeball."""
    s = trimesh.creation.icosphere(subdivisions=3, radius=0.65)
    v, f = np.asarray(s.vertices), np.asarray(s.faces)
    keep = v[:, 2] > 0.25
    f = f[keep[f].all(1)]
    used = np.unique(f)
    remap = np.full(len(v), -1)
    remap[used] = np.arange(len(used))
    centre = eye - [0.0, 0.0, EYE_BACK] + [0.0, 0.0, EYE_RADIUS + 0.2 - 0.65]
    return v[used] + centre, remap[f]


def main():
    real = RealRig.load("../shared/rigs/makehuman_arkit.npz")
    mesh, _ = assemble(real.neutral, real.faces, head_parts(EYE, EYE * [-1, 1, 1], MOUTH))
    v, f = [mesh.vertices], [mesh.faces]
    n = mesh.n_vertices
    for eye in (EYE, EYE * [-1, 1, 1]):
        cv, cf = cornea(eye)
        v.append(cv)
        f.append(cf + n)
        n += len(cv)
    mesh = Mesh(np.concatenate(v), np.concatenate(f))
    w = np.zeros(53, np.float32)
    for name, value in (("eyeLookOut_L", 1.0), ("eyeLookIn_R", 1.0), ("eyeLookUp_L", 0.6),
                        ("eyeLookUp_R", 0.6)):
        w[FACS_INDEX[name]] = value
    poses = {"neutral": mesh.vertices,
             "look left and up, eyes at rest": Retargeter.load(None, turn_eyes=False).animate(mesh, w),
             "look left and up, eyes turned": Retargeter.load(None).animate(mesh, w)}
    images = [render_frontal(verts - CENTRE, mesh.faces, size=420, channels=("shaded",), fit=BOX)
              .transpose(1, 2, 0)[120:300] for verts in poses.values()]     # the band of the eyes
    save_png(OUT, contact_sheet(images, list(poses), cols=3))
    print(OUT)


if __name__ == "__main__":
    main()
