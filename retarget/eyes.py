"""Eyeballs that turn with the gaze.

A head given with separate parts goes to the network as its face alone (``retarget.mesh.face_part``);
the 53 FACS shapes move the eyelids of a look (``eyeLookIn`` / ``Out`` / ``Up`` / ``Down``) but say
nothing of the eyeballs, which an artist's rig turns with a joint. Left at rest, a target looks
straight ahead while its lids follow a look aside. This module finds a mesh's eyes and turns them.

- The **eyes** (:class:`Eyes`, :func:`find_eyes`): of the parts beside the face, the eyeballs are
  two near-spheres (``sphere_fit``: the RMS distance of a part's vertices from its fitted sphere
  at most ``SPHERE_RESIDUAL`` of its radius) mirrored across the face's midline in its canonical
  frame (+x the face's left, +y up, +z its front): centres within ``PAIR_TOLERANCE`` of their
  distance apart in height, depth and mirrored side, radii within ``RADIUS_RATIO`` of each other
  and between ``RADIUS_RANGE`` of that distance, above the middle height of the face. Every other
  part lying wholly within ``INSIDE`` radii of an eyeball's centre (a cornea, an iris, a pupil)
  turns with it. Of several such pairs, the pair with the most vertices.
- The **gaze** of an eye: (yaw, pitch) in radians in that canonical frame, 0 looking along +z;
  yaw > 0 turns the pupil towards +x (the face's left), pitch > 0 up. An eye's turn is the one
  that carries +z to that direction without roll, about the eyeball's centre.
- **From FACS weights** (:func:`gaze_from_weights`): a look at weight 1 turns the eye by
  ``GAZE_DEGREES`` (a convention, as a rig's joint limits are: in / out, up, down);
  ``eyeLookOut_L`` turns the left eye towards +x, ``eyeLookIn_L`` towards the nose; for the right
  eye the other way round. :func:`weights_from_gaze` is its inverse, clipped to [0, 1].
- **From a source's own eyeballs** (:meth:`Eyes.measure`): the rotation of each eye's vertices
  against the neutral's (``retarget.stabilise.rigid_fit``), read as a gaze.

``Retargeter`` (``eyes``, default on; CLI ``--still-parts`` leaves them at rest) turns a target's
eyes in every decoded frame: ``transfer`` by the gaze of the source's eyeballs when the source
has them, else by the gaze of the weights it reads; ``animate`` by the weights; ``bake`` /
``export-rig`` store each look's turn at weight 1 in its shape (linear, so a look at weight 0.5
draws the eye a little inside its sphere: 1 − cos(θ/2) of the radius, 3 % at 30°). ``invert``
reads the looks from a source's eyeballs when it has them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from data_synth.facs import FACS_INDEX, N_FACS

from .mesh import mesh_parts
from .stabilise import rigid_fit

GAZE_DEGREES = (30.0, 25.0, 30.0)   # a look at weight 1: in / out, up, down (degrees)
SPHERE_RESIDUAL = 0.08              # an eyeball: RMS distance from its fitted sphere / its radius
RADIUS_RANGE = (0.08, 0.4)          # ... its radius / the distance between the two eyes' centres
RADIUS_RATIO = 1.25                 # ... the larger radius of a pair / the smaller at most
PAIR_TOLERANCE = 0.25               # mirrored centres: height, depth, side apart / their distance
INSIDE = 1.3                        # a part wholly within this many radii of an eyeball turns with it
#                                     (a cornea stands up to 0.2 radii proud of its eyeball)
STILL = 1e-6                        # a gaze (radians) no further from 0 leaves the eye at rest, bit for bit
#: the look shapes, per eye: (yaw towards +x, yaw towards −x, up, down)
LOOKS = (("eyeLookOut_L", "eyeLookIn_L", "eyeLookUp_L", "eyeLookDown_L"),
         ("eyeLookIn_R", "eyeLookOut_R", "eyeLookUp_R", "eyeLookDown_R"))
LOOK_INDEX = np.array([[FACS_INDEX[n] for n in eye] for eye in LOOKS])   # (2, 4)


def sphere_fit(points: np.ndarray) -> tuple[np.ndarray, float, float]:
    """The least-squares sphere through points (N,3): (centre (3,), radius, RMS distance of the
    points from it / radius). Algebraic fit |p|² = 2 c·p + (r² − |c|²)."""
    p = np.asarray(points, np.float64)
    a = np.c_[2.0 * p, np.ones(len(p))]
    sol = np.linalg.lstsq(a, (p * p).sum(1), rcond=None)[0]
    centre = sol[:3]
    radius = float(np.sqrt(max(sol[3] + centre @ centre, 0.0)))
    if radius <= 0:
        return centre, 0.0, np.inf
    rms = float(np.sqrt(np.mean((np.linalg.norm(p - centre, axis=1) - radius) ** 2)))
    return centre, radius, rms / radius


def gaze_from_weights(weights: np.ndarray) -> np.ndarray:
    """FACS weights (..., 53) in ICT order -> the gaze (..., 2, 2) they look with (module
    docstring): per eye (left, right) (yaw, pitch) in radians, by ``GAZE_DEGREES``."""
    w = np.clip(np.asarray(weights, np.float64), 0.0, 1.0)[..., LOOK_INDEX]     # (..., 2, 4)
    side, up, down = np.radians(GAZE_DEGREES)
    return np.stack([(w[..., 0] - w[..., 1]) * side, w[..., 2] * up - w[..., 3] * down], axis=-1)


def weights_from_gaze(gaze: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """The gaze (..., 2, 2) -> FACS weights (..., 53): ``weights`` (default zeros) with their eight
    look weights moved to the nearest (least squares) that ``gaze_from_weights`` turns into that
    gaze, each pair within [0, 1]. A turn only says the difference of a pair (out − in, up − down):
    what both looks of a pair share stays as ``weights`` had it; from zeros, one look of each pair
    is 0. A gaze beyond a pair's range gives its nearest end (1 and 0)."""
    g = np.asarray(gaze, np.float64)
    dtype = np.float32 if weights is None else np.asarray(weights).dtype
    out = (np.zeros(g.shape[:-2] + (N_FACS,)) if weights is None
           else np.array(weights, np.float64, copy=True))
    side, up, down = np.radians(GAZE_DEGREES)
    w0 = out[..., LOOK_INDEX]                                            # (..., 2, 4)
    looks = np.empty_like(w0)
    for pair, scale, angle in (((0, 1), (side, -side), g[..., 0]), ((2, 3), (up, -down), g[..., 1])):
        a = np.array(scale)
        x0 = w0[..., list(pair)]                                         # (..., 2, 2)
        # the line a·x = angle through the pair's square: nearest point to x0, kept in the square
        x = x0 + ((angle - x0 @ a) / (a @ a))[..., None] * a
        d = np.array([a[1], -a[0]]) / np.linalg.norm(a)                 # along the line
        with np.errstate(divide="ignore", invalid="ignore"):
            ends = np.stack([(0.0 - x) / d, (1.0 - x) / d], axis=-1)     # (..., 2, 2 coords, 2)
        lo, hi = ends.min(-1).max(-1), ends.max(-1).min(-1)
        inside = lo <= hi
        t = np.clip(0.0, lo, hi)
        end = np.where((angle > 0)[..., None], a > 0, a < 0).astype(np.float64)   # out of range
        x = np.where(inside[..., None], x + t[..., None] * d, end)
        looks[..., list(pair)] = np.clip(x, 0.0, 1.0)
    out[..., LOOK_INDEX] = looks
    return out.astype(dtype)


