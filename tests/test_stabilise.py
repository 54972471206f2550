"""Head stabilisation (retarget.stabilise, Retargeter.stabilise_frames): the rigid motion of a
frame against its neutral found on the rest vertices and removed; frames that do not correspond
to the neutral refused."""
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from data_synth.identity import sample_identity
from data_synth.rig import build_rig
from data_synth.tessellate import tessellate
from nets.model import NFSConfig, NFSModel
from retarget.api import Retargeter
from retarget.errors import RetargetError
from retarget.mesh import Mesh
from retarget.stabilise import MISMATCH, REST_SHARE, rest_vertices, rigid_fit


@pytest.fixture(scope="module")
def rig():
    return build_rig(sample_identity(0, split="test"), tessellate(n_vertices=1500, kind="regular"))


def moved(points, degrees, axis, shift):
    q = Rotation.from_rotvec(np.radians(degrees) * np.asarray(axis, float) / np.linalg.norm(axis)).as_matrix()
    return points @ q.T + shift, q


def test_rest_vertices_are_those_the_rig_moves_least():
    deltas = np.random.default_rng(0).normal(size=(4, 3000, 3))
    deltas[:, 100:300] *= 1e-3
    rest = rest_vertices(deltas)
    assert len(rest) == round(REST_SHARE * 3000) and set(rest) <= set(range(100, 300))
    assert len(rest_vertices(deltas[:, :500])) == 100          # never fewer than MIN_REST


def test_rigid_fit_recovers_a_head_turn_under_an_expression(rig):
    w = np.random.default_rng(1).uniform(0, 1, 53)
    frame = rig.neutral + np.tensordot(w, rig.deltas, axes=1)          # every shape at once
    rest = rest_vertices(rig.deltas)
    turned, q = moved(frame, 8.0, [1, 2, 0.5], [0.7, -0.4, 1.1])
    m = rigid_fit(turned, rig.neutral, rest)
    assert np.allclose(m.rotation, q, atol=1e-6) and m.angle_degrees() == pytest.approx(8.0, abs=1e-4)
    assert np.abs(m.remove(turned) - frame).max() < 1e-5
    assert not m.still and m.mismatch < 0.01
    # the same expression unmoved: no motion, so nothing to remove
    still = rigid_fit(frame, rig.neutral, rest)
    assert still.still and np.abs(still.remove(frame) - frame).max() < 1e-6
    # a plain least-squares fit on every vertex is pulled by the expression
    every = rigid_fit(frame, rig.neutral, np.arange(len(frame)))
    assert every.moved > 10 * still.moved


def test_a_neutral_in_another_vertex_order_is_a_mismatch(rig):
    perm = np.random.default_rng(2).permutation(len(rig.neutral))
    m = rigid_fit(rig.neutral[perm], rig.neutral, rest_vertices(rig.deltas))
    assert m.mismatch > MISMATCH
    assert rigid_fit(rig.neutral * 10.0, rig.neutral, rest_vertices(rig.deltas)).mismatch > MISMATCH


def off_rest(rig, rest, n: int, seed: int, first: int = 0) -> list:
    """n frames of random expressions of ``rig`` that leave the ``rest`` vertices where they are,
    named f{first}, f{first + 1}, ..."""
    motion = np.tensordot(np.random.default_rng(seed).uniform(0, 1, (n, 53)), rig.deltas, axes=1)
    motion[:, rest] = 0.0
    return [Mesh(rig.neutral + d, rig.faces, f"f{first + i}") for i, d in enumerate(motion)]


@pytest.fixture(scope="module")
def r():
    torch.manual_seed(0)
    return Retargeter(NFSModel(NFSConfig.preset("tiny", neutral_channels=True)), device="cpu")


