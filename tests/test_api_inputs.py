"""What the API takes as a mesh (retarget.mesh.as_mesh: Mesh, trimesh.Trimesh, (vertices, faces)) at
every entry point, and the source-topology cache that makes single-frame calls cheap."""
import numpy as np
import pytest
import trimesh

from retarget import api
from retarget.api import Retargeter, check_head_like
from retarget.errors import RetargetError
from retarget.io import load_mesh, save_mesh
from retarget.mesh import Mesh, as_mesh, is_mesh_like

from .test_api import head_mesh, tiny_checkpoint


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory):
    return tiny_checkpoint(tmp_path_factory.mktemp("ckpt") / "tiny.pt")


def fresh(ckpt, tmp_path, **kwargs) -> Retargeter:
    """A Retargeter with an empty source cache and its own (empty) operator cache folder."""
    return Retargeter.load(ckpt, device="cpu", cache_dir=tmp_path / "ops", **kwargs)


def shuffled(mesh: Mesh, seed: int = 0) -> Mesh:
    """The same surface with its vertices in another order (faces re-indexed)."""
    perm = np.random.default_rng(seed).permutation(mesh.n_vertices)
    inverse = np.argsort(perm)
    return Mesh(mesh.vertices[perm], inverse[mesh.faces], mesh.name)


# ------------------------------------------------------------------------------- as_mesh
def test_as_mesh_takes_trimesh_and_pairs_keeping_the_vertex_order(tmp_path):
    m = shuffled(head_mesh(2))
    assert as_mesh(m) is m
    dup = Mesh(np.vstack([m.vertices, m.vertices[:1]]), m.faces)  # an unused duplicate vertex
    tm = trimesh.Trimesh(dup.vertices, dup.faces, process=False)
    got = as_mesh(tm)
    np.testing.assert_array_equal(got.vertices, dup.vertices)      # nothing merged, nothing moved
    np.testing.assert_array_equal(got.faces, dup.faces)
    assert type(got.vertices) is np.ndarray and got.faces.dtype == np.int64
    save_mesh(tmp_path / "head.obj", m)
    loaded = trimesh.load_mesh(tmp_path / "head.obj", process=False, maintain_order=True)
    from_file = as_mesh(loaded)
    assert from_file.name == "head.obj"                             # named after its file
    np.testing.assert_allclose(from_file.vertices, load_mesh(tmp_path / "head.obj").vertices)
    for pair in ((m.vertices, m.faces), [m.vertices.tolist(), m.faces.tolist()],
                 (m.vertices.astype(np.float32), m.faces.astype(np.float64))):
        p = as_mesh(pair, name="pair")
        np.testing.assert_allclose(p.vertices, m.vertices, atol=1e-6)
        np.testing.assert_array_equal(p.faces, m.faces)
    assert is_mesh_like((m.vertices, m.faces)) and not is_mesh_like([m, m])   # two frames
    assert not is_mesh_like([(m.vertices, m.faces)] * 2)


@pytest.mark.parametrize("obj, message", [
    ("head.obj", r"target: expected a retarget Mesh, a trimesh.Trimesh or a \(vertices \(V,3\), "
                 r"faces \(F,3\)\) pair, got str$"),
    (np.zeros((100, 3)), r"got numpy.ndarray \(vertices alone: pass \(vertices, faces\)\)"),
    (trimesh.Scene(), r"got trimesh.Scene \(trimesh.load_mesh\(path, process=False"),
    (trimesh.PointCloud(np.random.default_rng(0).normal(size=(60, 3))),
     r"got trimesh.PointCloud \(a point cloud has no faces\)"),
    ((np.zeros((4, 3)), np.array([[0, 1, 2.5]])), r"target: faces of a \(vertices, faces\) pair "
                                                  r"must be integer vertex indices, got float64"),
    ((np.zeros((4, 3)), np.array([[0, 1, 9]])), r"target: face index out of range"),
    ((np.zeros((4, 2)), np.array([[0, 1, 2]])), r"target: vertices must be \(V,3\), got \(4, 2\)"),
])
def test_as_mesh_refuses_other_types_naming_the_role(obj, message):
    with pytest.raises(RetargetError, match=message):
        as_mesh(obj, role="target")


