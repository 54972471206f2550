"""Eyeballs that turn with the gaze (retarget.eyes): found beside the face, turned by FACS looks or by
a source's own eyeballs, baked into the look shapes."""
import numpy as np
import pytest
import trimesh

from data_synth.facs import FACS_INDEX
from retarget.eyes import (GAZE_DEGREES, LOOK_INDEX, find_eyes, gaze_from_weights, gaze_rotation,
                           sphere_fit, weights_from_gaze)
from retarget.mesh import Mesh


def sphere(centre, radius=1.2, subdivisions=2):
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(s.vertices) + centre, np.asarray(s.faces)


def cap(centre, radius):
    """The front third of a sphere (a cornea), open at the back."""
    v, f = sphere(np.zeros(3), radius)
    keep = v[:, 2] > 0.5 * radius
    f = f[keep[f].all(1)]
    idx = np.unique(f)
    remap = np.full(len(v), -1)
    remap[idx] = np.arange(len(idx))
    return v[idx] + centre, remap[f]


def box(centre, size):
    b = trimesh.creation.box(size)
    return np.asarray(b.vertices) + centre, np.asarray(b.faces)


def assemble(parts):
    vs, fs, n, index = [], [], 0, []
    for v, f in parts:
        vs.append(v)
        fs.append(f + n)
        index.append(np.arange(n, n + len(v)))
        n += len(v)
    return np.concatenate(vs), np.concatenate(fs), index


def face_sheet():
    """A face: a 20 x 24 grid (cm) in the plane z = 0, its middle height at y = 0."""
    x, y = np.meshgrid(np.linspace(-10, 10, 21), np.linspace(-12, 12, 25))
    v = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    f = []
    for i in range(24):
        for j in range(20):
            a = i * 21 + j
            f += [[a, a + 1, a + 22], [a, a + 22, a + 21]]
    return v, np.asarray(f)


EYE_L, EYE_R = np.array([3.2, 4.0, -1.5]), np.array([-3.2, 4.0, -1.5])


def head_with_eyes():
    """The sheet, two eyeballs with a cornea each, a lash strip over the left eye, teeth below."""
    parts = [face_sheet(), sphere(EYE_L), sphere(EYE_R), cap(EYE_L + [0, 0, 0.5], 0.75),
             cap(EYE_R + [0, 0, 0.5], 0.75), box(EYE_L + [0, 1.3, 1.0], (2.4, 0.1, 1.0)),
             box([0.0, -6.0, -1.0], (4.0, 0.8, 1.0))]
    return assemble(parts)


def test_sphere_fit_and_the_look_convention():
    v, _ = sphere(np.array([1.0, -2.0, 3.0]), radius=2.5)
    centre, radius, residual = sphere_fit(v)
    assert np.allclose(centre, [1.0, -2.0, 3.0]) and radius == pytest.approx(2.5) and residual < 1e-9
    w = np.zeros(53)
    w[FACS_INDEX["eyeLookOut_L"]], w[FACS_INDEX["eyeLookIn_R"]] = 1.0, 0.5     # both look to +x
    w[FACS_INDEX["eyeLookUp_L"]], w[FACS_INDEX["eyeLookDown_R"]] = 0.4, 1.0
    g = gaze_from_weights(w)
    side, up, down = np.radians(GAZE_DEGREES)
    assert np.allclose(g, [[side, 0.4 * up], [0.5 * side, -down]])
    back = weights_from_gaze(g)                   # from zeros: one look of each pair
    assert np.allclose(back[LOOK_INDEX], w[LOOK_INDEX]) and not np.delete(back, LOOK_INDEX.ravel()).any()
    near = weights_from_gaze(g, np.full(53, 0.3))  # the nearest looks to 0.3 that turn so
    assert np.allclose(gaze_from_weights(near), g) and np.allclose(np.delete(near, LOOK_INDEX.ravel()), 0.3)
    assert near[FACS_INDEX["eyeLookOut_L"]] - near[FACS_INDEX["eyeLookIn_L"]] == pytest.approx(1.0)
    assert near[FACS_INDEX["eyeLookIn_R"]] + near[FACS_INDEX["eyeLookOut_R"]] == pytest.approx(0.6)
    far = weights_from_gaze(np.array([[1.0, 0.0], [-1.0, -1.0]]))   # 57 degrees: beyond the range
    assert np.allclose(far[LOOK_INDEX], [[1, 0, 0, 0], [0, 1, 0, 1]])
    d = gaze_rotation(*g[0]) @ [0.0, 0.0, 1.0]
    assert d[0] > 0 and d[1] > 0 and np.degrees(np.arctan2(d[0], d[2])) == pytest.approx(GAZE_DEGREES[0])
    assert np.allclose(gaze_rotation(0.0, 0.0), np.eye(3))


