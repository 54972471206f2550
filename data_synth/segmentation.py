"""Segmentation of the head into facial muscle-group regions, defined on the (u, v) domain.

The finest level has 24 regions; 20 (the paper's L), 14 and 6 merge them (nested). Regions are
written in template angles (a, e) (see `head`), so every tessellation gets the same labels at the
same (u, v). `_L` regions lie at a > 0 (+x, the character's left).
"""
from __future__ import annotations

import numpy as np

from . import head
from .head import EYE_A, EYE_HALF_W, MOUTH_E, MOUTH_HALF_W

_FINE = (
    "scalp", "forehead_L", "forehead_R", "brow_L", "brow_R", "upper_eyelid_L", "upper_eyelid_R",
    "lower_eyelid_L", "lower_eyelid_R", "nose_bridge", "nose_tip", "cheek_L", "cheek_R",
    "upper_lip", "lower_lip", "mouth_corner_L", "mouth_corner_R", "chin", "jaw_L", "jaw_R",
    "throat", "nape", "ear_L", "ear_R",
)
# coarser level name for every fine region: {L: {fine name: coarse name}}
_MERGE = {
    20: {"forehead_L": "forehead", "forehead_R": "forehead", "throat": "neck", "nape": "neck",
         "ear_L": "scalp", "ear_R": "scalp"},
    14: {"forehead_L": "forehead", "forehead_R": "forehead", "throat": "neck", "nape": "neck",
         "ear_L": "scalp", "ear_R": "scalp", "upper_eyelid_L": "eye_L", "lower_eyelid_L": "eye_L",
         "upper_eyelid_R": "eye_R", "lower_eyelid_R": "eye_R", "nose_bridge": "nose",
         "nose_tip": "nose", "upper_lip": "mouth", "lower_lip": "mouth", "mouth_corner_L": "mouth",
         "mouth_corner_R": "mouth"},
}
_14_TO_6 = {"scalp": "scalp_neck", "neck": "scalp_neck", "forehead": "upper_face",
            "brow_L": "upper_face", "brow_R": "upper_face", "eye_L": "eyes", "eye_R": "eyes",
            "nose": "nose", "cheek_L": "cheeks_jaw", "cheek_R": "cheeks_jaw", "jaw_L": "cheeks_jaw",
            "jaw_R": "cheeks_jaw", "mouth": "mouth_chin", "chin": "mouth_chin"}
_MERGE[6] = {fine: _14_TO_6[_MERGE[14].get(fine, fine)] for fine in _FINE}
_MERGE[24] = {}


def _names(level):
    out = []
    for fine in _FINE:
        name = _MERGE[level].get(fine, fine)
        if name not in out:
            out.append(name)
    return tuple(out)


SEGMENT_LEVELS = (6, 14, 20, 24)
SEGMENT_NAMES = {level: _names(level) for level in SEGMENT_LEVELS}
_FINE_TO = {level: np.array([SEGMENT_NAMES[level].index(_MERGE[level].get(f, f)) for f in _FINE])
            for level in SEGMENT_LEVELS}


def region_painter(lab: np.ndarray, left: np.ndarray):
    """``put(mask, name_l, name_r=None)``: write the finest region ``name_l`` into the labels
    ``lab`` (V,) where ``mask``, or ``name_l`` / ``name_r`` split by ``left`` (V,) bool (+x side)."""

    def put(mask, name_l, name_r=None):
        if name_r is None:
            lab[mask] = _FINE.index(name_l)
        else:
            lab[mask & left] = _FINE.index(name_l)
            lab[mask & ~left] = _FINE.index(name_r)

    return put


def _fine_labels(a, e):
    """Finest (24-region) labels (V,) int64 from template angles (rad)."""
    side = np.abs(a)
    left = a >= 0
    lab = np.full(a.shape, _FINE.index("scalp"), dtype=np.int64)
    put = region_painter(lab, left)

    face = (side < 1.25) & (e > -1.0) & (e < 0.95)
    put(face & (e >= 0.7), "forehead_L", "forehead_R")
    put(face & (e < 0.7) & (e >= -0.3), "cheek_L", "cheek_R")
    put(face & (e < -0.3), "jaw_L", "jaw_R")
    put(face & (side < 0.75) & (e >= 0.5) & (e < 0.7), "brow_L", "brow_R")
    rel = e - head.eye_centre_line(side)
    eye = face & (np.abs(side - EYE_A) < EYE_HALF_W + 0.05)
    put(eye & (rel >= 0.0) & (rel < 0.15), "upper_eyelid_L", "upper_eyelid_R")
    put(eye & (rel < 0.0) & (rel > -0.1), "lower_eyelid_L", "lower_eyelid_R")
    put((side < 0.09) & (e >= 0.2) & (e < 0.55), "nose_bridge")
    put((side < 0.15) & (e >= -0.02) & (e < 0.2), "nose_tip")
    upper = head.in_mouth_slit(a, e) & (e >= MOUTH_E) | ((e >= MOUTH_E) & (e < -0.02))
    lips = side < MOUTH_HALF_W - 0.04
    put(lips & upper, "upper_lip")
    put(lips & (e < MOUTH_E) & (e >= MOUTH_E - 0.11), "lower_lip")
    corner = (side >= MOUTH_HALF_W - 0.04) & (side < MOUTH_HALF_W + 0.11) & (np.abs(e - MOUTH_E) < 0.1)
    put(corner, "mouth_corner_L", "mouth_corner_R")
    put((side < 0.3) & (e < MOUTH_E - 0.11) & (e > -1.0), "chin")
    put((np.abs(side - 1.56) < 0.17) & (np.abs(e - 0.4) < 0.3), "ear_L", "ear_R")
    neck = (e < -1.0) | ((side >= 1.7) & (e < -0.4))
    put(neck & (side < 1.6), "throat")
    put(neck & (side >= 1.6), "nape")
    return lab


def segment_labels(uv, n_segments=20) -> np.ndarray:
    """Region label (V,) int64 in [0, n_segments) for disc coordinates uv (V,2).

    n_segments is one of SEGMENT_LEVELS (6, 14, 20, 24); names in SEGMENT_NAMES[n_segments].
    """
    if n_segments not in SEGMENT_NAMES:
        raise ValueError(f"n_segments must be one of {SEGMENT_LEVELS}, got {n_segments}")
    a, e = head.uv_to_template(uv)
    return _FINE_TO[n_segments][_fine_labels(a, e)]
