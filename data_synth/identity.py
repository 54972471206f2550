"""Identity space z_ID: named smooth modes acting linearly on the head parameters (FLAME's linear
shape space, generated instead of learned).

head parameters = BASE_PARAMS + sum_j z_ID[j] * MODE_DELTAS[j]     (cm, rad or unitless)

Coefficients are ~N(0, 1); the stylised share draws wider (cartoon proportions) and turns the
stylised modes on. Modes in `ASYMMETRIC_MODES` are odd under x -> -x (nose deviation, mouth tilt);
all others are even, so `mirror_identity` (negating the odd ones) describes the mirrored head.

Seeds: `sample_identity(seed, split)` draws from numpy's generator seeded with the entropy words
[SPLIT_IDS[split], seed] (any seed >= 0). The split id is part of the seed itself, so the train,
val and test seed spaces are disjoint by construction: (0, s), (1, s) and (2, s) never coincide
(seed ranges {0}x N, {1}x N, {2}x N), and no train seed can reproduce a test identity.
"""
from __future__ import annotations

import numpy as np

BASE_PARAMS = {
    # base volumes (cm): cranium and jaw ellipsoids, neck cylinder
    "cranium_w": 7.7, "cranium_h": 9.6, "cranium_d": 9.6, "cranium_cy": 1.4, "cranium_cz": -1.2,
    "jaw_w": 5.9, "jaw_h": 8.2, "jaw_d": 7.6, "jaw_cy": -4.3, "jaw_cz": 1.7,
    "neck_rx": 5.3, "neck_rz": 5.5,
    # eyes (cm)
    "eyeball_r": 1.2, "eye_protrusion": 0.35, "lid_thickness": 0.12, "socket_depth": 1.0,
    # features (cm heights, rad positions and widths)
    "brow_h": 0.45, "brow_e": 0.6, "forehead_h": 1.0,
    "cheekbone_h": 0.45, "cheekbone_e": 0.12, "cheek_h": 0.3, "temple_depth": 0.35,
    "chin_h": 1.3, "chin_w": 0.2, "chin_e": -0.74, "jaw_angle_h": 0.2, "fold_depth": 0.1,
    "ear_h": 1.2, "ear_e": 0.4, "ear_size": 0.15,
    "nose_root_e": 0.46, "nose_tip_e": 0.13, "nose_base_e": 0.035,
    "nose_root_h": 0.35, "nose_tip_h": 1.8, "nose_tip_bulb": 0.35,
    "nose_bridge_w": 0.055, "nose_base_w": 0.085, "alae_h": 0.55, "alae_a": 0.085, "nose_shift": 0.0,
    "lip_upper_h": 0.45, "lip_lower_h": 0.55, "mouth_bulge": 0.3,
    # warp (rad or unitless)
    "eye_shift": 0.0, "eye_scale": 0.0, "eye_raise": 0.0,
    "mouth_scale": 0.0, "mouth_raise": 0.0, "mouth_tilt": 0.0,
}

# (name, {parameter: change per unit coefficient})
_MODES = (
    ("head_width", {"cranium_w": 0.35, "jaw_w": 0.15}),
    ("head_height", {"cranium_h": 0.4, "cranium_cy": 0.15}),
    ("head_depth", {"cranium_d": 0.4, "cranium_cz": -0.15}),
    ("crown_height", {"cranium_cy": 0.35}),
    ("back_of_head", {"cranium_cz": -0.3, "cranium_d": 0.2}),
    ("jaw_width", {"jaw_w": 0.4}),
    ("jaw_depth", {"jaw_d": 0.35}),
    ("face_length", {"jaw_h": 0.45, "jaw_cy": -0.25}),
    ("lower_face_forward", {"jaw_cz": 0.3}),
    ("chin_length", {"chin_e": -0.035, "jaw_h": 0.2}),
    ("chin_protrusion", {"chin_h": 0.3}),
    ("chin_width", {"chin_w": 0.04}),
    ("jaw_angle", {"jaw_angle_h": 0.15}),
    ("nose_length", {"nose_tip_e": -0.025, "nose_base_e": -0.02}),
    ("nose_width", {"nose_base_w": 0.012, "alae_a": 0.012}),
    ("nose_bridge", {"nose_root_h": 0.15}),
    ("nose_tip_size", {"nose_tip_bulb": 0.12}),
    ("nose_projection", {"nose_tip_h": 0.3}),
    ("nostril_flare", {"alae_h": 0.15}),
    ("eye_size", {"eye_scale": 0.045}),
    ("eye_spacing", {"eye_shift": 0.012}),
    ("eye_height", {"eye_raise": 0.012}),
    ("eye_depth", {"socket_depth": 0.2, "eye_protrusion": -0.05}),
    ("brow_height", {"brow_e": 0.025}),
    ("brow_ridge", {"brow_h": 0.15}),
    ("forehead_slope", {"forehead_h": 0.3}),
    ("cheekbone_height", {"cheekbone_e": 0.03}),
    ("cheekbone_prominence", {"cheekbone_h": 0.15}),
    ("cheek_fullness", {"cheek_h": 0.15}),
    ("temple_depth", {"temple_depth": 0.1}),
    ("nasolabial_depth", {"fold_depth": 0.06}),
    ("lip_upper_thickness", {"lip_upper_h": 0.12}),
    ("lip_lower_thickness", {"lip_lower_h": 0.12}),
    ("mouth_width", {"mouth_scale": 0.045}),
    ("mouth_height", {"mouth_raise": 0.012}),
    ("mouth_protrusion", {"mouth_bulge": 0.2}),
    ("neck_width", {"neck_rx": 0.3, "neck_rz": 0.3}),
    ("ear_size", {"ear_size": 0.02, "ear_h": 0.15}),
    ("ear_height", {"ear_e": 0.03}),
    ("stylised_big_eyes", {"eye_scale": 0.05, "eyeball_r": 0.08, "socket_depth": 0.1}),
    ("stylised_small_jaw", {"jaw_w": -0.35, "jaw_h": -0.35, "chin_h": -0.15, "cranium_w": 0.2}),
    ("stylised_long_nose", {"nose_tip_h": 0.45, "nose_tip_e": -0.02, "nose_tip_bulb": 0.08}),
    ("stylised_heavy_jaw", {"jaw_w": 0.35, "chin_h": 0.3, "jaw_angle_h": 0.2, "chin_w": 0.03}),
    ("stylised_round_head", {"cranium_w": 0.3, "cranium_h": 0.25, "cranium_d": 0.25}),
    ("stylised_big_mouth", {"mouth_scale": 0.04, "lip_upper_h": 0.1, "lip_lower_h": 0.12}),
    ("asym_nose", {"nose_shift": 0.008}),
    ("asym_mouth", {"mouth_tilt": 0.02}),
)