# ------------------------------------------------------------------------------- entry points
def test_every_entry_point_takes_trimesh_and_pairs(ckpt, tmp_path):
    r = fresh(ckpt, tmp_path)
    tgt, frames = head_mesh(2, name="tgt"), [head_mesh(2, smile=s) for s in (0.0, 0.6, 1.0)]
    as_tm = [trimesh.Trimesh(f.vertices, f.faces, process=False) for f in frames]
    as_pair = [(f.vertices, f.faces) for f in frames]
    tgt_tm, tgt_pair = trimesh.Trimesh(tgt.vertices, tgt.faces, process=False), (tgt.vertices, tgt.faces)
    prepared = r.prepare(tgt)
    for t in (tgt_tm, tgt_pair):
        p = r.prepare(t)
        np.testing.assert_allclose(p.codes.z_id.numpy(), prepared.codes.z_id.numpy(), atol=1e-6)
    want = {"one": r.transfer(frames[1], prepared), "seq": r.transfer(frames, prepared),
            "neutral": r.transfer(frames[1:], prepared, source_neutral=frames[0]),
            "invert": r.invert(frames), "codes": r.encode(frames, source_neutral=frames[0])}
    for src, t in ((as_tm, tgt_tm), (as_pair, tgt_pair)):
        np.testing.assert_allclose(r.transfer(src[1], t), want["one"], atol=1e-5)
        np.testing.assert_allclose(r.transfer(src, t), want["seq"], atol=1e-5)
        np.testing.assert_allclose(r.transfer(src[1:], t, source_neutral=src[0]), want["neutral"],
                                   atol=1e-5)
        np.testing.assert_allclose(r.invert(src), want["invert"], atol=1e-6)
        np.testing.assert_allclose(r.expression_codes(src, source_neutral=src[0]), want["codes"],
                                   atol=1e-6)
        w = np.eye(53, dtype=np.float32)[:2]
        np.testing.assert_allclose(r.animate(t, w), r.animate(prepared, w), atol=1e-5)
        np.testing.assert_allclose(r.bake(t).deltas, r.bake(prepared).deltas, atol=1e-5)
        z = want["codes"][:1]
        np.testing.assert_allclose(next(r.iter_decode(t, z)), r.decode(prepared, z)[0], atol=1e-5)
        check_head_like(t, "target")
    save_mesh(tmp_path / "tm.obj", tgt_tm)
    np.testing.assert_allclose(load_mesh(tmp_path / "tm.obj").vertices, tgt.vertices, atol=1e-8)


def test_entry_points_name_the_role_of_a_bad_input(ckpt, tmp_path):
    r = fresh(ckpt, tmp_path)
    good = head_mesh(2)
    with pytest.raises(RetargetError, match=r"^target: expected .* got dict"):
        r.prepare({"vertices": good.vertices})
    with pytest.raises(RetargetError, match=r"^source frame 1: expected .* got NoneType"):
        r.invert([good, None])
    with pytest.raises(RetargetError, match=r"^source neutral: expected .* got str"):
        r.transfer(good, good, source_neutral="neutral.obj")


# ------------------------------------------------------------------------------- source cache
def count_operator_calls(monkeypatch) -> list:
    calls = []
    real = api.load_or_compute_operators
    monkeypatch.setattr(api, "load_or_compute_operators",
                        lambda *a, **k: calls.append(1) or real(*a, **k))
    return calls


def test_single_frame_calls_reuse_the_operators_of_their_topology(ckpt, tmp_path, monkeypatch):
    calls = count_operator_calls(monkeypatch)
    frames = [head_mesh(2, smile=s) for s in np.linspace(0.0, 1.0, 4)]
    r = fresh(ckpt, tmp_path)
    first = r.encode(frames[0])
    streamed = [r.invert(f) for f in frames[1:]] + [r.encode(frames[3])]
    assert len(calls) == 1 and len(r._sources) == 1                 # computed once, then reused
    other = shuffled(frames[0])                                      # another topology: own entry
    r.encode(other)
    assert len(calls) == 2 and len(r._sources) == 2
    nocache = fresh(ckpt, tmp_path, source_cache_size=0)
    for f in frames:
        nocache.invert(f)
    assert len(calls) == 6 and not nocache._sources                  # 0: computed on every call
    np.testing.assert_array_equal(first, nocache.encode(frames[0]))  # the first call: as uncached
    assert all(np.isfinite(s).all() for s in streamed)
    r.clear_source_cache()
    assert not r._sources


def test_each_source_neutral_keeps_its_own_entry_and_results_do_not_change(ckpt, tmp_path, monkeypatch):
    calls = count_operator_calls(monkeypatch)
    r = fresh(ckpt, tmp_path, source_cache_size=2)
    nocache = fresh(ckpt, tmp_path, source_cache_size=0)
    a, b = head_mesh(2), head_mesh(2, smile=0.3)                     # two neutrals, one topology
    frame = head_mesh(2, smile=1.0)
    for neutral in (a, b, a, b):
        np.testing.assert_array_equal(r.encode(frame, source_neutral=neutral),
                                      nocache.encode(frame, source_neutral=neutral))
    assert len(r._sources) == 2 and len(calls) == 2 + 4                 # a and b once; no cache: 4
    r.encode(frame)                                                  # a third entry: LRU of 2
    assert len(r._sources) == 2
    assert len(calls) == 7
    r.encode(frame, source_neutral=b)
    assert len(calls) == 7                                           # b was still cached
    r.encode(frame, source_neutral=a)                                # a was evicted: recomputed
    assert len(calls) == 8