def test_frames_moving_as_a_whole_read_as_the_same_expression(r, rig):
    neutral = Mesh(rig.neutral, rig.faces, "neutral")
    rest = r.source_rig(neutral).rest
    frames = off_rest(rig, rest, 2, seed=3)    # their expression leaves the rest vertices alone
    turned = [Mesh(moved(f.vertices, 6.0 * (i + 1), [0, 1, 0.3], [0.5, 0.2, -0.3])[0], rig.faces, f.name)
              for i, f in enumerate(frames)]
    out, motions = r.stabilise_frames(turned, neutral)
    assert [m.angle_degrees() for m in motions] == pytest.approx([6.0, 12.0], abs=1e-4)
    assert all(np.abs(o.vertices - f.vertices).max() < 1e-5 for o, f in zip(out, frames))
    same, still = r.stabilise_frames(frames, neutral)
    assert all(s is f for s, f in zip(same, frames)) and all(m.still for m in still)
    for refine in (False, True):
        a = r.invert(turned, source_neutral=neutral, refine=refine)
        b = r.invert(frames, source_neutral=neutral, refine=refine)
        np.testing.assert_allclose(a, b, atol=1e-4)
    np.testing.assert_allclose(r.expression_codes(turned, neutral, refine=True),
                               r.expression_codes(frames, neutral, refine=True), atol=1e-4)
    # switched off, the head motion is read as expression
    r.stabilise = False
    try:
        assert np.abs(r.encode(turned, neutral) - r.encode(frames, neutral)).max() > 1e-3
    finally:
        r.stabilise = True


def test_frames_that_do_not_follow_the_neutral_are_refused(r, rig):
    neutral = Mesh(rig.neutral, rig.faces, "neutral.obj")
    perm = np.random.default_rng(4).permutation(len(rig.neutral))
    scrambled = Mesh(rig.neutral[perm], rig.faces, "frame_0001.obj")
    with pytest.raises(RetargetError, match=r"frame_0001.obj: its vertices do not follow those of "
                                            r"neutral.obj one by one"):
        r.invert([scrambled], source_neutral=neutral)
    with pytest.raises(RetargetError, match="frame_0001.obj: 10 vertices, but neutral.obj has"):
        r.stabilise_frames([Mesh(rig.neutral[:10], np.array([[0, 1, 2]]), "frame_0001.obj")], neutral)


def test_a_take_without_its_neutral_is_stabilised_on_its_first_frame(r, rig):
    first = Mesh(rig.neutral, rig.faces, "f0")
    rest = r.source_rig(first).rest
    frames = [first] + off_rest(rig, rest, 3, seed=5, first=1)
    turned = [first] + [Mesh(moved(f.vertices, 5.0, [1, 0, 0.2], [0.3, 0.0, 0.1])[0], rig.faces, f.name)
                        for f in frames[1:]]
    np.testing.assert_allclose(r.encode(turned), r.encode(frames), atol=1e-4)
    np.testing.assert_allclose(r.estimate_neutral(turned).vertices, r.estimate_neutral(frames).vertices,
                               atol=1e-4)
    r.stabilise = False
    try:
        assert np.abs(r.encode(turned) - r.encode(frames)).max() > 1e-3
    finally:
        r.stabilise = True


def test_head_motion_is_carried_onto_the_target_on_request(r, rig):
    neutral = Mesh(rig.neutral, rig.faces, "neutral")
    frames = off_rest(rig, r.source_rig(neutral).rest, 2, seed=6)
    motions = [moved(np.zeros((1, 3)), 7.0 * (i + 1), [0.2, 1, 0], [0.4, -0.2, 0.3]) for i in range(2)]
    turned = [Mesh(f.vertices @ q.T + t[0], rig.faces, f.name) for f, (t, q) in zip(frames, motions)]
    still = r.transfer(turned, neutral, source_neutral=neutral)
    carried = r.transfer(turned, neutral, source_neutral=neutral, head_motion=True)
    # onto the source's own neutral the motion comes back as it was
    for c, s, (t, q) in zip(carried, still, motions):
        np.testing.assert_allclose(c, s @ q.T + t[0], atol=1e-6)
    # onto a head twice as large and moved, the turn is the same and the shift twice as long
    big = Mesh(rig.neutral * 2.0 + 5.0, rig.faces, "big")
    still_big = r.transfer(turned, big, source_neutral=neutral)
    carried_big = r.transfer(turned, big, source_neutral=neutral, head_motion=True)
    for c, s, (t, q) in zip(carried_big, still_big, motions):
        np.testing.assert_allclose(c, (s - 5.0) @ q.T + 2.0 * t[0] + 5.0, atol=1e-5)
    r.stabilise = False
    try:
        with pytest.raises(RetargetError, match="head_motion needs stabilise"):
            r.transfer(turned, neutral, source_neutral=neutral, head_motion=True)
    finally:
        r.stabilise = True


