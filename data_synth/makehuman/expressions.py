"""The 53 FACS shapes (ICT order) on a realistic head identity.

Two expression sources, both authored on the MakeHuman base head and carried onto the identity by
deformation transfer (``transfer.deformation_transfer``, one factorisation per identity):

- ``"arkit"``: the artist's 52 ARKit shapes of ``makehuman_arkit.npz``; ARKit ``browInnerUp`` and
  ``cheekPuff`` are split into their ICT halves by side, ``tongueOut`` (no skin motion) is dropped;
- ``"units"``: MakeHuman's CC0 expression units mapped to their closest ICT shapes (the table of
  data/README.md, "Expression units and their closest FACS / ICT / ARKit shapes"): 29 of the 53;
  the others are absent (``present`` False). This is the ARKit-withheld source of the
  generalisation study.

``style`` varies each rig so that the network learns what a FACS shape means rather than one
artist's rig: per-shape gain (left/right partners nearly equal), a smooth random spatial warp of
each delta's magnitude, and (for ``"arkit"``) a random blend towards the mapped expression unit.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..facs import ARKIT_NAMES, FACS_INDEX, N_FACS, arkit_to_ict, left_weight, split_to_ict
from . import assets
from .transfer import deformation_transfer

# MakeHuman expression unit -> ICT shape(s); a two-name entry is split by side (+x = _L)
UNIT_TO_ICT = {
    "eye-left-closure": ("eyeBlink_L",), "eye-right-closure": ("eyeBlink_R",),
    "eye-left-opened-up": ("eyeWide_L",), "eye-right-opened-up": ("eyeWide_R",),
    "eye-left-slit": ("eyeSquint_L",), "eye-right-slit": ("eyeSquint_R",),
    "eyebrows-left-down": ("browDown_L",), "eyebrows-right-down": ("browDown_R",),
    "eyebrows-left-extern-up": ("browOuterUp_L",), "eyebrows-right-extern-up": ("browOuterUp_R",),
    "eyebrows-left-inner-up": ("browInnerUp_L",), "eyebrows-right-inner-up": ("browInnerUp_R",),
    "mouth-open": ("jawOpen",),
    "mouth-corner-puller": ("mouthSmile_L", "mouthSmile_R"),
    "mouth-depression": ("mouthFrown_L", "mouthFrown_R"),
    "mouth-elevation": ("mouthUpperUp_L", "mouthUpperUp_R"),
    "mouth-compression": ("mouthPress_L", "mouthPress_R"),
    "mouth-retraction": ("mouthStretch_L", "mouthStretch_R"),
    "mouth-depression-retraction": ("mouthLowerDown_L", "mouthLowerDown_R"),
    "mouth-pursing": ("mouthPucker",), "mouth-protusion": ("mouthFunnel",),
    "nose-left-elevation": ("noseSneer_L",), "nose-right-elevation": ("noseSneer_R",),
}
MIDLINE_CM = 1.0   # half width of the blend across the mid-plane x = 0 when a shape is split


def _to_ict(named: dict[str, tuple[str, ...]], deltas: np.ndarray, x: np.ndarray):
    """Shapes (K,V,3) whose names map to ICT slots -> ((53,V,3) float32, present (53,) bool); a
    shape feeding both halves is split across the mid-plane x = 0 over ±MIDLINE_CM."""
    slots = [tuple(FACS_INDEX[s] for s in names) for names in named.values()]
    return split_to_ict(zip(slots, deltas), left_weight(x, 0.0, MIDLINE_CM))


@lru_cache(maxsize=1)
def base_arkit_ict() -> tuple[np.ndarray, np.ndarray]:
    """The artist's shapes on the base head in ICT order: ((53,4326,3) float32 cm, present)."""
    a = assets.arkit()
    named = {str(n): arkit_to_ict(str(n)) for n in a["names"]}
    assert tuple(named) == ARKIT_NAMES
    return _to_ict(named, a["full_deltas"], a["full_neutral"][:, 0])


def base_units_ict(race: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MakeHuman's expression units on the base head, mixed by ``race`` (3,) as MakeHuman
    weights them, in ICT order: ((53,4326,3) float32 cm, present (53,) bool)."""
    z = assets.heads()
    scale = np.float32(z["deltas_scale_cm"])
    names = [str(n) for n in z["expr_unit_names"]]
    used = [names.index(u) for u in UNIT_TO_ICT]
    q = z["target_deltas_q"][z["expr_unit_targets"][used]].astype(np.float32) * scale  # (U,3,V,3)
    mixed = np.tensordot(np.asarray(race, np.float32), q, axes=([0], [1]))
    return _to_ict(UNIT_TO_ICT, mixed, z["full_neutral"][:, 0])


def smooth_field(rng: np.random.Generator, points: np.ndarray, n_bumps: int = 4,
                 radius_cm: tuple = (3.0, 8.0)) -> np.ndarray:
    """(V,) a smooth random field in about [-1, 1]: a sum of Gaussian bumps at random points."""
    centres = points[rng.integers(len(points), size=n_bumps)]
    radii = rng.uniform(*radius_cm, size=n_bumps)
    amps = rng.uniform(-1, 1, size=n_bumps)
    d2 = ((points[:, None, :] - centres[None]) ** 2).sum(-1)
    return (np.exp(-d2 / (2 * radii ** 2)) * amps).sum(1).clip(-1, 1)


def style_shapes(deltas: np.ndarray, neutral: np.ndarray, rng: np.random.Generator,
                 gain: float = 0.25, warp: float = 0.3) -> np.ndarray:
    """One rig's style: each shape (53,V,3) times a gain in [1-gain, 1+gain] (mirror partners
    within 0.05 of each other) and times (1 + warp * a smooth field over the neutral (V,3))."""
    g = 1 + rng.uniform(-gain, gain, size=N_FACS)
    for i, name in enumerate(FACS_INDEX):
        if name.endswith("_R"):
            g[i] = g[FACS_INDEX[name[:-2] + "_L"]] + rng.uniform(-0.05, 0.05)
    out = np.empty_like(deltas)
    for k in range(N_FACS):
        out[k] = deltas[k] * (g[k] * (1 + warp * smooth_field(rng, neutral)))[:, None]
    return out


def identity_expressions(neutral: np.ndarray, race: np.ndarray, source: str = "arkit",
                         style_seed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The 53 shapes on an identity's head neutral (4326,3) cm: ((53,4326,3) float32, present).

    source "arkit" or "units" (module docstring); style_seed None = the source as authored, else
    the rig's random style (``style_shapes``, and for "arkit" a blend of share U(0, 0.5) towards
    the mapped unit on the shapes that have one, with probability 1/2)."""
    base = assets.heads()["full_neutral"]
    faces = assets.heads()["full_faces"]
    rng = None if style_seed is None else np.random.default_rng([int(style_seed), 5150])
    if source == "arkit":
        shapes, present = base_arkit_ict()
        if rng is not None and rng.random() < 0.5:
            units, has_unit = base_units_ict(race)
            alpha = rng.uniform(0, 0.5)
            shapes = shapes.copy()
            shapes[has_unit] = (1 - alpha) * shapes[has_unit] + alpha * units[has_unit]
    elif source == "units":
        shapes, present = base_units_ict(race)
    else:
        raise ValueError(f"expression source must be 'arkit' or 'units', got {source!r}")
    deltas = np.zeros_like(shapes)
    deltas[present] = deformation_transfer(base, shapes[present], neutral, faces)
    if rng is not None:
        deltas = style_shapes(deltas, np.asarray(neutral, np.float64), rng)
        deltas[~present] = 0.0
    return deltas.astype(np.float32), present
