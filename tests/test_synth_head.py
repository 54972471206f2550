"""The procedural head surface and identity space (data_synth.head, data_synth.identity)."""
import numpy as np
import pytest

from data_synth import head
from data_synth.identity import (ASYMMETRIC_MODES, IDENTITY_MODES, N_IDENTITY, head_params,
                                 mean_identity, mirror_identity, sample_identity)


def _disc(n=161):
    """uv points (m,2) of an n x n grid inside the unit disc."""
    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    uv = np.stack([u.ravel(), v.ravel()], -1)
    return uv[np.hypot(uv[:, 0], uv[:, 1]) <= 1.0]


def _grid(n=60):
    a, e = np.meshgrid(np.linspace(-1.4, 1.4, n), np.linspace(-1.15, 1.0, n))
    return a.ravel(), e.ravel()


def test_identity_space_has_named_modes():
    assert N_IDENTITY >= 40 and len(set(IDENTITY_MODES)) == N_IDENTITY


def test_sample_identity_is_deterministic_and_splits_differ():
    assert np.array_equal(sample_identity(7, "train"), sample_identity(7, "train"))
    train = np.stack([sample_identity(s, "train") for s in range(200)])
    test = np.stack([sample_identity(s, "test") for s in range(200)])
    val = np.stack([sample_identity(s, "val") for s in range(200)])
    for a, b in ((train, test), (train, val), (val, test)):
        d = np.abs(a[:, None] - b[None]).sum(-1)
        assert d.min() > 1e-6            # no identity shared between splits
    assert train.std(0).mean() > 0.5     # actually random
    with pytest.raises(ValueError, match="split"):
        sample_identity(0, "holdout")


def test_chart_round_trip():
    a, e = _grid()
    a2, e2 = head.uv_to_template(head.template_to_uv(a, e))
    assert np.allclose(a, a2, atol=1e-9) and np.allclose(e, e2, atol=1e-9)


def test_mean_head_proportions():
    uv = _disc()
    p = head.surface(uv, mean_identity())
    a, _ = head.uv_to_template(uv)
    no_ears = np.abs(np.abs(a) - 1.56) > 0.3
    assert 13.5 < np.ptp(p[no_ears, 0]) < 16.5                 # ~15 cm wide
    chin = head.surface(head.template_to_uv(np.zeros(1), np.full(1, -0.74)), mean_identity())[0]
    assert 21.0 < p[:, 1].max() - chin[1] < 25.0                # chin to crown ~23 cm
    assert 10.0 < p[:, 2].max() < 12.0                          # nose tip
    tip = p[np.argmax(p[:, 2])]
    assert abs(tip[0]) < 0.2 and -4 < tip[1] < 1


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_openings_at_neutral(seed):
    z = sample_identity(seed, "test")
    a = np.array([head.EYE_A])
    up, lo = head.eye_margins(a)
    p = head.surface(head.template_to_uv(np.r_[a, a], np.r_[up, lo]), z)
    assert 0.75 < np.linalg.norm(p[0] - p[1]) < 1.05            # eye open ~0.8-1.0 cm
    hs = head.slit_half_height(np.zeros(1))
    q = head.surface(head.template_to_uv(np.zeros(2), np.r_[head.MOUTH_E + hs, head.MOUTH_E - hs]), z)
    assert np.linalg.norm(q[0] - q[1]) <= 0.3                   # lips nearly touch


@pytest.mark.parametrize("coef", [-3.0, 3.0])
def test_warp_is_orientation_preserving_for_every_mode(coef):
    a, e = _grid(90)
    h = 1e-5
    for j in range(N_IDENTITY):
        z = np.zeros(N_IDENTITY)
        z[j] = coef
        P = head_params(z)
        a0, e0 = head.warp(a, e, P)
        a1, e1 = head.warp(a + h, e, P)
        a2, e2 = head.warp(a, e + h, P)
        det = (a1 - a0) * (e2 - e0) - (a2 - a0) * (e1 - e0)
        assert det.min() / h ** 2 > 0.2, IDENTITY_MODES[j]


def test_surface_is_a_pure_function_of_uv():
    z = sample_identity(3)
    uv = head.template_to_uv(*_grid(30))
    full = head.surface(uv, z)
    part = head.surface(uv[::7], z)
    assert np.array_equal(full[::7], part)


def test_mirror_identity_mirrors_the_head():
    z = sample_identity(11)
    z[[IDENTITY_MODES.index(m) for m in ASYMMETRIC_MODES]] = 1.5
    uv = head.template_to_uv(*_grid(40))
    p = head.surface(uv, z)
    q = head.surface(uv * [-1, 1], mirror_identity(z))
    assert np.allclose(p * [-1, 1, 1], q, atol=1e-9)
    assert not np.allclose(p * [-1, 1, 1], head.surface(uv * [-1, 1], z), atol=1e-3)


def test_every_identity_mode_changes_the_head():
    uv = _disc(81)
    base = head.surface(uv, mean_identity())
    for j, name in enumerate(IDENTITY_MODES):
        z = np.zeros(N_IDENTITY)
        z[j] = 1.0
        moved = np.linalg.norm(head.surface(uv, z) - base, axis=1).max()
        assert 0.03 < moved < 3.0, (name, moved)
