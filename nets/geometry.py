"""Precomputed surface operators for DiffusionNet (Sharp, Attaiki, Crane, Ovsjanikov 2022).

For a mesh (or a point cloud) we prepare, once, everything DiffusionNet needs:

- ``mass``   (V,)    lumped (Voronoi-like) vertex areas M, in squared input units;
- ``L``      (V,V)   the (positive semi-definite, weak-form) cotangent Laplacian, scipy csr, from
  ``robust_laplacian`` (intrinsic Delaunay / tufted cover, so non-manifold meshes and point clouds work);
- ``evals``  (k,), ``evecs`` (V,k): the k smallest generalised eigenpairs of ``L x = lambda M x``,
  M-orthonormal (``evecs.T @ (mass[:, None] * evecs) = I``); evals in inverse squared input units;
- ``frames`` (V,3,3): per-vertex orthonormal frame, rows = (tangent X, tangent Y, normal);
- ``gradX``, ``gradY`` (V,V) csr: the tangent-plane gradient of a per-vertex scalar field, expressed in
  each vertex's (X, Y) frame, by local least squares over the one-ring edges projected to the tangent
  plane (k nearest neighbours for point clouds). Units: 1 / input length unit.

The maths runs in float64; the stored arrays are float32 (csr matrices included).

Operators are intrinsic up to the tangent frames, which DiffusionNet's gradient features do not depend
on. An expression mesh may therefore reuse the operators of its neutral mesh (the NFS authors do this):
the caller simply passes the neutral's :class:`Operators` / :class:`TorchOperators`.

``load_or_compute_operators`` caches by content hash on disk (``$RETARGET_CACHE`` or
``~/.cache/retarget/operators``) and in a small in-process LRU. The disk cache is optional: it is
kept under ``$RETARGET_CACHE_MAX_MB`` megabytes (default 2048; least recently used entries go
first), switched off by ``RETARGET_NO_CACHE=1``, and a folder that cannot be written is skipped
with one :class:`CacheWarning` (the operators are then computed each time).

Run ``python -m nets.geometry`` for the preparation-cost benchmark (:func:`benchmark_operators`).
"""
from __future__ import annotations

import hashlib
import os
import resource
import tempfile
import time
import tracemalloc
import warnings
import zipfile
from collections import OrderedDict
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import robust_laplacian
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg
import torch
from scipy.spatial import cKDTree

#: Bumped whenever the computation changes, so stale disk-cache entries are never reused.
OPERATORS_VERSION = "nets.geometry/2"
#: Neighbours used by the point-cloud Laplacian and for point-cloud gradients and normals.
POINT_CLOUD_NEIGHBOURS = 30
#: Below this vertex count the generalised eigenproblem is solved densely (robust, and cheap).
DENSE_EIG_MAX_VERTICES = 600
#: Initial diagonal shift eps (relative to the mean mass) in ``(L + eps M) x = (lambda + eps) M x``.
EIG_SHIFT = 1e-8
#: How many times the shift is multiplied by 10 and the sparse solve retried before giving up.
EIG_RETRIES = 4
#: Entries of the in-process LRU of :func:`load_or_compute_operators`.
MEMORY_CACHE_SIZE = 8
#: Default size limit of the disk cache, megabytes (``$RETARGET_CACHE_MAX_MB``).
DISK_CACHE_MAX_MB = 2048
#: A cache temporary file older than this (seconds) was left by a killed writer and is removed.
STALE_TMP_SECONDS = 3600.0


class CacheWarning(UserWarning):
    """The disk cache of operators could not be used (the job goes on without it)."""


_MEMORY_CACHE: "OrderedDict[str, Operators]" = OrderedDict()
#: Cache folders found unwritable in this process (warned about once, then skipped).
_UNWRITABLE: set = set()


