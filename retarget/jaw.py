"""Separate parts carried by the jaw: lower teeth and a tongue follow the chin.

A head given with separate parts (eyeballs, teeth, a tongue beside the skin) goes to the network
as its face alone (``retarget.mesh.face_part``), and the 53 FACS shapes say nothing of the other
parts. An artist's rig moves the lower teeth and the tongue with the jaw bone; left at rest they
stay put while the chin drops, and an open mouth shows them floating in it. This module finds
those parts on a target and moves them with the jaw of each result.

- The **chin** (:attr:`JawParts.jaw`): of the face's vertices that the target's own baked
  ``jawOpen`` moves at least ``JAW_SHARE`` of its most, the ``CHIN_SHARE`` the mouth shapes move
  least relative to ``jawOpen`` (the chin and the jaw line rather than the lower lip). The jaw's
  rigid motion in a result is fitted on them (``retarget.stabilise.rigid_fit``: Kabsch with
  Tukey's reweighting, so a lip or chin shape on top of the jaw's turn weighs little).
- The **jaw's parts** (:attr:`JawParts.carried`): every part beside the face whose median height
  in the face's canonical frame (+y up) lies below the mouth corners (where the baked
  ``mouthSmile_L`` / ``_R`` move the face most; up to ``LIFT`` mouth widths above them) and whose
  centre lies within ``REACH`` mouth widths of the mouth's centre: lower teeth and a tongue, not
  eyes, lashes or upper teeth.

``Retargeter`` (``jaw_parts``, default on; CLI ``--still-parts`` leaves them at rest) applies the
jaw's motion to those parts in every decoded frame (``transfer``, ``animate``) and bakes it into
each of the 53 shapes of ``bake`` / ``export-rig`` (each shape's jaw motion at weight 1, as a
blendshape rig stores teeth).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from data_synth.facs import FACS_NAMES

from .mesh import mesh_parts
from .stabilise import rigid_fit

JAW_SHARE = 0.5        # chin candidates: moved by jawOpen at least this share of its most
CHIN_SHARE = 0.5       # ... of which the share least moved by the mouth shapes (relative to jawOpen)
MIN_CHIN = 12          # ... but at least this many (all candidates when fewer)
CORNER_VERTICES = 10   # each mouth corner: the mean of the vertices its smile moves most
REACH = 1.0            # a jaw part's centre lies within this many mouth widths of the mouth's centre
LIFT = 0.05            # ... and its median height below the corners' + this many mouth widths (chosen
#                        on validation heads: docs/results/parts/jaw.py)
JAW = "jawOpen"
CORNERS = ("mouthSmile_L", "mouthSmile_R")
MOUTH = tuple(n for n in FACS_NAMES if n.startswith("mouth"))
#: the baked shapes :func:`find_jaw_parts` reads, in this order
SHAPES = (JAW,) + MOUTH


@dataclass(frozen=True)
class JawParts:
    """The parts of a target carried by its jaw. neutral: (V,3) float64 the target's vertices
    (its units); face: (V',) int64 the face's indices in them; jaw: (J,) int64 the chin, indices
    into the face's vertices; carried: (C,) int64 the jaw's parts' vertices, indices into the
    mesh; parts: how many separate parts they are."""

    neutral: np.ndarray
    face: np.ndarray
    jaw: np.ndarray
    carried: np.ndarray
    parts: int

    def motion(self, face_vertices: np.ndarray, neutral: np.ndarray | None = None):
        """The jaw's rigid motion (``RigidMotion``) from the neutral (V,3) (default the target's
        vertices) to a result's face vertices (V',3), fitted on the chin."""
        rest = (self.neutral if neutral is None else np.asarray(neutral, np.float64))[self.face[self.jaw]]
        return rigid_fit(np.asarray(face_vertices, np.float64)[self.jaw], rest, np.arange(len(rest)))

    def carry(self, vertices: np.ndarray) -> np.ndarray:
        """A result's vertices (V,3) (its parts at rest) -> a copy with the jaw's parts moved as
        its chin moved, (V,3) of the input's dtype."""
        out = np.array(vertices, copy=True)
        m = self.motion(out[self.face])
        rest = self.neutral[self.carried]
        out[self.carried] = rest @ m.rotation.T + m.translation
        return out

    def carry_shapes(self, deltas: np.ndarray, neutral: np.ndarray | None = None) -> np.ndarray:
        """A baked rig's shapes (K,V,3) (zero on the parts) -> a copy in which each shape moves
        the jaw's parts as it moves the chin at weight 1 (the linear blendshape of that motion).
        neutral: the rig's neutral (V,3) the shapes add to (default the target's vertices)."""
        out = np.array(deltas, copy=True)
        rest = self.neutral[self.carried]
        base = self.neutral if neutral is None else np.asarray(neutral, np.float64)
        for k, d in enumerate(out):
            m = self.motion(base[self.face] + d[self.face], base)
            out[k, self.carried] = rest @ m.rotation.T + m.translation - rest
        return out


