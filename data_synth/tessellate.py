"""Tessellations of the (u, v) domain: regular, jittered and adaptive triangle meshes of the head.

Points are laid out in a *sampling space* s (the unit disc) and triangulated there; a map takes s
to the (u, v) disc: the identity for "regular"/"jittered"; for "adaptive" a polar warp
(rho, alpha) -> (R(rho), alpha - g(rho) sin(alpha)) where R' = 1 - k (bump at the face ring) +
k r (bump at the crown cap) compresses the ring of the face radially and g the front (alpha ~ 0)
azimuthally: up to (1-k)^-1 (1-g)^-1 = 4x denser at the face centre (the face gets about 1.5x the
vertices of a regular tessellation of the same size), sparser on the back of the head and the
crown. It is a diffeomorphism (triangular, R' > 0 and 1 - g cos(alpha) > 0); g fades to 0 at the
crown and at the neck cut, where R' is 1, so triangles stay near-isotropic there.
Hole boundaries (eye openings, mouth slit) and the face-crop boundary are sampled as vertex loops;
Delaunay triangles inside holes or outside the region are dropped, and boundary segments missing
from the triangulation are split until every boundary is a loop of mesh edges (conforming Delaunay).
Triangles are wound so that normals point out of the head in 3D.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay, cKDTree
from scipy.special import erf

from . import head
from .identity import mean_identity

KINDS = ("regular", "jittered", "adaptive")
REGIONS = ("full", "face")
ADAPTIVE_RADIAL_GAIN, ADAPTIVE_AZIMUTH_GAIN = 0.5, 0.5   # k and g of the adaptive warp
FACE_RING, CROWN_CAP = (0.55, 0.17), (0.12, 0.1)         # (centre, width) in rho
FACE_A_MAX = 1.25               # face crop: |a| < FACE_A_MAX, FACE_E_MIN < e < FACE_E_MAX (rad)
FACE_E_MIN, FACE_E_MAX = -1.0, 0.95
MIN_LOOP_POINTS = {"eye": 16, "mouth": 24}


@dataclass
class Tessellation:
    """A triangle mesh of the (u, v) domain: uv (V,2) float64, faces (F,3) int64, name str."""

    uv: np.ndarray
    faces: np.ndarray
    name: str

    @property
    def n_vertices(self) -> int:
        return len(self.uv)


def _bump_integral(rho, centre, width):
    """Integral from 0 to rho of exp(-((x - centre) / width)^2)."""
    return 0.5 * np.sqrt(np.pi) * width * (erf((rho - centre) / width) - erf(-centre / width))


def _radial(rho):
    """rho -> rho - k (B(rho) - r C(rho)): compress the face ring, expand the crown cap.

    B, C: integrals of Gaussian bumps at FACE_RING and CROWN_CAP; r makes _radial(1) = 1."""
    face = _bump_integral(rho, *FACE_RING)
    crown = _bump_integral(rho, *CROWN_CAP)
    r = _bump_integral(1.0, *FACE_RING) / _bump_integral(1.0, *CROWN_CAP)
    return rho - ADAPTIVE_RADIAL_GAIN * (face - r * crown)


def _azimuth_gain(rho):
    """g(rho): full between the crown cap and the neck, fading to 0 at both (smoothstep ramps)."""
    up = np.clip(rho / 0.35, 0.0, 1.0)
    down = np.clip((1.0 - rho) / 0.25, 0.0, 1.0)
    return ADAPTIVE_AZIMUTH_GAIN * up * up * (3.0 - 2.0 * up) * down * down * (3.0 - 2.0 * down)


def sampling_to_uv(s, kind):
    """(n,2) sampling-space points -> (n,2) disc coordinates."""
    s = np.asarray(s, dtype=np.float64)
    if kind != "adaptive":
        return s
    rho = np.hypot(s[..., 0], s[..., 1])
    alpha = np.arctan2(s[..., 0], s[..., 1])
    rho2 = _radial(rho)
    alpha2 = alpha - _azimuth_gain(rho) * np.sin(alpha)
    return np.stack([rho2 * np.sin(alpha2), rho2 * np.cos(alpha2)], -1)


def uv_to_sampling(uv, kind):
    """Inverse of `sampling_to_uv` (bisection in rho, Newton in alpha)."""
    uv = np.asarray(uv, dtype=np.float64)
    if kind != "adaptive":
        return uv
    target = np.hypot(uv[..., 0], uv[..., 1])
    alpha2 = np.arctan2(uv[..., 0], uv[..., 1])
    lo, hi = np.zeros_like(target), np.ones_like(target)
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        low = _radial(mid) < target
        lo, hi = np.where(low, mid, lo), np.where(low, hi, mid)
    rho = 0.5 * (lo + hi)
    g = _azimuth_gain(rho)
    alpha = alpha2.copy()
    for _ in range(12):
        alpha -= (alpha - g * np.sin(alpha) - alpha2) / (1.0 - g * np.cos(alpha))
    return np.stack([rho * np.sin(alpha), rho * np.cos(alpha)], -1)


def inside_region(uv, region, holes):
    """Boolean (n,): uv points that belong to the tessellated domain."""
    a, e = head.uv_to_template(uv)
    keep = np.hypot(uv[:, 0], uv[:, 1]) < 1.0
    if region == "face":
        keep &= (np.abs(a) < FACE_A_MAX) & (e > FACE_E_MIN) & (e < FACE_E_MAX)
    if holes:
        keep &= ~(head.in_eye_opening(a, e) | head.in_mouth_slit(a, e))
    return keep


def _loops_uv(region, holes):
    """Dense closed boundary polylines in uv: list of ((n,2) array, kind name)."""
    loops = []
    if region == "full":
        t = np.linspace(0.0, 2.0 * np.pi, 2000, endpoint=False)
        loops.append((np.stack([np.sin(t), np.cos(t)], -1), "outer"))
    else:
        n = 600
        a_lo, a_hi = -FACE_A_MAX, FACE_A_MAX
        e_lo, e_hi = FACE_E_MIN, FACE_E_MAX
        a = np.concatenate([np.linspace(a_lo, a_hi, n, endpoint=False), np.full(n, a_hi),
                            np.linspace(a_hi, a_lo, n, endpoint=False), np.full(n, a_lo)])
        e = np.concatenate([np.full(n, e_lo), np.linspace(e_lo, e_hi, n, endpoint=False),
                            np.full(n, e_hi), np.linspace(e_hi, e_lo, n, endpoint=False)])
        loops.append((head.template_to_uv(a, e), "outer"))
    if holes:
        for (a, e), kind in zip(head.hole_boundaries(), ("eye", "eye", "mouth")):
            loops.append((head.template_to_uv(a, e), kind))
    return loops


class _Loop:
    """A closed boundary curve in sampling space and the mesh vertices placed along it.

    curve (k,2) dense polyline; arc (k+1,) cumulative length; t (n,) arc positions of the
    boundary vertices (sorted) and index (n,) their vertex indices; is_outer.
    """

    def __init__(self, curve, is_outer):
        closed = np.vstack([curve, curve[:1]])
        self.curve = closed
        self.arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
        self.is_outer = is_outer
        self.t = np.zeros(0)
        self.index = np.zeros(0, dtype=np.int64)

    @property
    def length(self):
        return self.arc[-1]

    def at(self, t):
        """Points (n,2) at arc positions t (n,)."""
        t = np.mod(t, self.length)
        return np.stack([np.interp(t, self.arc, self.curve[:, k]) for k in range(2)], -1)

    def segments(self):
        """(n,2) vertex index pairs of consecutive boundary vertices."""
        return np.stack([self.index, np.roll(self.index, -1)], -1)

    def polygon(self, points):
        return points[self.index]

    def split(self, pairs, first_new_index):
        """Insert a vertex on the curve half-way (in arc length) along each segment in pairs (m,2).

        Returns the new points (m,2)."""
        pos = {int(v): t for v, t in zip(self.index, self.t)}
        t0 = np.array([pos[int(i)] for i in pairs[:, 0]])
        t1 = np.array([pos[int(j)] for j in pairs[:, 1]])
        t1 = np.where(t1 <= t0, t1 + self.length, t1)
        t_new = np.mod(0.5 * (t0 + t1), self.length)
        self.t = np.concatenate([self.t, t_new])
        self.index = np.concatenate([self.index, first_new_index + np.arange(len(pairs))])
        order = np.argsort(self.t)
        self.t, self.index = self.t[order], self.index[order]
        return self.at(t_new)


def _lattice(h, rng, jitter):
    """Triangular lattice points (n,2) with spacing h covering the unit disc, optionally jittered."""
    dy = h * np.sqrt(3.0) / 2.0
    ys = np.arange(-1.0 - dy, 1.0 + dy, dy)
    rows = []
    for i, y in enumerate(ys):
        xs = np.arange(-1.0 - h, 1.0 + h, h) + (0.5 * h if i % 2 else 0.0)
        rows.append(np.stack([xs, np.full_like(xs, y)], -1))
    pts = np.vstack(rows)
    if jitter:
        pts = pts + rng.uniform(-0.3 * h, 0.3 * h, size=pts.shape)
    return pts


def _layout(h, kind, region, holes, rng):
    """Lattice + boundary points in sampling space: returns (points (n,2), loops [_Loop])."""
    lattice = _lattice(h, rng, kind == "jittered")
    lattice = lattice[inside_region(sampling_to_uv(lattice, kind), region, holes)]
    loops, boundary = [], []
    offset = 0
    for loop_uv, loop_kind in _loops_uv(region, holes):
        loop = _Loop(uv_to_sampling(loop_uv, kind), loop_kind == "outer")
        n = max(MIN_LOOP_POINTS.get(loop_kind, 8), int(np.ceil(loop.length / h)))
        loop.t = np.linspace(0.0, loop.length, n, endpoint=False)
        loop.index = offset + np.arange(n)
        boundary.append(loop.at(loop.t))
        loops.append(loop)
        offset += n
    boundary = np.vstack(boundary)
    # keep lattice points away from boundaries (no slivers)
    dist, _ = cKDTree(boundary).query(lattice)
    return np.vstack([boundary, lattice[dist >= 0.55 * h]]), loops


def _inside_polygon(points, polygon):
    """Even-odd test: boolean (n,) for points (n,2) inside a closed polygon (m,2)."""
    inside = np.zeros(len(points), dtype=bool)
    x, y = points[:, 0], points[:, 1]
    lo, hi = polygon.min(axis=0), polygon.max(axis=0)
    cand = np.flatnonzero((x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1]))
    xc, yc = x[cand], y[cand]
    for (x0, y0), (x1, y1) in zip(polygon, np.roll(polygon, -1, axis=0)):
        crosses = (y0 > yc) != (y1 > yc)
        x_at = x0 + (yc - y0) * (x1 - x0) / np.where(y1 != y0, y1 - y0, 1.0)
        inside[cand] ^= crosses & (xc < x_at)
    return inside


def _kept_faces(points, faces, loops):
    """Faces whose centroid is inside the outer loop and outside every hole loop."""
    centroids = points[faces].mean(axis=1)
    keep = np.ones(len(faces), dtype=bool)
    for loop in loops:
        inside = _inside_polygon(centroids, loop.polygon(points))
        keep &= inside if loop.is_outer else ~inside
    return faces[keep]


def _triangulate(points, loops, max_rounds=12):
    """Conforming Delaunay in sampling space; returns (points, faces) with holes/outside removed.

    Boundary segments missing from the triangulation are split by a new vertex on the boundary
    curve until every loop is a chain of mesh edges.
    """
    for _ in range(max_rounds):
        faces = _kept_faces(points, Delaunay(points).simplices, loops)
        edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        edge_keys = set(map(tuple, edges))
        done = True
        for loop in loops:
            seg = loop.segments()
            missing = np.array([tuple(sorted(sg)) not in edge_keys for sg in seg])
            if missing.any():
                done = False
                points = np.vstack([points, loop.split(seg[missing], len(points))])
        if done:
            return points, faces
    raise ValueError("tessellate: boundary recovery did not converge; try another n_vertices")


def _orient_outward(uv, faces):
    """Flip the winding of all faces if their 3D normals point into the head (mean identity)."""
    p = head.surface(uv, mean_identity())
    n = np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])
    outward = np.sum(n * (p[faces].mean(axis=1) - head.STAR_CENTRE), axis=1)
    return faces if np.sum(outward > 0) >= np.sum(outward < 0) else faces[:, ::-1].copy()


def _region_area(kind, region, holes):
    """Area of the tessellated region in sampling space (Monte Carlo on a fine lattice)."""
    s = _lattice(0.01, None, False)
    s = s[np.hypot(s[:, 0], s[:, 1]) < 1.0]
    frac = np.mean(inside_region(sampling_to_uv(s, kind), region, holes))
    return np.pi * frac


def tessellate(n_vertices=5000, kind="regular", region="full", holes=True, seed=0) -> Tessellation:
    """Triangulate the (u, v) domain with about `n_vertices` vertices (within ~10 %).

    kind: "regular" (triangular lattice), "jittered" (lattice moved by up to 0.3 spacing, seeded),
    "adaptive" (lattice through the adaptive warp: the face gets ~1.5x the vertices it gets from
    "regular" at the same n_vertices).
    region: "full" head or "face" crop; holes: cut the eye openings and the mouth slit.
    Returns Tessellation(uv (V,2) float64, faces (F,3) int64, name).
    """
    if kind not in KINDS:
        raise ValueError(f"tessellate: kind must be one of {KINDS}, got {kind!r}")
    if region not in REGIONS:
        raise ValueError(f"tessellate: region must be one of {REGIONS}, got {region!r}")
    if not 100 <= int(n_vertices) <= 2_000_000:
        raise ValueError(f"tessellate: n_vertices must be in [100, 2e6], got {n_vertices}")
    area = _region_area(kind, region, holes)
    h = np.sqrt(2.0 * area / (np.sqrt(3.0) * n_vertices))
    for _ in range(3):   # correct the spacing for boundary points and clipping
        points, loops = _layout(h, kind, region, holes, np.random.default_rng(seed))
        ratio = len(points) / n_vertices
        if abs(ratio - 1.0) < 0.04:
            break
        h *= np.sqrt(ratio)
    points, faces = _triangulate(points, loops)
    used = np.unique(faces)
    remap = np.full(len(points), -1)
    remap[used] = np.arange(len(used))
    uv = sampling_to_uv(points[used], kind)
    faces = _orient_outward(uv, remap[faces].astype(np.int64))
    name = f"{kind}-{region}-{'holes' if holes else 'closed'}-{len(uv)}-s{seed}"
    return Tessellation(uv=uv, faces=faces, name=name)