@dataclass(frozen=True)
class TorchOperators:
    """:class:`Operators` as torch tensors on one device, in one float dtype.

    mass (V,), evals (k,), evecs (V,k), frames (V,3,3) are dense; L, gradX, gradY (V,V) are sparse
    CSR tensors (on the CPU, CSR ``sparse @ dense`` forward+backward is ~1.7x faster than COO).
    grad_xy (2V,V) = [gradX; gradY] and its transpose grad_xy_t (V,2V), both CSR, give the two
    gradients in one product whose backward needs no transposition (``sparse_matmul``); None when
    built by hand, then gradX and gradY are used.
    """

    mass: torch.Tensor
    L: torch.Tensor
    evals: torch.Tensor
    evecs: torch.Tensor
    gradX: torch.Tensor
    gradY: torch.Tensor
    frames: torch.Tensor
    grad_xy: torch.Tensor | None = None
    grad_xy_t: torch.Tensor | None = None

    @property
    def n_vertices(self) -> int:
        return int(self.mass.shape[0])

    def to(self, device) -> "TorchOperators":
        """The same operators on ``device``."""
        return TorchOperators(**{f.name: None if getattr(self, f.name) is None
                                 else getattr(self, f.name).to(device) for f in fields(self)})


@dataclass(frozen=True)
class Operators:
    """Precomputed operators of one surface (numpy / scipy, float32). See the module docstring."""

    mass: np.ndarray
    L: scipy.sparse.csr_matrix
    evals: np.ndarray
    evecs: np.ndarray
    gradX: scipy.sparse.csr_matrix
    gradY: scipy.sparse.csr_matrix
    frames: np.ndarray

    @property
    def n_vertices(self) -> int:
        return int(self.mass.shape[0])

    @property
    def k(self) -> int:
        return int(self.evals.shape[0])

    def to_torch(self, device="cpu", dtype: torch.dtype = torch.float32) -> TorchOperators:
        """Torch copies on ``device`` in ``dtype`` (sparse matrices as CSR tensors)."""

        def dense(a: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(np.ascontiguousarray(a)).to(device=device, dtype=dtype)

        def sparse(m: scipy.sparse.csr_matrix) -> torch.Tensor:
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message="Sparse CSR tensor support is in beta")
                return torch.sparse_csr_tensor(
                    torch.as_tensor(m.indptr.astype(np.int64)),
                    torch.as_tensor(m.indices.astype(np.int64)),
                    torch.as_tensor(m.data),
                    size=m.shape,
                    check_invariants=False,
                ).to(device=device, dtype=dtype)

        stacked = scipy.sparse.vstack([self.gradX, self.gradY], format="csr")
        return TorchOperators(
            mass=dense(self.mass),
            L=sparse(self.L),
            evals=dense(self.evals),
            evecs=dense(self.evecs),
            gradX=sparse(self.gradX),
            gradY=sparse(self.gradY),
            frames=dense(self.frames),
            grad_xy=sparse(stacked),
            grad_xy_t=sparse(stacked.T.tocsr()),
        )


# ----------------------------------------------------------------------------------------------
# The individual operators (float64 in, float64 out)
# ----------------------------------------------------------------------------------------------


def _has_faces(faces) -> bool:
    return faces is not None and np.asarray(faces).size > 0


def laplacian_and_mass(verts: np.ndarray, faces: np.ndarray | None):
    """Cotangent Laplacian and lumped mass.

    verts (V,3) float64; faces (F,3) int or None/empty for a point cloud.
    Returns L (V,V) csr float64 (positive semi-definite, rows sum to 0) and mass (V,) float64 > 0.
    Vertices referenced by no face get a tiny mass from robust_laplacian's mollification; the mass is
    floored at 1e-8 x its mean so the generalised eigenproblem stays well posed.
    """
    if _has_faces(faces):
        L, M = robust_laplacian.mesh_laplacian(verts, np.asarray(faces, dtype=np.int64))
    else:
        n_neighbours = min(POINT_CLOUD_NEIGHBOURS, len(verts) - 1)
        L, M = robust_laplacian.point_cloud_laplacian(verts, n_neighbors=n_neighbours)
    mass = np.asarray(M.diagonal(), dtype=np.float64)
    mass = np.maximum(mass, 1e-8 * mass.mean())
    return scipy.sparse.csr_matrix(L, dtype=np.float64), mass