def chin_vertices(jaw: np.ndarray, mouth: np.ndarray) -> np.ndarray | None:
    """The chin of a rig (module docstring): sorted indices (J,) int64 of its vertices, from its
    jawOpen shape (V,3) and its mouth shapes (M,V,3); None when jawOpen moves nothing."""
    jaw = np.linalg.norm(np.asarray(jaw, np.float64), axis=1)
    if not jaw.max() > 0:
        return None
    mouth = np.sqrt(np.square(np.asarray(mouth, np.float64)).sum(axis=(0, 2)))
    cand = np.flatnonzero(jaw >= JAW_SHARE * jaw.max())
    n = min(len(cand), max(MIN_CHIN, int(round(CHIN_SHARE * len(cand)))))
    return np.sort(cand[np.argsort(mouth[cand] / jaw[cand], kind="stable")[:n]]).astype(np.int64)


def find_jaw_parts(vertices: np.ndarray, faces: np.ndarray, face: np.ndarray, shapes: np.ndarray,
                   to_canonical) -> JawParts | None:
    """The jaw's parts of a mesh with separate parts (module docstring), or None when none is.

    vertices (V,3), faces (F,3): the whole mesh; face (V',) the face's indices (``face_part``);
    shapes (len(SHAPES), V', 3) the target's baked shapes ``SHAPES`` on the face (its units);
    to_canonical: maps (N,3) vertices of the mesh to the face's canonical frame (+y up)."""
    vertices = np.asarray(vertices, np.float64)
    shapes = np.asarray(shapes, np.float64)
    chin = chin_vertices(shapes[0], shapes[1:])
    if chin is None:
        return None

    canon_face = to_canonical(vertices[face])
    corners = []
    for name in CORNERS:
        moved = np.linalg.norm(shapes[SHAPES.index(name)], axis=1)
        top = np.argsort(moved, kind="stable")[-CORNER_VERTICES:]
        corners.append((canon_face[top] * moved[top, None]).sum(0) / max(moved[top].sum(), 1e-300))
    centre, width = (corners[0] + corners[1]) / 2, float(np.linalg.norm(corners[0] - corners[1]))

    labels = mesh_parts(vertices, faces)
    labels[face] = -1
    carried, parts = [], 0
    for label in np.unique(labels[labels >= 0]):
        idx = np.flatnonzero(labels == label)
        c = to_canonical(vertices[idx])
        if (np.median(c[:, 1]) < centre[1] + LIFT * width
                and np.linalg.norm(c.mean(0) - centre) <= REACH * width):
            carried.append(idx)
            parts += 1
    if not carried:
        return None
    return JawParts(vertices, np.asarray(face, np.int64), chin,
                    np.sort(np.concatenate(carried)).astype(np.int64), parts)
