"""Canonicalisation: the network sees every mesh centred and at one size, whatever its units.

Two frames (the kind is recorded per model: ``nets.model.NFSConfig.canonical``):

- ``"bbox"`` (every checkpoint trained before the face frame, and the default): the centre of the
  mesh's axis-aligned bounding box goes to the origin and the mesh is scaled uniformly so its width
  (x extent, ear to ear) is ``CANONICAL_WIDTH`` = 16 canonical units, about the width of a real head
  in centimetres (the unit of the synthetic training rigs). It depends on the crop: a bust with
  shoulders comes out at a third of the size of the same head cut at the neck.
- ``"face"``: fitted to the front of the face, so a face mask, a head, a head with eye sockets and
  mouth cavity, and a bust give one frame (see :func:`fit_face_frame`). Its constants are set so
  that on procedural full heads it is close to the bounding-box frame (``FACE_WIDTH_CANONICAL``,
  ``FACE_POINT_CANONICAL``).

Axes are not changed (the input must already be +y up, +z forward; see
``retarget.io.axis_rotation``), but a head that is tilted from facing +z can be turned upright
first (:func:`upright_rotation`, the ``rotation`` of :class:`Canonicaliser`; ``Retargeter`` does
so). Network outputs (positions or displacements in canonical units) are mapped back to the
input's frame and units with :meth:`Canonicaliser.from_canonical` /
:meth:`displacement_from_canonical`. Hence a head given in metres, centimetres or millimetres yields
the same expression, in its own units: the result for the millimetre head is the centimetre result
times ten. This is the robustness to scale and translation that NFS lacks (paper Fig. 11).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from .errors import RetargetError

CANONICAL_WIDTH = 16.0
FRAMES = ("bbox", "face")

# ---- the face frame (fit_face_frame); lengths relative to the mesh's own size
HEAD_WINDOW_GAIN = 1.3    # head window depth below the top = gain × the window's x extent
WINDOW_START = 0.05       # ... grown from this fraction of the mesh's height (past a flat crown)
GRID_CELLS = 96           # height-field cells along the head window's depth
SAMPLE_SPACING = 0.5      # spacing of the triangle samples, in height-field cells
FRONT_COS = 0.5           # the face front: surface normals within 60° of +z (cos 60° = 0.5) ...
JUMP_CELLS = 4.0          # ... and no step in the height field above 4 cells between neighbours
NOSE_RADIUS = 0.03        # a nose tip given to fit_face_frame: searched this fraction of the window
                          # depth around it
NOSE_CANDIDATES = 12      # the nose finder (nose_candidates): peaks of the front read, at most,
NOSE_SPACING = 0.03       # ... this many window depths apart,
NOSE_DEPTH = 0.12         # ... at most this many behind the front-most point;
NOSE_PATCH = 9            # its features: the height field on a 9 x 9 grid
NOSE_SPAN = 0.15          # ... +-0.15 window depths around each peak,
NOSE_CLIP = 0.3           # ... relative heights clipped at -0.3 window depths
NOSE_MARGIN = 0.3         # another peak is the nose when the finder rates it this much above the
                          # front-most point (probabilities)
SEED_RADIUS = 0.1         # components of the face front reaching this fraction of the window
                          # depth around the nose tip make the face (the nose alone may be cut off)
SLICE_BANDS = 64          # horizontal slices of the mesh's height for finding the shoulders
SHOULDER_GAIN = 1.4       # the shoulders: the first slice wider than the head and this many times
                          # as wide as the neck ...
SHOULDER_MIN_DEPTH = 0.6  # ... at least this many head widths below the top (past the crown),
SHOULDER_MIN_HEAD = 0.2   # ... under a head at least this share of the slice's width (not a lone
                          # vertex or spike at the top of a tilted face mask)
#: Canonical width of the face front (the scale) and canonical position of the face point (the
#: nose tip, at the front's mid x): chosen so the face frame of procedural full heads is within a
#: few per cent of their bounding-box frame.
FACE_WIDTH_CANONICAL = 11.5
FACE_POINT_CANONICAL = np.array([0.0, 1.1, 10.3])
#: Turning a head upright (:func:`upright_rotation`): a small morphable model of the front of the
#: face, ``UPRIGHT_TEMPLATE_HEADS`` regular MakeHuman training heads each in its face frame (their
#: skin vertices inside ``UPRIGHT_FACE_BOX``, canonical [min, max]: brow to chin), their mean and
#: ``UPRIGHT_SHAPES`` principal shapes, is fitted to the mesh by ICP: a rigid motion and the
#: shapes' coefficients (ridge ``UPRIGHT_SHAPE_PRIOR`` over each shape's variance), so that a face
#: with a long chin or a sloping forehead is read as that shape, not as a turned head. The fit
#: starts from each of ``UPRIGHT_STARTS`` (pitch, yaw in degrees) with ``UPRIGHT_COARSE_STEPS``
#: steps, the best goes on for at most ``UPRIGHT_STEPS`` more, matching the ``UPRIGHT_TRIM`` share
#: of model points nearest the mesh (at most ``UPRIGHT_MAX_POINTS`` of its vertices). A head is
#: turned when the fit is good (RMS point-to-plane distance ≤ ``UPRIGHT_MAX_RMS`` canonical units:
#: 380 of 386 regular MakeHuman heads fit within 0.09, stylised ones 0.06-0.19, procedural heads
#: 0.13-0.17) and it is pitched at least ``UPRIGHT_MIN_PITCH`` or turned sideways (yaw and
#: roll) at least ``UPRIGHT_MIN_SIDE`` degrees: none of 450 upright MakeHuman heads of the three
#: splits, stylised ones included, is turned (docs/RESULTS.md, "Heads that do not face +z").
UPRIGHT_TEMPLATE_HEADS = 64
UPRIGHT_SHAPES = 8
UPRIGHT_SHAPE_PRIOR = 1.0
UPRIGHT_FACE_BOX = np.array([[-5.5, -11.0, 3.0], [5.5, 9.0, 20.0]])
UPRIGHT_STARTS = ((0.0, 0.0), (-20.0, 0.0), (20.0, 0.0), (0.0, -25.0), (0.0, 25.0))
UPRIGHT_COARSE_STEPS = 10
UPRIGHT_STEPS = 30
UPRIGHT_TRIM = 0.8
UPRIGHT_MIN_PITCH = 9.0
UPRIGHT_MIN_SIDE = 4.0
UPRIGHT_MAX_RMS = 0.09
UPRIGHT_MAX_POINTS = 40000
UPRIGHT_CONVERGED = 1e-5     # an ICP step below this (radians, canonical units) ends the fit
UPRIGHT_SETTLE = 0.5         # a first fit reading under this share of both thresholds is final
#: The frontal render of a face-frame model frames this canonical box ([min, max], (2,3)) instead
#: of each mesh's bounding box, so the image follows the face frame whatever the crop.
FACE_RENDER_BOX = np.array([[-10.0, -15.0, -13.0], [10.0, 16.0, 12.0]])


@dataclass(frozen=True)
class Canonicaliser:
    """Similarity (rotation + translation + uniform scale) from a mesh's frame to the canonical frame.

    centre: (3,) float64, input units: the point (of the turned mesh) that goes to the canonical
    origin. scale: canonical units per input unit. kind: "bbox" or "face" (how it was fitted).
    rotation: (3,3) float64 turning the mesh upright before the fit (:func:`upright_rotation`), or
    None (the mesh is taken as it is: the network's frame is +y up, +z forward).
    canonical = (points · rotationᵀ − centre) · scale.
    """

    centre: np.ndarray
    scale: float
    kind: str = "bbox"
    rotation: np.ndarray | None = None

    @classmethod
    def fit(cls, vertices, name: str = "mesh", kind: str = "bbox", faces=None,
            rotation: np.ndarray | None = None) -> "Canonicaliser":
        """Fit to vertices (V,3) (faces (F,3) int: needed by the "face" kind), turned by
        ``rotation`` (3,3) first when given.

        "bbox": bounding-box centre, and scale making the x extent 16 units. "face": see
        :func:`fit_face_frame`. RetargetError (naming ``name``) for a mesh with no width."""
        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        if rotation is not None:
            rotation = np.asarray(rotation, np.float64)
            v = v @ rotation.T
        lo, hi = v.min(axis=0), v.max(axis=0)
        width = float(hi[0] - lo[0])
        if not np.isfinite(width) or width <= 1e-12 * max(1.0, float(np.abs(v).max())):
            raise RetargetError(f"{name}: has no width along x (extent {width:g}); "
                                "is it a face mesh in the +y up, +z forward frame?")
        if kind == "bbox":
            return cls(centre=0.5 * (lo + hi), scale=CANONICAL_WIDTH / width, rotation=rotation)
        if kind == "face":
            if faces is None:
                raise ValueError("Canonicaliser.fit(kind='face') needs the faces")
            point, face_width = fit_face_frame(v, faces)
            scale = FACE_WIDTH_CANONICAL / face_width
            return cls(centre=point - FACE_POINT_CANONICAL / scale, scale=scale, kind="face",
                       rotation=rotation)
        raise ValueError(f"unknown canonical frame {kind!r}; choose from {FRAMES}")

    @property
    def render_fit(self):
        """What ``retarget.render`` frames for the frontal image of a mesh in this canonical frame:
        True (each mesh's bounding box) for "bbox", the fixed canonical ``FACE_RENDER_BOX`` for
        "face"."""
        return True if self.kind == "bbox" else FACE_RENDER_BOX

    def _turn(self, d: np.ndarray) -> np.ndarray:
        return d if self.rotation is None else d @ self.rotation.T

    def _unturn(self, d: np.ndarray) -> np.ndarray:
        return d if self.rotation is None else d @ self.rotation

    def to_canonical(self, points) -> np.ndarray:
        """(..., 3) points in input units -> (..., 3) float64 canonical."""
        return (self._turn(np.asarray(points, dtype=np.float64)) - self.centre) * self.scale

    def from_canonical(self, points) -> np.ndarray:
        """(..., 3) canonical points -> (..., 3) float64 in the input's frame and units."""
        return self._unturn(np.asarray(points, dtype=np.float64) / self.scale + self.centre)

    def displacement_from_canonical(self, d) -> np.ndarray:
        """(..., 3) canonical displacements -> (..., 3) float64 input units (rotation and scale)."""
        return self._unturn(np.asarray(d, dtype=np.float64) / self.scale)

    def displacement_to_canonical(self, d) -> np.ndarray:
        """(..., 3) displacements in input units -> (..., 3) float64 canonical (rotation and scale)."""
        return self._turn(np.asarray(d, dtype=np.float64)) * self.scale


# ------------------------------------------------------------------------------------- face frame
def shoulder_depth(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Depth below the mesh's top (max y) where a bust's shoulders begin, inf if none.

    The surface (sampled densely, so any tessellation gives the same slices) is cut into
    ``SLICE_BANDS`` horizontal slices of the mesh's height; the shoulders are the first slice wider
    (x extent) than every slice above it and ``SHOULDER_GAIN`` times as wide as the narrowest slice
    between it and the widest one above (the neck), at least ``SHOULDER_MIN_DEPTH`` head widths
    below the top (the crown's slices widen fast), under a head at least ``SHOULDER_MIN_HEAD`` of
    its width (a face mask whose top is one vertex above the rest, as a tilted straight cut gives,
    has a first slice of nearly no width: the next one is no shoulder). A head, a face mask or a
    head with its neck has none. vertices (V,3) float64, faces (F,3) int -> depth in the
    vertices' units."""
    top = vertices[:, 1].max()
    band = max(float(top - vertices[:, 1].min()), 1e-300) / SLICE_BANDS
    # the corners, and samples of the triangles whose xy box is longer than a slice (the others
    # would add only their corners)
    used = np.zeros(len(vertices), bool)
    used[faces.ravel()] = True
    box = [np.maximum(np.maximum(c[:, 0], c[:, 1]), c[:, 2]) - np.minimum(np.minimum(c[:, 0], c[:, 1]), c[:, 2])
           for c in (vertices[:, 0][faces], vertices[:, 1][faces])]    # column-wise: 8x np.ptp's speed
    long = np.hypot(*box) > band
    points = vertices[used]
    if long.any():
        points = np.concatenate([points, surface_samples(vertices, faces[long], band)[0]])
    index = np.clip(((top - points[:, 1]) / band).astype(np.int64), 0, SLICE_BANDS - 1)
    lo = np.full(SLICE_BANDS, np.inf)
    hi = np.full(SLICE_BANDS, -np.inf)
    np.minimum.at(lo, index, points[:, 0])
    np.maximum.at(hi, index, points[:, 0])
    head = neck = 0.0                                  # the widest slice so far, the narrowest since
    for i, width in enumerate(hi - lo):
        if not np.isfinite(width):
            continue
        if width > head:
            if (head >= SHOULDER_MIN_HEAD * width and width > SHOULDER_GAIN * neck
                    and i * band >= SHOULDER_MIN_DEPTH * head):
                return float(i * band)
            head = neck = float(width)
        neck = min(neck, float(width))
    return float("inf")


def head_window_depth(vertices: np.ndarray, shoulders: float = float("inf")) -> float:
    """Depth d below the mesh's top (max y) of the head window: the fixed point of
    d <- HEAD_WINDOW_GAIN × (x extent of the vertices less than min(d, ``shoulders``) below the
    top), grown from d = WINDOW_START × the mesh's height.

    Growing the window from the top, the head widens faster than the window deepens until the ears;
    then the x extent stops growing and the window stops about one head width below the crown, above
    the shoulders of a bust. On a bust with a wide or a short head that point lies below the top of
    the shoulders, whose width would then grow the window over the whole bust: the extent is
    therefore taken above the shoulders (``shoulders``: a bust's :func:`shoulder_depth`).
    vertices (V,3) float64 -> d in their units."""
    order = np.argsort(-vertices[:, 1], kind="stable")
    depth = vertices[order, 1]
    depth = depth[0] - depth                                     # ascending
    x = vertices[order, 0]
    ext = np.maximum.accumulate(x) - np.minimum.accumulate(x)   # extent of the first i+1 vertices
    d = WINDOW_START * depth[-1]
    for _ in range(1000):
        grown = HEAD_WINDOW_GAIN * ext[np.searchsorted(depth, min(d, shoulders), side="right") - 1]
        if grown <= d:
            break
        d = grown
    return float(d)


def surface_samples(vertices: np.ndarray, faces: np.ndarray,
                    spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points on the triangles (F,3) of vertices (V,3), at most about ``spacing`` apart in x and y:
    each triangle's barycentric lattice of n = ceil(longest xy edge / spacing) steps (capped at 64).
    Returns (points (N,3) float64, |n_z| (N,) of the unit normal of each point's triangle)."""
    tri = vertices[faces]                                        # (F,3,3)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nz = np.abs(normal[:, 2]) / np.maximum(np.linalg.norm(normal, axis=1), 1e-300)
    edge = np.linalg.norm((tri - tri[:, [1, 2, 0]])[..., :2], axis=-1).max(axis=1)
    n = np.clip(np.ceil(edge / spacing), 1, 64).astype(np.int64)
    order = np.argsort(n, kind="stable")                         # triangles grouped by their n
    tri, nz, n = tri[order], nz[order], n[order]
    steps, starts = np.unique(n, return_index=True)
    points, nzs = [], []
    for k, a, b in zip(steps, starts, np.r_[starts[1:], len(n)]):
        i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        keep = (i + j) <= k
        bary = np.stack([k - i[keep] - j[keep], i[keep], j[keep]], axis=1) / k   # (P,3)
        points.append((bary @ tri[a:b]).reshape(-1, 3))         # (f,P,3); matmul, not einsum: 9x
        nzs.append(np.repeat(nz[a:b], len(bary)))
    return np.concatenate(points), np.concatenate(nzs)


def front_height_field(points: np.ndarray, nz: np.ndarray, lo: np.ndarray, cell: float,
                       shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The front surface seen along −z on a grid: cell (i, j) covers x = lo[0] + i·cell,
    y = lo[1] + j·cell. points (N,3), nz (N,) from :func:`surface_samples`.
    Returns (height (H,W): max z, −inf where empty; front_nz (H,W): |n_z| there, 0 where empty)."""
    i = np.floor((points[:, 0] - lo[0]) / cell)                  # one column at a time: 3x faster
    j = np.floor((points[:, 1] - lo[1]) / cell)                  # than on the (N,2) slice
    ok = (i >= 0) & (i < shape[0]) & (j >= 0) & (j < shape[1])
    key = i[ok].astype(np.int64) * shape[1] + j[ok].astype(np.int64)
    z, nz = points[ok, 2], nz[ok]
    height = np.full(shape[0] * shape[1], -np.inf)
    np.maximum.at(height, key, z)
    front = z == height[key]                                        # the front-most sample(s)
    front_nz = np.zeros(shape[0] * shape[1])
    np.maximum.at(front_nz, key[front], nz[front])
    return height.reshape(shape), front_nz.reshape(shape)


def face_front(height: np.ndarray, front_nz: np.ndarray, cell: float) -> np.ndarray:
    """Component labels (H,W) int of the face-front graph: cells whose surface faces forward
    (|n_z| > FRONT_COS), joined to their 4-neighbours where the height field has no step above
    JUMP_CELLS cells (a silhouette or an occlusion, such as the chin over the neck). −1 = not front."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    front = front_nz > FRONT_COS
    index = np.arange(height.size).reshape(height.shape)
    rows, cols = [], []
    for a, b in (((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
                 ((slice(None), slice(None, -1)), (slice(None), slice(1, None)))):
        ok = front[a] & front[b] & (np.abs(np.subtract(height[a], height[b], where=front[a] & front[b], out=np.full(front[a].shape, np.inf))) <= JUMP_CELLS * cell)
        rows.append(index[a][ok])
        cols.append(index[b][ok])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    graph = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(height.size,) * 2)
    labels = connected_components(graph, directed=False)[1].reshape(height.shape)
    return np.where(front, labels, -1)


@dataclass
class FaceField:
    """The front of a head seen along −z (:func:`face_field`): height (H,W) max z of the surface
    per cell (−inf where empty) and front_nz (H,W) its |n_z|, on cells of side ``cell`` from
    ``lo`` (2,) (cell (i, j) covers x = lo[0] + i·cell, y = lo[1] + j·cell); rows_y (W,) the cells'
    y; top the mesh's max y; depth the head window's depth (:func:`head_window_depth`); shoulders
    a bust's :func:`shoulder_depth` (inf if none). Input units."""

    height: np.ndarray
    front_nz: np.ndarray
    lo: np.ndarray
    cell: float
    rows_y: np.ndarray
    top: float
    depth: float
    shoulders: float

    def cell_xy(self, cells: np.ndarray) -> np.ndarray:
        """(K,2) int cells -> (K,2) their centres' x, y."""
        return self.lo + (np.asarray(cells) + 0.5) * self.cell

    def front_most(self) -> tuple[int, int]:
        """The front-most cell of the head window (the nose tip, on most heads)."""
        window = np.where(self.rows_y >= self.top - self.depth, self.height, -np.inf)
        return np.unravel_index(np.argmax(window), self.height.shape)


def face_field(vertices: np.ndarray, faces: np.ndarray) -> FaceField:
    """The height field of a head's front around its front-most point (:class:`FaceField`): the
    head window (:func:`head_window_depth`, above a bust's shoulders), its front-most vertex, and
    the triangles near it sampled densely (:func:`front_height_field`) on ``GRID_CELLS`` cells
    per window depth, 0.8 window depths each way. vertices (V,3) float64, faces (F,3) int."""
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    shoulders = shoulder_depth(vertices, faces)
    d = head_window_depth(vertices, shoulders)
    top = vertices[:, 1].max()
    in_window = vertices[:, 1] >= top - d
    tip = vertices[in_window][np.argmax(vertices[in_window, 2])]
    cell = d / GRID_CELLS
    half = 0.8 * d                                              # region of interest around the tip
    lo = tip[:2] - half
    shape = (int(np.ceil(2 * half / cell)),) * 2
    tri = vertices[faces]
    near = ((tri[..., :2] >= lo - cell) & (tri[..., :2] <= lo + 2 * half + cell)).all(-1).any(-1)
    near &= tri[..., 2].max(axis=1) >= tip[2] - 0.6 * d
    height, front_nz = front_height_field(*surface_samples(vertices, faces[near],
                                                           SAMPLE_SPACING * cell), lo, cell, shape)
    rows_y = lo[1] + (np.arange(shape[1]) + 0.5) * cell
    return FaceField(height, front_nz, lo, cell, rows_y, float(top), float(d), float(shoulders))


def nose_candidates(field: FaceField) -> tuple[np.ndarray, np.ndarray]:
    """Where the nose tip may be, and what the nose finder reads there: the front-most cell of the
    head window first, then up to ``NOSE_CANDIDATES`` − 1 more peaks of the height field (greedy,
    each the highest forward-facing cell at least ``NOSE_SPACING`` window depths from those before,
    at most ``NOSE_DEPTH`` behind the first, inside or below the window). Returns (cells (K,2)
    int, features (K, NOSE_PATCH² + 3) float32: the height field on a NOSE_PATCH × NOSE_PATCH grid
    ±``NOSE_SPAN`` window depths around the cell relative to the cell's own height, the cell's
    height below the first and its depth below the mesh's top, all in window depths and clipped
    at −``NOSE_CLIP``, and 1 for the first candidate)."""
    d, cell, h = field.depth, field.cell, field.height
    first = field.front_most()
    free = np.where((field.front_nz > FRONT_COS) & (h >= h[first] - NOSE_DEPTH * d), h, -np.inf)
    gi, gj = np.ogrid[:h.shape[0], :h.shape[1]]
    cells = [first]
    while True:
        c = cells[-1]
        free[(gi - c[0]) ** 2 + (gj - c[1]) ** 2 <= (NOSE_SPACING * d / cell) ** 2] = -np.inf
        if len(cells) == NOSE_CANDIDATES or not np.isfinite(free).any():
            break
        cells.append(np.unravel_index(np.argmax(free), h.shape))
    cells = np.array(cells)
    offsets = np.linspace(-NOSE_SPAN, NOSE_SPAN, NOSE_PATCH) * d / cell
    features = []
    for k, (i, j) in enumerate(cells):
        ii = np.clip(np.round(i + offsets).astype(int), 0, h.shape[0] - 1)
        jj = np.clip(np.round(j + offsets).astype(int), 0, h.shape[1] - 1)
        patch = np.maximum((h[np.ix_(ii, jj)] - h[i, j]) / d, -NOSE_CLIP)   # −inf (empty) clipped
        features.append(np.r_[patch.ravel(), max((h[i, j] - h[first]) / d, -NOSE_CLIP),
                              (field.top - field.rows_y[j]) / d, float(k == 0)])
    return cells, np.asarray(features, np.float32)


def packaged_arrays(path: Path, keys: tuple[str, ...], what: str) -> tuple[np.ndarray, ...]:
    """The arrays ``keys`` of a data file shipped with the package (npz), float64; RetargetError
    naming the file and ``what`` it holds when it is missing or unreadable."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return tuple(z[k].astype(np.float64) for k in keys)
    except (OSError, KeyError, ValueError) as e:
        raise RetargetError(f"{path}: the packaged {what} is missing or unreadable ({e}); "
                            "reinstall the package") from None


NOSE_FINDER_PATH = (Path(__file__).resolve().parents[1] / "data_synth" / "makehuman" / "data"
                    / "nose_finder.npz")


@lru_cache(maxsize=1)
def nose_finder() -> tuple[np.ndarray, ...]:
    """The shipped nose finder (``NOSE_FINDER_PATH``): a one-hidden-layer scorer of
    :func:`nose_candidates`' features, (w1 (F,H), b1 (H,), w2 (H,), b2 ()) float64, trained on
    MakeHuman training heads whose nose tips are known (docs/results/face_frame/nose_finder.py)."""
    return packaged_arrays(NOSE_FINDER_PATH, ("w1", "b1", "w2", "b2"), "nose finder")


def nose_probabilities(features: np.ndarray) -> np.ndarray:
    """The nose finder's probability (K,) that each candidate (features (K,F)) is the nose tip."""
    w1, b1, w2, b2 = nose_finder()
    score = np.tanh(features @ w1 + b1) @ w2 + b2
    p = np.exp(score - score.max())
    return p / p.sum()


def fit_face_frame(vertices: np.ndarray, faces: np.ndarray,
                   nose: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The face's reference point and width, from the front of the face.

    1. The height field of the head's front (:func:`face_field`; triangles sampled densely, so any
       tessellation gives the same field and hidden parts, such as eye sockets and a mouth cavity,
       do not count).
    2. The nose tip: the front-most point of the head window (the top of the mesh down to about
       one head width, :func:`head_window_depth`; a bust's chest, as far forward, is below it),
       unless the nose finder (:func:`nose_candidates`, :func:`nose_probabilities`) puts another
       peak ahead of it by ``NOSE_MARGIN`` in probability: on a head whose lips, chin or brow lie
       further forward than its nose, or whose nose lies below the window.
    3. The face front (:func:`face_front`): the forward-facing surface connected to the nose tip
       without crossing a silhouette; it ends where the cheeks and temples turn sideways, under the
       chin and up the forehead, so the neck, the ears and a bust's chest are not part of it, and a
       face mask that keeps the cheeks has all of it. Its width (x extent) is the face's size. On a
       bust whose chin runs into the neck without a silhouette, the front stops at the shoulders
       (:func:`shoulder_depth`).

    vertices (V,3) float64 (+y up, +z forward, any units), faces (F,3) int. nose: (2,) the x, y of
    the nose tip when it is known: the tip is then the front-most point within ``NOSE_RADIUS``
    of the window's depth from it (docs/RESULTS.md, "The face frame's nose tip").
    Returns (point (3,): the front's mid x, the nose tip's y and z; the front's width), input units.
    """
    field = face_field(vertices, faces)
    h, d, cell = field.height, field.depth, field.cell
    shape = h.shape
    seed = field.front_most()
    if nose is not None:
        x, y = np.meshgrid(field.lo[0] + (np.arange(shape[0]) + 0.5) * cell - nose[0],
                           field.rows_y - nose[1], indexing="ij")
        around = np.hypot(x, y) <= NOSE_RADIUS * d
        if np.isfinite(h[around]).any():
            seed = np.unravel_index(np.argmax(np.where(around, h, -np.inf)), shape)
    else:
        cells, features = nose_candidates(field)
        p = nose_probabilities(features)
        if p.max() - p[0] > NOSE_MARGIN:
            seed = tuple(cells[np.argmax(p)])
    labels = face_front(h, field.front_nz, cell)
    labels[:, field.rows_y < field.top - field.shoulders] = -1   # nothing below a bust's shoulders
    gi, gj = np.ogrid[:shape[0], :shape[1]]
    near_tip = (gi - seed[0]) ** 2 + (gj - seed[1]) ** 2 <= (SEED_RADIUS * d / cell) ** 2
    touching = np.unique(labels[near_tip & (labels >= 0)])
    if len(touching) == 0:
        raise RetargetError("no surface faces forward around the front-most point; is the mesh "
                            "a face in the +y up, +z forward frame?")
    ii = np.nonzero(np.isin(labels, touching))[0]
    x_mid = field.lo[0] + 0.5 * (ii.max() + ii.min() + 1) * cell
    return (np.array([x_mid, field.rows_y[seed[1]], h[seed]]),
            float((ii.max() - ii.min() + 1) * cell))


# ------------------------------------------------------------------------------------- upright
def turn_matrix(pitch: float = 0.0, yaw: float = 0.0) -> np.ndarray:
    """(3,3) rotation: ``pitch`` degrees about +x (+: the face looks down), then ``yaw`` degrees about
    +y (+: the face turns to its left, +x)."""
    a, b = np.radians(pitch), np.radians(yaw)
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    return ry @ rx


def rotation_angle(rotation: np.ndarray) -> float:
    """The angle (degrees) of a (3,3) rotation."""
    return float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0))))


#: The face model of :func:`upright_face_model`, shipped with the MakeHuman data it is made from
#: (made by :func:`build_upright_face_model`; ``write_upright_face_model`` writes it again).
UPRIGHT_MODEL_PATH = (Path(__file__).resolve().parents[1] / "data_synth" / "makehuman" / "data"
                      / "upright_face_model.npz")


def build_upright_face_model() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The morphable front of the face that :func:`upright_fit` fits: ``UPRIGHT_TEMPLATE_HEADS``
    regular MakeHuman training heads (``sample_head_identity(seed, "train")``, seeds from 0, the
    stylised ones skipped), each in its own face frame, their skin vertices inside
    ``UPRIGHT_FACE_BOX`` of the mean. Returns (mean (N,3), shapes (K,N,3) of unit norm, variances
    (K,)), float64: the ``UPRIGHT_SHAPES`` principal shapes and the variance of the heads along
    each; canonical units. From the packaged CC0 MakeHuman data (about 1.5 s)."""
    from data_synth.makehuman import assets
    from data_synth.makehuman.identity import head_neutral, sample_head_identity

    faces = assets.heads()["full_faces"]
    heads, seed = [], 0
    while len(heads) < UPRIGHT_TEMPLATE_HEADS:
        identity = sample_head_identity(seed, "train")
        seed += 1
        if not identity.stylised:
            v = head_neutral(identity, "head").astype(np.float64)
            heads.append(Canonicaliser.fit(v, kind="face", faces=faces).to_canonical(v)[:assets.N_SKIN])
    heads = np.asarray(heads)
    mean = heads.mean(axis=0)
    keep = ((mean >= UPRIGHT_FACE_BOX[0]) & (mean <= UPRIGHT_FACE_BOX[1])).all(axis=1)
    _, sv, vt = np.linalg.svd((heads[:, keep] - mean[keep]).reshape(len(heads), -1),
                              full_matrices=False)
    shapes = vt[:UPRIGHT_SHAPES]
    shapes *= np.sign(shapes[np.arange(len(shapes)), np.abs(shapes).argmax(axis=1)])[:, None]
    return (mean[keep], shapes.reshape(UPRIGHT_SHAPES, -1, 3),      # each shape's largest entry > 0:
            sv[:UPRIGHT_SHAPES] ** 2 / (len(heads) - 1))              # the same file on any LAPACK


def write_upright_face_model(path=UPRIGHT_MODEL_PATH) -> Path:
    """Write :func:`build_upright_face_model` to ``path`` (npz of mean, shapes, variances, float32;
    atomically)."""
    from .io import atomic_output

    mean, shapes, variances = build_upright_face_model()
    with atomic_output(path) as tmp:
        np.savez_compressed(tmp, mean=mean.astype(np.float32), shapes=shapes.astype(np.float32),
                            variances=variances.astype(np.float32))
    return Path(path)


@lru_cache(maxsize=1)
def upright_face_model() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`build_upright_face_model`'s (mean (N,3), shapes (K,N,3), variances (K,)) as shipped
    (``UPRIGHT_MODEL_PATH``), float64."""
    return packaged_arrays(UPRIGHT_MODEL_PATH, ("mean", "shapes", "variances"), "face model")


def axis_angle_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """(3,3) rotation by ``angle`` radians about the unit vector ``axis`` (3,) (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _skew_exp(w: np.ndarray) -> np.ndarray:
    """exp of the cross-product matrix of w (3,): the rotation by |w| radians about w."""
    theta = float(np.linalg.norm(w))
    return np.eye(3) if theta < 1e-15 else axis_angle_rotation(w / theta, theta)


def _icp(tree, points: np.ndarray, normals: np.ndarray, steps: int, rotation: np.ndarray,
         shift: np.ndarray, coeffs: np.ndarray) -> tuple:
    """Trimmed point-to-plane ICP of the face model (:func:`upright_face_model`) onto the points
    (M,3) with unit normals (M,3) (``tree``: their cKDTree): the model face mean + Σ coeffs_k
    shape_k moved by p -> rotation · p + shift, with a ridge pull of each coefficient towards 0
    (``UPRIGHT_SHAPE_PRIOR`` / its variance). At most ``steps`` linearised steps from the given
    fit (fewer once a step is below ``UPRIGHT_CONVERGED``). Returns (rotation, shift, coeffs, the
    RMS point-to-plane distance of the ``UPRIGHT_TRIM`` share of nearest model points)."""
    mean, shapes, variances = upright_face_model()
    ridge = np.concatenate([np.zeros(6), UPRIGHT_SHAPE_PRIOR / variances])
    for _ in range(steps):
        p = (mean + np.tensordot(coeffs, shapes, axes=1)) @ rotation.T + shift
        dist, j = tree.query(p)
        keep = dist <= np.quantile(dist, UPRIGHT_TRIM)
        p, q, n = p[keep], points[j[keep]], normals[j[keep]]
        moved = shapes[:, keep] @ rotation.T                         # (K, n, 3): each shape, turned
        a = np.concatenate([np.cross(p, n), n, np.einsum("kpd,pd->pk", moved, n)], axis=1)
        x = np.linalg.solve(a.T @ a + np.diag(ridge),                 # n·(ω×p + t + Σδc_k R s_k)
                            a.T @ ((q - p) * n).sum(axis=1) - ridge * np.r_[np.zeros(6), coeffs])
        step = _skew_exp(x[:3])
        rotation, shift, coeffs = step @ rotation, step @ shift + x[3:6], coeffs + x[6:]
        if np.abs(x).max() < UPRIGHT_CONVERGED:
            break
    p = (mean + np.tensordot(coeffs, shapes, axes=1)) @ rotation.T + shift
    j = tree.query(p)[1]
    dist = np.sort(np.abs(((points[j] - p) * normals[j]).sum(axis=1)))[:int(UPRIGHT_TRIM * len(p))]
    return rotation, shift, coeffs, float(np.sqrt(np.mean(dist ** 2)))


def upright_fit(vertices: np.ndarray, faces: np.ndarray,
                settle: bool = False) -> tuple[np.ndarray, float]:
    """How far a head is turned from upright: the rotation U (3,3) such that vertices · Uᵀ faces +z
    as the MakeHuman training heads do, and the RMS point-to-plane distance (canonical units) of
    the face model (:func:`upright_face_model`) fitted to it. From each start of
    ``UPRIGHT_STARTS`` the mesh is turned, put in its face frame and the model fitted by ICP
    (:func:`_icp`); the best fit is refined. A start from which the face frame cannot be fitted
    (a bust pitched up, whose chest then leads) is skipped; with none left the head counts as
    not fitted (identity, RMS inf). ``settle``: return the first start's (upright) coarse
    fit at once when it fits well and reads under ``UPRIGHT_SETTLE`` of both turning thresholds
    (:func:`upright_rotation` would leave such a head: 0.055 s instead of 0.32 s for an
    11,000-vertex head). vertices (V,3) float64
    (+y up, +z forward, roughly), faces (F,3) int."""
    from scipy.spatial import cKDTree

    from nets.geometry import vertex_normals

    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    v = np.asarray(vertices, np.float64)
    used = np.unique(faces)
    if len(used) > UPRIGHT_MAX_POINTS:
        used = np.sort(np.random.default_rng(0).choice(used, UPRIGHT_MAX_POINTS, replace=False))
    fits = []
    for pitch, yaw in UPRIGHT_STARTS:
        start = turn_matrix(pitch, yaw)
        try:
            cv = Canonicaliser.fit(v, kind="face", faces=faces, rotation=start).to_canonical(v)
        except RetargetError:
            continue     # no face frame from this start (a bust turned up: its chest leads)
        points, normals = cv[used], vertex_normals(cv, faces)[used]
        tree = cKDTree(points)
        fit = _icp(tree, points, normals, UPRIGHT_COARSE_STEPS, np.eye(3), np.zeros(3),
                   np.zeros(UPRIGHT_SHAPES))
        if settle and not fits and fit[-1] <= UPRIGHT_MAX_RMS:
            pitch_read, side_read = pitch_and_side(fit[0].T @ start)
            if (pitch_read < UPRIGHT_SETTLE * UPRIGHT_MIN_PITCH
                    and side_read < UPRIGHT_SETTLE * UPRIGHT_MIN_SIDE):
                return fit[0].T @ start, fit[-1]
        fits.append((fit[-1], start, tree, points, normals, fit))
    if not fits:
        return np.eye(3), float("inf")
    _, start, tree, points, normals, (r, t, c, _) = min(fits, key=lambda f: f[0])
    r, _, _, rms = _icp(tree, points, normals, UPRIGHT_STEPS, r, t, c)
    return r.T @ start, rms                      # the model turned by r fits: undo r


def side_turn(rotation: np.ndarray) -> np.ndarray:
    """The yaw-and-roll part S (3,3) of a rotation U that turns a head upright: the least rotation
    taking the head's left-right axis Uᵀ e_x to e_x. U = P · S with P a pure pitch (about x)."""
    a = rotation.T @ np.array([1.0, 0.0, 0.0])
    axis = np.cross(a, [1.0, 0.0, 0.0])
    sin = float(np.linalg.norm(axis))
    if sin < 1e-12:
        return np.eye(3)
    return _skew_exp(axis / sin * np.arctan2(sin, float(a[0])))


def pitch_and_side(rotation: np.ndarray) -> tuple[float, float]:
    """The pitch and the yaw-and-roll (degrees) of a rotation U = P · S (:func:`side_turn`)."""
    side = side_turn(rotation)
    return rotation_angle(rotation @ side.T), rotation_angle(side)


def upright_rotation(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray | None:
    """The rotation (3,3) that turns a head upright before its face frame is fitted, or None when
    it needs none. From :func:`upright_fit` U = P · S (:func:`side_turn`): the whole of U when its
    pitch P is at least ``UPRIGHT_MIN_PITCH``; else S alone when the head is turned sideways (yaw
    and roll) at least ``UPRIGHT_MIN_SIDE``; never when the face model fits it too badly to tell
    (``UPRIGHT_MAX_RMS``: procedural and many stylised heads). The thresholds lie above what
    upright MakeHuman heads that fit read from their own shape (pitch up to 8.4°, yaw and roll up
    to 2.7°, on 450 heads of the three splits), so heads like those the network was trained on are
    taken as they are: turning one by what its shape reads can cost more than it saves (a stylised
    test head read at 6.2° and turned: 3.3 times the inversion error). Without it a head turned
    10° up, down or aside loses most of its accuracy (docs/RESULTS.md, "Heads that do not face
    +z").
    vertices (V,3), faces (F,3) int."""
    rotation, rms = upright_fit(vertices, faces, settle=True)
    if rms > UPRIGHT_MAX_RMS:
        return None
    pitch, side = pitch_and_side(rotation)
    if pitch >= UPRIGHT_MIN_PITCH:
        return rotation
    return side_turn(rotation) if side >= UPRIGHT_MIN_SIDE else None
