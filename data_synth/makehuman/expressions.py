"""The 53 FACS shapes (ICT order) on a realistic head identity.

Two expression sources, both authored on the MakeHuman base head and carried onto the identity by
deformation transfer (``transfer.deformation_transfer``, one factorisation per identity):

- ``"arkit"``: the artist's 52 ARKit shapes of ``makehuman_arkit.npz``; ARKit ``browInnerUp`` and
  ``cheekPuff`` are split into their ICT halves by side, ``tongueOut`` (no skin motion) is dropped;
- ``"units"``: MakeHuman's CC0 expression units mapped to their closest ICT shapes (the table of
  data/README.md, "Expression units and their closest FACS / ICT / ARKit shapes"): 29 of the 53;
  the others are absent (``present`` False). This is the ARKit-withheld source of the
  generalisation study;
- ``"units_full"``: ``"units"`` completed to all 53 by surrogates for the other 24
  (``base_surrogates_ict``), made from MakeHuman's CC0 face modifiers, the expression units and
  rigid motions of the jaw and eyelid regions those units move, following each shape's FACS
  description (never fitted to the artist's ARKit shapes, which the study holds out).

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
LIP_BAND_CM = 0.3  # half width of the blend between the upper and the lower lip
JAW_YAW_RAD = 0.1  # jawLeft / jawRight: yaw of the jaw region about the fitted hinge
JAW_FORWARD_CM = 0.6
LID_SHIFT_CM = 0.2  # eyeLookIn / eyeLookOut: sideways shift of the eyelid region


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


def expression_units(names, race: np.ndarray) -> np.ndarray:
    """MakeHuman expression units by name on the base head, mixed by ``race`` (3,) as MakeHuman
    weights them: (len(names),4326,3) float32 cm."""
    z = assets.heads()
    all_names = [str(n) for n in z["expr_unit_names"]]
    rows = [all_names.index(n) for n in names]
    scale = np.float32(z["deltas_scale_cm"])
    q = z["target_deltas_q"][z["expr_unit_targets"][rows]].astype(np.float32) * scale
    return np.tensordot(np.asarray(race, np.float32), q, axes=([0], [1]))   # q: (U,3,V,3)


def base_units_ict(race: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MakeHuman's expression units on the base head, mixed by ``race`` (3,) as MakeHuman
    weights them, in ICT order: ((53,4326,3) float32 cm, present (53,) bool)."""
    x = assets.heads()["full_neutral"][:, 0]
    return _to_ict(UNIT_TO_ICT, expression_units(UNIT_TO_ICT, race), x)


def _modifier_target(name: str) -> np.ndarray:
    """One MakeHuman face-modifier target on the base head: (4326,3) cm."""
    z = assets.heads()
    i = [str(n) for n in z["target_names"]].index(name)
    return z["target_deltas_q"][i].astype(np.float32) * np.float32(z["deltas_scale_cm"])


def region_weight(delta: np.ndarray, quantile: float = 0.9) -> np.ndarray:
    """(V,) in [0, 1]: a delta's (V,3) magnitude over its ``quantile`` among the moved vertices
    (> 0.05 cm), clipped: the region a unit moves, 1 where it moves most."""
    m = np.linalg.norm(delta, axis=1)
    return np.clip(m / np.quantile(m[m > 0.05], quantile), 0.0, 1.0).astype(np.float32)


def jaw_hinge(points: np.ndarray, delta: np.ndarray,
              weight: np.ndarray) -> tuple[float, float, float]:
    """(angle rad, y, z cm) of the rotation about an x-parallel axis through (y, z) that best
    explains a jaw-opening delta (V,3) on points (V,3), least squares weighted by weight (V,):
    to first order d_y = -a (z - z_h), d_z = a (y - y_h), linear in (a, a z_h, a y_h)."""
    y, zc = points[:, 1].astype(np.float64), points[:, 2].astype(np.float64)
    n = len(y)
    A = np.zeros((2 * n, 3))
    A[:n, 0], A[:n, 1] = -zc, 1.0
    A[n:, 0], A[n:, 2] = y, -1.0
    b = np.concatenate([delta[:, 1], delta[:, 2]]).astype(np.float64)
    sw = np.sqrt(np.concatenate([weight, weight]).astype(np.float64))
    a, az, ay = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)[0]
    return float(a), float(ay / a), float(az / a)


SURROGATE_NAMES = tuple(n for n in FACS_INDEX
                        if n not in {s for v in UNIT_TO_ICT.values() for s in v})


