"""The picture of docs/results/parts/jaw.png: the artist's ARKit head given eyeballs, teeth and a
tongue (jaw.py's parts), driven to jawOpen 0.8 with the parts at rest (``carry_jaw=False``,
``--still-parts``) and carried by the jaw (the default); front views, and side views with the
skin's left half cut away (docs/RESULTS.md, "Heads with eyes and teeth").

    OMP_NUM_THREADS=2 python docs/results/parts/jaw_picture.py
"""
from __future__ import annotations

import sys

import numpy as np

from data_synth.facs import FACS_INDEX
from data_synth.makehuman.segmentation import EYE, MOUTH
from retarget.api import Retargeter
from retarget.evaluate import RealRig
from retarget.render import contact_sheet, render_frontal, save_png

sys.path.insert(0, "docs/results/parts")
from jaw import assemble, head_parts  # noqa: E402

OUT = "docs/results/parts/jaw.png"
CENTRE = np.array([0.0, 66.0, 12.0])                       # cm, near the mouth
BOX = np.array([[-7.0, -6.5, -7.0], [7.0, 6.5, 7.0]])      # the framed box around CENTRE
SIDE = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])   # the cut seen from +x


def main():
    real = RealRig.load("../shared/rigs/makehuman_arkit.npz")
    mesh, _ = assemble(real.neutral, real.faces, head_parts(EYE, EYE * [-1, 1, 1], MOUTH))
    w = np.zeros(53, np.float32)
    w[FACS_INDEX["jawOpen"]] = 0.8
    poses = {"neutral": mesh.vertices,
             "jawOpen 0.8, parts at rest": Retargeter.load(None, carry_jaw=False).animate(mesh, w),
             "jawOpen 0.8, carried by the jaw": Retargeter.load(None).animate(mesh, w)}
    skin = (mesh.faces < len(real.neutral)).all(1)
    cut = mesh.faces[~(skin & (mesh.vertices[mesh.faces][:, :, 0] > 0.0).any(1))]
    images, labels = [], []
    for view, faces, rot in (("front", mesh.faces, np.eye(3)), ("side, cut", cut, SIDE)):
        for name, verts in poses.items():
            img = render_frontal((verts - CENTRE) @ rot.T, faces, size=320, channels=("shaded",), fit=BOX)
            images.append(img.transpose(1, 2, 0))
            labels.append(f"{name} ({view})")
    save_png(OUT, contact_sheet(images, labels, cols=3))
    print(OUT)


if __name__ == "__main__":
    main()
