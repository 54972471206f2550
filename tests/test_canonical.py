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


# ------------------------------------------------------------------------------------- face frame
from pathlib import Path  # noqa: E402

from data_synth.identity import sample_identity  # noqa: E402
from data_synth.rig import build_rig  # noqa: E402
from data_synth.tessellate import tessellate  # noqa: E402

SHARED_RIGS = Path(__file__).resolve().parents[2] / "shared" / "rigs"
PACKAGED = Path(__file__).resolve().parents[1] / "data_synth" / "makehuman" / "data"
RIGS = SHARED_RIGS if (SHARED_RIGS / "makehuman_heads.npz").is_file() else PACKAGED


def procedural(identity: int, n: int, kind: str, region: str):
    rig = build_rig(sample_identity(identity, split="test"), tessellate(n, kind, region=region, seed=0))
    return rig.neutral.astype(np.float64), rig.faces


def test_face_frame_ignores_units_and_offsets():
    v, f = procedural(0, 1500, "adaptive", "full")
    a = Canonicaliser.fit(v, kind="face", faces=f)
    b = Canonicaliser.fit(v * 10.0 + [30.0, -200.0, 5.0], kind="face", faces=f)   # mm, moved
    assert a.kind == b.kind == "face"
    assert np.allclose(a.to_canonical(v), b.to_canonical(v * 10.0 + [30.0, -200.0, 5.0]), atol=1e-6)
    assert a.render_fit is not True and Canonicaliser.fit(v).render_fit is True


@pytest.mark.parametrize("identity", [0, 2])
def test_face_frame_of_a_procedural_face_crop_matches_its_full_head(identity):
    full = procedural(identity, 2500, "adaptive", "full")
    face = procedural(identity, 1800, "regular", "face")
    a, b = (Canonicaliser.fit(v, kind="face", faces=f) for v, f in (full, face))
    box_a, box_b = Canonicaliser.fit(full[0]), Canonicaliser.fit(face[0])
    assert abs(b.scale / a.scale - 1) < 0.05
    assert abs(box_b.scale / box_a.scale - 1) > 0.1                 # the bounding box is fooled
    assert np.linalg.norm(b.centre - a.centre) < 1.0                 # cm


def makehuman_crops():
    """The MakeHuman head (cm) as face mask (cut here: a ball around the face, in front of the
    ears), head + upper neck, head with sockets and mouth cavity, and bust."""
    a = np.load(RIGS / "makehuman_arkit.npz", allow_pickle=False)
    h = np.load(RIGS / "makehuman_heads.npz", allow_pickle=False)
    v, f = a["neutral"].astype(np.float64), a["faces"].astype(np.int64)
    tip = v[np.argmax(v[:, 2])]
    keep = (np.linalg.norm(v[f] - (tip - [0, -2.0, 7.0]), axis=-1) < 11.0).all(axis=1)
    keep &= (v[f][..., 2] > tip[2] - 9.5).all(axis=1)
    used = np.unique(f[keep])
    remap = np.full(len(v), -1)
    remap[used] = np.arange(len(used))
    return {"face mask": (v[used], remap[f[keep]]), "head": (v, f),
            "full head": (a["full_neutral"].astype(np.float64), a["full_faces"].astype(np.int64)),
            "bust": (h["bust_neutral"].astype(np.float64), h["bust_faces"].astype(np.int64))}


@pytest.mark.skipif(not (RIGS / "makehuman_heads.npz").is_file(), reason="MakeHuman heads not present")
def test_face_frame_is_the_same_for_a_face_mask_a_head_and_a_bust():
    crops = makehuman_crops()
    assert len(crops["face mask"][0]) < 0.8 * len(crops["head"][0])
    fits = {k: Canonicaliser.fit(v, k, kind="face", faces=f) for k, (v, f) in crops.items()}
    boxes = {k: Canonicaliser.fit(v, k) for k, (v, f) in crops.items()}
    ref = fits["head"]
    for name, c in fits.items():
        assert abs(c.scale / ref.scale - 1) < 0.05, name
        assert np.linalg.norm(c.centre - ref.centre) < 0.5, name           # 5 mm
    assert boxes["bust"].scale < 0.5 * boxes["head"].scale                  # what the face frame fixes
    assert abs(boxes["face mask"].scale / boxes["head"].scale - 1) > 0.1


