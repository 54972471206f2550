"""The triangle mesh object of the pipeline and its validation.

A :class:`Mesh` is a pair of arrays in the project frame (centimetres or the user's own units, +y up,
+z forward, +x = the character's left) plus a name (usually the file it came from). Treat the arrays
as immutable: derived quantities (vertex normals) are computed lazily and cached, trimesh style; use
:meth:`Mesh.copy` or build a new Mesh to change geometry.

:func:`as_mesh` is the one conversion of what users hold (a Mesh, a ``trimesh.Trimesh``, a
``(vertices, faces)`` pair) into a Mesh; every API call that takes a mesh goes through it.
"""
from __future__ import annotations

import sys
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


#: vertices closer than this share of the mesh's bounding-box diagonal count as one position when
#: parts are told apart (``mesh_parts``): a mesh split along its UV seams stays one part
WELD_TOLERANCE = 1e-6


def mesh_parts(vertices: np.ndarray, faces: np.ndarray, weld: bool = True) -> np.ndarray:
    """The connected part of each vertex: (V,) int64 labels 0..P-1, −1 for a vertex no face uses.
    vertices (V,3), faces (F,3) int. With ``weld``, vertices at one position (within
    ``WELD_TOLERANCE`` of the bounding-box diagonal) are joined, so pieces that only share
    positions, as a mesh split along its UV seams (every glTF file) is, count as one part."""
    import scipy.sparse
    from scipy.sparse.csgraph import connected_components

    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    n = len(v)
    used = np.zeros(n, bool)
    used[f.ravel()] = True

    def parts(node: np.ndarray) -> np.ndarray:      # node (V,): the graph node of each vertex
        edges = node[np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])]
        graph = scipy.sparse.coo_matrix((np.ones(len(edges), np.int8), (edges[:, 0], edges[:, 1])),
                                        shape=(n, n))
        labels = np.where(used, connected_components(graph, directed=False)[1][node], -1)
        _, dense = np.unique(labels[used], return_inverse=True)   # parts numbered 0..P-1
        labels[used] = dense.ravel()
        return labels.astype(np.int64)

    labels = parts(np.arange(n))
    if not weld or labels.max() < 1:
        return labels
    step = WELD_TOLERANCE * max(float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))), 1e-300)
    q = np.round(v / step).astype(np.int64)
    order = np.lexsort(q.T[::-1])                   # equal positions next to each other
    first = np.r_[True, (q[order][1:] != q[order][:-1]).any(axis=1)]
    node = np.empty(n, np.int64)
    node[order] = np.cumsum(first) - 1
    return parts(node)


def face_part(mesh: "Mesh") -> np.ndarray | None:
    """The vertices of the face of a mesh with separate parts (eyeballs, teeth, a tongue, lashes
    or a mouth bag beside the skin): the part (``mesh_parts``, welded) with the most vertices, as
    sorted indices (V',) int64 into ``mesh.vertices``; None when that part is every vertex (a mesh
    of one part, however it is split along its seams)."""
    labels = mesh_parts(mesh.vertices, mesh.faces)
    counts = np.bincount(labels[labels >= 0])
    if len(counts) == 1 and (labels >= 0).all():
        return None
    return np.flatnonzero(labels == int(np.argmax(counts)))


def submesh(mesh: "Mesh", index: np.ndarray) -> "Mesh":
    """The mesh of the vertices ``index`` (V',) int (sorted, unique) and the faces whose three
    corners are among them, re-indexed; vertex i of it is vertex index[i] of ``mesh``."""
    new = np.full(mesh.n_vertices, -1, np.int64)
    new[index] = np.arange(len(index))
    faces = new[mesh.faces]
    return Mesh(mesh.vertices[index], faces[(faces >= 0).all(axis=1)], mesh.name)


MESH_TYPES = "a retarget Mesh, a trimesh.Trimesh or a (vertices (V,3), faces (F,3)) pair"


def _is_trimesh(obj) -> bool:
    """Whether ``obj`` is a trimesh.Trimesh (without importing trimesh: a Trimesh implies it is)."""
    trimesh = sys.modules.get("trimesh")
    return trimesh is not None and isinstance(obj, trimesh.Trimesh)


def _pair(obj):
    """(vertices, faces) arrays if ``obj`` is a 2-item tuple/list of 2-D numeric arrays, else None."""
    if not isinstance(obj, (tuple, list)) or len(obj) != 2 or any(is_mesh_like(x) for x in obj):
        return None
    try:
        v, f = np.asarray(obj[0]), np.asarray(obj[1])
    except (ValueError, TypeError):  # ragged or not numbers
        return None
    if v.ndim != 2 or f.ndim != 2 or v.dtype.kind not in "iuf" or f.dtype.kind not in "iuf":
        return None
    return v, f


def is_mesh_like(obj) -> bool:
    """Whether :func:`as_mesh` takes ``obj`` as one mesh (not as a sequence of frames)."""
    return isinstance(obj, Mesh) or _is_trimesh(obj) or _pair(obj) is not None


def as_mesh(obj, name: str = "", role: str = "mesh") -> Mesh:
    """The pipeline's Mesh from what a user holds; every API call that takes a mesh uses this.

    - a :class:`Mesh`: returned as it is (not re-validated);
    - a ``trimesh.Trimesh``: its ``vertices`` and ``faces`` exactly as stored, vertex order kept
      (``process=False`` semantics: nothing merged or removed here; load files with
      ``trimesh.load_mesh(path, process=False, maintain_order=True)`` so that trimesh keeps the
      file's order too); named after its file (``metadata``) unless ``name`` is given;
    - a ``(vertices (V,3), faces (F,3))`` pair of arrays (or nested lists), faces integer-valued.

    Converted meshes are validated (:func:`check_mesh`). RetargetError naming ``role`` (e.g.
    "target", "source frame 3") for anything else: a trimesh.Scene or PointCloud, float faces,
    wrong shapes, another type.
    """
    if isinstance(obj, Mesh):
        return obj
    pair = None if _is_trimesh(obj) else _pair(obj)
    if _is_trimesh(obj):
        meta = getattr(obj, "metadata", None) or {}
        name = name or str(meta.get("file_path") or meta.get("file_name") or meta.get("name") or "")
        v, f = np.asarray(obj.vertices), np.asarray(obj.faces)
    elif pair is not None:
        v, f = pair
        if f.dtype.kind == "f":
            if not (np.isfinite(f).all() and (f == np.round(f)).all()):
                raise RetargetError(f"{name or role}: faces of a (vertices, faces) pair must be "
                                    f"integer vertex indices, got {f.dtype} values")
            f = f.astype(np.int64)
    else:
        module = type(obj).__module__.split(".")[0]
        kind = type(obj).__name__ if module == "builtins" else f"{module}.{type(obj).__name__}"
        hint = {"trimesh.Scene": " (trimesh.load_mesh(path, process=False, maintain_order=True) "
                                 "gives one Trimesh)",
                "trimesh.PointCloud": " (a point cloud has no faces)",
                "numpy.ndarray": " (vertices alone: pass (vertices, faces))"}.get(kind, "")
        raise RetargetError(f"{name or role}: expected {MESH_TYPES}, got {kind}{hint}")
    mesh = Mesh(v, f, name or role)  # its shape errors name the role
    mesh.name = name
    return check_mesh(mesh, name or role)


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
