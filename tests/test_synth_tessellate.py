"""Tessellations of the (u, v) domain: validity in 3D for several identities (data_synth.tessellate)."""
import numpy as np
import pytest

from data_synth import head
from data_synth.identity import N_IDENTITY, mean_identity, sample_identity
from data_synth.tessellate import tessellate

CASES = [(900, "regular", "full", True), (700, "jittered", "full", True),
         (1200, "adaptive", "full", True), (600, "regular", "face", True),
         (800, "adaptive", "face", False), (500, "jittered", "full", False)]


def _extreme_identity(seed):
    rng = np.random.default_rng(seed)
    return 3.0 * rng.choice([-1.0, 1.0], N_IDENTITY)


def _identities():
    return [mean_identity(), sample_identity(0, "test"), sample_identity(1, "train", 1.0),
            _extreme_identity(0), _extreme_identity(1)]


def _edges(faces):
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return e


def _boundary_loops(faces):
    """Number of boundary loops (edges used by exactly one face, chained)."""
    e = np.sort(_edges(faces), axis=1)
    keys, counts = np.unique(e, axis=0, return_counts=True)
    b = keys[counts == 1]
    parent = {}

    def find(x):
        while parent.setdefault(x, x) != x:
            x = parent[x]
        return x
    for i, j in b:
        parent[find(i)] = find(j)
    return len({find(v) for v in b.ravel()})


@pytest.mark.parametrize("n,kind,region,holes", CASES)
def test_tessellation_is_a_valid_mesh(n, kind, region, holes):
    tess = tessellate(n, kind=kind, region=region, holes=holes, seed=3)
    uv, faces = tess.uv, tess.faces
    assert faces.dtype == np.int64 and uv.shape[1] == 2
    assert 0.85 * n <= len(uv) <= 1.15 * n
    assert np.array_equal(np.unique(faces), np.arange(len(uv)))      # no unused vertex
    # manifold and consistently oriented: every directed edge appears at most once
    directed = _edges(faces)
    assert len(np.unique(directed, axis=0)) == len(directed)
    _, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert counts.max() <= 2
    expected_loops = (1 if region == "full" else 1) + (3 if holes else 0)
    assert _boundary_loops(faces) == expected_loops
    for z in _identities():
        p = head.surface(uv, z)
        n3 = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
        area = 0.5 * np.linalg.norm(n3, axis=1)
        assert area.min() > 1e-5                                       # cm^2, no degenerate face
        outward = np.sum(n3 * (p[faces].mean(1) - head.STAR_CENTRE), axis=1)
        assert (outward > 0).all()                                     # normals point out


def test_hole_boundaries_follow_the_openings():
    tess = tessellate(1500, kind="adaptive", holes=True)
    a, e = head.uv_to_template(tess.uv)
    inside_eye = np.abs(e - head.eye_centre_line(np.abs(a))) < head.eye_half_height(np.abs(a)) - 1e-5
    inside_mouth = np.abs(e - head.MOUTH_E) < head.slit_half_height(a) - 1e-5
    assert not (inside_eye | inside_mouth).any()
    closed = tessellate(1500, kind="adaptive", holes=False)
    a, e = head.uv_to_template(closed.uv)
    assert head.in_eye_opening(a, e).sum() > 0


def test_adaptive_is_denser_on_the_face_and_seeds_matter():
    reg = tessellate(3000, kind="regular")
    ada = tessellate(3000, kind="adaptive")
    def face(t):
        a, e = head.uv_to_template(t.uv)
        return np.sum((np.abs(a) < 0.8) & (np.abs(e) < 0.8))
    assert face(ada) > 1.4 * face(reg)
    j0, j1 = tessellate(800, kind="jittered", seed=0), tessellate(800, kind="jittered", seed=1)
    assert not np.array_equal(j0.uv[: min(len(j0.uv), len(j1.uv))], j1.uv[: min(len(j0.uv), len(j1.uv))])
    again = tessellate(800, kind="jittered", seed=0)
    assert np.array_equal(j0.uv, again.uv) and np.array_equal(j0.faces, again.faces)


def test_bad_arguments():
    with pytest.raises(ValueError, match="kind"):
        tessellate(1000, kind="hexagonal")
    with pytest.raises(ValueError, match="region"):
        tessellate(1000, region="torso")
