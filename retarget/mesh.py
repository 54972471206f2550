"""The triangle mesh object of the pipeline and its validation.

A :class:`Mesh` is a pair of arrays in the project frame (centimetres or the user's own units, +y up,
+z forward, +x = the character's left) plus a name (usually the file it came from). Treat the arrays
as immutable: derived quantities (vertex normals) are computed lazily and cached, trimesh style; use
:meth:`Mesh.copy` or build a new Mesh to change geometry.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from nets.geometry import vertex_normals  # noqa: F401  (one implementation, re-exported)

from .errors import RetargetError

MAX_COORDINATE = 1e15       # any unit: 1e15 nm is 1000 km
COLLINEAR_TOLERANCE = 1e-5  # relative spread across the line under which a mesh is a line


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Triangle areas: vertices (V,3), faces (F,3) -> (F,) float64 in squared input units."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    return 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)


@dataclass(eq=False)
class Mesh:
    """A triangle mesh.

    vertices: (V,3) float64, in the input's units (the pipeline maps results back to them).
    faces: (F,3) int64 vertex indices, counter-clockwise seen from outside.
    name: where it came from (a file path) — used in error messages.
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = ""

    def __post_init__(self):
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int64)
        if self.faces.size == 0:
            self.faces = self.faces.reshape(0, 3)
        if self.vertices.size == 0:
            self.vertices = self.vertices.reshape(0, 3)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise RetargetError(f"{self.name or 'mesh'}: vertices must be (V,3), got {self.vertices.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise RetargetError(f"{self.name or 'mesh'}: faces must be (F,3) triangles, got {self.faces.shape}")

    @property
    def n_vertices(self) -> int:
        """V, the number of vertices."""
        return len(self.vertices)

    @cached_property
    def vertex_normals(self) -> np.ndarray:
        """(V,3) float64 area-weighted unit vertex normals (computed once, cached)."""
        return vertex_normals(self.vertices, self.faces)

    def copy(self) -> "Mesh":
        """A deep copy (fresh arrays, no cached normals)."""
        return Mesh(self.vertices.copy(), self.faces.copy(), self.name)


def check_mesh(mesh: Mesh, path=None) -> Mesh:
    """Validate a mesh for the pipeline; return it unchanged or raise RetargetError.

    Refused, each with one line naming ``path`` (default ``mesh.name``): no vertices, non-finite
    coordinates or coordinates beyond ``MAX_COORDINATE`` (their squares would overflow), no faces
    (a point cloud), face indices out of range, every face degenerate (zero area relative to the mesh
    size), or all vertices on one line up to rounding (the second principal spread of the used
    vertices below ``COLLINEAR_TOLERANCE`` times the first: a relative test, which file rounding
    noise does not pass). Individual degenerate faces are allowed.
    """
    where = str(path if path is not None else (mesh.name or "mesh"))
    v, f = mesh.vertices, mesh.faces
    if len(v) == 0:
        raise RetargetError(f"{where}: the mesh is empty (no vertices)")
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise RetargetError(
            f"{where}: {int(bad.sum())} vertices have NaN/inf coordinates (first: vertex {int(np.argmax(bad))})"
        )
    huge = (np.abs(v) > MAX_COORDINATE).any(axis=1)
    if huge.any():
        raise RetargetError(f"{where}: {int(huge.sum())} vertices have coordinates beyond ±{MAX_COORDINATE:g} "
                            f"(first: vertex {int(np.argmax(huge))}); check the file's units")
    if len(f) == 0:
        raise RetargetError(f"{where}: is a point cloud (no faces); a triangle mesh is needed")
    if f.min() < 0 or f.max() >= len(v):
        raise RetargetError(
            f"{where}: face index out of range (indices {int(f.min())}..{int(f.max())}, "
            f"but only {len(v)} vertices)"
        )
    diag = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    if not (face_areas(v, f) > 1e-12 * diag * diag).any():
        raise RetargetError(f"{where}: all {len(f)} faces are degenerate (zero area)")
    mask = np.zeros(len(v), bool)
    mask[f.ravel()] = True
    used = v[mask]
    spread = np.linalg.eigvalsh(np.cov(used - used.mean(axis=0), rowvar=False))  # ascending, σ²
    if spread[1] <= (COLLINEAR_TOLERANCE ** 2) * spread[2]:
        raise RetargetError(f"{where}: all {len(f)} faces are degenerate (the vertices lie on a line, "
                            "up to rounding)")
    return mesh
