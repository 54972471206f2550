"""Head stabilisation: the rigid motion of a source frame against its neutral, found and removed.

Captured frames move as a whole (the performer turns and nods, the scanner's origin drifts); the
network reads every displacement from the neutral as expression, so a head turned by 3 degrees
reads as a dozen FACS shapes at full strength. :func:`rigid_fit` finds the rigid motion that
carries the neutral onto a frame on the head's *rest* vertices, those that no expression moves
(``rest_vertices``: the share ``REST_SHARE`` that the source's own rig, the network's 53 shapes
baked on its neutral, moves least: the skull, the back of the neck, the top of the forehead), by
Kabsch's least squares reweighted with Tukey's biweight of each vertex's residual.
``Retargeter.stabilise_frames`` removes it before anything reads the frame.

Frames must correspond vertex by vertex with the neutral. Where the best rigid fit still leaves
the typical vertex far from the neutral (another vertex order, other units), :func:`rigid_fit`'s
``mismatch`` says so (``MISMATCH``) instead of the network reading noise as expression.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

REST_SHARE = 0.05         # share of a head's vertices, the least moved by its rig, that fit the motion
MIN_REST = 100            # ... but at least this many
MAX_REST = 5000           # and of a large mesh's (``Retargeter.rest_vertices``) at most this many
TUKEY_C = 4.685           # Tukey's biweight constant, in robust standard deviations
SIGMA_FLOOR = 1e-4        # robust scale floor, relative to the neutral's bounding-box diagonal
ITERATIONS = 10
STILL = 1e-4              # motion carrying no vertex further than this (relative to the diagonal)
#                           is no motion: the frame is left as it is
MISMATCH = 0.1            # a median vertex this far from the neutral (relative) after the fit:
#                           the frame does not correspond to the neutral vertex by vertex


@dataclass(frozen=True)
class RigidMotion:
    """x_frame ≈ x_neutral @ rotation.T + translation on the head's rest vertices: rotation (3,3),
    translation (3,) in the frame's units. ``moved``: the largest distance it carries a vertex
    of the neutral, and ``mismatch``: the median distance of all vertices from the neutral once it
    is removed, both relative to the neutral's bounding-box diagonal."""

    rotation: np.ndarray
    translation: np.ndarray
    moved: float
    mismatch: float

    @property
    def still(self) -> bool:
        """Too small to be motion (``STILL``)."""
        return self.moved < STILL

    def remove(self, vertices: np.ndarray) -> np.ndarray:
        """Frame vertices (V,3) -> the frame moved back onto the neutral, (V,3) float64."""
        return (np.asarray(vertices, np.float64) - self.translation) @ self.rotation

    def angle_degrees(self) -> float:
        """The rotation's angle (degrees; ``retarget.canonical.rotation_angle``)."""
        from .canonical import rotation_angle

        return rotation_angle(self.rotation)


def rest_vertices(deltas: np.ndarray) -> np.ndarray:
    """The rest vertices of a rig: indices (R,) int64 of the ``REST_SHARE`` of vertices (at least
    ``MIN_REST``) with the least squared motion summed over its shapes; deltas (K,V,3)."""
    q = np.zeros(np.shape(deltas)[1])
    for d in deltas:                     # a shape at a time: no float64 copy of the whole rig
        q += np.square(np.asarray(d, np.float64)).sum(axis=1)
    n = min(len(q), max(MIN_REST, int(round(REST_SHARE * len(q)))))
    return np.sort(np.argsort(q, kind="stable")[:n])


def _kabsch(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation R and translation t minimising Σ w |R src + t − dst|²: src, dst (N,3), w (N,)."""
    w = w / w.sum()
    mu_s, mu_d = w @ src, w @ dst
    h = (src - mu_s).T @ ((dst - mu_d) * w[:, None])
    u, _, vt = np.linalg.svd(h)
    d = 1.0 if np.linalg.det(vt.T @ u.T) >= 0 else -1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, mu_d - mu_s @ r.T


def rigid_fit(frame: np.ndarray, neutral: np.ndarray, rest: np.ndarray) -> RigidMotion:
    """The rigid motion carrying ``neutral`` (V,3) onto ``frame`` (V,3) (one vertex order, one
    unit) on the ``rest`` vertices (R,) int: Kabsch's least squares, then up to ``ITERATIONS``
    passes weighting each rest vertex by Tukey's biweight of its residual (robust scale 1.4826 ×
    the median residual, at least ``SIGMA_FLOOR`` of the neutral's bounding-box diagonal)."""
    neutral = np.asarray(neutral, np.float64)
    frame = np.asarray(frame, np.float64)
    diag = float(np.linalg.norm(neutral.max(0) - neutral.min(0))) or 1.0
    ref, cur = neutral[rest], frame[rest]
    r, t = _kabsch(ref, cur, np.ones(len(ref)))
    for _ in range(ITERATIONS):
        res = np.linalg.norm(ref @ r.T + t - cur, axis=1)
        sigma = max(1.4826 * float(np.median(res)), SIGMA_FLOOR * diag)
        u = res / (TUKEY_C * sigma)
        w = np.where(u < 1.0, (1.0 - u * u) ** 2, 0.0)
        if w.sum() < 1e-9:
            break
        r_new, t_new = _kabsch(ref, cur, w)
        step = max(np.abs(r_new - r).max(), np.abs(t_new - t).max() / diag)
        r, t = r_new, t_new
        if step < 1e-12:
            break
    moved = float(np.linalg.norm(neutral @ r.T + t - neutral, axis=1).max()) / diag
    mismatch = float(np.median(np.linalg.norm((frame - t) @ r - neutral, axis=1))) / diag
    return RigidMotion(r, t, moved, mismatch)


def carry_motion(motion: RigidMotion, source, target, vertices: np.ndarray) -> np.ndarray:
    """A target's vertices (V,3) moved as the source's head moved: ``motion`` (the source's, in its
    own units) expressed in the source's canonical frame (``source``, a
    ``retarget.canonical.Canonicaliser``) and applied in the target's (``target``), so a turn
    about the source's face becomes the same turn about the target's face and a shift scales with
    the faces' sizes. -> (V,3) float64 in the target's units."""
    corners = np.vstack([np.zeros(3), np.eye(3)])                 # four canonical points
    moved = source.to_canonical(source.from_canonical(corners) @ motion.rotation.T + motion.translation)
    r, t = _kabsch(corners, moved, np.ones(4))                    # exact: a similarity's image
    return target.from_canonical(target.to_canonical(vertices) @ r.T + t)