def base_surrogates_ict(race: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Surrogates on the base head for the 24 ICT shapes no expression unit maps to
    (``SURROGATE_NAMES``), in ICT order: ((53,4326,3) float32 cm, present (53,) bool).

    - cheekPuff / cheekSquint: the cheek-volume-incr / cheek-trans-up modifiers of each side;
    - mouthLeft / Right: mouth-trans-out / -in; mouthDimple: mouth-dimples-in (twice) plus 0.3 of
      the mouth-retraction unit, split by side; mouthShrugUpper: upperlip-middle-up;
      mouthShrugLower: lowerlip-middle-down plus 0.3 of chin-height-decr (the chin raiser);
      mouthRoll*: minus that lip's part of the mouth-eversion unit plus twice its lip-volume-decr;
      mouthClose: minus the mouth-parling unit plus half of lowerlip-middle-down;
    - jawForward / Left / Right: the region the mouth-open unit moves, translated forward by
      JAW_FORWARD_CM or turned by ±JAW_YAW_RAD about a vertical axis through the hinge fitted to
      that unit (``jaw_hinge``);
    - eyeLook*: the lids the eye-closure unit moves: Up 0.5 of eye-opened-up, Down 0.4 of the
      closure, In / Out shifted sideways by LID_SHIFT_CM (towards / away from the nose)."""
    z = assets.heads()
    p = z["full_neutral"].astype(np.float32)
    x, y = p[:, 0], p[:, 1]
    left = left_weight(x, 0.0, MIDLINE_CM)[:, None]
    mouth = region_weight(_modifier_target("mouth/mouth-trans-up"))
    mouth_y = float((y * mouth).sum() / mouth.sum())
    upper_lip = left_weight(y, mouth_y, LIP_BAND_CM)[:, None]   # 1 above the mouth line
    t = _modifier_target
    unit_names = ("mouth-retraction", "mouth-eversion", "mouth-parling", "mouth-open",
                  "eye-left-closure", "eye-left-opened-up",
                  "eye-right-closure", "eye-right-opened-up")
    u = dict(zip(unit_names, expression_units(unit_names, race)))
    s: dict[str, np.ndarray] = {}
    for side, tag, w in (("_L", "l", left), ("_R", "r", 1.0 - left)):
        s["cheekPuff" + side] = t(f"cheek/{tag}-cheek-volume-incr")
        s["cheekSquint" + side] = t(f"cheek/{tag}-cheek-trans-up")
        s["mouthDimple" + side] = w * (2.0 * t("mouth/mouth-dimples-in")
                                       + 0.3 * u["mouth-retraction"])
    s["mouthLeft"], s["mouthRight"] = t("mouth/mouth-trans-out"), t("mouth/mouth-trans-in")
    s["mouthShrugUpper"] = t("mouth/mouth-upperlip-middle-up")
    s["mouthShrugLower"] = t("mouth/mouth-lowerlip-middle-down") + 0.3 * t("chin/chin-height-decr")
    eversion = u["mouth-eversion"]
    s["mouthRollUpper"] = -upper_lip * eversion + 2.0 * t("mouth/mouth-upperlip-volume-decr")
    s["mouthRollLower"] = -(1.0 - upper_lip) * eversion + 2.0 * t("mouth/mouth-lowerlip-volume-decr")
    s["mouthClose"] = -u["mouth-parling"] + 0.5 * t("mouth/mouth-lowerlip-middle-down")
    jaw_open = u["mouth-open"]
    jaw = region_weight(jaw_open)
    _, _, hinge_z = jaw_hinge(p, jaw_open, jaw ** 2)
    zero = np.zeros_like(x)
    s["jawForward"] = JAW_FORWARD_CM * jaw[:, None] * np.array([0.0, 0.0, 1.0], np.float32)
    yaw = np.stack([JAW_YAW_RAD * (p[:, 2] - hinge_z), zero, -JAW_YAW_RAD * x], 1) * jaw[:, None]
    s["jawLeft"], s["jawRight"] = yaw, yaw * np.array([-1.0, 1.0, -1.0], np.float32)
    for side, tag, out_x in (("_L", "left", 1.0), ("_R", "right", -1.0)):
        closure = u[f"eye-{tag}-closure"]
        lids = region_weight(closure)[:, None]
        s["eyeLookUp" + side] = 0.5 * u[f"eye-{tag}-opened-up"]
        s["eyeLookDown" + side] = 0.4 * closure
        s["eyeLookOut" + side] = lids * np.array([out_x * LID_SHIFT_CM, 0.0, 0.0], np.float32)
        s["eyeLookIn" + side] = -s["eyeLookOut" + side]
    assert set(s) == set(SURROGATE_NAMES)
    deltas = np.zeros((N_FACS, len(p), 3), np.float32)
    present = np.zeros(N_FACS, bool)
    for name, d in s.items():
        deltas[FACS_INDEX[name]], present[FACS_INDEX[name]] = d, True
    return deltas, present


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

    source "arkit", "units" or "units_full" (module docstring); style_seed None = the source as
    authored, else the rig's random style (``style_shapes``, and for "arkit" a blend of share U(0, 0.5) towards
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
    elif source == "units_full":
        shapes, present = base_units_ict(race)
        extra, has_extra = base_surrogates_ict(race)
        shapes, present = np.where(has_extra[:, None, None], extra, shapes), present | has_extra
    else:
        raise ValueError(f"expression source must be 'arkit', 'units' or 'units_full', "
                         f"got {source!r}")
    deltas = np.zeros_like(shapes)
    deltas[present] = deformation_transfer(base, shapes[present], neutral, faces)
    if rng is not None:
        deltas = style_shapes(deltas, np.asarray(neutral, np.float64), rng)
        deltas[~present] = 0.0
    return deltas.astype(np.float32), present