def gaze_rotation(yaw: float, pitch: float) -> np.ndarray:
    """The canonical-frame rotation (3,3) carrying +z to the gaze's direction without roll:
    turn about x by −pitch (up), then about y by yaw."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    turn_y = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    tilt_x = np.array([[1.0, 0.0, 0.0], [0.0, cp, sp], [0.0, -sp, cp]])
    return turn_y @ tilt_x


@dataclass(frozen=True, repr=False)
class Eyes:
    """The eyes of a mesh. neutral: (V,3) float64 its vertices (its units); centres: (2,3) the
    eyeballs' centres (left, right) in them; vertices: each eye's turning vertices, (2,) tuple of
    index arrays into the mesh; canon: (3,3) the rotation of the mesh's frame into its face's
    canonical frame (directions: d_canonical ∝ R d); parts: how many separate parts turn; balls:
    each eyeball's own vertices (2,) tuple of index arrays, on which its centre is fitted."""

    neutral: np.ndarray
    centres: np.ndarray
    vertices: tuple
    canon: np.ndarray
    parts: int
    balls: tuple

    def at(self, vertices: np.ndarray) -> "Eyes":
        """The same eyes at rest in other vertices (V,3) of the mesh (a take's first frame)."""
        v = np.asarray(vertices, np.float64)
        return Eyes(v, np.stack([sphere_fit(v[b])[0] for b in self.balls]), self.vertices, self.canon,
                    self.parts, self.balls)

    def turns(self, gaze: np.ndarray) -> list[np.ndarray]:
        """The gaze (2,2) -> each eye's rotation (3,3) in the mesh's frame."""
        g = np.asarray(gaze, np.float64)
        return [self.canon.T @ gaze_rotation(*g[e]) @ self.canon for e in range(2)]

    def pose(self, vertices: np.ndarray, gaze: np.ndarray) -> np.ndarray:
        """A result's vertices (V,3) (its eyes at rest) -> a copy with each eye turned from its rest
        place to the gaze (2,2), of the input's dtype; an eye looking ahead (``STILL``) as it was."""
        out = np.array(vertices, copy=True)
        g = np.asarray(gaze, np.float64)
        for e, (idx, c, q) in enumerate(zip(self.vertices, self.centres, self.turns(g))):
            if np.abs(g[e]).max() > STILL:
                out[idx] = (self.neutral[idx] - c) @ q.T + c
        return out

    def pose_shapes(self, deltas: np.ndarray) -> np.ndarray:
        """A baked rig's 53 shapes (53,V,3) (zero on the eyes) -> a copy in which each look shape
        turns its eye as it does at weight 1 (the linear blendshape of that turn)."""
        out = np.array(deltas, copy=True)
        for k in np.unique(LOOK_INDEX):
            onehot = np.zeros(N_FACS)
            onehot[k] = 1.0
            posed = self.pose(self.neutral, gaze_from_weights(onehot))
            for idx in self.vertices:
                out[k, idx] = posed[idx] - self.neutral[idx]
        return out

    def measure(self, vertices: np.ndarray) -> np.ndarray:
        """The gaze (2,2) of a frame's eyes (V,3) (head motion removed): each eye's rotation
        against the neutral (``rigid_fit``) read in the canonical frame; roll is dropped."""
        out = np.zeros((2, 2))
        v = np.asarray(vertices, np.float64)
        for e, idx in enumerate(self.vertices):
            m = rigid_fit(v[idx], self.neutral[idx], np.arange(len(idx)))
            d = self.canon @ m.rotation @ self.canon.T @ np.array([0.0, 0.0, 1.0])
            out[e] = np.arctan2(d[0], d[2]), np.arcsin(np.clip(d[1], -1.0, 1.0))
        out[np.abs(out) <= STILL] = 0.0                  # rounding is no look
        return out


