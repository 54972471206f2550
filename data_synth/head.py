"""The procedural head surface p(u, v; z_ID), a pure vectorised function of the parameter domain.

Parameter chain (every step is an orientation-preserving diffeomorphism, so a tessellation of the
(u, v) domain is a valid mesh of the surface for every identity)::

    (u, v) in the unit disc  --chart-->  template angles (a, e)  --warp(z_ID)-->  geometric angles
    (a', e')  -->  direction d(a', e') from the star centre O  -->  p = O + R(d, a, e; z_ID) * d

- The disc is an azimuthal map centred on the crown: the polar angle from +y is theta(rho) (linear
  up to rho = NECK_RHO, then slowing down so that the neck, seen at grazing angles from O, is not
  stretched), the polar angle alpha gives a = alpha - AZIMUTH_GAIN * sin(alpha), which magnifies
  the front (+z, v > 0) where the face is. rho = 1 is the neck cut (theta = THETA_MAX).
- a is the azimuth (0 = front, +x = the character's left), e the elevation seen from O.
- The surface is star-shaped about O: R > 0 is a function of the direction only, so the surface
  never self-intersects and a triangle of the domain keeps its orientation in 3D.
- Features (nose, brows, lips, chin, ...) are radial offsets written in template angles, so they
  stay on the same (u, v) for every identity; identity moves them through the warp and their
  parameters. Eye openings and the mouth slit are fixed regions of the template (the holes).

Units: centimetres; frame +y up, +z forward, +x = character's left.
"""
from __future__ import annotations

import numpy as np

from .identity import head_params

THETA_MAX = 0.88 * np.pi         # polar angle of the neck cut (rad): about 5 cm below the chin
AZIMUTH_GAIN = 0.3               # front magnification of the disc chart
NECK_RHO, NECK_KAPPA = 0.82, 40.0   # d(theta)/d(rho) falls to 1/(1 + kappa (rho - NECK_RHO)^2)
STAR_CENTRE = np.array([0.0, -3.0, -2.0])   # O, cm (head frame: origin near the skull centre)

# Template landmarks (rad), fixed for every identity: the holes live here.
EYE_A, EYE_E = 0.31, 0.43        # centre of the left eye opening (a > 0)
EYE_HALF_W, EYE_HALF_H = 0.125, 0.04
EYE_EXPONENT = 0.75              # almond corners
EYE_TILT = 0.08                  # outer corner higher (de/da)
MOUTH_E = -0.255                 # mouth line
MOUTH_HALF_W = 0.25              # corner azimuth
SLIT_HALF_H = 0.022              # template half-height of the mouth slit
SLIT_EXPONENT = 0.6
MOUTH_COMPRESS, MOUTH_COMPRESS_SIGMA = 0.72, 0.04   # the lips band is compressed in 3D


def gauss(x, s):
    """exp(-x^2 / 2 s^2), elementwise."""
    return np.exp(-0.5 * (x / s) ** 2)