def eigen_decomposition(L: scipy.sparse.spmatrix, mass: np.ndarray, k: int, name: str = "mesh"):
    """The k smallest eigenpairs of ``L x = lambda M x`` (M = diag(mass)).

    L (V,V) sparse float64, mass (V,) float64. k is capped at V-2. Returns evals (k,) float64 >= 0
    (ascending; tiny negatives clamped to 0) and evecs (V,k) float64, M-orthonormal.
    Small problems (V <= DENSE_EIG_MAX_VERTICES) are solved densely; larger ones with ARPACK
    shift-invert around 0 on ``L + eps M``, retrying with eps x 10 on failure. ARPACK starts
    from a fixed vector (seeded by V), so one mesh gets the same eigenpairs whatever ran before
    in the process (its own default start draws from a generator that calls advance).
    Raises ValueError naming ``name`` if no attempt converges.
    """
    n = L.shape[0]
    k = max(0, min(int(k), n - 2))
    if k == 0:
        return np.zeros(0), np.zeros((n, 0))
    M = scipy.sparse.diags(mass)
    eps = EIG_SHIFT * float(mass.mean())
    errors = []
    v0 = np.random.default_rng(n).standard_normal(n) if n > DENSE_EIG_MAX_VERTICES else None
    for _ in range(EIG_RETRIES + 1):
        shifted = (L + eps * M).tocsc()
        try:
            if n <= DENSE_EIG_MAX_VERTICES:
                evals, evecs = scipy.linalg.eigh(shifted.toarray(), M.toarray(), subset_by_index=(0, k - 1))
            else:
                evals, evecs = scipy.sparse.linalg.eigsh(shifted, k=k, M=M.tocsc(), sigma=0.0, which="LM", v0=v0)
        except (RuntimeError, ValueError, np.linalg.LinAlgError,
                scipy.sparse.linalg.ArpackError, scipy.sparse.linalg.ArpackNoConvergence) as exc:
            errors.append(f"shift {eps:.1e}: {exc}")
            eps *= 10.0
            continue
        order = np.argsort(evals)
        evals = np.clip(evals[order] - eps, 0.0, None)
        return evals, evecs[:, order]
    raise ValueError(
        f"{name}: the Laplacian eigendecomposition (V={n}, k={k}) failed for every shift tried "
        f"({'; '.join(errors)}); the mesh is probably degenerate (zero-area faces, duplicate vertices)"
    )


def _neighbour_pairs(verts: np.ndarray, faces: np.ndarray | None):
    """Directed neighbour pairs (i, j), i != j, each once: one-ring edges, or kNN for point clouds."""
    if _has_faces(faces):
        faces = np.asarray(faces, dtype=np.int64)
        i = faces.ravel()
        j = np.roll(faces, -1, axis=1).ravel()
        pairs = np.concatenate([np.stack([i, j], 1), np.stack([j, i], 1)])
    else:
        n_neighbours = min(POINT_CLOUD_NEIGHBOURS, len(verts) - 1)
        _, nn = cKDTree(verts).query(verts, k=n_neighbours + 1)
        pairs = np.stack([np.repeat(np.arange(len(verts)), n_neighbours), nn[:, 1:].ravel()], 1)
    pairs = np.unique(pairs[pairs[:, 0] != pairs[:, 1]], axis=0)
    return pairs[:, 0], pairs[:, 1]


def vertex_normals(verts: np.ndarray, faces: np.ndarray | None) -> np.ndarray:
    """Unit vertex normals (V,3) float64.

    Meshes: area-weighted sum of face normals (orientation follows the winding). Vertices without
    a usable face normal (isolated, or point clouds) get the smallest principal axis of their
    POINT_CLOUD_NEIGHBOURS nearest neighbours (sign arbitrary).
    """
    normals = np.zeros_like(verts)
    if _has_faces(faces):
        faces = np.asarray(faces, dtype=np.int64)
        tri = verts[faces]
        face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 x area
        for k in range(3):  # bincount: far faster than np.add.at on large meshes
            normals[:, k] = np.bincount(faces.ravel(), weights=np.repeat(face_n[:, k], 3),
                                        minlength=len(verts))
    length = np.linalg.norm(normals, axis=1)
    missing = length <= 1e-12 * max(float(length.max(initial=0.0)), 1e-300)
    if missing.any():
        n_neighbours = min(POINT_CLOUD_NEIGHBOURS, len(verts) - 1) + 1
        _, nn = cKDTree(verts).query(verts[missing], k=n_neighbours)
        local = verts[nn] - verts[nn].mean(axis=1, keepdims=True)
        _, _, vt = np.linalg.svd(local, full_matrices=False)
        normals[missing] = vt[:, -1]
        length[missing] = 1.0
    return normals / length[:, None]


def tangent_frames(normals: np.ndarray) -> np.ndarray:
    """Per-vertex orthonormal frames (V,3,3): rows (X, Y, n), X and Y spanning the tangent plane.

    X is the projection of whichever world axis is least aligned with n; Y = n x X (right-handed).
    """
    axes = np.eye(3)[np.argmin(np.abs(normals), axis=1)]
    x = axes - np.sum(axes * normals, axis=1, keepdims=True) * normals
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(normals, x)
    return np.stack([x, y, normals], axis=1)