@pytest.mark.parametrize("split,seed", [("test", 19), ("train", 1020)])
def test_face_frame_of_a_bust_with_a_wide_or_short_head_stops_at_the_shoulders(split, seed):
    """Two MakeHuman busts whose head is wide (test 19, 22 cm at the ears) or short (train 1020): the
    head window's fixed point lies below the top of their shoulders. Before the shoulders were
    found, the window grew over the whole bust and the face front ran into the chest, so their face
    frame was 3-4 times too wide and the model drew garbage on them (its rig 1.3-2x the shapes'
    size off). The bust's frame must be its head's."""
    from data_synth.makehuman import (base_head_rig, build_head_rig, head_tessellation,
                                      sample_head_identity)
    from retarget.canonical import fit_face_frame, shoulder_depth

    base = base_head_rig(sample_head_identity(seed, split), "arkit")
    crops = {crop: build_head_rig(base, head_tessellation(seed=seed, n_vertices=2000, kind="decimated",
                                                          crop=crop), 6)
             for crop in ("head_neck", "bust")}
    frames = {k: fit_face_frame(r.neutral.astype(np.float64), r.faces) for k, r in crops.items()}
    shoulders = {k: shoulder_depth(r.neutral.astype(np.float64), r.faces) for k, r in crops.items()}
    assert shoulders["head_neck"] == np.inf
    assert 15.0 < shoulders["bust"] < 30.0                               # cm below the crown
    (p_head, w_head), (p_bust, w_bust) = frames["head_neck"], frames["bust"]
    assert abs(w_bust / w_head - 1) < 0.05
    assert np.linalg.norm(p_bust - p_head) < 0.5                         # cm


def test_face_mask_with_a_sliver_on_top_has_no_shoulders():
    """A face mask with something narrow above its top: a sliver triangle (a stray scrap of a scan,
    or the one vertex a tilted straight cut leaves on top: training's small rotations of a face
    crop made one). Its first slice had nearly no width, and the next slice, the whole top of the
    mask, was read as a bust's shoulders a slice below the top; the head window then held the
    forehead alone, the face front was empty, and "no surface faces forward" stopped a training
    run. The frame must be the mask's own."""
    from data_synth.makehuman import (base_head_rig, build_head_rig, head_tessellation,
                                      sample_head_identity)
    from retarget.canonical import SLICE_BANDS, fit_face_frame, shoulder_depth

    rig = build_head_rig(base_head_rig(sample_head_identity(0, "test"), "arkit"),
                         head_tessellation(seed=0, n_vertices=1800, kind="decimated", crop="face"), 6)
    v, f = rig.neutral.astype(np.float64), rig.faces
    band = np.ptp(v[:, 1]) / SLICE_BANDS
    top = v[np.argmax(v[:, 1])]
    sliver = top + np.array([[-0.05, 1.2 * band, 0.0], [0.05, 1.2 * band, 0.0], [0.0, 0.9 * band, 0.0]])
    vs, fs = np.vstack([v, sliver]), np.vstack([f, [[len(v), len(v) + 1, len(v) + 2]]])
    assert shoulder_depth(v, f) == np.inf
    assert shoulder_depth(vs, fs) == np.inf
    (p0, w0), (p1, w1) = fit_face_frame(v, f), fit_face_frame(vs, fs)
    assert abs(w1 / w0 - 1) < 0.02 and np.linalg.norm(p1 - p0) < 0.2   # cm


def test_frame_kind_errors():
    v, f = procedural(0, 600, "regular", "full")
    with pytest.raises(ValueError, match="unknown canonical frame"):
        Canonicaliser.fit(v, kind="sphere")
    with pytest.raises(ValueError, match="needs the faces"):
        Canonicaliser.fit(v, kind="face")


def test_model_config_records_the_frame_and_old_checkpoints_are_bbox():
    from nets.model import NFSConfig

    assert NFSConfig.from_dict({}).canonical == "bbox"          # checkpoints without the key
    assert NFSConfig.preset("tiny", canonical="face").to_dict()["canonical"] == "face"
    with pytest.raises(ValueError, match="canonical"):
        NFSConfig(canonical="sphere")


