"""Canonicalisation: centre + scale to 16 canonical units wide, exact inverse, unit invariance."""
import numpy as np
import pytest

from retarget.canonical import CANONICAL_WIDTH, Canonicaliser
from retarget.errors import RetargetError


@pytest.fixture
def head_cm():
    """A head-sized point set in centimetres, off-centre."""
    rng = np.random.default_rng(3)
    return rng.uniform([-7.5, -11, -9], [7.5, 12, 10], size=(200, 3)) + [3.0, 160.0, -2.0]


def test_canonical_frame_is_centred_and_16_wide(head_cm):
    c = Canonicaliser.fit(head_cm)
    x = c.to_canonical(head_cm)
    assert np.isclose(x[:, 0].max() - x[:, 0].min(), CANONICAL_WIDTH)
    assert np.allclose(0.5 * (x.min(axis=0) + x.max(axis=0)), 0.0, atol=1e-12)
    # uniform scale: aspect ratios kept
    ext_in, ext_out = np.ptp(head_cm, axis=0), np.ptp(x, axis=0)
    assert np.allclose(ext_out / ext_in, c.scale)


def test_round_trip_and_displacements(head_cm):
    c = Canonicaliser.fit(head_cm)
    assert np.allclose(c.from_canonical(c.to_canonical(head_cm)), head_cm)
    d = np.random.default_rng(0).standard_normal((5, 200, 3))
    moved = c.from_canonical(c.to_canonical(head_cm) + d)
    assert np.allclose(moved - head_cm, c.displacement_from_canonical(d))
    assert np.allclose(c.displacement_to_canonical(c.displacement_from_canonical(d)), d)


@pytest.mark.parametrize("unit", [0.01, 10.0])  # metres, millimetres
def test_units_do_not_change_the_canonical_mesh(head_cm, unit):
    shifted = head_cm * unit + np.array([100.0, -5.0, 2.0]) * unit
    a = Canonicaliser.fit(head_cm)
    b = Canonicaliser.fit(shifted)
    assert np.allclose(a.to_canonical(head_cm), b.to_canonical(shifted))
    # a canonical displacement comes back in each mesh's own units
    d = np.ones(3)
    assert np.allclose(b.displacement_from_canonical(d), a.displacement_from_canonical(d) * unit)


def test_flat_mesh_is_refused():
    flat = np.array([[0, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    with pytest.raises(RetargetError, match="face.obj: has no width"):
        Canonicaliser.fit(flat, name="face.obj")
