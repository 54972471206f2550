"""The 53 expression operators and the rig (data_synth.expressions, data_synth.rig)."""

import numpy as np
import pytest

from data_synth import FACS_NAMES, head
from data_synth.expressions import expression_deltas
from data_synth.identity import (ASYMMETRIC_MODES, IDENTITY_MODES, mean_identity, mirror_identity,
                                 sample_identity)
from data_synth.rig import build_rig
from data_synth.segmentation import SEGMENT_NAMES, segment_labels
from data_synth.tessellate import tessellate

M = np.array([-1.0, 1.0, 1.0])
K = {n: i for i, n in enumerate(FACS_NAMES)}

# Regions (20-level names, L side; swapped for _R) holding >= 75 % of each shape's motion energy.
EXPECTED = {
    "browDown": "brow upper_eyelid nose_bridge", "browInnerUp": "brow forehead upper_eyelid nose_bridge",
    "browOuterUp": "brow upper_eyelid forehead", "cheekPuff": "cheek mouth_corner jaw",
    "cheekSquint": "cheek lower_eyelid", "eyeBlink": "upper_eyelid lower_eyelid",
    "eyeLookDown": "upper_eyelid lower_eyelid", "eyeLookIn": "upper_eyelid lower_eyelid",
    "eyeLookOut": "upper_eyelid lower_eyelid", "eyeLookUp": "upper_eyelid lower_eyelid",
    "eyeSquint": "upper_eyelid lower_eyelid cheek", "eyeWide": "upper_eyelid lower_eyelid",
    "jawForward": "chin jaw lower_lip neck", "jawLeft": "chin jaw lower_lip neck",
    "jawOpen": "chin jaw lower_lip neck", "mouthClose": "lower_lip chin mouth_corner",
    "mouthDimple": "mouth_corner cheek upper_lip lower_lip", "mouthFrown": "mouth_corner jaw chin lower_lip",
    "mouthFunnel": "upper_lip lower_lip mouth_corner chin",
    "mouthLeft": "upper_lip lower_lip mouth_corner chin",
    "mouthLowerDown": "lower_lip chin", "mouthPress": "upper_lip lower_lip mouth_corner",
    "mouthPucker": "upper_lip lower_lip mouth_corner", "mouthRollLower": "lower_lip chin",
    "mouthRollUpper": "upper_lip", "mouthShrugLower": "chin lower_lip", "mouthShrugUpper": "upper_lip",
    "mouthSmile": "mouth_corner cheek upper_lip lower_lip", "mouthStretch": "mouth_corner lower_lip chin jaw",
    "mouthUpperUp": "upper_lip mouth_corner", "noseSneer": "nose_tip nose_bridge cheek",
}


@pytest.fixture(scope="module")
def tess():
    return tessellate(2500, kind="adaptive", region="full", holes=True)


def _symmetric(z):
    z = np.array(z)
    z[[IDENTITY_MODES.index(m) for m in ASYMMETRIC_MODES]] = 0.0
    return z


def _expected(name):
    """Label ids where shape `name` should move: sided regions on its own side only for _L/_R."""
    sided = name[-2:] in ("_L", "_R")
    base = name[:-2] if sided else {"jawRight": "jawLeft", "mouthRight": "mouthLeft"}.get(name, name)
    sides = [name[-1]] if sided else ["L", "R"]
    out = set()
    for region in EXPECTED[base].split():
        names = [region] if region in SEGMENT_NAMES[20] else [f"{region}_{s}" for s in sides]
        out |= {SEGMENT_NAMES[20].index(n) for n in names}
    return out


def test_every_shape_moves_mainly_inside_its_regions(tess):
    d = expression_deltas(tess.uv, mean_identity())
    lab = segment_labels(tess.uv, 20)
    energy = (d ** 2).sum(-1)
    for k, name in enumerate(FACS_NAMES):
        frac = np.bincount(lab, weights=energy[k], minlength=20) / energy[k].sum()
        inside = sum(frac[i] for i in _expected(name))
        assert inside >= 0.75, (name, inside)
        assert 0.05 < np.sqrt(energy[k].max()) < 4.5, name


@pytest.mark.parametrize("z", [mean_identity(), _symmetric(sample_identity(4, "test"))])
def test_left_right_shapes_are_exact_mirrors(tess, z):
    d = expression_deltas(tess.uv, z)
    dm = expression_deltas(tess.uv * [-1, 1], z)
    for k, name in enumerate(FACS_NAMES):
        partner = {"jawLeft": "jawRight", "jawRight": "jawLeft", "mouthLeft": "mouthRight",
                   "mouthRight": "mouthLeft"}.get(name)
        if partner is None:
            partner = name[:-1] + {"L": "R", "R": "L"}[name[-1]] if name[-2:] in ("_L", "_R") else name
        assert np.allclose(d[k] * M, dm[K[partner]], atol=1e-9), name
    left = [k for k, n in enumerate(FACS_NAMES) if n.endswith("_L")]
    for k in left:   # a _L shape acts on the character's left (+x)
        p = head.surface(tess.uv, z)
        e = (d[k] ** 2).sum(-1)
        assert e[p[:, 0] > 0].sum() > 0.9 * e.sum(), FACS_NAMES[k]