def test_face_frame_model_renders_the_face_box_whatever_the_crop():
    """prepare_mesh of a face-frame model: a bust's image shows the face where the head's does."""
    from retarget.prepare import prepare_mesh

    if not (RIGS / "makehuman_heads.npz").is_file():
        pytest.skip("MakeHuman heads not present")
    crops = makehuman_crops()
    img = {(k, kind): prepare_mesh(*crops[k], k_eig=8, image_size=32, image_channels=("shaded",),
                                   canonical=kind).image
           for k in ("head", "bust") for kind in ("bbox", "face")}
    face_diff = np.abs(img["head", "face"] - img["bust", "face"])[:, :20].mean()   # the face rows
    bbox_diff = np.abs(img["head", "bbox"] - img["bust", "bbox"])[:, :20].mean()
    assert face_diff < 0.3 * bbox_diff


def test_a_face_frame_model_prepares_and_transfers_in_any_units():
    """A model whose config says canonical: face canonicalises its targets and sources that way."""
    import torch

    from nets.model import NFSConfig, NFSModel
    from retarget.api import Retargeter
    from retarget.mesh import Mesh

    torch.manual_seed(0)
    r = Retargeter(NFSModel(NFSConfig.preset("tiny", canonical="face")), device="cpu")
    v, f = procedural(1, 700, "regular", "full")
    target = r.prepare(Mesh(v, f))
    assert target.proxy.canon.kind == "face"
    frame = Mesh(v + 0.1, f)
    cm = r.transfer(frame, target, source_neutral=Mesh(v, f))
    mm = r.transfer(Mesh(frame.vertices * 10, f), Mesh(v * 10 + 3.0, f), source_neutral=Mesh(v * 10, f))
    assert np.allclose(mm, cm * 10 + 3.0, atol=1e-3)


# ------------------------------------------------------------------------------------- upright
from retarget.canonical import (rotation_angle, side_turn, turn_matrix, upright_fit,  # noqa: E402
                                upright_rotation)


def arkit_neutral():
    a = np.load(RIGS / "makehuman_arkit.npz", allow_pickle=False)
    return a["neutral"].astype(np.float64), a["faces"].astype(np.int64)


def test_a_rotation_is_undone_exactly_and_round_trips():
    v, f = arkit_neutral()
    turn = turn_matrix(20.0, -10.0)
    a = Canonicaliser.fit(v, kind="face", faces=f)
    b = Canonicaliser.fit(v @ turn.T, kind="face", faces=f, rotation=turn.T)
    assert np.allclose(b.to_canonical(v @ turn.T), a.to_canonical(v), atol=1e-9)
    assert np.allclose(b.from_canonical(b.to_canonical(v)), v)
    d = np.random.default_rng(0).standard_normal((4, len(v), 3))
    assert np.allclose(b.displacement_from_canonical(a.displacement_to_canonical(d)),
                       d @ turn.T)   # the upright head's motion comes back turned with the mesh
    assert np.allclose(b.displacement_to_canonical(d @ turn.T), a.displacement_to_canonical(d))


@pytest.mark.parametrize("pitch, yaw", [(20.0, 0.0), (-15.0, 0.0), (0.0, 15.0), (10.0, -10.0)])
def test_upright_fit_finds_how_a_head_is_turned(pitch, yaw):
    v, f = arkit_neutral()
    turn = turn_matrix(pitch, yaw)
    rotation, rms = upright_fit(v @ turn.T, f)
    assert rotation_angle(rotation @ turn) < 1.0          # undoes the turn within 1°
    assert rms < 0.1


def test_upright_fit_skips_a_start_without_a_face_frame():
    """A MakeHuman training bust (seed 452) pitched up by the −20° start has its chest in front:
    the face frame refuses that start, and the fit goes on from the others."""
    from data_synth.makehuman import head_tessellation, sample_head_identity
    from data_synth.makehuman.identity import head_neutral
    from retarget.canonical import UPRIGHT_STARTS
    from retarget.errors import RetargetError
    tess = head_tessellation(seed=452, n_vertices=2000, kind="jittered", crop="bust")
    v = tess.apply(head_neutral(sample_head_identity(452, "train"), "bust")).astype(np.float64)
    assert (-20.0, 0.0) in UPRIGHT_STARTS
    with pytest.raises(RetargetError, match="faces forward"):
        Canonicaliser.fit(v, kind="face", faces=tess.faces, rotation=turn_matrix(-20.0, 0.0))
    rotation, rms = upright_fit(v, tess.faces)
    assert np.isfinite(rms) and rotation_angle(rotation) < 3.0
    assert upright_rotation(v, tess.faces) is None          # an upright bust stays as it is


