"""The 53 FACS expression operators (ICT names and order) on the procedural head.

Each expression is an operator on one identity's neutral surface (a `head.SurfaceSample`: points,
normals, template angles, eyeball centres, head parameters) that returns a displacement per point:
deltas[k] = p_k - p_0 in cm. All inputs are functions of (u, v) and z_ID only, so every
tessellation gets exactly corresponding deltas.

- Joints (FLAME/JNR style): jawOpen/Left/Right/Forward rotate (and slide) the lower face about an
  identity-dependent hinge in front of the ears with smooth skinning weights `jaw_weights`;
  eyelids rotate about the eyeball centre (`_lid_motion`), and eyeBlink adds the residual that makes
  the upper margin land exactly on the (slightly raised) lower margin.
- Local fields (ASM-like Gaussian mixtures in template angles): `Lobe`s with a 3D vector in the
  world frame or along the normal, optionally gated to the upper or lower lip.
- Sided shapes are written for the left (+x) side; the right shape is the exact mirror:
  delta_R(u, v; z) = M delta_L(-u, v; mirror(z)), M = diag(-1, 1, 1) (`expression_deltas`). On a
  symmetric identity this is the plain mirror image; with asymmetry modes it is the left operator
  applied to the mirrored head, mirrored back (the head's own left/right, not the world's).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import head
from .facs import FACS_NAMES
from .head import MOUTH_E, MOUTH_HALF_W, EYE_A, EYE_HALF_W, gauss, smoothstep
from .identity import mirror_identity

MIRROR = np.array([-1.0, 1.0, 1.0])
GAZE_PIVOT_DEPTH = 2.5  # cm behind the eyeball centre: small lid motions slide nearly vertically


@dataclass(frozen=True)
class Lobe:
    """One Gaussian lobe of a displacement field: centre (a0, e0) and widths (sa, se) in template
    radians, vector (3,) in cm (frame "world", or "normal": vector[2] along the outward normal of
    the smooth base head),
    gate None | "upper" | "lower" (restrict to above / below the mouth line)."""

    a0: float
    e0: float
    sa: float
    se: float
    vector: tuple
    frame: str = "world"
    gate: str | None = None

    def mirrored(self) -> "Lobe":
        x, y, z = self.vector
        vec = (x, y, z) if self.frame == "normal" else (-x, y, z)
        return Lobe(-self.a0, self.e0, self.sa, self.se, vec, self.frame, self.gate)


# ----------------------------------------------------------------------------- weights
def lip_gate_upper(a, e):
    """(V,) in [0,1]: 1 above the mouth line (upper lip and up), 0 below; the step lies inside the
    slit between the corners and widens over the cheeks beyond them."""
    half = head.slit_half_height(a) + 0.004 + 0.5 * np.maximum(np.abs(a) - MOUTH_HALF_W, 0.0)
    return smoothstep(MOUTH_E - half, MOUTH_E + half, e)


def jaw_weights(a, e):
    """Skinning weights (V,) of the jaw joint: 1 on the chin and lower lip, 0 on the upper lip and
    above, smooth over the cheeks up toward the hinge, fading on the throat and behind the jaw."""
    side = np.abs(a)
    beyond = np.maximum(side - MOUTH_HALF_W, 0.0)
    line = MOUTH_E + 0.36 * beyond
    half = head.slit_half_height(a) + 0.004 + 0.5 * beyond
    w = 1.0 - smoothstep(line - half, line + half, e)
    w *= 1.0 - 0.5 * gauss(side - MOUTH_HALF_W, 0.07) * gauss(e - MOUTH_E, 0.07)   # corners go half-way
    w *= 1.0 - smoothstep(1.35, 1.8, side)
    w *= 1.0 - smoothstep(-0.95, -1.2, e)
    return w


def _lobe_field(ctx, lobes):
    """Sum of lobes (V,3) cm on a surface sample."""
    out = np.zeros_like(ctx.points)
    upper = lip_gate_upper(ctx.a, ctx.e)
    for lb in lobes:
        w = gauss(ctx.a - lb.a0, lb.sa) * gauss(ctx.e - lb.e0, lb.se)
        if lb.gate == "upper":
            w = w * upper
        elif lb.gate == "lower":
            w = w * (1.0 - upper)
        vec = ctx.smooth_normals * lb.vector[2] if lb.frame == "normal" else np.asarray(lb.vector, float)
        out += w[:, None] * vec
    return out


def _rot_x(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rotate(points, centre, rotation, weights):
    """Linear-blend-skinned rotation: weights (V,) * (R (p - c) + c - p), (V,3)."""
    rel = points - centre
    return weights[..., None] * (rel @ rotation.T - rel)


# ----------------------------------------------------------------------------- joints
def jaw_hinge(ctx):
    """(3,) hinge point of the jaw (cm): below and in front of the ear, on the mid-plane."""
    ear = ctx.at_template(np.array([1.56]), np.array([ctx.P["ear_e"]]))[0]
    return np.array([0.0, ear[1] - 2.0, ear[2] + 0.6])


def _jaw(ctx, pitch=0.0, yaw=0.0, shift=(0.0, 0.0, 0.0)):
    """Jaw joint motion (V,3): rotation about the hinge (pitch about +x opens; yaw about +y through
    the left condyle turns the chin toward +x while the right condyle slides forward) plus a
    translation (condyle slide), skinned with `jaw_weights`."""
    w = jaw_weights(ctx.a, ctx.e)
    hinge = jaw_hinge(ctx)
    out = _rotate(ctx.points, hinge, _rot_x(pitch), w) + w[:, None] * np.asarray(shift, float)
    if yaw:
        out += _rotate(ctx.points, hinge + [ctx.P["jaw_w"] * 0.85, 0.0, 0.0], _rot_y(yaw), w)
    return out


JAW_OPEN = dict(pitch=0.30, shift=(0.0, -0.5, 1.0))


def _jaw_open(ctx):
    return _jaw(ctx, **JAW_OPEN)


# ----------------------------------------------------------------------------- eyelids
def _lid_frame(ctx, pivot_depth):
    """Per-point quantities of the left eye for lid rotations about the pivot `pivot_depth` cm
    behind the eyeball centre: margins, lid weights, opening angle (kept in ctx.cache)."""
    key = ("lid", pivot_depth)
    if key in ctx.cache:
        return ctx.cache[key]
    a, e = ctx.a, ctx.e
    s = (a - EYE_A) / EYE_HALF_W
    lateral = np.exp(-(np.maximum(np.abs(s) - 0.8, 0.0) / 0.5) ** 2) * (a > 0)
    a_clip = EYE_A + EYE_HALF_W * np.clip(s, -0.999, 0.999)
    e_up, e_lo = head.eye_margins(a_clip)
    gap = np.maximum(e_up - e_lo, 1e-9)
    lam = np.clip((e - e_lo) / gap, 0.0, 1.0)
    w_up = np.where(e >= e_up, 1.0 - smoothstep(e_up, e_up + 0.13, e), lam) * lateral
    w_lo = np.where(e <= e_lo, 1.0 - smoothstep(e_lo, e_lo - 0.09, e), 1.0 - lam) * lateral
    t = np.clip((e - e_up) / 0.13, 0.0, 1.0)
    fold = np.sin(np.pi * t) ** 2 * lateral                    # 0 at the margin and at the brow
    near = (w_up > 0) | (w_lo > 0)
    p_up = np.zeros_like(ctx.points)
    p_lo = np.zeros_like(ctx.points)
    p_up[near] = ctx.at_template(a_clip[near], e_up[near])
    p_lo[near] = ctx.at_template(a_clip[near], e_lo[near])
    centre = ctx.eyeball_centres[0] - np.array([0.0, 0.0, pivot_depth])

    def elevation(p):
        return np.arctan2(p[:, 1] - centre[1], p[:, 2] - centre[2])
    opening = np.where(near, elevation(p_up) - elevation(p_lo), 0.0)   # rad, seen from the pivot
    ctx.cache[key] = dict(w_up=w_up, w_lo=w_lo, fold=fold, p_up=p_up, p_lo=p_lo, opening=opening,
                          centre=centre)
    return ctx.cache[key]


def _rotate_about_x_per_point(rel, angle):
    """Rotate (V,3) vectors about +x by per-point angles (V,) (positive moves +z points down)."""
    c, s = np.cos(angle), np.sin(angle)
    out = rel.copy()
    out[:, 1] = c * rel[:, 1] - s * rel[:, 2]
    out[:, 2] = s * rel[:, 1] + c * rel[:, 2]
    return out


def _lid_motion(ctx, upper=0.0, lower=0.0, yaw=0.0, close=False, unfold=0.0,
                pivot_depth=GAZE_PIVOT_DEPTH):
    """Left eyelid motion (V,3): skinned rotations about a pivot on the eye's axis, `pivot_depth` cm
    behind the eyeball centre (0: the eyeball centre itself, so the lids roll over the eye).

    upper/lower: rotation of the upper/lower lid margin as a fraction of the opening angle seen from
    the pivot (positive = down); a lid point rotates by its lid weight times the angle of its margin
    (same azimuth). yaw (rad): sideways rotation of both lids (gaze in/out). close=True adds, with
    the squared lid weight, the residual that lands the upper margin exactly on the moved lower one.
    unfold (cm): extra downward slide of the upper-lid skin between margin and crease (zero at the
    margin), as the lid fold flattens when the eye closes.
    """
    f = _lid_frame(ctx, pivot_depth)
    c = f["centre"]
    rel = ctx.points - c
    g_up = upper * f["opening"]
    g_lo = lower * f["opening"]
    out = _rotate_about_x_per_point(rel, f["w_up"] * g_up) - rel
    out += _rotate_about_x_per_point(rel, f["w_lo"] * g_lo) - rel
    if close:
        meet = _rotate_about_x_per_point(f["p_lo"] - c, g_lo)
        residual = meet - _rotate_about_x_per_point(f["p_up"] - c, g_up)
        out += (f["w_up"] ** 2)[:, None] * residual
    if yaw:
        out += _rotate(ctx.points, c, _rot_y(yaw), np.maximum(f["w_up"], f["w_lo"]))
    if unfold:
        out[:, 1] -= unfold * f["fold"]
    return out


# ----------------------------------------------------------------------------- shape table
# Left (or symmetric) operators. Values: ("lobes", lobes, symmetric) | ("lid", kwargs, lobes) |
# callable. Vectors are tuned against a real ARKit rig (docs/CALIBRATION.md).
_UL, _LL = "upper", "lower"
_LEFT_OR_SYMMETRIC = {
    "browDown": ("lobes", (Lobe(0.13, 0.59, 0.12, 0.09, (-0.3, -0.5, 0.08)),
                           Lobe(0.32, 0.61, 0.16, 0.09, (-0.05, -0.3, 0.0)),
                           Lobe(0.07, 0.5, 0.05, 0.06, (-0.1, -0.15, 0.1))), False),
    "browInnerUp": ("lobes", (Lobe(0.11, 0.62, 0.09, 0.09, (0.0, 0.45, 0.0)),
                              Lobe(0.1, 0.78, 0.12, 0.1, (0.0, 0.15, 0.0))), False),
    "browOuterUp": ("lobes", (Lobe(0.45, 0.6, 0.12, 0.08, (0.0, 0.65, -0.1)),), False),
    "cheekPuff": ("lobes", (Lobe(0.42, -0.22, 0.17, 0.14, (0.0, 0.0, 1.25), "normal"),
                            Lobe(0.2, -0.2, 0.08, 0.1, (0.1, 0.0, 0.2))), False),
    "cheekSquint": ("lobes", (Lobe(0.5, 0.08, 0.2, 0.12, (0.08, 0.65, -0.1)),
                              Lobe(0.36, 0.3, 0.13, 0.06, (0.0, 0.25, 0.0))), False),
    "eyeBlink": ("lid", dict(upper=0.85, lower=-0.15, close=True, unfold=0.4, pivot_depth=0.0), ()),
    "eyeLookDown": ("lid", dict(upper=0.35, lower=0.15), ()),
    "eyeLookIn": ("lid", dict(yaw=-0.025), ()),
    "eyeLookOut": ("lid", dict(yaw=0.025), ()),
    "eyeLookUp": ("lid", dict(upper=-0.22, lower=-0.1), ()),
    "eyeSquint": ("lid", dict(upper=0.1, lower=-0.3),
                  (Lobe(EYE_A + 0.05, 0.33, 0.14, 0.07, (-0.2, 0.15, 0.0)),)),
    "eyeWide": ("lid", dict(upper=-0.35, lower=0.05), ()),
    "jawForward": lambda ctx: _jaw(ctx, shift=(0.0, -0.1, 0.85)),
    "jawLeft": lambda ctx: _jaw(ctx, yaw=0.06, shift=(0.25, 0.0, 0.0)),
    "jawOpen": _jaw_open,
    "mouthClose": lambda ctx: _mouth_close(ctx),
    "mouthDimple": ("lobes", (Lobe(0.28, -0.255, 0.12, 0.11, (0.45, 0.35, -0.45)),), False),
    "mouthFrown": ("lobes", (Lobe(0.27, -0.26, 0.11, 0.09, (0.15, -0.5, 0.05)),
                             Lobe(0.3, -0.4, 0.13, 0.13, (0.05, -0.25, 0.0))), False),
    "mouthFunnel": ("lobes", (Lobe(0.0, -0.215, 0.2, 0.07, (0.0, 0.1, 0.5), gate=_UL),
                              Lobe(0.0, -0.3, 0.2, 0.09, (0.0, -0.7, 0.45), gate=_LL),
                              Lobe(0.0, -0.5, 0.24, 0.18, (0.0, -0.3, 0.0)),
                              Lobe(0.25, -0.255, 0.07, 0.06, (-0.35, 0.0, 0.2))), True),
    "mouthLeft": ("lobes", (Lobe(0.0, -0.27, 0.35, 0.16, (0.85, 0.3, -0.05)),
                            Lobe(0.27, -0.255, 0.08, 0.08, (0.1, 0.1, -0.2))), False),
    "mouthLowerDown": ("lobes", (Lobe(0.15, -0.31, 0.11, 0.08, (0.3, -0.4, 0.05), gate=_LL),), False),
    "mouthPress": ("lobes", (Lobe(0.2, -0.255, 0.13, 0.09, (0.45, 0.3, 0.0)),
                             Lobe(0.1, -0.3, 0.13, 0.07, (0.15, 0.3, 0.0), gate=_LL),
                             Lobe(0.1, -0.22, 0.13, 0.07, (0.1, -0.1, 0.0), gate=_UL)), False),
    "mouthPucker": ("lobes", (Lobe(0.0, -0.255, 0.22, 0.13, (0.0, 0.0, 0.7)),
                              Lobe(0.25, -0.255, 0.1, 0.09, (-0.6, 0.0, 0.25))), True),
    "mouthRollLower": ("lobes", (Lobe(0.0, -0.3, 0.17, 0.04, (0.0, 0.4, -0.2), gate=_LL),
                                 Lobe(0.0, -0.39, 0.17, 0.05, (0.0, 0.3, 0.25))), True),
    "mouthRollUpper": ("lobes", (Lobe(0.0, -0.225, 0.2, 0.06, (0.0, -0.75, -0.45), gate=_UL),), True),
    "mouthShrugLower": ("lobes", (Lobe(0.0, -0.35, 0.18, 0.08, (0.0, 0.4, 0.25), gate=_LL),
                                  Lobe(0.0, -0.55, 0.12, 0.08, (0.0, 0.3, 0.2))), True),
    "mouthShrugUpper": ("lobes", (Lobe(0.0, -0.2, 0.2, 0.06, (0.0, 0.45, -0.1), gate=_UL),), True),
    "mouthSmile": ("lobes", (Lobe(0.27, -0.255, 0.12, 0.1, (0.55, 1.0, -0.4)),
                             Lobe(0.42, -0.1, 0.2, 0.17, (0.15, 0.45, 0.1)),
                             Lobe(0.12, -0.25, 0.1, 0.05, (0.2, 0.25, -0.1))), False),
    "mouthStretch": ("lobes", (Lobe(0.27, -0.27, 0.11, 0.09, (0.55, -0.35, -0.2)),
                               Lobe(0.15, -0.3, 0.13, 0.08, (0.3, -0.2, 0.0), gate=_LL)), False),
    "mouthUpperUp": ("lobes", (Lobe(0.15, -0.2, 0.11, 0.08, (0.1, 0.5, 0.0), gate=_UL),), False),
    "noseSneer": ("lobes", (Lobe(0.1, 0.15, 0.07, 0.1, (-0.15, 0.25, 0.05)),
                            Lobe(0.09, 0.06, 0.05, 0.05, (-0.1, 0.2, 0.0)),
                            Lobe(0.22, 0.2, 0.1, 0.12, (-0.45, -0.05, 0.05)),
                            Lobe(0.04, 0.38, 0.05, 0.05, (-0.1, -0.15, 0.05))), False),
}
_MIRROR_PAIRS = {"jawRight": "jawLeft", "mouthRight": "mouthLeft"}


def _mouth_close(ctx):
    """Corrective: cancels jawOpen on the lower lip (pushes it up) and lowers the upper lip."""
    lower_lip = (1.0 - lip_gate_upper(ctx.a, ctx.e)) * (1.0 - smoothstep(-0.34, -0.72, ctx.e))
    lower_lip *= np.exp(-(ctx.a / 0.38) ** 4)
    upper = _lobe_field(ctx, (Lobe(0.0, -0.215, 0.2, 0.05, (0.0, -0.12, 0.0), gate=_UL),))
    return -lower_lip[:, None] * _jaw_open(ctx) + upper


def _evaluate(base, ctx):
    """Displacement (V,3) of one left/symmetric operator `base` on a surface sample."""
    spec = _LEFT_OR_SYMMETRIC[base]
    if callable(spec):
        return spec(ctx)
    if spec[0] == "lid":
        return _lid_motion(ctx, **spec[1]) + _lobe_field(ctx, spec[2])
    lobes = spec[1]
    if spec[2]:   # symmetric: add the mirror of every off-centre lobe
        lobes = tuple(lobes) + tuple(lb.mirrored() for lb in lobes if lb.a0 != 0.0)
    return _lobe_field(ctx, lobes)


def _split(name):
    """FACS name -> (left/symmetric operator name, is_right)."""
    if name in _MIRROR_PAIRS:
        return _MIRROR_PAIRS[name], True
    if name.endswith("_R"):
        return name[:-2], True
    if name.endswith("_L"):
        return name[:-2], False
    return name, False


def expression_deltas(uv, identity, names=FACS_NAMES) -> np.ndarray:
    """Displacements (K, V, 3) float64 cm of the named expressions (default: all 53, ICT order) at
    disc coordinates uv (V,2) for identity z_ID (J,)."""
    unknown = [n for n in names if n not in FACS_NAMES]
    if unknown:
        raise ValueError(f"expression_deltas: unknown expression names {unknown}; see FACS_NAMES")
    uv = np.asarray(uv, dtype=np.float64)
    ctx = head.SurfaceSample(uv, identity)
    ctx_m = None
    if any(_split(n)[1] for n in names):
        ctx_m = head.SurfaceSample(uv * np.array([-1.0, 1.0]), mirror_identity(identity))
    out = np.empty((len(names), len(uv), 3))
    for k, name in enumerate(names):
        base, right = _split(name)
        out[k] = _evaluate(base, ctx_m) * MIRROR if right else _evaluate(base, ctx)
    return out

