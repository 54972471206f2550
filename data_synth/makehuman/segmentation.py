"""The 24 / 20 / 14 / 6 facial regions on the MakeHuman head, defined once on its base vertices.

The regions and their merges are those of the procedural heads (``data_synth.segmentation``):
the finest 24 are written here with landmarks of the hm08 base head (cm, its own frame: eye
centres from the lid-margin loops, the mouth centre from the inner lip margin, nose tip, chin).
Every identity, crop and tessellation takes its labels from these through its correspondence to
the base vertices, so the labels agree across all of them.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..segmentation import _FINE, _FINE_TO, SEGMENT_NAMES, region_painter
from . import assets

EYE = np.array([3.24, 72.82, 13.40])      # left (+x) eye centre; the right one mirrors it
EYE_HALF_W = 1.16
MOUTH = np.array([0.0, 66.19, 14.46])     # mouth centre (inner lip margin)
MOUTH_HALF_W = 2.5
NOSE_TIP_Y = 69.09
CHIN_Y = 61.56


def _fine_labels(v: np.ndarray, part: np.ndarray) -> np.ndarray:
    """Finest labels (V,) int64 of the base vertices v (V,3) cm; part (V,) int: 0 skin, 1 mouth
    cavity, 2/3 eye sockets, 4 bust."""
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    side, left = np.abs(x), x >= 0
    lab = np.full(len(v), _FINE.index("scalp"), np.int64)
    put = region_painter(lab, left)

    front = z > 9.0 - 0.25 * np.maximum(0, EYE[1] + 4 - y)    # the face, not the sides of the head
    put(front & (y >= EYE[1] + 3.0) & (y < EYE[1] + 8.0), "forehead_L", "forehead_R")
    put(front & (y >= MOUTH[1] + 0.5) & (y < EYE[1] + 3.0), "cheek_L", "cheek_R")
    put((z > 4.0) & (y < MOUTH[1] + 0.5) & (y > CHIN_Y - 3.5), "jaw_L", "jaw_R")
    dx, dy = side - EYE[0], y - EYE[1]
    put(front & (np.abs(dx) < 2.9) & (dy >= 1.1) & (dy < 3.0), "brow_L", "brow_R")
    near_eye = (np.abs(dx) < EYE_HALF_W + 0.6) & (z > 11.0)
    put(near_eye & (dy >= 0.0) & (dy < 1.1), "upper_eyelid_L", "upper_eyelid_R")
    put(near_eye & (dy < 0.0) & (dy > -0.9), "lower_eyelid_L", "lower_eyelid_R")
    put((side < 1.0) & (y >= NOSE_TIP_Y + 0.8) & (y < EYE[1] + 1.1) & (z > 13.0), "nose_bridge")
    put((side < 2.0) & (y >= MOUTH[1] + 1.5) & (y < NOSE_TIP_Y + 0.8) & (z > 13.0), "nose_tip")
    mx, my = side / MOUTH_HALF_W, y - MOUTH[1]
    lips = (mx < 0.85) & (np.abs(my) < 1.5) & (z > 12.0)
    put(lips & (my >= 0), "upper_lip")
    put(lips & (my < 0), "lower_lip")
    put((mx >= 0.85) & (mx < 1.45) & (np.abs(my) < 1.2) & (z > 11.0), "mouth_corner_L",
        "mouth_corner_R")
    put((side < 2.6) & (y < MOUTH[1] - 1.5) & (y > CHIN_Y - 1.0) & (z > 10.0), "chin")
    put((side > 6.8) & (y > 67.5) & (y < 78.0) & (z > 1.5) & (z < 8.0), "ear_L", "ear_R")
    neck = (y < CHIN_Y - 1.0) & ~((side < 2.6) & (z > 10.0)) | (part == 4) | \
           ((y < MOUTH[1] - 2.0) & (z <= 4.0))
    put(neck & (z > 2.0), "throat")
    put(neck & (z <= 2.0), "nape")
    # the inner parts follow the skin they belong to
    put((part == 1) & (y >= MOUTH[1]), "upper_lip")
    put((part == 1) & (y < MOUTH[1]), "lower_lip")
    eye = (part == 2) | (part == 3)
    put(eye & (dy >= 0), "upper_eyelid_L", "upper_eyelid_R")
    put(eye & (dy < 0), "lower_eyelid_L", "lower_eyelid_R")
    return lab


def vertex_parts() -> np.ndarray:
    """(5472,) int8 part of every bust vertex (the head's first): 0 skin, 1 mouth cavity, 2 left and
    3 right eye socket, 4 bust; a vertex shared by skin and an inner part counts as skin."""
    z = assets.heads()
    part = np.full(assets.N_BUST, 4, np.int8)
    part[:assets.N_HEAD] = 0
    for p in (1, 2, 3):
        inner = np.unique(z["full_faces"][z["full_face_part"] == p])
        part[inner[inner >= assets.N_SKIN]] = p
    return part


@lru_cache(maxsize=4)
def base_segments(n_segments: int = 20) -> np.ndarray:
    """Region label (5472,) int64 in [0, n_segments) of every base bust vertex (the head's first
    4326); names in ``data_synth.segmentation.SEGMENT_NAMES[n_segments]``."""
    if n_segments not in SEGMENT_NAMES:
        raise ValueError(f"n_segments must be one of {tuple(SEGMENT_NAMES)}, got {n_segments}")
    return _FINE_TO[n_segments][_fine_labels(assets.heads()["bust_neutral"].astype(np.float64),
                                             vertex_parts())]
