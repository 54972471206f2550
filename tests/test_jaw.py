"""Separate parts carried by the jaw (retarget.jaw): which parts, and how they move."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from data_synth.facs import FACS_INDEX
from retarget.jaw import MOUTH, SHAPES, chin_vertices, find_jaw_parts
from retarget.mesh import Mesh


def turn_x(points: np.ndarray, angle: float, hinge=(0.0, -1.0, -8.0)) -> np.ndarray:
    """``points`` (N,3) turned by ``angle`` radians about the x-parallel axis through ``hinge``."""
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return (points - hinge) @ rot.T + hinge


def boxes(centres):
    """Small closed boxes at ``centres``: [(vertices, faces)]."""
    box = trimesh.creation.box((1.0, 0.5, 0.5))
    return [(np.asarray(box.vertices) + c, np.asarray(box.faces)) for c in centres]


@pytest.fixture(scope="module")
def face_rig():
    """A flat face (grid x in [-5, 5], y in [-6, 6], looking along +z, in its canonical frame)
    whose jawOpen turns everything below y = -1 by 0.3 rad about a hinge 8 behind the mouth,
    whose mouth shapes move the lips (-1.5 < y < 0) and whose smiles pull the mouth corners
    (±2.5, -1); beside it three parts: below the mouth and behind it (a jaw part), above the mouth
    (not), and far below it (not)."""
    gx, gy = np.meshgrid(np.linspace(-5, 5, 21), np.linspace(-6, 6, 25))
    face_v = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]
    idx = np.arange(gx.size).reshape(gx.shape)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    face_f = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    shapes = np.zeros((len(SHAPES),) + face_v.shape)
    lower = face_v[:, 1] < -1.0
    shapes[0, lower] = turn_x(face_v[lower], 0.3) - face_v[lower]
    lips = (face_v[:, 1] > -1.5) & (face_v[:, 1] < 0.0)
    rng = np.random.default_rng(0)
    for k in range(1, len(SHAPES)):
        shapes[k, lips] = rng.normal(0, 0.3, (lips.sum(), 3))
    for name, x in (("mouthSmile_L", 2.5), ("mouthSmile_R", -2.5)):
        near = np.exp(-np.square(face_v - [x, -1.0, 0.0]).sum(1))
        shapes[SHAPES.index(name)] = near[:, None] * [np.sign(x), 0.5, 0.0] * 3.0
    parts = boxes([(0.0, -2.0, -1.0), (0.0, 0.5, -1.0), (0.0, -12.0, -1.0)])
    v, f, n = [face_v], [face_f], len(face_v)
    for pv, pf in parts:
        v.append(pv)
        f.append(pf + n)
        n += len(pv)
    mesh = Mesh(np.concatenate(v), np.concatenate(f))
    return mesh, np.arange(len(face_v)), shapes


def test_the_part_below_the_mouth_is_the_jaws_and_follows_the_chin_exactly(face_rig):
    mesh, face, shapes = face_rig
    jaw = find_jaw_parts(mesh.vertices, mesh.faces, face, shapes, lambda x: x)
    n = len(face)
    assert jaw is not None and jaw.parts == 1
    assert np.array_equal(jaw.carried, np.arange(n, n + 8))            # the first box alone
    assert (mesh.vertices[face[jaw.jaw], 1] < -1.0).all()               # the chin turns with the jaw
    # a result whose chin turned rigidly: the jaw's part turns with it, exactly; the others stay
    turned = mesh.vertices.copy()
    lower = np.flatnonzero(mesh.vertices[:n, 1] < -1.0)
    turned[lower] = turn_x(mesh.vertices[lower], 0.21)
    out = jaw.carry(turned)
    assert np.allclose(out[jaw.carried], turn_x(mesh.vertices[jaw.carried], 0.21), atol=1e-9)
    assert np.array_equal(out[n + 8:], mesh.vertices[n + 8:]) and np.array_equal(out[:n], turned[:n])
    # a baked rig: each shape moves the jaw's part as it moves the chin at weight 1
    deltas = np.zeros((2,) + mesh.vertices.shape)
    deltas[0, :n] = shapes[0]
    deltas[1, :n] = shapes[SHAPES.index("mouthSmile_L")]
    rig = jaw.carry_shapes(deltas)
    assert np.allclose(rig[0, jaw.carried], turn_x(mesh.vertices[jaw.carried], 0.3) - mesh.vertices[jaw.carried],
                       atol=1e-9)
    assert np.abs(rig[1, jaw.carried]).max() < 1e-4                    # a smile barely moves the chin
    assert not rig[:, n + 8:].any() and np.array_equal(rig[:, :n], deltas[:, :n])
    # a rig whose neutral is not the target's (an MLP decoder's output at zero): the motion of its
    # own chin counts
    assert np.array_equal(jaw.carry_shapes(deltas, mesh.vertices), rig)
    raised = mesh.vertices.copy()
    raised[lower] = turn_x(mesh.vertices[lower], -0.1)
    assert not np.allclose(jaw.carry_shapes(deltas, raised)[0, jaw.carried], rig[0, jaw.carried], atol=1e-3)


def test_no_jaw_part_without_a_part_below_the_mouth_or_a_jaw(face_rig):
    mesh, face, shapes = face_rig
    n = len(face)
    keep = np.r_[np.arange(n), np.arange(n + 8, n + 16)]                 # the face and the upper box
    upper = Mesh(mesh.vertices[keep], np.searchsorted(keep, mesh.faces[np.isin(mesh.faces, keep).all(1)]))
    assert find_jaw_parts(upper.vertices, upper.faces, face, shapes, lambda x: x) is None
    still = shapes.copy()
    still[0] = 0.0
    assert find_jaw_parts(mesh.vertices, mesh.faces, face, still, lambda x: x) is None
    assert chin_vertices(still[0], still[1:]) is None


def test_bundled_model_moves_lower_teeth_with_the_jaw_and_nothing_else():
    """The bundled model on the packaged ARKit head given eyeballs, upper and lower teeth: jawOpen
    carries the lower teeth down, the eyes and upper teeth stay, the skin is what it was, and the
    source side (invert) and the rig refine fits ignore it."""
    from retarget.api import Retargeter
    from retarget.evaluate import TEMPLATE_RIG, RealRig

    from data_synth.makehuman.segmentation import EYE, MOUTH as MOUTH_CENTRE

    rig = RealRig.load(TEMPLATE_RIG)
    eye = EYE - [0.0, 0.0, 1.2]
    parts = boxes([eye, eye * [-1, 1, 1],                              # eyes, upper and lower teeth
                   MOUTH_CENTRE + [0.0, 0.5, -1.5], MOUTH_CENTRE + [0.0, -0.6, -1.5]])
    v, f, n = [rig.neutral], [rig.faces], len(rig.neutral)
    for pv, pf in parts:
        v.append(pv)
        f.append(pf + n)
        n += len(pv)
    mesh = Mesh(np.concatenate(v), np.concatenate(f))
    v0 = len(rig.neutral)
    carry, still = Retargeter.load(None, device="cpu"), Retargeter.load(None, device="cpu", carry_jaw=False)
    jaw = carry.jaw_parts(carry.prepare(mesh))
    assert jaw is not None and np.array_equal(jaw.carried, np.arange(v0 + 24, v0 + 32))
    w = np.zeros(53, np.float32)
    w[FACS_INDEX["jawOpen"]] = 1.0
    out, rest = carry.animate(mesh, w), still.animate(mesh, w)
    assert np.array_equal(out[:v0], rest[:v0])
    assert np.array_equal(out[v0:v0 + 24], mesh.vertices[v0:v0 + 24])
    drop = out[v0 + 24:, 1] - mesh.vertices[v0 + 24:, 1]
    assert (drop < -0.5).all()                                          # centimetres down
    assert np.array_equal(rest[v0:], mesh.vertices[v0:])
    baked = carry.bake(mesh)
    assert np.allclose(baked.evaluate(w)[v0 + 24:], out[v0 + 24:], atol=1e-4)
    assert not carry.bake(mesh, parts=False).deltas[:, v0:].any()
    assert carry.jaw_parts(Mesh(rig.neutral, rig.faces)) is None and still.jaw_parts(mesh) is None
    frames = [Mesh(rig.neutral + 0.5 * rig.deltas[k], rig.faces) for k in (3, 17)]
    assert np.array_equal(carry.invert(frames, source_neutral=Mesh(rig.neutral, rig.faces), refine=True),
                          still.invert(frames, source_neutral=Mesh(rig.neutral, rig.faces), refine=True))


def test_mouth_shapes_are_the_mouth_names():
    assert MOUTH and all(n.startswith("mouth") for n in MOUTH) and SHAPES[0] == "jawOpen"
    assert set(MOUTH) <= set(FACS_INDEX)
