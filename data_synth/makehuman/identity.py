"""Realistic head identities: random, plausible mixes of MakeHuman's CC0 shape targets.

An identity is one weight per target of ``makehuman_heads.npz`` (796) plus one per bust-only macro
target (34): the head is ``neutral + weights · targets`` (MakeHuman is purely linear). Macros
(gender, age, muscle, weight, height, body proportions, a Dirichlet mix of the three ethnic
bases) follow MakeHuman's macro formulas (data/README.md, "How MakeHuman combines targets"); face
modifiers, one head shape and the asymmetry pairs are drawn in the ranges of data/README.md
("Sampling plausible identities"), which stay human. A ``stylised`` identity widens every range
(the macro corners and about 2.5x the modifier spread): caricatures, not monsters.

Seeds of the three splits are disjoint (train from 0, val from 10**8, test from 2 * 10**8), as for
the procedural identities (``data_synth.identity``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import assets

SPLIT_OFFSET = {"train": 0, "val": 100_000_000, "test": 200_000_000}
FACE_GROUPS = ("head", "forehead", "eyebrows", "neck", "eyes", "nose", "mouth", "ears", "chin",
               "cheek")
EXCLUDED_MODIFIERS = ("head/head-trans-in|out", "head/head-trans-down|up",
                      "head/head-trans-backward|forward", "head/head-angle-in|out",
                      "neck/neck-trans-in|out", "neck/neck-trans-down|up",
                      "neck/neck-trans-backward|forward")
HEAD_SHAPES = ("oval", "round", "rectangular", "square", "triangular", "invertedtriangular",
               "diamond")
RACES = ("african", "asian", "caucasian")


@dataclass
class HeadIdentity:
    """weights (796,) float32: per head-shape target; extra (34,) float32: per bust-only macro
    target; macros: the macro variables drawn (gender, age, muscle, weight, height,
    proportions in [0,1], race (3,) summing to 1); seed, split, stylised: how it was drawn."""

    weights: np.ndarray
    extra: np.ndarray
    macros: dict
    seed: int
    split: str
    stylised: bool


def category_values(gender, age, muscle, weight, height, proportions, race) -> dict[str, float]:
    """MakeHuman's val() of every category value ('' = 1) for the given macro variables in [0,1]."""
    if age < 0.5:
        young = max(0.0, 3.2 * (age - 0.1875))
        ages = {"baby": max(0.0, 1 - 5.333 * age), "young": young,
                "child": max(0.0, min(1.0, 5.333 * age) - young), "old": 0.0}
    else:
        ages = {"baby": 0.0, "child": 0.0, "old": 2 * age - 1, "young": 2 - 2 * age}

    def triangle(x, lo, mid, hi):
        vmax, vmin = max(0.0, 2 * x - 1), max(0.0, 1 - 2 * x)
        return {hi: vmax, lo: vmin, mid: 1 - vmax - vmin}

    vals = {"": 1.0, "male": gender, "female": 1 - gender, **ages,
            **triangle(muscle, "minmuscle", "averagemuscle", "maxmuscle"),
            **triangle(weight, "minweight", "averageweight", "maxweight"),
            **triangle(height, "minheight", "averageheight", "maxheight"),
            **triangle(proportions, "uncommonproportions", "regularproportions",
                       "idealproportions")}
    vals.update(zip(RACES, map(float, race)))
    return vals


def macro_weights(macro_vars: np.ndarray, vals: dict[str, float]) -> np.ndarray:
    """Weights (K,) of macro targets whose category values are the rows of ``macro_vars`` (K,7)."""
    return np.array([np.prod([vals[v] for v in row]) for row in macro_vars], np.float32)


def _modifier_spread(z: dict) -> np.ndarray:
    """(M,) the largest displacement (cm) of each modifier's targets."""
    m = np.zeros(len(z["modifier_names"]))
    for side in ("modifier_neg", "modifier_pos"):
        idx = z[side]
        m = np.maximum(m, np.where(idx >= 0, z["target_max_cm"][np.maximum(idx, 0)], 0.0))
    return m