def smoothstep(x0, x1, x):
    """C1 step from 0 at x0 to 1 at x1 (x0 > x1 allowed), elementwise."""
    t = np.clip((x - x0) / (x1 - x0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def smax(r1, r2, k):
    """Smooth maximum (log-sum-exp) with sharpness k (1/cm)."""
    m = np.maximum(r1, r2)
    return m + np.log(np.exp(k * (r1 - m)) + np.exp(k * (r2 - m))) / k


def smin(r1, r2, k):
    """Smooth minimum with sharpness k (1/cm)."""
    return -smax(-r1, -r2, k)


# ----------------------------------------------------------------------------- chart
def _theta_shape(rho):
    """Unscaled polar angle: rho up to NECK_RHO, then an arctan ramp (C2, monotone)."""
    k = np.sqrt(NECK_KAPPA)
    beyond = np.maximum(rho - NECK_RHO, 0.0)
    return np.minimum(rho, NECK_RHO) + np.arctan(k * beyond) / k


_THETA_SCALE = THETA_MAX / _theta_shape(1.0)


def theta_of_rho(rho):
    """Polar angle from +y (rad) at disc radius rho (...,)."""
    return _THETA_SCALE * _theta_shape(rho)


def rho_of_theta(theta):
    """Inverse of `theta_of_rho` (Newton; the map is monotone)."""
    target = np.asarray(theta, dtype=np.float64) / _THETA_SCALE
    rho = np.minimum(target, NECK_RHO)
    for _ in range(30):
        slope = 1.0 / (1.0 + NECK_KAPPA * np.maximum(rho - NECK_RHO, 0.0) ** 2)
        rho = rho - (_theta_shape(rho) - target) / slope
    return rho


def uv_to_template(uv):
    """(..., 2) disc coordinates -> template azimuth a and elevation e, each (...,) rad."""
    uv = np.asarray(uv, dtype=np.float64)
    rho = np.hypot(uv[..., 0], uv[..., 1])
    alpha = np.arctan2(uv[..., 0], uv[..., 1])
    a = alpha - AZIMUTH_GAIN * np.sin(alpha)
    e = 0.5 * np.pi - theta_of_rho(rho)
    return a, e


def template_to_uv(a, e):
    """Inverse of `uv_to_template`: template angles (...,) rad -> (..., 2) disc coordinates."""
    a = np.asarray(a, dtype=np.float64)
    alpha = a.copy()
    for _ in range(8):   # Newton on alpha - g sin(alpha) = a (derivative >= 1 - g > 0)
        alpha -= (alpha - AZIMUTH_GAIN * np.sin(alpha) - a) / (1.0 - AZIMUTH_GAIN * np.cos(alpha))
    rho = rho_of_theta(0.5 * np.pi - np.asarray(e, dtype=np.float64))
    return np.stack([rho * np.sin(alpha), rho * np.cos(alpha)], axis=-1)


def direction(a, e):
    """Unit direction (..., 3) from the star centre for azimuth a and elevation e (rad)."""
    ce = np.cos(e)
    return np.stack([ce * np.sin(a), np.sin(e), ce * np.cos(a)], axis=-1)


# ----------------------------------------------------------------------------- holes
def eye_half_height(a_side):
    """Half-height (rad) of the left eye opening at template azimuth |a| (0 beyond the corners)."""
    s = (a_side - EYE_A) / EYE_HALF_W
    return EYE_HALF_H * np.clip(1.0 - s * s, 0.0, None) ** EYE_EXPONENT


def eye_centre_line(a_side):
    """Template elevation (rad) of the middle of the eye opening at azimuth |a|."""
    return EYE_E + EYE_TILT * (a_side - EYE_A)


def slit_half_height(a):
    """Template half-height (rad) of the mouth slit at azimuth a (0 beyond the corners)."""
    s = a / MOUTH_HALF_W
    return SLIT_HALF_H * np.clip(1.0 - s * s, 0.0, None) ** SLIT_EXPONENT


def eye_margins(a_side):
    """Template elevations (upper, lower) of the eyelid margins at azimuth |a| (rad)."""
    c, h = eye_centre_line(a_side), eye_half_height(a_side)
    return c + h, c - h


def in_eye_opening(a, e):
    """Boolean (...,): template point inside either eye opening."""
    a_side = np.abs(a)
    return np.abs(e - eye_centre_line(a_side)) < eye_half_height(a_side)


def in_mouth_slit(a, e):
    """Boolean (...,): template point inside the mouth slit."""
    return np.abs(e - MOUTH_E) < slit_half_height(a)


def hole_boundaries(n_eye=400, n_mouth=600):
    """Closed template polylines of the holes: list of (a (n,), e (n,)) in rad.

    Order: left eye, right eye, mouth. Dense; `tessellate` resamples them.
    """
    out = []
    t = np.linspace(0.0, 2.0 * np.pi, n_eye, endpoint=False)
    a_side = EYE_A + EYE_HALF_W * np.cos(t)
    e = eye_centre_line(a_side) + EYE_HALF_H * np.abs(np.sin(t)) ** (2 * EYE_EXPONENT) * np.sign(np.sin(t))
    for side in (1.0, -1.0):
        out.append((side * a_side, e))
    t = np.linspace(0.0, 2.0 * np.pi, n_mouth, endpoint=False)
    a = MOUTH_HALF_W * np.cos(t)
    e = MOUTH_E + SLIT_HALF_H * np.abs(np.sin(t)) ** (2 * SLIT_EXPONENT) * np.sign(np.sin(t))
    out.append((a, e))
    return out


# ----------------------------------------------------------------------------- warp
def warp(a, e, P):
    """Template angles -> geometric angles (a', e') (rad) for head parameters P (dict).

    Stage 1 moves a (monotone in a for every e), stage 2 moves e (monotone in e for every a'), so the
    map is an orientation-preserving diffeomorphism; `tests/test_synth_head.py` checks its Jacobian.
    """
    ge = gauss(e - EYE_E, 0.22)
    eye_l, eye_r = a - EYE_A, a + EYE_A
    a2 = (a
          + P["eye_shift"] * (gauss(eye_l, 0.16) - gauss(eye_r, 0.16)) * ge
          + P["eye_scale"] * (eye_l * gauss(eye_l, 0.14) + eye_r * gauss(eye_r, 0.14))
          * gauss(e - EYE_E, 0.12)
          + P["mouth_scale"] * a * gauss(a, 0.3) * gauss(e - MOUTH_E, 0.12))
    t = e - MOUTH_E
    e1 = e - MOUTH_COMPRESS * np.exp(-(a2 / 0.42) ** 4) * t * gauss(t, MOUTH_COMPRESS_SIGMA)
    eyes_a = gauss(a2 - EYE_A, 0.3) + gauss(a2 + EYE_A, 0.3)
    eyes_a_narrow = gauss(a2 - EYE_A, 0.14) + gauss(a2 + EYE_A, 0.14)
    e2 = (e1
          + P["eye_raise"] * gauss(e - EYE_E, 0.2) * eyes_a
          + P["eye_scale"] * (e - EYE_E) * gauss(e - EYE_E, 0.12) * eyes_a_narrow
          + (P["mouth_raise"] + P["mouth_tilt"] * a2) * gauss(t, 0.15) * gauss(a2, 0.4))
    return a2, e2


# ----------------------------------------------------------------------------- radial function
def _ellipsoid_exit(d, centre, axes):
    """Distance along unit rays d (...,3) from O to the far side of an ellipsoid containing O."""
    q = (STAR_CENTRE - centre) / axes
    w = d / axes
    A = np.sum(w * w, -1)
    B = np.sum(w * q, -1)
    C = np.sum(q * q) - 1.0
    return (-B + np.sqrt(B * B - A * C)) / A


def _neck_exit(d, P):
    """Distance along d to the elliptic neck cylinder (axis along y through O), capped above."""
    w = d[..., [0, 2]] / np.array([P["neck_rx"], P["neck_rz"]])
    r_cyl = 1.0 / np.sqrt(np.sum(w * w, -1) + 1e-12)
    r_cap = np.where(d[..., 1] > 1e-6, 3.0 / np.maximum(d[..., 1], 1e-6), 1e3)
    return smin(np.minimum(r_cyl, 1e3), r_cap, 2.0)


def radial_base(d, P):
    """Radius (...,) cm of the base head (cranium, jaw and neck blended) along unit directions d."""
    cranium = _ellipsoid_exit(d, np.array([0.0, P["cranium_cy"], P["cranium_cz"]]),
                              np.array([P["cranium_w"], P["cranium_h"], P["cranium_d"]]))
    jaw = _ellipsoid_exit(d, np.array([0.0, P["jaw_cy"], P["jaw_cz"]]),
                          np.array([P["jaw_w"], P["jaw_h"], P["jaw_d"]]))
    return smax(smax(cranium, jaw, 1.6), _neck_exit(d, P), 1.2)


def _pair(a, e, a0, e0, sa, se):
    """Left + mirrored right Gaussian lobes in template angles."""
    ge = gauss(e - e0, se)
    return (gauss(a - a0, sa) + gauss(a + a0, sa)) * ge


def _nose(a, e, P):
    """Radial offset of the nose (bridge ramp, tip, alae) in cm."""
    t = np.clip((P["nose_root_e"] - e) / (P["nose_root_e"] - P["nose_tip_e"]), 0.0, 1.2)
    height = P["nose_root_h"] + (P["nose_tip_h"] - P["nose_root_h"]) * t ** 1.3
    top = 1.0 / (1.0 + np.exp(-(P["nose_root_e"] + 0.06 - e) / 0.025))
    bottom = 1.0 / (1.0 + np.exp(-(e - P["nose_base_e"]) / 0.022))
    an = a - P["nose_shift"]
    width = P["nose_bridge_w"] + (P["nose_base_w"] - P["nose_bridge_w"]) * np.clip(t, 0, 1)
    ridge = height * top * bottom * np.exp(-0.5 * (an / width) ** 2)
    tip = P["nose_tip_bulb"] * gauss(an, 0.045) * gauss(e - P["nose_tip_e"] + 0.015, 0.04)
    alae = P["alae_h"] * (gauss(an - P["alae_a"], 0.035) + gauss(an + P["alae_a"], 0.035)) * gauss(
        e - P["nose_base_e"] - 0.045, 0.035)
    return ridge + tip + alae


def _mouth_region(a, e, P):
    """Radial offset of lips, slit crease, mentolabial sulcus and the mouth's forward bulge (cm)."""
    s = np.abs(a) / (MOUTH_HALF_W * 1.12)
    taper = np.clip(1.0 - s * s, 0.0, None) ** 1.5           # lips thin out toward the corners
    upper = P["lip_upper_h"] * taper * gauss(e - MOUTH_E - 0.045, 0.03)
    lower = P["lip_lower_h"] * taper * gauss(e - MOUTH_E + 0.055, 0.038)
    crease = -0.3 * np.exp(-(a / (1.05 * MOUTH_HALF_W)) ** 6) * gauss(e - MOUTH_E, 0.012)
    bulge = P["mouth_bulge"] * gauss(a, 0.3) * gauss(e - MOUTH_E, 0.13)
    sulcus = -0.2 * gauss(a, 0.15) * gauss(e - MOUTH_E + 0.2, 0.06)
    return upper + lower + crease + bulge + sulcus


def _nasolabial(a, e, P):
    """Radial offset (cm) of the nasolabial grooves: from beside the alae to past the mouth corners."""
    start, end = np.array([0.14, 0.03]), np.array([0.34, -0.33])
    seg = end - start
    rel = np.stack([np.abs(a) - start[0], e - start[1]], -1)
    t = np.clip(rel @ seg / (seg @ seg), 0.0, 1.0)
    dist = np.linalg.norm(rel - t[..., None] * seg, axis=-1)
    return -P["fold_depth"] * gauss(dist, 0.04) * np.sin(np.pi * (0.15 + 0.85 * t)) ** 0.5


def features(a, e, P):
    """Radial feature offsets (...,) cm in template angles: face relief other than the eyeballs."""
    socket = -P["socket_depth"] * _pair(a, e, EYE_A + 0.01, EYE_E + 0.01, 0.13, 0.085)
    brow = P["brow_h"] * (gauss(np.abs(a) - 0.28, 0.2) + 0.6 * gauss(a, 0.12)) * gauss(e - P["brow_e"], 0.07)
    forehead = P["forehead_h"] * gauss(a, 0.45) * gauss(e - 0.95, 0.22)
    cheekbone = P["cheekbone_h"] * _pair(a, e, 0.6, P["cheekbone_e"], 0.2, 0.11)
    cheek = P["cheek_h"] * _pair(a, e, 0.42, -0.2, 0.16, 0.14)
    temple = -P["temple_depth"] * _pair(a, e, 0.95, 0.62, 0.22, 0.2)
    chin = P["chin_h"] * gauss(a, P["chin_w"]) * gauss(e - P["chin_e"], 0.11)
    jaw_angle = P["jaw_angle_h"] * _pair(a, e, 1.3, -0.62, 0.16, 0.13)
    ears = P["ear_h"] * _pair(a, e, 1.56, P["ear_e"], 0.09, P["ear_size"])
    return (socket + brow + forehead + cheekbone + cheek + temple + chin + jaw_angle + ears
            + _nose(a, e, P) + _mouth_region(a, e, P) + _nasolabial(a, e, P))


def eye_open_mask(a, e):
    """Smooth indicator (...,) in [0, 1] of the eye openings (1 inside)."""
    a_side = np.abs(a)
    return 1.0 / (1.0 + np.exp((np.abs(e - eye_centre_line(a_side)) - eye_half_height(a_side)) / 0.004))


def eyeball_centres(P):
    """(2, 3) eyeball centres (left, right) in cm for head parameters P: behind the centre of each
    eye opening along +z (gaze straight ahead), the front of the ball `eye_protrusion` cm in front
    of the socket surface."""
    a0 = np.array([EYE_A, -EYE_A])
    e0 = np.full(2, EYE_E)
    a1, e1 = warp(a0, e0, P)
    d = direction(a1, e1)
    socket = STAR_CENTRE + (radial_base(d, P) + features(a0, e0, P))[:, None] * d
    return socket + np.array([0.0, 0.0, P["eye_protrusion"] - P["eyeball_r"]])


def _eyeball_radius(d, centres, r_ball):
    """Distance (...,) along rays d from O to the front of the nearer eyeball it crosses (the far
    ray/sphere intersection: O is inside the head, behind the eyes), -inf where a ray misses both."""
    out = np.full(d.shape[:-1], -np.inf)
    for c in centres:
        oc = c - STAR_CENTRE
        b = d @ oc
        disc = b * b - (oc @ oc - r_ball ** 2)
        t = np.where(disc > 0, b + np.sqrt(np.maximum(disc, 0.0)), -np.inf)
        out = np.maximum(out, t)
    return out


def lid_region(a, e):
    """Smooth indicator (...,) in [0, 1] of the eyelids' extent around either eye opening: an
    ellipse in template angles reaching about 5 mm beyond the lid margins."""
    a_side = np.abs(a)
    q = ((a_side - EYE_A) / (EYE_HALF_W + 0.05)) ** 2 + ((e - eye_centre_line(a_side)) / (EYE_HALF_H + 0.06)) ** 2
    return 1.0 / (1.0 + np.exp(np.minimum((q - 1.0) / 0.35, 50.0)))


def radius(a, e, d, P, centres):
    """Final radius (...,) cm: base + features, smoothly maxed with the eyeballs under the lids.

    Inside the lid region the eyeball front (plus the lid thickness outside the opening) pokes
    out of the socket; outside it the eyeball is sunk 1 cm under the face, so it never shows.
    """
    r_face = radial_base(d, P) + features(a, e, P)
    r_eye = (_eyeball_radius(d, centres, P["eyeball_r"])
             + P["lid_thickness"] * (1.0 - eye_open_mask(a, e)) - 1.0 * (1.0 - lid_region(a, e)))
    r_eye = np.where(np.isfinite(r_eye), r_eye, r_face - 10.0)
    return np.maximum(smax(r_face, r_eye, 12.0), 1.0)


def surface_template(a, e, identity):
    """Head points (..., 3) cm at template angles (a, e) for identity coefficients z_ID (J,)."""
    P = head_params(identity)
    return _surface(a, e, P, eyeball_centres(P))


def _surface(a, e, P, centres):
    a2, e2 = warp(a, e, P)
    d = direction(a2, e2)
    return STAR_CENTRE + radius(a, e, d, P, centres)[..., None] * d


def _base_surface(a, e, P):
    """Points of the smooth base head (cranium/jaw/neck only, no features) at template angles."""
    d = direction(*warp(a, e, P))
    return STAR_CENTRE + radial_base(d, P)[..., None] * d


def surface(uv, identity):
    """Head points (V, 3) float64 cm at disc coordinates uv (V, 2) for identity z_ID (J,)."""
    a, e = uv_to_template(uv)
    return surface_template(a, e, identity)


def _uv_normals(point_fn, uv, step):
    """Unit outward normals (V,3) of point_fn(uv) by central differences in uv."""
    du, dv = np.array([step, 0.0]), np.array([0.0, step])
    n = np.cross(point_fn(uv + dv) - point_fn(uv - dv), point_fn(uv + du) - point_fn(uv - du))
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)


class SurfaceSample:
    """The surface of one identity at given uv, with what expression operators need.

    Attributes: uv (V,2); a, e (V,) template angles (rad); points (V,3) cm; normals (V,3) unit,
    outward (by central differences in uv, so they depend only on uv and z_ID); smooth_normals (V,3):
    normals of the feature-free base head (stable directions for inflation); P (dict of head
    parameters); eyeball_centres (2,3) cm; identity (J,); cache (dict): per-sample quantities that
    several expression operators share (e.g. the eyelid frame), filled lazily by them.
    """

    def __init__(self, uv, identity, fd_step=2e-4):
        self.uv = np.asarray(uv, dtype=np.float64)
        self.identity = np.asarray(identity, dtype=np.float64)
        self.P = head_params(self.identity)
        self.eyeball_centres = eyeball_centres(self.P)
        self.a, self.e = uv_to_template(self.uv)
        self.points = self.at_template(self.a, self.e)
        self.normals = _uv_normals(self.at_uv, self.uv, fd_step)
        self.smooth_normals = _uv_normals(lambda q: _base_surface(*uv_to_template(q), self.P),
                                          self.uv, fd_step)
        self.cache = {}

    def at_uv(self, uv):
        """Points (...,3) of this identity at other disc coordinates."""
        a, e = uv_to_template(uv)
        return self.at_template(a, e)

    def at_template(self, a, e):
        """Points (...,3) of this identity at template angles."""
        return _surface(np.asarray(a, float), np.asarray(e, float), self.P, self.eyeball_centres)