def find_eyes(vertices: np.ndarray, faces: np.ndarray, face: np.ndarray, to_canonical,
              canon_rotation: np.ndarray | None = None) -> Eyes | None:
    """The eyes of a mesh with separate parts (module docstring), or None when it has none.

    vertices (V,3), faces (F,3): the whole mesh; face (V',) the face's indices (``face_part``);
    to_canonical: maps (N,3) vertices of the mesh to the face's canonical frame (+y up, +z front);
    canon_rotation: the rotation (3,3) part of that map (``Canonicaliser.rotation``; None: none)."""
    vertices = np.asarray(vertices, np.float64)
    labels = mesh_parts(vertices, faces)
    labels[face] = -1
    faces = np.asarray(faces, np.int64)
    ids = np.unique(labels[labels >= 0])
    parts = [np.flatnonzero(labels == k) for k in ids]
    canon = [to_canonical(vertices[idx]) for idx in parts]
    spheres = []                                     # (part, centre, radius) of the near-spheres
    for k, (label, c) in enumerate(zip(ids, canon)):
        # the vertices and the centres of the part's triangles: a box's corners lie on a sphere
        centres = to_canonical(vertices[faces[labels[faces[:, 0]] == label]].mean(1))
        if len(c) >= 8:
            centre, radius, residual = sphere_fit(np.concatenate([c, centres]))
            if residual <= SPHERE_RESIDUAL:
                spheres.append((k, centre, radius))
    middle = float(np.median(to_canonical(vertices[face])[:, 1]))
    best = None
    for kl, cl, rl in spheres:
        for kr, cr, rr in spheres:
            if not cl[0] > 0 > cr[0]:
                continue
            apart = float(np.linalg.norm(cl - cr))
            off = np.abs([cl[0] + cr[0], cl[1] - cr[1], cl[2] - cr[2]]) / apart
            if (off.max() <= PAIR_TOLERANCE and max(rl, rr) <= RADIUS_RATIO * min(rl, rr)
                    and RADIUS_RANGE[0] * apart <= min(rl, rr) and max(rl, rr) <= RADIUS_RANGE[1] * apart
                    and (cl[1] + cr[1]) / 2 > middle):
                size = len(parts[kl]) + len(parts[kr])
                if best is None or size > best[0]:
                    best = (size, (kl, cl, rl), (kr, cr, rr))
    if best is None:
        return None
    groups, count = [], 0
    for k0, centre, radius in best[1:]:
        members = [k for k, c in enumerate(canon)
                   if k == k0 or np.linalg.norm(c - centre, axis=1).max() <= INSIDE * radius]
        groups.append(np.sort(np.concatenate([parts[k] for k in members])).astype(np.int64))
        count += len(members)
    rot = np.eye(3) if canon_rotation is None else np.asarray(canon_rotation, np.float64)
    balls = tuple(parts[k0] for k0, _, _ in best[1:])
    return Eyes(vertices, np.zeros((2, 3)), tuple(groups), rot, count, balls).at(vertices)