def test_upright_rotation_turns_only_tilted_human_heads():
    v, f = arkit_neutral()
    assert upright_rotation(v, f) is None                                  # upright
    assert upright_rotation(v @ turn_matrix(3.0, 0.0).T, f) is None        # pitch below 5°
    pitched = upright_rotation(v @ turn_matrix(20.0, 0.0).T, f)
    assert pitched is not None and abs(rotation_angle(pitched) - 20.0) < 1.0
    sideways = upright_rotation(v @ turn_matrix(3.0, 12.0).T, f)          # the yaw alone is undone
    assert sideways is not None and rotation_angle(sideways @ side_turn(sideways).T) < 1e-6
    assert abs(rotation_angle(sideways) - 12.0) < 1.0
    pv, pf = procedural(0, 2500, "adaptive", "full")                       # not a human face:
    assert upright_rotation(pv @ turn_matrix(20.0, 0.0).T, pf) is None     # left as it is


def test_the_shipped_face_model_is_what_the_builder_makes():
    from retarget.canonical import build_upright_face_model, upright_face_model

    for shipped, built in zip(upright_face_model(), build_upright_face_model()):
        np.testing.assert_allclose(shipped, built, rtol=1e-5, atol=1e-5)


def test_a_rolled_head_is_turned_back():
    v, f = arkit_neutral()
    a = np.radians(10.0)
    roll = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    rotation = upright_rotation(v @ roll.T, f)                   # roll is a sideways turn
    assert rotation is not None and rotation_angle(rotation @ roll) < 1.0


def test_a_given_nose_tip_is_taken_where_the_lips_lie_further_forward():
    """The face frame takes the front-most point for the nose tip; on a head whose lips stick out
    past its nose that is the lips, unless the nose tip is given (fit_face_frame(nose=))."""
    from retarget.canonical import fit_face_frame

    from .test_api import head_mesh

    head = head_mesh(4)                                        # its nose bump at (0, 0), 3 cm
    v = head.vertices.copy()
    front = v[:, 2] > 0
    v[:, 2] += 4.0 * np.exp(-(v[:, 0] ** 2 / 6.0 + (v[:, 1] + 5.0) ** 2 / 1.0)) * front  # lips
    point, width = fit_face_frame(v, head.faces)
    assert abs(point[1] + 5.0) < 0.5                           # taken at the lips
    point, same = fit_face_frame(v, head.faces, nose=np.array([0.0, 0.0]))
    assert abs(point[1]) < 0.5 and point[2] > 11.0 and same == width


def test_the_nose_finder_takes_the_nose_where_the_lips_lie_further_forward(monkeypatch):
    """Validation head 124 (head and neck, 2,000 vertices): its upper lip lies further forward than
    its nose, so the front-most point is the lip; the shipped nose finder takes the nose."""
    from data_synth.makehuman import assets, base_head_rig, build_head_rig, head_tessellation
    from data_synth.makehuman import head_neutral, sample_head_identity
    from retarget import canonical
    from retarget.canonical import fit_face_frame, nose_finder

    w1, b1, w2, b2 = nose_finder()
    assert w1.shape == (canonical.NOSE_PATCH ** 2 + 3, len(b1)) and w2.shape == b1.shape and b2.shape == ()
    ident = sample_head_identity(124, "val")
    rig = build_head_rig(base_head_rig(ident, "arkit"), head_tessellation(
        seed=124, n_vertices=2000, kind="decimated", crop="head_neck"), 6)
    base = assets.heads()["full_neutral"]
    midline = np.flatnonzero((np.abs(base[:, 0]) < 0.3) & (np.abs(base[:, 1] - 69.09) < 1.5))
    tip = head_neutral(ident, "bust")[midline[np.argmax(base[midline, 2])]]
    v = rig.neutral.astype(np.float64)
    point, width = fit_face_frame(v, rig.faces)
    assert np.hypot(*(point[:2] - tip[:2])) < 0.05 * width              # 0.02 face widths
    monkeypatch.setattr(canonical, "NOSE_MARGIN", 2.0)                   # the finder off
    point, width = fit_face_frame(v, rig.faces)
    assert np.hypot(*(point[:2] - tip[:2])) > 0.1 * width               # 0.13: the upper lip