def gradient_operators(verts: np.ndarray, faces: np.ndarray | None, frames: np.ndarray,
                       regulariser: float = 1e-6):
    """Tangent-plane gradient operators gradX, gradY (V,V) csr float64.

    For vertex i with neighbours j, the edge vectors e_ij = p_j - p_i are projected to the tangent
    plane, giving 2D vectors d_ij = (e_ij . X_i, e_ij . Y_i). The gradient g_i (2,) of a scalar field
    f minimises sum_j (d_ij . g_i - (f_j - f_i))^2 + lambda |g_i|^2, i.e.
    g_i = (D^T D + lambda I)^-1 D^T (f_N - f_i), with lambda = ``regulariser`` x trace(D^T D) / 2.
    Exact for fields linear in the tangent plane. Vertices with no neighbours get zero rows.
    """
    n = len(verts)
    i, j = _neighbour_pairs(verts, faces)
    edges = verts[j] - verts[i]
    d = np.stack([np.sum(edges * frames[i, 0], axis=1), np.sum(edges * frames[i, 1], axis=1)], axis=1)
    gram = np.zeros((n, 2, 2))
    np.add.at(gram, i, d[:, :, None] * d[:, None, :])
    trace = gram[:, 0, 0] + gram[:, 1, 1]
    gram += (regulariser * 0.5 * trace + 1e-300)[:, None, None] * np.eye(2)
    coeff = np.einsum("eab,eb->ea", np.linalg.inv(gram)[i], d)  # (E,2): weight of f_j - f_i
    rows = np.concatenate([i, i])

    def assemble(c: np.ndarray) -> scipy.sparse.csr_matrix:
        return scipy.sparse.csr_matrix((np.concatenate([c, -c]), (rows, np.concatenate([j, i]))), shape=(n, n))

    return assemble(coeff[:, 0]), assemble(coeff[:, 1])


# ----------------------------------------------------------------------------------------------
# Public entry points
# ----------------------------------------------------------------------------------------------


