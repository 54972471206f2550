"""Realistic rig synthesis on the MakeHuman head (data_synth.makehuman)."""
import numpy as np
import pytest

from data_synth import FACS_NAMES
from data_synth.makehuman import (CROPS, base_head_rig, build_head_rig, head_neutral,
                                  head_tessellation, sample_head_identity)
from data_synth.makehuman import assets
from data_synth.makehuman.expressions import (SURROGATE_NAMES, base_arkit_ict, base_surrogates_ict,
                                              identity_expressions, jaw_hinge)
from data_synth.makehuman import transfer
from data_synth.makehuman.transfer import deformation_transfer


def test_identities_deterministic_disjoint_and_human():
    a, b = sample_head_identity(5, "train"), sample_head_identity(5, "train")
    assert np.array_equal(a.weights, b.weights)
    assert not np.array_equal(a.weights, sample_head_identity(5, "test").weights)
    for seed in range(4):
        head = head_neutral(sample_head_identity(seed, "val"))
        skin = head[:assets.N_SKIN]
        width, height = np.ptp(skin[:, 0]), np.ptp(skin[:, 1])
        assert 13.0 < width < 24.0 and 22.0 < height < 36.0     # cm: human-sized heads
        assert np.isfinite(head).all()


def test_partial_macro_heads_lie_between_the_base_mesh_and_the_full_head():
    full = sample_head_identity(3, "train")
    assert np.array_equal(sample_head_identity(3, "train", partial_macro_share=0.0).weights, full.weights)
    part = sample_head_identity(3, "train", partial_macro_share=1.0)
    assert np.array_equal(part.weights, sample_head_identity(3, "train", partial_macro_share=1.0).weights)
    macro = assets.heads()["macro_target"]
    other = np.setdiff1d(np.arange(len(full.weights)), macro)
    assert np.array_equal(part.weights[other], full.weights[other])     # modifiers untouched
    s = part.weights[macro].sum() / full.weights[macro].sum()
    assert 0.0 <= s < 1.0 and np.allclose(part.weights[macro], s * full.weights[macro], rtol=1e-5)


def test_deformation_transfer_reproduces_on_its_own_neutral():
    z = assets.arkit()
    deltas = z["full_deltas"][:4]
    out = deformation_transfer(z["full_neutral"], deltas, z["full_neutral"], z["full_faces"])
    assert np.abs(out - deltas).max() < 1e-4


def test_deformation_transfer_reuses_its_factorisations_exactly(monkeypatch):
    z = assets.arkit()
    deltas = z["full_deltas"][:3]
    heads = [head_neutral(sample_head_identity(s, "test"))[:assets.N_HEAD] for s in (2, 3)]
    monkeypatch.setattr(transfer, "_factors", type(transfer._factors)())
    monkeypatch.setattr(transfer, "FACTOR_CACHE_BYTES", 0)      # nothing kept: every solve factorises
    fresh = [deformation_transfer(z["full_neutral"], deltas, h, z["full_faces"]) for h in heads]
    assert len(transfer._factors) == 0
    monkeypatch.setattr(transfer, "FACTOR_CACHE_BYTES", 256 * 2**20)
    cached = [deformation_transfer(z["full_neutral"], deltas, h, z["full_faces"]) for h in heads]
    assert len(transfer._factors) == 3              # one per shape, reused for the second head
    for a, b in zip(fresh, cached):
        assert np.array_equal(a, b)
    assert not np.allclose(cached[0], cached[1])    # the heads differ, the factors do not
    one = next(iter(transfer._factors.values()))[1]
    monkeypatch.setattr(transfer, "FACTOR_CACHE_BYTES", 2 * one)
    deformation_transfer(z["full_neutral"], z["full_deltas"][3:6], heads[0], z["full_faces"])
    assert sum(b for _, b in transfer._factors.values()) <= 2 * one   # oldest dropped first


def test_transferred_shapes_act_where_the_artist_put_them():
    ident = sample_head_identity(1, "test")
    neutral = head_neutral(ident)
    deltas, present = identity_expressions(neutral, ident.macros["race"], "arkit")
    base, _ = base_arkit_ict()
    assert present.all() and deltas.shape == (53, assets.N_HEAD, 3)
    for name in ("jawOpen", "eyeBlink_L", "mouthSmile_R"):
        k = FACS_NAMES.index(name)
        moved, ref = np.linalg.norm(deltas[k], axis=1), np.linalg.norm(base[k], axis=1)
        assert np.corrcoef(moved, ref)[0, 1] > 0.8
        assert 0.5 < moved.max() / ref.max() < 2.0
    # the transfer stays on the side the artist's shape moves (no drift across the face)
    k = FACS_NAMES.index("eyeBlink_L")
    x = assets.heads()["full_neutral"][:, 0]
    share = [np.linalg.norm(d[k], axis=1)[x < 0].sum() / np.linalg.norm(d[k], axis=1).sum()
             for d in (deltas, base)]
    assert share[0] < share[1] + 0.02


