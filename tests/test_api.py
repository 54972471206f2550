"""The Python API (retarget.api) on tiny head-like meshes with a tiny checkpoint made here: loading and
refusing checkpoints, transfer / animate / invert / bake, units and offset invariance, awkward
meshes, large meshes through the proxy, chunked decoding; decimation and temporal smoothing."""
from pathlib import Path

import numpy as np
import pytest
import torch

import retarget
from nets.model import NFSConfig, NFSModel
from retarget import api
from retarget.api import Retargeter, check_head_like
from retarget.checkpoint import CHECKPOINT_FORMAT, save_checkpoint
from retarget.decimate import cluster_decimate, cluster_means
from retarget.eyes import LOOK_INDEX, gaze_from_weights
from retarget.errors import RetargetError
from retarget.mesh import Mesh
from retarget.smoothing import one_euro, savgol, smooth_codes


# ------------------------------------------------------------------------------- shared helpers
def head_mesh(subdivisions: int = 2, scale: float = 1.0, offset=(0.0, 0.0, 0.0), name: str = "head",
              smile: float = 0.0) -> Mesh:
    """An icosphere stretched to a 16 x 22 x 18 cm head with a nose bump (+z) and, with ``smile``,
    a mouth-corner lift; ``scale`` converts centimetres to other units (0.01: metres, 10: mm)."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = s.vertices * np.array([8.0, 11.0, 9.0])
    front = v[:, 2] > 0
    v[:, 2] += 3.0 * np.exp(-(v[:, 0] ** 2 + v[:, 1] ** 2) / 8.0) * front
    v[:, 1] += smile * np.exp(-((np.abs(v[:, 0]) - 4.0) ** 2 + (v[:, 1] + 5.0) ** 2) / 4.0) * front
    return Mesh(v * scale + np.asarray(offset), s.faces, name)


def tiny_checkpoint(path: Path, seed: int = 0, **overrides) -> Path:
    """Save an untrained NFS model of the "tiny" preset (random weights, seeded) as a checkpoint."""
    torch.manual_seed(seed)
    cfg = NFSConfig.preset("tiny", **overrides)
    save_checkpoint(Path(path), {"format": CHECKPOINT_FORMAT, "model_config": cfg.to_dict(),
                                 "train_config": {}, "model": NFSModel(cfg).state_dict(), "step": 0})
    return Path(path)


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory):
    return tiny_checkpoint(tmp_path_factory.mktemp("ckpt") / "tiny.pt")


@pytest.fixture(scope="module")
def r(ckpt, tmp_path_factory):
    return Retargeter.load(ckpt, device="cpu", cache_dir=tmp_path_factory.mktemp("ops"))


# ------------------------------------------------------------------------------- checkpoints
def test_missing_bundled_checkpoint_message(monkeypatch, tmp_path):
    monkeypatch.setattr(api, "default_checkpoint_path", lambda: tmp_path / "default.pt")
    with pytest.raises(RetargetError, match=r"no bundled checkpoint at .*default\.pt; train one"):
        Retargeter.load()


def test_checkpoint_of_another_config_and_tampered_file_are_refused(tmp_path):
    other = tiny_checkpoint(tmp_path / "other.pt", enc_width=32)
    state = torch.load(other, weights_only=True)
    state["model_config"] = NFSConfig.preset("tiny").to_dict()  # says tiny, holds wider weights
    torch.save(state, tmp_path / "mismatch.pt")
    with pytest.raises(RetargetError, match=r"mismatch\.pt: checkpoint does not match"):
        Retargeter.load(tmp_path / "mismatch.pt")
    state["model_config"]["no_such_field"] = 1
    torch.save(state, tmp_path / "unknown_key.pt")
    with pytest.raises(RetargetError, match=r"unknown_key\.pt: bad model_config in the checkpoint"):
        Retargeter.load(tmp_path / "unknown_key.pt")
    state["model_config"] = Path("pickled object")  # not a plain type: weights_only refuses it
    torch.save(state, tmp_path / "tampered.pt")
    with pytest.raises(RetargetError, match=r"tampered\.pt: holds pickled code .* and was refused"):
        Retargeter.load(tmp_path / "tampered.pt")


# ------------------------------------------------------------------------------- the four jobs
def test_transfer_animate_invert_bake_shapes(r):
    target = r.prepare(head_mesh(2))
    src = [head_mesh(2, smile=s) for s in (0.0, 0.5, 1.0)]
    one = r.transfer(src[1], target)
    seq = r.transfer(src, target, source_neutral=src[0])
    assert one.shape == (162, 3) and seq.shape == (3, 162, 3) and np.isfinite(seq).all()
    assert not np.allclose(seq[0], seq[2])  # a different expression moves the target differently
    w = r.invert(src[2])
    ws = r.invert(src, smooth="savgol")
    assert w.shape == (53,) and ws.shape == (3, 53) and (ws >= 0).all() and (ws <= 1).all()
    assert len(retarget.FACS_NAMES) == 53 == len(set(retarget.FACS_NAMES))
    z = r.expression_codes(src, source_neutral=src[0])
    streamed = list(r.iter_decode(target, z))
    assert len(streamed) == 3 and np.allclose(np.stack(streamed), seq)   # frame by frame = batch
    named = r.animate(target, {"jawOpen": 0.7, "eyeBlink_L": 0.2})
    arr = np.zeros(53, np.float32)
    arr[retarget.FACS_NAMES.index("jawOpen")], arr[retarget.FACS_NAMES.index("eyeBlink_L")] = 0.7, 0.2
    assert np.allclose(named, r.animate(target, arr))
    rig = r.bake(target)
    assert rig.deltas.shape == (53, 162, 3)
    k = retarget.FACS_NAMES.index("jawOpen")
    assert np.allclose(rig.evaluate(np.eye(53)[k]), r.animate(target, np.eye(53)[k]), atol=1e-5)
    assert np.allclose(rig.evaluate(np.zeros((2, 53))), rig.neutral)


def test_weight_names_and_shapes_are_checked(r):
    target = r.prepare(head_mesh(2))
    with pytest.raises(RetargetError, match="unknown FACS weight names: smileBig, zzz"):
        r.animate(target, [{"jawOpen": 1.0}, {"zzz": 1.0, "smileBig": 0.5}])
    with pytest.raises(RetargetError, match=r"got shape \(52,\)"):
        r.animate(target, np.zeros(52))
    with pytest.raises(RetargetError, match="unknown smoothing 'kalman'"):
        smooth_codes(np.zeros((4, 3)), "kalman")


def test_units_and_offset_invariance(r):
    """The same heads in centimetres, in metres and in millimetres (shifted): the same expression
    code, and target results equal up to the scale factor and the offset."""
    results = {}
    for unit, scale in (("cm", 1.0), ("m", 0.01), ("mm", 10.0)):
        offset = np.array([3.0, -120.0, 40.0]) * scale
        src = head_mesh(2, scale, offset, smile=1.0)
        z = r.encode(src)
        out = r.transfer(src, head_mesh(2, scale, offset))
        results[unit] = (z, (out - offset) / scale)
    for unit in ("m", "mm"):
        assert np.allclose(results[unit][0], results["cm"][0], atol=1e-5)
        assert np.allclose(results[unit][1], results["cm"][1], atol=1e-4)
    # ... and the result does move the target (the comparison is not between two neutrals)
    assert np.abs(results["cm"][1] - head_mesh(2).vertices).max() > 1e-3


def _awkward_meshes() -> dict:
    """Meshes a user may bring: with a hole, several components, a non-manifold edge."""
    base = head_mesh(2)
    holed = Mesh(base.vertices, base.faces[base.vertices[base.faces[:, 0], 2] < 7.5], "holed")
    eye = head_mesh(1, 0.1, (3.0, 2.0, 9.0))
    two = Mesh(np.vstack([base.vertices, eye.vertices]),
               np.vstack([base.faces, eye.faces + base.n_vertices]), "two components")
    a, b = base.faces[0, 0], base.faces[0, 1]  # an edge shared by two faces gets a third (a fin)
    fin_v = np.vstack([base.vertices, base.vertices[[a, b]].mean(0) + [0.0, 0.0, 2.0]])
    fin = Mesh(fin_v, np.vstack([base.faces, [[a, b, base.n_vertices]]]), "non-manifold")
    return {"holed": holed, "two": two, "fin": fin}


@pytest.mark.parametrize("kind", ["holed", "two", "fin"])
def test_awkward_meshes_work_as_target_and_source(r, kind):
    mesh = _awkward_meshes()[kind]
    out = r.transfer(mesh, mesh)
    assert out.shape == mesh.vertices.shape and np.isfinite(out).all()


def test_objects_that_cannot_be_faces_are_refused(r):
    flat = head_mesh(2)
    flat.vertices[:, 2] *= 0.05  # a disc
    flat.name = "plate.obj"
    with pytest.raises(RetargetError, match=r"plate\.obj: not a face-sized object"):
        r.prepare(flat)
    with pytest.raises(RetargetError, match=r"plate\.obj: not a face-sized object"):
        r.encode(flat)
    few = head_mesh(0, name="ico.obj")  # 12 vertices
    with pytest.raises(RetargetError, match=r"ico\.obj: only 12 vertices"):
        check_head_like(few, "target")
    check_head_like(head_mesh(2, 0.001))  # tiny units are fine: only proportions are judged


# ------------------------------------------------------------------------------- large meshes
def test_large_target_and_source_go_through_the_proxy(ckpt):
    small = Retargeter.load(ckpt, device="cpu", proxy_vertices=300, chunk=100)
    whole = Retargeter.load(ckpt, device="cpu", proxy_vertices=300, chunk=10**6)
    mesh = head_mesh(3)  # 642 vertices
    target = small.prepare(mesh)
    assert target.proxy.n_vertices <= 300 and target.feat.shape == (642, 6)
    assert target.codes.omega_skin.shape[0] == 642
    src = head_mesh(3, smile=1.0)
    z = small.encode(src, source_neutral=mesh)
    assert z.shape == (128,) and np.isfinite(z).all()
    out = small.decode(target, z)
    assert out.shape == (642, 3) and np.isfinite(out).all()
    assert np.allclose(out, whole.decode(whole.prepare(mesh), z), atol=1e-5)  # chunked == unchunked


# ------------------------------------------------------------------------------- decimation
def test_cluster_decimate_maps_every_vertex_and_keeps_valid_faces():
    mesh = head_mesh(3)
    (pv, pf), cluster = cluster_decimate(mesh.vertices, mesh.faces, 200)
    assert 50 <= len(pv) <= 200 < mesh.n_vertices
    assert cluster.shape == (642,) and set(np.unique(cluster)) == set(range(len(pv)))
    assert pf.min() >= 0 and pf.max() < len(pv)
    assert (pf[:, 0] != pf[:, 1]).all() and (pf[:, 1] != pf[:, 2]).all() and (pf[:, 0] != pf[:, 2]).all()
    assert len(np.unique(np.sort(pf, axis=1), axis=0)) == len(pf)
    assert np.allclose(pv, cluster_means(mesh.vertices, cluster))
    # proxy vertices lie near the vertices they stand for
    cell = np.linalg.norm(pv[cluster] - mesh.vertices, axis=1).max()
    assert cell < 0.2 * np.ptp(mesh.vertices, axis=0).max()


# ------------------------------------------------------------------------------- smoothing
def test_one_euro_smooths_noise_and_settles_on_a_step():
    rng = np.random.default_rng(0)
    noisy = 0.5 + 0.05 * rng.standard_normal((300, 4))
    out = one_euro(noisy, fps=30.0)
    assert out[30:].std(axis=0).max() < 0.5 * noisy[30:].std(axis=0).min()
    step = np.where(np.arange(90) < 30, 0.0, 1.0)[:, None]
    filtered = one_euro(step, fps=30.0)
    assert 0.0 < filtered[30, 0] < 1.0  # it lags...
    assert abs(filtered[-1, 0] - 1.0) < 1e-3  # ...and keeps the final value


def test_savgol_keeps_a_quadratic_exactly():
    t = np.arange(30, dtype=np.float64)
    quad = np.stack([0.01 * t ** 2 - 0.3 * t + 2.0, -0.5 * t ** 2], axis=1)
    assert np.allclose(savgol(quad), quad, atol=1e-9)
    assert np.allclose(smooth_codes(quad[:3], "savgol"), quad[:3])  # shorter than the window


# ------------------------------------------------------------------------------- basis decoder
@pytest.mark.parametrize("proxy_vertices", [20000, 300])
def test_basis_decoder_bake_is_the_decoder(tmp_path, proxy_vertices):
    """With the basis decoder the baked rig is the decoder's own (ω_Skin ⊙ M): equal to animate
    within float rounding, directly and through the proxy of a large target (rig at full size)."""
    ckpt = tiny_checkpoint(tmp_path / "basis.pt", decoder="basis", decoder_fourier=2)
    r = Retargeter.load(ckpt, device="cpu", proxy_vertices=proxy_vertices, chunk=100,
                        cache_dir=tmp_path)
    mesh = head_mesh(3, scale=0.01, offset=(1.0, 0.0, 0.0))   # 642 vertices, in metres
    target = r.prepare(mesh)
    assert target.codes.basis.shape == (642, 3, 128)
    weights = np.random.default_rng(0).uniform(0, 1, (4, 53)).astype(np.float32)
    baked = r.bake(target)
    full = r.animate(target, weights)
    assert np.allclose(baked.neutral, mesh.vertices.astype(np.float32))
    assert baked.deltas.shape == (53, 642, 3) and baked.deltas.flags["C_CONTIGUOUS"]  # fast playback
    mse_mm2 = ((baked.evaluate(weights) - full) * 1000) ** 2   # metres -> mm
    assert mse_mm2.sum(-1).mean() <= 1e-6 and np.abs(full - mesh.vertices).max() > 0
    # the rig does not depend on the chunk size it was prepared in
    whole = Retargeter.load(ckpt, device="cpu", proxy_vertices=proxy_vertices, chunk=10**6,
                            cache_dir=tmp_path)
    assert np.allclose(whole.animate(whole.prepare(mesh), weights), full, atol=1e-7)


# ------------------------------------------------------------------------------- tilted heads
def test_a_tilted_head_is_turned_upright_and_back(tmp_path):
    from retarget.canonical import turn_matrix

    a = np.load(Path(__file__).resolve().parents[1] / "data_synth" / "makehuman" / "data"
                / "makehuman_arkit.npz", allow_pickle=False)
    head = Mesh(a["neutral"].astype(np.float64), a["faces"].astype(np.int64), "head")
    ckpt = tiny_checkpoint(tmp_path / "face.pt", canonical="face")
    up = Retargeter.load(ckpt, device="cpu", cache_dir=tmp_path / "ops")
    flat = Retargeter.load(ckpt, device="cpu", cache_dir=tmp_path / "ops", upright=False)
    turn = turn_matrix(20.0, 0.0)
    tilted = Mesh(head.vertices @ turn.T, head.faces, "tilted")
    assert up.prepare(head).proxy.canon.rotation is None                  # upright: as it was
    assert up.prepare(tilted).proxy.canon.rotation is not None
    assert flat.prepare(tilted).proxy.canon.rotation is None
    z = np.random.default_rng(0).standard_normal(up.cfg.code_dim).astype(np.float32)
    want = (up.decode(head, z) - head.vertices) @ turn.T   # the upright head's motion, turned
    err = {name: np.linalg.norm(r.decode(tilted, z) - tilted.vertices - want) / np.linalg.norm(want)
           for name, r in (("upright", up), ("as it faces", flat))}
    assert err["upright"] < 0.05 and err["as it faces"] > 0.2, err   # 0.028, 0.27; 0.086 if the
    # motion came back unturned


# ------------------------------------------------------------------------------- separate parts
def with_parts(head: Mesh, seed: int = 0) -> Mesh:
    """``head`` and, appended after its vertices, two eyeballs and a teeth block inside it: separate
    parts (42 + 42 + 8 vertices), shifted by a random few millimetres with ``seed`` > 0 (a frame
    in which the parts moved on their own)."""
    import trimesh

    parts = [trimesh.creation.icosphere(subdivisions=1, radius=1.2).apply_translation((x, 3.0, 5.0))
             for x in (-3.0, 3.0)] + [trimesh.creation.box((5.0, 1.0, 1.5)).apply_translation((0, -5, 4))]
    v, f = [head.vertices], [head.faces]
    n = head.n_vertices
    for p in parts:
        v.append(np.asarray(p.vertices) + np.random.default_rng(seed).normal(0, 0.3, 3) * (seed > 0))
        f.append(np.asarray(p.faces) + n)
        n += len(p.vertices)
    return Mesh(np.concatenate(v), np.concatenate(f), head.name)


def test_mesh_parts_weld_seams_and_the_face_is_the_largest_part():
    from retarget.mesh import face_part, mesh_parts, submesh

    head = head_mesh(2)
    full = with_parts(head)
    labels = mesh_parts(full.vertices, full.faces)
    assert labels.max() == 3 and len(np.unique(labels[:head.n_vertices])) == 1
    assert np.array_equal(face_part(full), np.arange(head.n_vertices))
    sub = submesh(full, face_part(full))
    assert np.array_equal(sub.vertices, head.vertices) and np.array_equal(sub.faces, head.faces)
    assert face_part(head) is None
    # split along a seam: the faces with x < 0 get their own copies of the vertices they share
    # with the others (as a glTF file holds a mesh cut along its UV seams); welded, one part
    left = head.vertices[head.faces].mean(1)[:, 0] < 0
    copies = np.intersect1d(head.faces[left], head.faces[~left])
    new = np.arange(head.n_vertices)
    new[copies] = head.n_vertices + np.arange(len(copies))
    faces = np.where(left[:, None], new[head.faces], head.faces)
    split = Mesh(np.concatenate([head.vertices, head.vertices[copies]]), faces)
    assert mesh_parts(split.vertices, split.faces, weld=False).max() == 1
    assert mesh_parts(split.vertices, split.faces).max() == 0 and face_part(split) is None
    # a vertex no face uses is no part, and not the face's
    loose = Mesh(np.concatenate([head.vertices, [[0.0, 0.0, 0.0]]]), head.faces)
    assert mesh_parts(loose.vertices, loose.faces)[-1] == -1
    assert np.array_equal(face_part(loose), np.arange(head.n_vertices))


def test_separate_parts_are_left_out_and_keep_their_place(r, ckpt, tmp_path):
    """Eyeballs and teeth beside the skin: the network sees the face alone, so every result on the
    face is what the head alone gives, and the parts keep their place (however they move in the
    source's frames, as long as its eyeballs do not turn); invert reads no look from eyeballs that
    do not turn; face_only=False feeds the whole mesh as before."""
    head, smile = head_mesh(2), head_mesh(2, smile=2.0)
    full = with_parts(head)
    n = head.n_vertices
    frames = [with_parts(smile, seed=1), with_parts(head, seed=2)]
    alone = r.transfer([smile, head], head, source_neutral=head, refine=True)
    both = r.transfer(frames, full, source_neutral=full, refine=True)
    assert both.shape == (2, full.n_vertices, 3)
    assert np.allclose(both[:, :n], alone, atol=1e-5)        # float32 sums: 1e-6 apart
    assert np.array_equal(both[:, n:], np.broadcast_to(full.vertices[n:], both[:, n:].shape))
    looks = np.unique(LOOK_INDEX)                 # the eyeballs, which do not turn, say: no look
    inverted = r.invert(frames, source_neutral=full, refine=True)
    assert np.abs(gaze_from_weights(inverted)).max() < 1e-6
    assert np.allclose(np.delete(inverted, looks, axis=1),
                       np.delete(r.invert([smile, head], source_neutral=head, refine=True), looks, axis=1),
                       atol=1e-6)
    baked = r.bake(full)
    assert baked.deltas.shape == (53, full.n_vertices, 3)
    assert not np.delete(baked.deltas, looks, axis=0)[:, n:].any()      # parts at rest, but for
    assert not baked.deltas[looks, -8:].any() and baked.deltas[looks, n:-8].any()   # turning eyes
    assert np.allclose(baked.deltas[:, :n], r.bake(head).deltas, atol=1e-6)
    whole = Retargeter.load(ckpt, device="cpu", cache_dir=tmp_path, face_only=False)
    assert np.abs(whole.transfer(frames, full)[:, n:] - full.vertices[n:]).max() > 1e-3