def test_right_shape_of_an_asymmetric_head_is_the_left_shape_of_its_mirror(tess):
    z = sample_identity(9)
    z[IDENTITY_MODES.index("asym_mouth")] = 2.0
    d = expression_deltas(tess.uv, z, names=("mouthSmile_R",))[0]
    dl = expression_deltas(tess.uv * [-1, 1], mirror_identity(z), names=("mouthSmile_L",))[0]
    assert np.allclose(d, dl * M, atol=1e-12)


def test_exact_correspondence_across_tessellations():
    z = sample_identity(5, "val")
    coarse = tessellate(600, kind="regular", holes=True)
    fine = tessellate(3000, kind="jittered", region="face", holes=False, seed=2)
    both = np.vstack([coarse.uv, fine.uv])
    d_both = expression_deltas(both, z)
    assert np.array_equal(d_both[:, : len(coarse.uv)], expression_deltas(coarse.uv, z))
    assert np.allclose(build_rig(z, coarse).deltas, d_both[:, : len(coarse.uv)], atol=1e-6)
    rig = build_rig(z, fine)
    assert np.allclose(rig.neutral, head.surface(fine.uv, z), atol=1e-5)
    assert np.allclose(rig.deltas, d_both[:, len(coarse.uv):], atol=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_jaw_open_moves_the_chin_down_and_back(seed):
    z = sample_identity(seed, "test", stylised_share=0.5)
    chin = head.template_to_uv(np.zeros(1), np.full(1, -0.74))
    d = expression_deltas(chin, z, names=("jawOpen",))[0, 0]
    assert 2.5 <= np.linalg.norm(d) <= 4.5
    assert d[1] < -0.6 * np.linalg.norm(d) and d[2] < 0 and abs(d[0]) < 1e-9
    # upper lip and forehead stay
    still = head.template_to_uv(np.zeros(2), np.array([-0.2, 0.8]))
    assert np.abs(expression_deltas(still, z, names=("jawOpen",))).max() < 1e-3


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_eye_blink_closes_the_eye(seed):
    z = sample_identity(seed, "test", stylised_share=0.5)
    for name, side in (("eyeBlink_L", 1.0), ("eyeBlink_R", -1.0)):
        a = side * np.linspace(head.EYE_A - 0.11, head.EYE_A + 0.11, 15)
        up, lo = head.eye_margins(np.abs(a))
        uv = head.template_to_uv(np.r_[a, a], np.r_[up, lo])
        p = head.surface(uv, z) + expression_deltas(uv, z, names=(name,))[0]
        gap = np.linalg.norm(p[:15] - p[15:], axis=1)
        assert gap.max() < 0.1, name                      # margins meet within 1 mm
        p0 = head.surface(uv, z)
        assert np.linalg.norm(p0[7] - p0[22]) > 0.7       # it was open


def test_mouth_close_corrects_jaw_open():
    z = sample_identity(2)
    hs = head.slit_half_height(np.zeros(1))
    uv = head.template_to_uv(np.zeros(2), np.r_[head.MOUTH_E + hs, head.MOUTH_E - hs])
    d = expression_deltas(uv, z, names=("jawOpen", "mouthClose"))
    p0 = head.surface(uv, z)
    opened = p0 + d[0]
    closed = p0 + d[0] + d[1]
    assert np.linalg.norm(opened[0] - opened[1]) > 2.0
    assert np.linalg.norm(closed[0] - closed[1]) < 0.4


def test_rig_evaluate():
    # (its speed is a benchmark, not a test: `python -m data_synth.rig` prints it)
    tess = tessellate(5000, kind="regular")
    z = sample_identity(1)
    rig = build_rig(z, tess)
    assert rig.deltas.shape == (53, rig.neutral.shape[0], 3) and rig.deltas.dtype == np.float32
    w = np.zeros(53)
    w[K["jawOpen"]] = 0.5
    assert np.allclose(rig.evaluate(w), rig.neutral + 0.5 * rig.deltas[K["jawOpen"]])
    assert rig.evaluate(np.zeros((4, 53))).shape == (4, len(tess.uv), 3)
    with pytest.raises(ValueError, match="weights"):
        rig.evaluate(np.zeros(52))
    with pytest.raises(ValueError, match="mouthSmileLeft"):
        expression_deltas(tess.uv[:5], z, names=("mouthSmileLeft",))