def sample_head_identity(seed: int, split: str = "train", stylised_share: float = 0.15,
                         partial_macro_share: float = 0.0) -> HeadIdentity:
    """A random head of ``split`` (its own seed range). Deterministic in (seed, split).

    partial_macro_share: the probability that the head's macro targets (ethnicity, gender, age,
    muscle, weight, height, proportions) are applied at a scale s ~ U(0, 1) instead of fully, so
    that heads between MakeHuman's raw base mesh (s = 0, which no full macro mix gives) and a
    finished human are drawn too. Drawn from a stream of its own: the heads of share 0 are those
    of earlier versions."""
    if split not in SPLIT_OFFSET:
        raise ValueError(f"split must be one of {tuple(SPLIT_OFFSET)}, got {split!r}")
    rng = np.random.default_rng([SPLIT_OFFSET[split] + int(seed), 4242])
    z = assets.heads()
    stylised = bool(rng.random() < stylised_share)
    wide = 2.5 if stylised else 1.0
    if stylised:
        gender = float(rng.uniform(0, 1))
        age = float(rng.uniform(0.3, 1.0))
        muscle, weight = rng.uniform(0.0, 1.0, size=2)
        height = float(rng.uniform(0.25, 0.75))
        race = rng.dirichlet([0.3, 0.3, 0.3])
    else:
        gender = float(rng.uniform(0, 0.25) if rng.random() < 0.5 else rng.uniform(0.75, 1.0))
        years = rng.uniform(18, 85)
        age = float((years - 1) / 48 if years < 25 else 0.5 + (years - 25) / 130)
        muscle, weight = float(rng.uniform(0.3, 0.8)), float(rng.uniform(0.2, 0.85))
        height = float(rng.uniform(0.3, 0.65))
        race = rng.dirichlet([0.6, 0.6, 0.6])
    proportions = float(rng.uniform(0.3, 0.9))
    macros = dict(gender=gender, age=age, muscle=float(muscle), weight=float(weight),
                  height=height, proportions=proportions, race=race)
    vals = category_values(**macros)

    weights = np.zeros(len(z["target_names"]), np.float32)
    weights[z["macro_target"]] = macro_weights(z["macro_vars"], vals)
    extra = macro_weights(z["bust_extra_macro_vars"], vals)

    names, groups = z["modifier_names"], z["modifier_group"]
    spread = _modifier_spread(z)
    values = np.zeros(len(names))
    shape = HEAD_SHAPES[int(rng.integers(len(HEAD_SHAPES)))]
    for m, name in enumerate(names):       # fixed order: one stream of draws per identity
        g = str(groups[m])
        s = min(0.2, 0.6 / max(spread[m], 1e-6))
        draw_two, draw_asym, draw_u = rng.normal(), rng.normal(), rng.uniform()
        if str(name) in EXCLUDED_MODIFIERS:
            continue
        if g == "asym":
            values[m] = np.clip(0.12 * wide * draw_asym, -0.3 * wide, 0.3 * wide)
        elif g in FACE_GROUPS and z["modifier_min"][m] < 0:
            values[m] = np.clip(wide * s * draw_two, -min(0.5, 2.5 * s) * wide,
                                min(0.5, 2.5 * s) * wide)
        elif g == "head" and str(name) == f"head/head-{shape}":
            values[m] = draw_u * min(0.5, 0.6 / max(spread[m], 1e-6)) * wide
    # symmetric l/r partners share one value plus a little noise (the lower index leads)
    for m, partner in enumerate(z["modifier_mirror"]):
        if partner > m and values[m] != 0.0:
            s = min(0.2, 0.6 / max(spread[m], 1e-6))
            values[partner] = values[m] + 0.25 * s * wide * rng.normal()
    for m, v in enumerate(values):
        if v > 0 and z["modifier_pos"][m] >= 0:
            weights[z["modifier_pos"][m]] += v
        elif v < 0 and z["modifier_neg"][m] >= 0:
            weights[z["modifier_neg"][m]] += -v
    if partial_macro_share > 0:
        part = np.random.default_rng([SPLIT_OFFSET[split] + int(seed), 4243])
        if part.random() < partial_macro_share:
            scale = np.float32(part.uniform(0.0, 1.0))
            weights[z["macro_target"]] *= scale
            extra = extra * scale
    return HeadIdentity(weights, extra, macros, int(seed), split, stylised)


def head_neutral(identity: HeadIdentity, part: str = "head") -> np.ndarray:
    """The identity's neutral: part "head" -> (4326,3) (skin, then mouth cavity and eye
    sockets), "bust" -> (5472,3); float32 cm, MakeHuman's origin (macros move the head a little)."""
    z = assets.heads()
    if part == "head":   # the bust's first rows (its bust-only targets are 0 there)
        return head_neutral(identity, "bust")[:assets.N_HEAD]
    if part == "bust":
        return (z["bust_neutral"] + np.tensordot(identity.weights, assets.bust_targets(), axes=1)
                + np.tensordot(identity.extra, assets.bust_extra_targets(), axes=1))
    raise ValueError(f"part must be 'head' or 'bust', got {part!r}")