def test_units_source_lacks_the_shapes_without_a_unit():
    ident = sample_head_identity(2, "train")
    deltas, present = identity_expressions(head_neutral(ident), ident.macros["race"], "units")
    assert 20 <= present.sum() < 53
    assert not present[FACS_NAMES.index("cheekPuff_L")] and present[FACS_NAMES.index("jawOpen")]
    assert np.abs(deltas[~present]).max() == 0.0


def test_units_full_source_completes_the_units_with_surrogates():
    ident = sample_head_identity(2, "train")
    neutral, race = head_neutral(ident), ident.macros["race"]
    units, has_unit = identity_expressions(neutral, race, "units")
    full, present = identity_expressions(neutral, race, "units_full")
    assert present.all() and len(SURROGATE_NAMES) == 53 - has_unit.sum()
    assert np.array_equal(full[has_unit], units[has_unit])      # the units themselves unchanged
    assert all(np.abs(full[FACS_NAMES.index(n)]).max() > 0.1 for n in SURROGATE_NAMES)  # cm


def test_surrogates_move_the_side_and_direction_their_name_says():
    deltas, present = base_surrogates_ict(np.full(3, 1 / 3, np.float32))
    x = assets.heads()["full_neutral"][:, 0]
    assert present.sum() == len(SURROGATE_NAMES)

    def mean_x(name):                       # magnitude-weighted x of where the shape acts, cm
        m = np.linalg.norm(deltas[FACS_NAMES.index(name)], axis=1)
        return (m * x).sum() / m.sum()

    for name in ("cheekPuff", "cheekSquint", "mouthDimple", "eyeLookUp", "eyeLookIn"):
        assert mean_x(name + "_L") > 1.0 and mean_x(name + "_R") < -1.0
    dx = {n: deltas[FACS_NAMES.index(n)][:, 0].sum() for n in
          ("jawLeft", "jawRight", "mouthLeft", "mouthRight", "eyeLookOut_L", "eyeLookIn_L")}
    assert dx["jawLeft"] > 0 > dx["jawRight"] and dx["mouthLeft"] > 0 > dx["mouthRight"]
    assert dx["eyeLookOut_L"] > 0 > dx["eyeLookIn_L"]           # the left eye looks out to +x
    assert deltas[FACS_NAMES.index("jawForward")][:, 2].min() >= 0.0


def test_jaw_hinge_recovers_a_known_rotation():
    rng = np.random.default_rng(0)
    p = rng.uniform([-5, 60, 5], [5, 70, 16], size=(300, 3))
    a, yh, zh = 0.2, 70.0, 4.0
    d = np.stack([np.zeros(300), -a * (p[:, 2] - zh), a * (p[:, 1] - yh)], 1)
    got = jaw_hinge(p, d, np.ones(300))
    assert np.allclose(got, (a, yh, zh), atol=1e-6)


@pytest.mark.parametrize("kind", ["decimated", "jittered", "subdivided", "flipped"])
def test_tessellations_are_exact_maps_of_the_base(kind):
    tess = head_tessellation(1500, kind=kind, crop="head", seed=3)
    w = tess.weights
    assert np.allclose(np.asarray(w.sum(axis=1)).ravel(), 1.0) and w.min() >= 0
    if kind in ("decimated", "jittered"):
        assert abs(tess.n_vertices - 1500) < 150
    assert tess.faces.max() < tess.n_vertices and len(np.unique(tess.faces)) == tess.n_vertices


def test_cross_topology_ground_truth_is_exact_and_labels_agree():
    base = base_head_rig(sample_head_identity(0, "test"), style_seed=4)
    a = build_head_rig(base, head_tessellation(800, "decimated", "head_neck", seed=1))
    b = build_head_rig(base, head_tessellation(2500, "jittered", "bust", seed=2))
    w = np.zeros(53, np.float32)
    w[FACS_NAMES.index("jawOpen")] = 0.7
    # every vertex of every tessellation is the same linear map of the base rig
    for rig in (a, b):
        expect = rig.correspondence @ (base.neutral + np.tensordot(w, base.deltas, axes=1))
        assert np.abs(rig.evaluate(w) - expect).max() < 1e-4
    assert a.segments.max() < 20 and set(np.unique(a.segments)) <= set(np.unique(b.segments))


def test_crops_nest():
    sizes = [len(np.unique(head_tessellation(500, "base", c).weights.indices)) for c in CROPS]
    assert sizes == sorted(sizes)        # face < head < head and neck < bust
    bust = build_head_rig(sample_head_identity(3), head_tessellation(500, "base", "bust"))
    assert bust.neutral.shape[0] > assets.N_SKIN and np.abs(bust.deltas[:, -100:]).max() == 0