def test_cli_removes_reports_and_on_request_carries_the_head_motion(tmp_path, rig, capsys):
    from retarget.cli import main
    from retarget.io import load_mesh, save_mesh

    from .test_api import tiny_checkpoint

    ckpt = tiny_checkpoint(tmp_path / "tiny.pt", neutral_channels=True)
    save_mesh(tmp_path / "neutral.obj", rig.neutral, rig.faces)
    r = Retargeter.load(ckpt, device="cpu")
    rest = r.source_rig(Mesh(rig.neutral, rig.faces)).rest
    turns = [moved(np.zeros((1, 3)), 6.0 * (i + 1), [1, 0.3, 0], [0.2, 0.1, -0.4]) for i in range(2)]
    (tmp_path / "take").mkdir()
    for i, (f, (t, q)) in enumerate(zip(off_rest(rig, rest, 2, seed=7), turns)):
        save_mesh(tmp_path / "take" / f"f{i}.obj", f.vertices @ q.T + t[0], rig.faces)
    common = [str(tmp_path / "take"), str(tmp_path / "neutral.obj"), "--source-neutral",
              str(tmp_path / "neutral.obj"), "--checkpoint", str(ckpt), "--device", "cpu"]
    assert main(["transfer", *common, "-o", str(tmp_path / "still")]) == 0
    assert "2 of 2 frame(s) move as a whole against the neutral (turned up to 12.0 degrees" in capsys.readouterr().err
    assert main(["transfer", *common, "-o", str(tmp_path / "moving"), "--head-motion"]) == 0
    for i, (t, q) in enumerate(turns):
        still = load_mesh(tmp_path / "still" / f"frame_{i:04d}.obj").vertices
        moving = load_mesh(tmp_path / "moving" / f"frame_{i:04d}.obj").vertices
        np.testing.assert_allclose(moving, still @ q.T + t[0], atol=1e-4)     # OBJ's 6 digits
    assert main(["transfer", *common, "-o", str(tmp_path / "x"), "--head-motion", "--no-stabilise"]) == 2
    assert "--head-motion needs the head motion that stabilisation finds" in capsys.readouterr().err
    # invert writes the head poses it removed: a quaternion and a translation per frame
    poses = tmp_path / "head.csv"
    assert main(["invert", str(tmp_path / "take"), "-o", str(tmp_path / "w.csv"), "--source-neutral",
                 str(tmp_path / "neutral.obj"), "--checkpoint", str(ckpt), "--device", "cpu",
                 "--head-poses", str(poses)]) == 0
    rows = np.loadtxt(poses, delimiter=",", skiprows=1)
    assert rows.shape == (2, 10)
    for row, (t, q) in zip(rows, turns):
        np.testing.assert_allclose(Rotation.from_quat(row[[3, 4, 5, 2]]).as_matrix(), q, atol=1e-6)
        np.testing.assert_allclose(row[6:9], t[0], atol=1e-5)
        assert row[9] == pytest.approx(np.degrees(np.arccos((np.trace(q) - 1) / 2)), abs=1e-4)
    assert main(["invert", str(tmp_path / "take"), "-o", str(tmp_path / "w.csv"),
                 "--head-poses", str(tmp_path / "w.csv"), "--checkpoint", str(ckpt)]) == 2
    assert "--head-poses and -o name the same file" in capsys.readouterr().err


def test_a_large_neutral_takes_its_rest_vertices_from_its_proxy(rig):
    torch.manual_seed(0)
    r = Retargeter(NFSModel(NFSConfig.preset("tiny", neutral_channels=True)), device="cpu",
                   proxy_vertices=400)                       # the 1,500-vertex rig is "large"
    neutral = Mesh(rig.neutral, rig.faces, "neutral")
    rest = r.rest_vertices(neutral)
    src = r.source_topology(neutral, neutral=True)
    assert src.cluster is not None and src.rest is rest      # made once, kept with the neutral
    proxy_rest = r.source_rig(src.proxy(neutral)).rest       # the proxy's rig, not the whole mesh's
    assert set(src.cluster[rest]) <= set(proxy_rest.tolist())
    assert len(rest) == np.isin(src.cluster, proxy_rest).sum()
    assert not any(s.baked.deltas.shape[1] == len(rig.neutral) for s in r._source_rigs.values())
    frames = off_rest(rig, rest, 1, seed=8)
    turned, q = moved(frames[0].vertices, 9.0, [0.3, 1, 0.1], [0.2, 0.4, 0.1])
    out, motions = r.stabilise_frames([Mesh(turned, rig.faces)], neutral)
    np.testing.assert_allclose(motions[0].rotation, q, atol=1e-6)
    np.testing.assert_allclose(out[0].vertices, frames[0].vertices, atol=1e-5)