def _validated(verts, faces, name: str):
    verts = np.asarray(verts, dtype=np.float64)
    if verts.ndim != 2 or verts.shape[1] != 3 or len(verts) < 3:
        raise ValueError(f"{name}: vertices must have shape (V>=3, 3), got {verts.shape}")
    if not np.isfinite(verts).all():
        raise ValueError(f"{name}: vertices contain NaN or infinite coordinates")
    if _has_faces(faces):
        faces = np.asarray(faces, dtype=np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise ValueError(f"{name}: faces must have shape (F,3) (triangles), got {faces.shape}")
        if faces.min() < 0 or faces.max() >= len(verts):
            raise ValueError(f"{name}: face indices outside [0, {len(verts)})")
    else:
        faces = None
    return verts, faces


def compute_operators(verts, faces, k: int = 64, name: str = "mesh") -> Operators:
    """All DiffusionNet operators of a mesh or point cloud.

    verts (V,3) (any float dtype, any length unit), faces (F,3) int triangles, or None / empty for a
    point cloud. k: number of eigenpairs, capped at V-2. ``name`` is used in error messages.
    Returns :class:`Operators` (float32). Raises ValueError on malformed input or when the
    eigensolver fails.
    """
    verts, faces = _validated(verts, faces, name)
    L, mass = laplacian_and_mass(verts, faces)
    evals, evecs = eigen_decomposition(L, mass, k, name)
    frames = tangent_frames(vertex_normals(verts, faces))
    grad_x, grad_y = gradient_operators(verts, faces, frames)
    f32 = np.float32
    return Operators(
        mass=mass.astype(f32),
        L=L.astype(f32),
        evals=evals.astype(f32),
        evecs=evecs.astype(f32),
        gradX=grad_x.astype(f32),
        gradY=grad_y.astype(f32),
        frames=frames.astype(f32),
    )


def default_cache_dir() -> Path:
    """``$RETARGET_CACHE`` (if set) or ``~/.cache/retarget/operators``."""
    env = os.environ.get("RETARGET_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "retarget" / "operators"


def disk_cache_enabled() -> bool:
    """False when ``$RETARGET_NO_CACHE`` is set to anything but "" or "0"."""
    return os.environ.get("RETARGET_NO_CACHE", "") in ("", "0")


def disk_cache_max_bytes() -> int:
    """``$RETARGET_CACHE_MAX_MB`` (default DISK_CACHE_MAX_MB) in bytes; a value that is not a
    number >= 0 gives a CacheWarning and the default."""
    env = os.environ.get("RETARGET_CACHE_MAX_MB", "")
    try:
        mb = float(env) if env else DISK_CACHE_MAX_MB
        if not mb >= 0 or mb == float("inf"):
            raise ValueError
    except ValueError:
        warnings.warn(f"RETARGET_CACHE_MAX_MB={env[:40]!r} is not a number of megabytes >= 0; using "
                      f"{DISK_CACHE_MAX_MB}", CacheWarning, stacklevel=3)
        mb = DISK_CACHE_MAX_MB
    return int(mb * 2**20)


def prune_cache(folder: Path, max_bytes: int, keep: Path | None = None) -> None:
    """Delete the least recently used ``*.npz`` entries of ``folder`` (by modification time, which a
    cache hit refreshes) until they total at most ``max_bytes`` (``keep`` is never deleted), and
    temporary files older than STALE_TMP_SECONDS (left by a killed writer)."""
    now, entries = time.time(), []
    for p in folder.iterdir():
        try:
            st = p.stat()
        except OSError:
            continue
        if p.suffix == ".tmp" and now - st.st_mtime > STALE_TMP_SECONDS:
            p.unlink(missing_ok=True)
        elif p.suffix == ".npz":
            entries.append((st.st_mtime, st.st_size, p))
    total = sum(size for _, size, _ in entries)
    for _, size, p in sorted(entries, key=lambda e: e[0]):
        if total <= max_bytes:
            break
        if p != keep:
            p.unlink(missing_ok=True)
            total -= size


def operators_key(verts, faces, k: int) -> str:
    """sha256 hex digest of (verts as float32, faces as int64, k, OPERATORS_VERSION)."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(verts, dtype=np.float32).tobytes())
    h.update(np.asarray(verts).shape.__repr__().encode())
    faces_bytes = b"" if not _has_faces(faces) else np.ascontiguousarray(faces, dtype=np.int64).tobytes()
    h.update(faces_bytes)
    h.update(f"k={int(k)};{OPERATORS_VERSION}".encode())
    return h.hexdigest()


_SPARSE_FIELDS = ("L", "gradX", "gradY")


def _save(ops: Operators, path: Path) -> None:
    """Write ``ops`` to ``path`` (npz) atomically: temp file in the same folder, then os.replace."""
    arrays = {}
    for f in fields(ops):
        value = getattr(ops, f.name)
        if f.name in _SPARSE_FIELDS:
            arrays.update({f"{f.name}_data": value.data, f"{f.name}_indices": value.indices,
                           f"{f.name}_indptr": value.indptr, f"{f.name}_shape": np.asarray(value.shape)})
        else:
            arrays[f.name] = value
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _load(path: Path, n_vertices: int) -> Operators:
    """Read an entry written by :func:`_save`; raises ValueError if it is unreadable or inconsistent."""
    try:
        with np.load(path, allow_pickle=False) as z:
            values = {}
            for f in fields(Operators):
                if f.name in _SPARSE_FIELDS:
                    values[f.name] = scipy.sparse.csr_matrix(
                        (z[f"{f.name}_data"], z[f"{f.name}_indices"], z[f"{f.name}_indptr"]),
                        shape=tuple(z[f"{f.name}_shape"]))
                else:
                    values[f.name] = z[f.name]
    except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: unreadable operator cache entry ({exc})") from exc
    ops = Operators(**values)
    if ops.mass.shape != (n_vertices,) or ops.evecs.shape != (n_vertices, ops.k) or ops.L.shape != (n_vertices,) * 2:
        raise ValueError(f"{path}: operator cache entry does not match the mesh ({n_vertices} vertices)")
    return ops


def load_or_compute_operators(verts, faces, k: int = 64, cache_dir=None, name: str = "mesh") -> Operators:
    """:func:`compute_operators`, memoised in a small in-process LRU and on disk.

    The key is :func:`operators_key`. cache_dir: folder for ``<key>.npz`` files, default
    :func:`default_cache_dir`. A missing or corrupt file is (re)computed and rewritten atomically, so
    several processes may fill the same entry concurrently. After a write the folder is pruned to
    :func:`disk_cache_max_bytes`; with ``RETARGET_NO_CACHE`` set the disk is not used, and a folder
    that cannot be written gives a CacheWarning (once per folder) and no disk cache.
    """
    key = operators_key(verts, faces, k)
    if key in _MEMORY_CACHE:
        _MEMORY_CACHE.move_to_end(key)
        return _MEMORY_CACHE[key]
    folder = Path(cache_dir if cache_dir is not None else default_cache_dir())
    path = folder / f"{key}.npz"
    use_disk = disk_cache_enabled() and folder not in _UNWRITABLE
    ops = None
    if use_disk and path.is_file():
        try:
            ops = _load(path, len(verts))
            os.utime(path)  # recently used: pruned last
        except (ValueError, OSError):
            ops = None
    if ops is None:
        ops = compute_operators(verts, faces, k, name=name)
        if use_disk:
            try:
                _save(ops, path)
                prune_cache(folder, disk_cache_max_bytes(), keep=path)
            except OSError as exc:
                _UNWRITABLE.add(folder)
                warnings.warn(f"operator cache {folder} cannot be written ({exc.strerror or exc}); "
                              "going on without it (set RETARGET_CACHE to another folder, or "
                              "RETARGET_NO_CACHE=1)", CacheWarning, stacklevel=2)
    _MEMORY_CACHE[key] = ops
    while len(_MEMORY_CACHE) > MEMORY_CACHE_SIZE:
        _MEMORY_CACHE.popitem(last=False)
    return ops


def clear_memory_cache() -> None:
    """Empty the in-process LRU of :func:`load_or_compute_operators` (the disk cache is untouched)."""
    _MEMORY_CACHE.clear()


# ----------------------------------------------------------------------------------------------
# Benchmark
# ----------------------------------------------------------------------------------------------


def _bumpy_grid(n_vertices: int):
    """A wavy square height field with about ``n_vertices`` vertices: verts (V,3), faces (F,3)."""
    m = max(2, int(round(np.sqrt(n_vertices))))
    u, v = np.meshgrid(np.linspace(0, 1, m), np.linspace(0, 1, m), indexing="ij")
    verts = np.stack([u, v, 0.05 * np.sin(6 * u) * np.cos(5 * v)], -1).reshape(-1, 3)
    idx = np.arange(m * m).reshape(m, m)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return verts, faces


def benchmark_operators(sizes=(1000, 10000, 100000), k: int = 64) -> list[dict]:
    """Time each stage of :func:`compute_operators` on wavy grids of the given vertex counts.

    Returns one dict per size: n_vertices, laplacian_s, eigsh_s, frames_s, gradients_s, total_s,
    peak_mb (tracemalloc peak of the numpy allocations during the run; misses C++/SuperLU buffers) and
    max_rss_mb (the process's peak resident memory so far: run sizes in increasing order).
    """
    results = []
    for size in sizes:
        verts, faces = _bumpy_grid(size)
        tracemalloc.start()
        t0 = time.perf_counter()
        L, mass = laplacian_and_mass(verts, faces)
        t1 = time.perf_counter()
        eigen_decomposition(L, mass, k)
        t2 = time.perf_counter()
        frames = tangent_frames(vertex_normals(verts, faces))
        t3 = time.perf_counter()
        gradient_operators(verts, faces, frames)
        t4 = time.perf_counter()
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        results.append(dict(n_vertices=len(verts), laplacian_s=t1 - t0, eigsh_s=t2 - t1, frames_s=t3 - t2,
                            gradients_s=t4 - t3, total_s=t4 - t0, peak_mb=peak / 2**20,
                            max_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024))
    return results


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description="Benchmark DiffusionNet operator preparation.")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    parser.add_argument("-k", type=int, default=64)
    args = parser.parse_args()
    print(f"{'V':>8} {'laplacian':>10} {'eigsh':>8} {'frames':>8} {'grads':>8} {'total':>8} {'peak MB':>8} {'RSS MB':>8}")
    for r in benchmark_operators(args.sizes, args.k):
        print(f"{r['n_vertices']:>8} {r['laplacian_s']:>10.3f} {r['eigsh_s']:>8.3f} {r['frames_s']:>8.3f} "
              f"{r['gradients_s']:>8.3f} {r['total_s']:>8.3f} {r['peak_mb']:>8.1f} {r['max_rss_mb']:>8.1f}")