@pytest.mark.parametrize("turn", [0.0, 25.0])
def test_the_eyeballs_and_their_corneas_are_found_and_turn_as_measured(turn):
    v, f, index = head_with_eyes()
    a = np.radians(turn)                       # the mesh turned aside; its canonical frame turns back
    rot = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    mesh_v = v @ rot.T
    eyes = find_eyes(mesh_v, f, index[0], lambda p: p @ rot, rot.T)
    assert eyes is not None and eyes.parts == 4
    assert np.array_equal(eyes.vertices[0], np.concatenate([index[1], index[3]]))   # left: +x
    assert np.array_equal(eyes.vertices[1], np.concatenate([index[2], index[4]]))
    assert np.allclose(eyes.centres, np.stack([EYE_L, EYE_R]) @ rot.T)
    gaze = np.radians([[20.0, -10.0], [15.0, 5.0]])
    posed = eyes.pose(mesh_v, gaze)
    assert np.allclose(eyes.measure(posed), gaze)
    moved = np.flatnonzero(np.abs(posed - mesh_v).max(1) > 1e-9)
    assert np.array_equal(moved, np.sort(np.concatenate(eyes.vertices)))             # lashes, teeth stay
    front = index[1][np.argmax(v[index[1], 2])]                # the left pupil goes to +x and down
    pupil = (posed[front] - eyes.centres[0]) @ rot
    assert pupil[0] > 0.3 and pupil[1] < -0.1
    assert np.array_equal(eyes.pose(mesh_v, np.zeros((2, 2))), mesh_v)


def test_no_eyes_without_a_mirrored_pair_above_the_middle():
    v, f, index = assemble([face_sheet(), sphere(EYE_L), box(EYE_R, (2.4, 2.4, 2.4))])
    assert find_eyes(v, f, index[0], lambda p: p) is None             # one sphere and a cube
    v, f, index = assemble([face_sheet(), sphere(EYE_L * [1, -1, 1]), sphere(EYE_R * [1, -1, 1])])
    assert find_eyes(v, f, index[0], lambda p: p) is None             # below the face's middle
    v, f, index = assemble([face_sheet(), sphere(EYE_L), sphere(EYE_R, radius=2.0)])
    assert find_eyes(v, f, index[0], lambda p: p) is None             # unlike sizes
    v, f, index = assemble([face_sheet(), box(EYE_L, (2.0, 2.0, 2.0)), box(EYE_R, (2.0, 2.0, 2.0))])
    assert find_eyes(v, f, index[0], lambda p: p) is None             # cubes, corners on a sphere


def test_bundled_model_turns_eyes_from_looks_and_from_a_sources_eyeballs():
    """The packaged ARKit head given two eyeballs: a look turns its eye by the convention, the baked
    look shapes do the same at weight 1, a source with eyeballs hands their turn to transfer and
    invert, and turn_eyes=False keeps them at rest."""
    from retarget.api import Retargeter
    from retarget.evaluate import TEMPLATE_RIG, RealRig

    from data_synth.makehuman.segmentation import EYE

    rig = RealRig.load(TEMPLATE_RIG)
    v, f, index = assemble([(rig.neutral, rig.faces), sphere(EYE - [0.0, 0.0, 1.15], 1.2, 3),
                            sphere(EYE * [-1, 1, 1] - [0.0, 0.0, 1.15], 1.2, 3)])
    mesh, n = Mesh(v, f), len(rig.neutral)
    r, still = Retargeter.load(None, device="cpu"), Retargeter.load(None, device="cpu", turn_eyes=False)
    eyes = r.eyes(mesh)
    assert eyes is not None and [list(e) for e in eyes.vertices] == [list(index[1]), list(index[2])]
    w = np.zeros(53, np.float32)
    w[FACS_INDEX["eyeLookOut_L"]] = 1.0
    out, rest = r.animate(mesh, w), still.animate(mesh, w)
    assert np.array_equal(out[:n], rest[:n]) and np.array_equal(rest[n:], v[n:])
    assert np.array_equal(out[index[2]], v[index[2]])                  # the right eye looks ahead
    front = index[1][np.argmax(v[index[1], 2])]
    d = out[front] - eyes.centres[0]
    assert np.degrees(np.arctan2(d[0], d[2])) == pytest.approx(GAZE_DEGREES[0], abs=0.5)
    assert np.allclose(r.bake(mesh).evaluate(w)[n:], out[n:], atol=1e-4)
    assert not still.bake(mesh).deltas[:, n:].any()
    # a source with eyeballs: its frames' eyes turned by their looks
    rng = np.random.default_rng(0)
    looks = np.zeros((3, 53), np.float32)
    looks[:, LOOK_INDEX.ravel()] = rng.uniform(0, 1, (3, 8)) * (rng.uniform(size=(3, 8)) < 0.5)
    frames = [Mesh(eyes.pose(v, g), f) for g in gaze_from_weights(looks)]
    assert np.allclose(r.source_gaze(frames, mesh), gaze_from_weights(looks), atol=1e-9)
    ahead = gaze_from_weights(looks) - np.median(gaze_from_weights(looks), axis=0)
    assert np.allclose(r.source_gaze(frames), ahead, atol=0.01)      # no neutral: the take's median
    z, gaze = r.expression(frames, mesh, smooth="one_euro")
    assert z.shape == (3, 128) and gaze.shape == (3, 2, 2) and np.isfinite(gaze).all()
    moved = r.transfer(frames, mesh, source_neutral=mesh, refine=True)
    assert np.allclose(moved[:, n:], np.stack([fr.vertices[n:] for fr in frames]), atol=1e-9)
    inverted = r.invert(frames, source_neutral=mesh, refine=True)
    assert np.allclose(gaze_from_weights(inverted), gaze_from_weights(looks), atol=1e-6)