IDENTITY_MODES = tuple(name for name, _ in _MODES)
N_IDENTITY = len(IDENTITY_MODES)
PARAM_NAMES = tuple(BASE_PARAMS)
STYLISED_MODES = tuple(n for n in IDENTITY_MODES if n.startswith("stylised_"))
ASYMMETRIC_MODES = tuple(n for n in IDENTITY_MODES if n.startswith("asym_"))

_BASE = np.array([BASE_PARAMS[k] for k in PARAM_NAMES])
MODE_DELTAS = np.zeros((N_IDENTITY, len(PARAM_NAMES)))   # (J, n_params)
for _j, (_name, _delta) in enumerate(_MODES):
    for _key, _value in _delta.items():
        MODE_DELTAS[_j, PARAM_NAMES.index(_key)] = _value

SPLITS = ("train", "val", "test")
SPLIT_IDS = {s: 1000 + i for i, s in enumerate(SPLITS)}
COEF_LIMIT = 3.0            # ordinary identities
STYLISED_LIMIT = 4.0        # stylised share (documented validity range: |z| <= 4)

_ODD = np.array([n in ASYMMETRIC_MODES for n in IDENTITY_MODES])
_STYLISED = np.array([n in STYLISED_MODES for n in IDENTITY_MODES])


def head_params(identity) -> dict:
    """Head parameters {name: float} for identity coefficients z_ID (J,)."""
    z = np.asarray(identity, dtype=np.float64)
    if z.shape != (N_IDENTITY,):
        raise ValueError(f"identity must have shape ({N_IDENTITY},), got {z.shape}")
    return dict(zip(PARAM_NAMES, _BASE + z @ MODE_DELTAS))


def mean_identity() -> np.ndarray:
    """The mean identity: zeros (J,) float64."""
    return np.zeros(N_IDENTITY)


def mirror_identity(identity) -> np.ndarray:
    """Coefficients (J,) of the head mirrored about x = 0 (asymmetric modes negated)."""
    z = np.array(identity, dtype=np.float64)
    z[_ODD] *= -1.0
    return z


def sample_identity(seed: int, split: str = "train", stylised_share: float = 0.2) -> np.ndarray:
    """Deterministic identity coefficients z_ID (J,) float64 for `seed` in `split`.

    Ordinary identities: anatomical modes ~N(0,1) clipped to +-3, stylised modes ~N(0, 0.3),
    asymmetric modes ~N(0, 0.5). With probability `stylised_share`: all modes ~N(0, 1.6) clipped
    to +-4 (cartoon proportions).
    """
    if split not in SPLIT_IDS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if int(seed) < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    if not 0.0 <= stylised_share <= 1.0:
        raise ValueError(f"stylised_share must be in [0, 1], got {stylised_share}")
    rng = np.random.default_rng([SPLIT_IDS[split], int(seed)])
    stylised = rng.random() < stylised_share
    z = rng.standard_normal(N_IDENTITY)
    if stylised:
        return np.clip(1.6 * z, -STYLISED_LIMIT, STYLISED_LIMIT)
    scale = np.where(_STYLISED, 0.3, np.where(_ODD, 0.5, 1.0))
    return np.clip(scale * z, -COEF_LIMIT, COEF_LIMIT)
