"""The Python API: ``Retargeter`` (DESIGN.md section 5).

    from retarget import Retargeter, load_mesh
    r = Retargeter.load()                      # bundled default checkpoint, or a path
    tgt = r.prepare(load_mesh("target.obj"))   # operators, image, identity + skinning codes
    verts = r.transfer(load_mesh("src_frame.obj"), tgt)   # (V_tgt, 3) in target units
    verts_seq = r.animate(tgt, [{"jawOpen": 1.0}, {"jawOpen": 0.5}])   # or a (T, 53) array
    w = r.invert(load_mesh("frame.obj"))       # (53,) FACS weights in ICT order
    neutral = load_mesh("actor_neutral.obj")  # the performer's neutral, when you have it:
    w = r.invert(load_mesh("frame.obj"), source_neutral=neutral, refine=True)  # fitted on its rig

Every mesh is canonicalised on the way in (centred, scaled to a 16-unit-wide head, and turned upright
when it is tilted: ``Retargeter.canonicaliser``) and results are mapped back to the target's own
frame and units. Meshes above ``proxy_vertices`` (targets and source
frames) are encoded on a vertex-clustered proxy; targets are decoded per vertex at full resolution,
in chunks of ``chunk`` vertices.

Every call that takes a mesh takes a ``retarget.mesh.Mesh``, a ``trimesh.Trimesh`` or a
``(vertices (V,3), faces (F,3))`` pair, vertex order kept (``retarget.mesh.as_mesh``). What a source
topology needs (its operators) is computed once and reused by later calls (``Retargeter.encode``), so
frames streamed one call at a time run at the batched speed.

Every target and source is checked to be plausibly a head or face (:func:`check_head_like`), since
the units are the user's own only proportions can be judged: at least ``MIN_VERTICES`` vertices, and
no bounding-box side shorter than ``MIN_ASPECT`` times the longest (a plane, a stick or a strip is
refused; the procedural face-only crop measures 0.66, the full head with neck 0.53).
"""
from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass, field
from functools import cached_property
from importlib import resources
from pathlib import Path

import numpy as np
import torch

from data_synth.facs import FACS_INDEX, N_FACS
from nets.geometry import Operators, TorchOperators, load_or_compute_operators, vertex_normals
from nets.model import NFSModel, TargetCodes, weights_to_code

from .canonical import Canonicaliser, upright_rotation
from .checkpoint import checkpoint_code_map, load_checkpoint, model_from_checkpoint
from .code_map import (check_code_map, check_gate, check_map_error, check_per_head, code_metric,
                       head_code_map, head_map_error)
from .decimate import cluster_decimate, cluster_means
from .errors import RetargetError
from .eyes import Eyes, find_eyes, gaze_from_weights, weights_from_gaze
from .jaw import SHAPES as JAW_SHAPES, JawParts, find_jaw_parts
from .mesh import Mesh, as_mesh, face_part, is_mesh_like, submesh
from .prepare import IMAGE_CHANNELS, PreparedMesh, neutral_channels, prepare_mesh, vertex_features
from .smoothing import smooth_codes
from .stabilise import MAX_REST, MISMATCH, RigidMotion, carry_motion, rest_vertices, rigid_fit

DEFAULT_CHECKPOINT = "default.pt"
MIN_VERTICES = 50   # fewer cannot describe a face
MIN_ASPECT = 0.1    # shortest / longest bounding-box side of a plausible head or face


def check_head_like(mesh: Mesh, role: str = "mesh") -> None:
    """RetargetError naming the mesh if it cannot be a face: fewer than MIN_VERTICES vertices, or a
    bounding box whose shortest side is below MIN_ASPECT times its longest (scale-free, so metres,
    centimetres and millimetres are all accepted). ``role``: "target" or "source", for the message.
    ``mesh``: anything :func:`retarget.mesh.as_mesh` takes."""
    mesh = as_mesh(mesh, role=role)
    name = mesh.name or role
    if mesh.n_vertices < MIN_VERTICES:
        raise RetargetError(f"{name}: only {mesh.n_vertices} vertices; a {role} face mesh needs at "
                            f"least {MIN_VERTICES}")
    ext = mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0)
    if ext.min() < MIN_ASPECT * ext.max():
        raise RetargetError(
            f"{name}: not a face-sized object (bounding box {ext[0]:.3g} x {ext[1]:.3g} x {ext[2]:.3g}: "
            f"one side is under {MIN_ASPECT:g} of another); is it a head, with --up/--forward right?")


def default_checkpoint_path() -> Path:
    """The checkpoint bundled with the package (``retarget/checkpoints/default.pt``)."""
    return Path(str(resources.files("retarget") / "checkpoints" / DEFAULT_CHECKPOINT))


@dataclass
class Target:
    """A prepared target neutral mesh (``Retargeter.prepare``).

    mesh: the user's mesh (its frame and units). face: None, or for a mesh with separate parts
    (eyeballs, teeth, ...) the indices (V',) int64 of the face's vertices in ``mesh``
    (``retarget.mesh.face_part``): the network sees the face alone and the other parts keep their
    place. proxy: the prepared (canonical) mesh the encoders ran on — the face, or its decimated
    proxy for large meshes. feat: (V',6) float32 canonical features of every vertex of the face
    (V' = V without parts). c: (128,) image code; codes: z_ID and skinning weights (ω_Skin per
    vertex of the face). jaw: the parts its jaw carries (``Retargeter.jaw_parts``, found on first
    use; ``jaw_found`` says whether it was looked for); eyes: its eyeballs (``Retargeter.eyes``,
    the same way, ``eyes_found``).
    """

    mesh: Mesh
    proxy: PreparedMesh
    feat: torch.Tensor
    c: torch.Tensor
    codes: TargetCodes
    face: np.ndarray | None = None
    jaw: JawParts | None = None
    jaw_found: bool = False
    eyes: Eyes | None = None
    eyes_found: bool = False

    @property
    def n_vertices(self) -> int:
        return self.mesh.n_vertices

    def on_mesh(self, d: np.ndarray) -> np.ndarray:
        """Displacements (..., V', 3) of the face's vertices -> (..., V, 3) of the mesh's, zero on
        its other parts (the array itself without parts)."""
        if self.face is None:
            return d
        out = np.zeros(d.shape[:-2] + (self.n_vertices, 3), d.dtype)
        out[..., self.face, :] = d
        return out

    def on_face(self, values: np.ndarray) -> np.ndarray:
        """Per-vertex values (V, ...) of the mesh -> (V', ...) of the face's vertices."""
        return values if self.face is None else values[self.face]


@dataclass
class BakedRig:
    """The 53 decoded shapes of a target: a linear rig for real-time playback.

    neutral: (V,3) target vertices (+ the decoder's output at zero weights); deltas: (53,V,3), both
    in the target's units. ``evaluate(w)`` = neutral + w·deltas for w (53,) or (T,53).
    """

    neutral: np.ndarray
    deltas: np.ndarray

    def evaluate(self, weights) -> np.ndarray:
        return self.neutral + np.tensordot(np.asarray(weights, np.float32), self.deltas, axes=1)


@dataclass
class SourceTopology:
    """What every frame of one source topology shares, kept across calls (``Retargeter.encode``).

    faces: (F',3) int64 faces of the encoded mesh (the proxy's for sources above ``proxy_vertices``).
    cluster: (V',) int64 proxy vertex of each vertex of the face, or None (the face itself is
    encoded). face: None, or the indices (V',) int64 of the face's vertices in a source mesh with
    separate parts (eyeballs, teeth, ...; ``retarget.mesh.face_part``): the encoder sees the face
    alone.
    canon: the canonicaliser of the reference mesh (the source neutral, or the first frame seen).
    ops: the operators of the reference's canonical mesh; ops_t: the same on the device.
    neutral: for an entry of a source neutral, (its proxy's canonical vertices (V',3) float32, their
    unit normals (V',3) float64) -- the reference of the neutral channels, made on first use.
    rest: for an entry of a source neutral, the indices of its rest vertices
    (``Retargeter.rest_vertices``), made on first use. eyes: its eyeballs (``Retargeter.source_eyes``),
    looked for on first use (``eyes_found``).
    """

    faces: np.ndarray
    cluster: np.ndarray | None
    canon: Canonicaliser
    ops: Operators
    ops_t: TorchOperators
    neutral: tuple[np.ndarray, np.ndarray] | None = None
    face: np.ndarray | None = None
    rest: np.ndarray | None = None
    eyes: Eyes | None = None
    eyes_found: bool = False

    def proxy(self, mesh: Mesh) -> Mesh:
        """The mesh the encoder sees for a frame of this topology: the frame's face, or its proxy
        (each proxy vertex the mean of its cluster)."""
        v = mesh.vertices if self.face is None else mesh.vertices[self.face]
        if self.cluster is None:
            return Mesh(v, self.faces, mesh.name) if self.face is not None else mesh
        return Mesh(cluster_means(v, self.cluster), self.faces, mesh.name)


def _digest(array: np.ndarray) -> str:
    return hashlib.blake2b(np.ascontiguousarray(array).tobytes(), digest_size=16).hexdigest()


def source_frames(frames) -> tuple[list[Mesh], bool]:
    """(the source frames as Meshes, whether one mesh was given): ``frames`` is one mesh (anything
    :func:`retarget.mesh.as_mesh` takes) or a list of them. RetargetError for an empty list."""
    single = is_mesh_like(frames)
    frames = [frames] if single else list(frames)
    if not frames:
        raise RetargetError("no source frames given")
    return [as_mesh(f, role="source" if single else f"source frame {i}")
            for i, f in enumerate(frames)], single


def basis_shapes(target: "Target", dims: slice, code_map: np.ndarray | None = None) -> np.ndarray:
    """The basis decoder's rig on a prepared target, the code dims ``dims`` of it, as shapes in the
    target's units: (K, V, 3) float32 (``dims`` = slice(0, 53): the baked FACS shapes). With
    ``code_map`` (code_dim, K) the shapes of its K columns as codes instead (``dims`` ignored).
    Zero on a mesh's parts beside the face (``Target.face``)."""
    basis = target.codes.basis
    if code_map is None:
        basis = basis[:, :, dims]
    else:
        basis = basis @ torch.as_tensor(code_map, dtype=basis.dtype, device=basis.device)
    shapes = basis.permute(2, 0, 1).cpu().numpy()
    return np.ascontiguousarray(target.on_mesh(target.proxy.canon.displacement_from_canonical(shapes)),
                                np.float32)


_BLAS_POOLS = None   # threadpoolctl's view of the BLAS libraries numpy and scipy load (lazily)


def one_blas_thread():
    """A context in which the BLAS of numpy and scipy runs on one thread, for small per-frame
    linear algebra between torch calls (``Retargeter.refine``). On CPU, OpenBLAS's worker threads
    keep spinning for a while after a multi-threaded call and then compete for the cores with
    torch's OpenMP threads: one frame of ``invert --refine`` took 125 ms instead of 46 ms
    (``retarget bench --sections frames``, 2 threads). The libraries are listed once (listing costs
    ~2 ms, the limit itself microseconds)."""
    global _BLAS_POOLS
    if _BLAS_POOLS is None:
        import scipy.linalg  # noqa: F401  (scipy's own BLAS is listed only once loaded)
        import scipy.optimize  # noqa: F401
        from threadpoolctl import ThreadpoolController

        _BLAS_POOLS = ThreadpoolController()
    return _BLAS_POOLS.limit(limits=1, user_api="blas")


def _ridge(gram: np.ndarray, prior: float) -> float:
    """λ = ``prior`` · mean diag(AᵀA) for the Gram matrix AᵀA (K,K) of a linear model."""
    return prior * float(np.trace(gram)) / len(gram) + 1e-12


def pull_scales(gram: np.ndarray, balance: float) -> np.ndarray:
    """The size each weight's pulls in ``SourceRig.fit`` are measured in, for the Gram matrix AᵀA
    (K,K) float64 of a rig: s_k = m^(1 − β) d_k^β, d_k = |shape k|² (diag AᵀA), m their mean,
    β = ``balance`` -> (K,) float64. β = 0: every weight pulled alike (m); β = 1: each in
    proportion to its own shape's size; between them, the geometric mean of the two."""
    d = np.diag(gram).astype(np.float64)
    m = float(d.mean())
    return m ** (1.0 - balance) * np.power(np.maximum(d, 1e-30), balance)


def _ridge_factor(gram: np.ndarray, prior: float) -> tuple[np.ndarray, float]:
    """For the Gram matrix AᵀA (K,K) float64 of a linear model: (upper-triangular R (K,K) with
    RᵀR = AᵀA + λI, λ), λ = ``_ridge(gram, prior)``."""
    ridge = _ridge(gram, prior)
    return np.linalg.cholesky(gram + ridge * np.eye(len(gram))).T, ridge


def box_least_squares(chol: np.ndarray, h: np.ndarray) -> np.ndarray:
    """argmin over w in [0,1]^K of wᵀRᵀRw − 2hᵀw (R = chol (K,K) upper-triangular, h (K,) float64):
    the unconstrained minimiser when it lies in the box, else BVLS on R w ≈ R⁻ᵀ h -> (K,) float64
    (``SourceRig.fit``; ``retarget.oracle.fit_rig_weights``)."""
    from scipy.linalg import solve_triangular
    from scipy.optimize import lsq_linear

    rhs = solve_triangular(chol, h, trans="T")
    w = solve_triangular(chol, rhs)
    if w.min() < 0.0 or w.max() > 1.0:
        w = lsq_linear(chol, rhs, bounds=(0.0, 1.0), method="bvls").x
    return np.clip(w, 0.0, 1.0)                              # BVLS may overstep a bound by 1 ulp


def _gram(a: np.ndarray) -> np.ndarray:
    """AᵀA (K,K) float64 of the rows Aᵀ (K, n)."""
    return a.astype(np.float64) @ a.T.astype(np.float64)


def _rig_key(neutral: Mesh) -> tuple:
    """The key of a source neutral's baked rig in ``Retargeter._source_rigs``: its content."""
    return _digest(neutral.vertices), _digest(neutral.faces)


def _residual_frames(frames, source_neutral, values, dims: int, name: str,
                     what: str) -> tuple[list, Mesh]:
    """(the frames as a list, the source neutral as a Mesh) for ``name`` (``fit_residuals``,
    ``code_residuals``), after checking that there is a neutral, one row of ``values`` (``what``,
    ``dims`` wide) per frame, and one topology."""
    if source_neutral is None:
        raise RetargetError(f"{name} needs the source's neutral (source_neutral=)")
    frames, _ = source_frames(frames)
    v = np.asarray(values, np.float32)
    if v.shape[-1:] != (dims,) or v.size != len(frames) * dims:
        raise RetargetError(f"{name}: {what} of shape {v.shape} for {len(frames)} "
                            f"frame(s); expected ({len(frames)}, {dims})")
    neutral = as_mesh(source_neutral, role="source neutral")
    if frames[0].vertices.shape != neutral.vertices.shape:
        raise RetargetError(f"{name}: the frames have {len(frames[0].vertices)} "
                            f"vertices, the source neutral {len(neutral.vertices)}: "
                            "they must share a topology")
    return frames, neutral


def _residual_rms(frames, drawn, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per frame the RMS over vertices of frame − drawn and of frame − rest: frames a list of
    Mesh (T), drawn an iterable of (V,3) arrays, rest (V,3) -> two (T,) float32 arrays."""
    residual, motion = np.empty(len(frames), np.float32), np.empty(len(frames), np.float32)
    for i, (frame, d) in enumerate(zip(frames, drawn)):
        residual[i] = np.sqrt(np.square(frame.vertices - d).sum(-1).mean())
        motion[i] = np.sqrt(np.square(frame.vertices - rest).sum(-1).mean())
    return residual, motion


@dataclass
class SourceRig:
    """The decoder's own rig on a source neutral, for analysis-by-synthesis (``Retargeter.refine``).

    target: the source neutral prepared as a target; baked: its 53 decoded one-hot shapes (source
    units); basis: Aᵀ (53,3V) float32, the baked deltas flattened; gram: AᵀA (53,53) float64, whose
    ridge factors (one per prior, the pull towards the encoder's estimate, and balance) are made
    when first used (factors); rest (made on first use): the indices of the face's vertices the
    baked shapes move least (``retarget.stabilise.rest_vertices``, in the mesh's indexing), on
    which a frame's head motion is fitted (``Retargeter.stabilise_frames``). With the basis
    decoder also free_basis:
    F (code_dim − 53, 3V) float32, the rig's columns of the free dims of z_GE (source units),
    and its factor free_chol with ridge free_ridge (``fit_free``, prior ``free_prior``); None for
    the MLP decoder. fit_basis Q (53, 3V) float32 and fit_gram (53, 53) float64: what ``fit``
    weighs a frame by when the rig's expected error is known (``retarget.code_map.code_metric``;
    None: A and AᵀA, the plain least squares). Made once per neutral.
    """

    target: Target
    baked: BakedRig
    basis: np.ndarray
    gram: np.ndarray
    free_basis: np.ndarray | None = None
    free_chol: np.ndarray | None = None
    free_ridge: float = 0.0
    fit_basis: np.ndarray | None = None
    fit_gram: np.ndarray | None = None
    factors: dict = field(default_factory=dict)

    @cached_property
    def rest(self) -> np.ndarray:
        """The rest vertices (R,) int64 of the baked shapes on the face (module docstring of
        ``retarget.stabilise``), made on first use: a rig baked for refine alone never needs them."""
        face = None if self.target is None else self.target.face
        if face is None:
            return rest_vertices(self.baked.deltas)
        return face[rest_vertices(self.baked.deltas[:, face])]

    @classmethod
    def make(cls, target: Target, baked: BakedRig, free: np.ndarray | None = None,
             free_prior: float = 1e-3, metric: tuple | None = None) -> "SourceRig":
        """free: (code_dim − 53, V, 3) the basis decoder's shapes of the free dims in source units.
        metric: (code_basis (code_dim, V, 3) every code dim's shape in source units, the head's
        error moment Σ (code_dim, code_dim), ρ) for ``fit`` to weigh frames by the rig's expected
        error (``retarget.code_map.code_metric``), or None."""
        a = np.ascontiguousarray(baked.deltas.reshape(N_FACS, -1), np.float32)   # Aᵀ (53, 3V)
        rig = cls(target, baked, a, _gram(a))
        if free is not None:
            rig.free_basis = np.ascontiguousarray(free.reshape(len(free), -1), np.float32)
            rig.free_chol, rig.free_ridge = _ridge_factor(_gram(rig.free_basis), free_prior)
        if metric is not None:
            code_basis, sigma, rho = metric
            rig.fit_basis, rig.fit_gram = code_metric(code_basis.reshape(len(code_basis), -1), a,
                                                      sigma, rho)
        return rig

    def fit_free(self, frame: np.ndarray, w: np.ndarray) -> np.ndarray:
        """The free dims f (code_dim − 53,) float32 of z_GE = [w, f] minimising
        |neutral + w·deltas + f·F − frame|² + λ_f |f|² with the weights w (53,) held: ridge least
        squares on the basis decoder's own rig, exact (what the gradient steps of the MLP decoder
        approximate, see ``Retargeter.refine``). frame (V,3) in the source's units."""
        from scipy.linalg import solve_triangular

        r = (np.asarray(frame, np.float32) - self.baked.neutral).reshape(-1) - w @ self.basis
        h = (self.free_basis @ r).astype(np.float64)
        f = solve_triangular(self.free_chol, solve_triangular(self.free_chol, h, trans="T"))
        return f.astype(np.float32)

    def fit_joint(self, frame: np.ndarray, w0: np.ndarray, prior: float,
                  sparsity: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Weights w (53,) in [0,1] and free dims f (code_dim − 53,) fitted together (basis decoder
        only): the minimiser of |neutral + w·deltas + f·F − frame|² + λ|w − w0|² + μ Σw + λ_f |f|²
        (λ, μ as in ``fit``, λ_f the free ridge of ``fit_free``). f is unbounded, so it is
        eliminated exactly: f(w) = (FFᵀ + λ_f)⁻¹ F (b − Aᵀw), and w solves a bounded least-squares
        problem on the Schur complement S = AᵀA + λI − AᵀFᵀ(FFᵀ + λ_f)⁻¹FA (53×53; its factor is
        made once per prior). Unlike ``fit`` then ``fit_free``, the free dims can take what the
        weights would otherwise explain badly. frame (V,3) in the source's units -> (w, f)
        float32."""
        from scipy.linalg import solve_triangular

        key = ("joint", prior)
        if key not in self.factors:
            cross = self.basis.astype(np.float64) @ self.free_basis.T.astype(np.float64)   # (53, F)
            x = solve_triangular(self.free_chol, cross.T, trans="T")                      # R_f⁻ᵀ C ᵀ
            ridge = _ridge(self.gram, prior)
            schur = self.gram + ridge * np.eye(len(self.gram)) - x.T @ x
            self.factors[key] = (np.linalg.cholesky(schur).T, ridge, x)
        chol, ridge, x = self.factors[key]
        b = (np.asarray(frame, np.float32) - self.baked.neutral).reshape(-1)
        gf = solve_triangular(self.free_chol, (self.free_basis @ b).astype(np.float64), trans="T")
        w = self._bounded_solve(chol, (self.basis @ b).astype(np.float64) + ridge * w0 - x.T @ gf,
                                sparsity)
        f = solve_triangular(self.free_chol, gf - x @ w.astype(np.float64))
        return w, f.astype(np.float32)

    def fit(self, frame: np.ndarray, w0: np.ndarray, prior: float, sparsity: float = 0.0,
            reweight: tuple = (), balance: float = 0.0, dense: tuple = ()) -> np.ndarray:
        """Weights (53,) in [0,1] minimising |neutral + w·deltas − frame|² + Σ_k λ_k (w_k − w0_k)² +
        Σ_k μ_k w_k (with the rig's expected error known, the first term weighed by it:
        ``fit_basis``, ``fit_gram``), λ_k = prior · s_k, μ_k = sparsity · s_k (an L1 pull towards 0, which on
        w ≥ 0 is linear), s_k = ``pull_scales(AᵀA, balance)``: with ``balance`` 0 the mean
        diag(AᵀA) for every weight, with 0.5 the geometric mean of that and shape k's own |B̂_k|²,
        so that a small shape (a brow, an eye look) is pulled less than a large one (docs/RESULTS.md,
        "Invert's pulls in proportion to each shape"): frame (V,3) in the source's units, w0 (53,)
        the encoder's estimate. Bounded
        least squares (``scipy.optimize.lsq_linear``, BVLS) on the 53×53 reduced system
        R w ≈ R⁻ᵀ (Aᵀb + λ w0), which has the same minimiser as the full (3V+53)-row problem; the
        problem is convex, so the estimate enters as the prior, not as a starting point. When the
        unconstrained minimiser lies in [0,1] it is the answer and BVLS is skipped.

        reweight: (μ_max, ε, passes) for reweighted L1 (Candès, Wakin and Boyd 2008): after the
        fit above, ``passes`` more fits with a pull of μ_max · ε / (w_k + ε) on each weight, w the
        previous pass's: weights the frame needs are barely pulled, the small ones a fit spreads
        over many shapes are pulled hard towards 0 (μ_k = that pull · s_k). () = off.

        dense: (count, threshold, prior, balance): a frame whose fitted weights (after the
        reweighting) have more than ``count`` above ``threshold`` moves much of the face at once,
        where a pull towards 0 only shrinks weights the frame needs; it is fitted again without
        the L1 pull, with that ``prior`` and ``balance`` (docs/RESULTS.md, "Frames that move many
        shapes: fitted again without the pull towards 0"). () = off."""
        gram = self.gram if self.fit_gram is None else self.fit_gram
        key = (prior, balance)
        if key not in self.factors:
            scales = pull_scales(gram, balance)
            ridge = prior * scales + 1e-12
            self.factors[key] = (np.linalg.cholesky(gram + np.diag(ridge)).T, ridge, scales)
        chol, ridge, scales = self.factors[key]
        b = (np.asarray(frame, np.float32) - self.baked.neutral).reshape(-1)
        shapes = self.basis if self.fit_basis is None else self.fit_basis
        h = (shapes @ b).astype(np.float64) + ridge * w0
        w = self._bounded_solve(chol, h, sparsity, scales)
        if reweight:
            mu_max, eps, passes = reweight
            for _ in range(int(passes)):
                w = self._bounded_solve(chol, h, mu_max * eps / (w.astype(np.float64) + eps), scales)
        if dense:
            count, threshold, dense_prior, dense_balance = dense
            if int(np.count_nonzero(w > threshold)) > count:
                return self.fit(frame, w0, dense_prior, 0.0, (), dense_balance)
        return w

    def _bounded_solve(self, chol: np.ndarray, h: np.ndarray, sparsity,
                       scales: np.ndarray | None = None) -> np.ndarray:
        """argmin over w in [0,1]^53 of wᵀRᵀRw − 2hᵀw + Σ μ_k w_k (R = chol (53,53) upper-triangular,
        h (53,) float64, μ_k = sparsity_k · s_k, sparsity a float or one per weight (53,), s the
        ``pull_scales`` (53,), by default mean diag(AᵀA) for every weight): the unconstrained
        minimiser when it lies in the box, else BVLS on R w ≈ R⁻ᵀ h -> (53,) float32."""
        if np.any(np.asarray(sparsity) > 0.0):
            s = float(np.trace(self.gram)) / len(self.gram) if scales is None else scales
            h = h - 0.5 * np.asarray(sparsity, np.float64) * s
        return box_least_squares(chol, h).astype(np.float32)


class Retargeter:
    """Expression cloning, driving from FACS weights and inverse rigging with one NFS model.

    proxy_vertices: meshes above this are encoded on a vertex-clustered proxy. chunk: vertices
    decoded at once. cache_dir: the on-disk operator cache (``nets.geometry``). source_cache_size:
    source topologies whose operators are kept in memory across calls (``encode``; 0 = none).
    upright: turn heads tilted from facing +z upright before the network sees them, and the
    results back (``canonicaliser``; False: every mesh as it faces). face_only: for a mesh with
    separate parts (eyeballs, teeth, a tongue, lashes beside the skin), the network sees the
    face alone (``retarget.mesh.face_part``: the part with the most vertices) and the other parts
    keep their place in every result (False: the whole mesh is the face), but for those of a
    target that its jaw carries (lower teeth, a tongue: ``jaw_parts``) with ``carry_jaw``, and its
    eyeballs, turned with the gaze (``eyes``) with ``turn_eyes`` (both False: every part stays at
    rest). stabilise: remove each
    source frame's head motion against the source's neutral (without one, against a take's first
    frame) before the frame is read (``stabilise_frames``; False: frames are taken as they are).
    """

    #: Analysis-by-synthesis (``refine``): weight of the pull towards the encoder's estimate,
    #: relative to the mean squared norm of the baked shapes — weak for the codes that transfer
    #: decodes (the source frame explained as well as the rig can), stronger for the weights that
    #: invert returns, which also get an L1 pull towards 0, reweighted twice (``SourceRig.fit``:
    #: the baked one-hot shapes are not the FACS shapes of the source, off by a median of 0.2-0.3
    #: of their own size on held-out heads with the bundled model and its code map, and the fit
    #: leans on the encoder a little); the ridge of the free dims (basis decoder); whether transfer and
    #: invert fit the weights and the free dims together (``SourceRig.fit_joint``; transfer
    #: does: the frame is explained better; invert does not: the free dims would take what its
    #: weights must say); source rigs kept baked; vertices decoded per gradient step of the
    #: free-dims refinement (MLP decoder). Tuned on a tuning set apart from the eval's test set
    #: (docs/RESULTS.md, "Stage 7", "Refine: weights and free dims fitted together",
    #: "Inverse rigging's weights" and, for invert's fit, "The code map" and "Frames that move many
    #: shapes").
    REFINE_PRIOR = 1e-3
    REFINE_SPARSITY = 0.0
    REFINE_BALANCE = 0.0
    REFINE_PRIOR_INVERT = 0.003
    REFINE_SPARSITY_INVERT = 0.002
    REFINE_REWEIGHT_INVERT = (0.05, 0.05, 2)
    #: how invert's pulls are shared between large and small shapes (``SourceRig.fit``'s
    #: ``balance``: 0.5 pulls each weight in proportion to the geometric mean of its shape's size
    #: and the mean size; transfer's fit keeps ``REFINE_BALANCE`` 0, every weight alike)
    REFINE_BALANCE_INVERT = 0.5
    #: a frame invert's fit reads as moving many shapes (more than 20 of the 53 weights above
    #: 0.05) is fitted again without the L1 pull, prior 0.01, balance 0.25 (``SourceRig.fit``'s
    #: ``dense``; () = never)
    REFINE_DENSE_INVERT = (20, 0.05, 0.01, 0.25)
    #: invert's fit (prior, sparsity, reweight, balance, dense) with a code map (the five above)
    #: and without one (the fit tuned before the map, better there on realistic heads): the
    #: code_map setter puts the one that fits in the five attributes of the instance
    REFINE_INVERT_FITS = {True: (REFINE_PRIOR_INVERT, REFINE_SPARSITY_INVERT, REFINE_REWEIGHT_INVERT,
                                 REFINE_BALANCE_INVERT, REFINE_DENSE_INVERT),
                          False: (0.1, 0.02, (0.1, 0.05, 2), 0.0, ())}
    #: invert's fit weighs each frame by its rig's expected error when the model holds the code
    #: map's error moments (``SourceRig.fit``, ``retarget.code_map.code_metric``): ρ, the share
    #: of white noise beside that error (None: the plain least squares; docs/RESULTS.md,
    #: "Invert's fit weighed by the rig's expected error"). Read when a source's rig is baked.
    REFINE_METRIC_RHO = 5.0
    REFINE_FREE_PRIOR = 1e-3
    REFINE_JOINT = True
    REFINE_JOINT_INVERT = False
    SOURCE_RIGS_KEPT = 8
    REFINE_ROWS = 2000
    #: ``estimate_neutral``: frames of a take used at most (evenly spaced; memory of the estimate:
    #: this many frames × 12 bytes a vertex)
    ESTIMATE_FRAMES = 32

    def __init__(self, model: NFSModel, device=None, proxy_vertices: int = 20000,
                 chunk: int = 16384, cache_dir=None, source_cache_size: int = 8,
                 refine_steps: int = 0, code_map: np.ndarray | None = None,
                 code_map_gate: np.ndarray | None = None, code_map_per_head: tuple | None = None,
                 code_map_error: np.ndarray | None = None, upright: bool = True,
                 face_only: bool = True, stabilise: bool = True, carry_jaw: bool = True,
                 turn_eyes: bool = True):
        self.device = torch.device(device or ("cuda" if torch.cuda.is_available() else "cpu"))
        self.model = model.to(self.device).eval()
        self.cfg = model.cfg
        self._source_rigs: dict[tuple, SourceRig] = {}
        self._code_map_gate = self._code_map_per_head = self._code_map_error = None
        self.code_map = code_map
        self.code_map_gate = code_map_gate
        self.code_map_per_head = code_map_per_head
        self.code_map_error = code_map_error
        self.proxy_vertices = proxy_vertices
        self.chunk = chunk
        self.cache_dir = cache_dir
        self.source_cache_size = int(source_cache_size)
        self._sources: OrderedDict[tuple, SourceTopology] = OrderedDict()
        self.refine_steps = refine_steps   # gradient steps on the free dims of z_GE after the fit
        self.upright = upright             # turn tilted heads upright first (``canonicaliser``)
        self.face_only = face_only         # the network sees a mesh's face part alone
        self.stabilise = stabilise         # source frames' head motion removed (``stabilise_frames``)
        self.carry_jaw = carry_jaw         # a target's lower teeth and tongue follow its jaw (``jaw_parts``)
        self.turn_eyes = turn_eyes         # a target's eyeballs turn with the gaze (``eyes``)

    def _checked(self, check, value):
        """``check(value, self.cfg)`` (one of ``retarget.code_map``'s checks of the map's parts),
        its ValueError raised as a RetargetError."""
        try:
            return check(value, self.cfg)
        except ValueError as e:
            raise RetargetError(str(e)) from None

    @property
    def code_map(self) -> np.ndarray | None:
        """The code of each FACS shape, (code_dim, 53) float32, or None for the paper's [w, 0]
        (``weight_codes``, ``retarget.code_map``). Setting it drops the source rigs baked so far
        and sets invert's fit to the one tuned with or without a map (``REFINE_INVERT_FITS``)."""
        return self._code_map

    @code_map.setter
    def code_map(self, value) -> None:
        self._code_map = self._checked(check_code_map, value)
        (self.REFINE_PRIOR_INVERT, self.REFINE_SPARSITY_INVERT, self.REFINE_REWEIGHT_INVERT,
         self.REFINE_BALANCE_INVERT, self.REFINE_DENSE_INVERT) = self.REFINE_INVERT_FITS[
            self._code_map is not None]
        self._source_rigs.clear()

    @property
    def code_map_gate(self) -> np.ndarray | None:
        """The code map's gate [a, b] (code_dim + 1,) float32, or None: each head then gets the
        map as far as σ(a·z_ID + b) says it is like the heads the map was fitted on
        (``head_code_map``). Setting it drops the source rigs baked so far."""
        return self._code_map_gate

    @code_map_gate.setter
    def code_map_gate(self, value) -> None:
        self._code_map_gate = self._checked(check_gate, value)
        self._source_rigs.clear()

    @property
    def code_map_per_head(self) -> tuple | None:
        """The per-head part of the code map, (features (d + 1, code_dim), slopes (d, code_dim,
        53)) float32, or None: each head's map is then ``code_map`` moved along its identity
        code's d whitened principal components (``retarget.code_map.HeadMapFit``). Setting it
        drops the source rigs baked so far."""
        return self._code_map_per_head

    @code_map_per_head.setter
    def code_map_per_head(self, value) -> None:
        self._code_map_per_head = self._checked(check_per_head, value)
        self._source_rigs.clear()

    @property
    def code_map_error(self) -> np.ndarray | None:
        """The code map's error moments (K, code_dim, code_dim) float32 (K = 2: MakeHuman-like and
        procedural heads, blended by the gate), or None: with them (and the map they were measured
        on) invert's fit weighs each frame by its rig's expected error (``REFINE_METRIC_RHO``,
        ``retarget.code_map.code_metric``). Setting it drops the source rigs baked so far."""
        return self._code_map_error

    @code_map_error.setter
    def code_map_error(self, value) -> None:
        self._code_map_error = self._checked(check_map_error, value)
        self._source_rigs.clear()

    def head_code_map(self, target) -> np.ndarray | None:
        """The code map of one prepared target (code_dim, 53) float32 (``retarget.code_map``:
        the map itself; with a per-head part, moved along the target's z_ID; with a gate, moved
        from the paper's map towards it by how MakeHuman-like the target's z_ID is), or None
        without a map."""
        if self.code_map is None:
            return None
        return head_code_map(self.code_map, self.code_map_gate,
                             target.codes.z_id.detach().cpu().numpy(), self.code_map_per_head)

    @classmethod
    def load(cls, path=None, device=None, **kwargs) -> "Retargeter":
        """Load a checkpoint (None = the bundled default). RetargetError for a missing, corrupt,
        tampered (refused by ``weights_only``) or incompatible file."""
        if path is None:
            path = default_checkpoint_path()
            if not path.is_file():
                raise RetargetError(f"no bundled checkpoint at {path}; train one with `retarget "
                                    "train` or pass --checkpoint")
        path = Path(path)
        state = load_checkpoint(path)
        code_map, gate, per_head, error = checkpoint_code_map(state)
        kwargs.setdefault("code_map", code_map)
        kwargs.setdefault("code_map_gate", gate)
        kwargs.setdefault("code_map_per_head", per_head)
        kwargs.setdefault("code_map_error", error)
        return cls(model_from_checkpoint(state, path), device, **kwargs)

    # --------------------------------------------------------------------------- preparation
    def canonicaliser(self, vertices: np.ndarray, faces: np.ndarray, name: str,
                      proxy: tuple | None = None) -> Canonicaliser:
        """The canonical frame of a target or source neutral (V,3) with faces (F,3), of the model's
        kind. With ``upright`` (the default) and the face frame, a head pitched 9° or more, or
        turned sideways 4° or more, from facing +z is turned upright first
        (``retarget.canonical.upright_rotation``, on ``proxy`` = (vertices, faces) of a decimated
        copy when given): the network was trained on upright heads, and its results are turned
        back into the mesh's own frame."""
        rotation = (upright_rotation(*(proxy or (vertices, faces)))
                    if self.upright and self.cfg.canonical == "face" else None)
        return Canonicaliser.fit(vertices, name=name, kind=self.cfg.canonical, faces=faces,
                                 rotation=rotation)

    def _prepare(self, mesh: Mesh, canon=None, ops=None) -> PreparedMesh:
        return prepare_mesh(mesh.vertices, mesh.faces, self.cfg.k_eig, self.cfg.image_size,
                            IMAGE_CHANNELS[self.cfg.image_channels], canon=canon, ops=ops,
                            cache_dir=self.cache_dir, canonical=self.cfg.canonical)

    @torch.no_grad()
    def prepare(self, mesh) -> Target:
        """Operators, frontal image, z_ID and skinning weights of a target neutral mesh: a Mesh, a
        ``trimesh.Trimesh`` or a ``(vertices, faces)`` pair (a Target is returned as it is). Of
        its face alone when it has separate parts and ``face_only`` (``Target.face``)."""
        if isinstance(mesh, Target):
            return mesh
        mesh = as_mesh(mesh, role="target")
        face = face_part(mesh) if self.face_only else None
        if face is None:
            return self._prepare_target(mesh)
        t = self._prepare_target(submesh(mesh, face))   # the face alone; the other parts keep
        return Target(mesh, t.proxy, t.feat, t.c, t.codes, face)   # their place

    def _prepare_target(self, mesh: Mesh) -> Target:
        """``prepare`` of a mesh taken whole (one part, or ``face_only`` off)."""
        check_head_like(mesh, "target")
        if mesh.n_vertices > self.proxy_vertices:
            (pv, pf), cluster = cluster_decimate(mesh.vertices, mesh.faces, self.proxy_vertices)
            canon = self.canonicaliser(mesh.vertices, mesh.faces, mesh.name or "target", (pv, pf))
            proxy = self._prepare(Mesh(pv, pf, mesh.name), canon=canon)
            feat = vertex_features(canon.to_canonical(mesh.vertices).astype(np.float32), mesh.faces)
        else:
            canon = self.canonicaliser(mesh.vertices, mesh.faces, mesh.name or "target")
            proxy, cluster = self._prepare(mesh, canon=canon), None
            feat = proxy.feat  # the proxy is the mesh itself: its features are computed already
        feat_p, img_p, ops_p = proxy.torch_inputs(self.device)
        c = self.model.image_code(img_p)[0]
        codes = self.model.encode_target(feat_p, c, ops_p, basis=cluster is None, chunk=self.chunk)
        feat = torch.from_numpy(feat).to(self.device)
        if cluster is not None and codes.omega_skin is not None:
            idx = torch.from_numpy(cluster).to(self.device)
            codes = TargetCodes(codes.z_id, codes.z_skin[idx], codes.omega_skin[idx])
            if self.cfg.decoder == "basis":   # the rig at full resolution; ω_Skin is folded into it
                codes = self.model.with_basis(feat, c, TargetCodes(codes.z_id, codes.z_skin, None),
                                              self.chunk)
        elif cluster is not None:
            codes = self.model.with_basis(feat, c, codes, self.chunk)
        return Target(mesh, proxy, feat, c, codes)

    # --------------------------------------------------------------------------- codes
    def source_topology(self, ref: Mesh, neutral: bool = False) -> SourceTopology:
        """The structure shared by the frames of ``ref``'s topology: from the in-memory cache, or
        computed on ``ref`` (proxy clustering above ``proxy_vertices``, canonicaliser, operators) and
        cached.

        The key is the vertex count and a hash of the face array, plus a hash of the vertices when
        ``ref`` is a source neutral (``neutral``), so each neutral keeps its own entry while frames
        without one share the entry of the first frame of their topology, and with it the turn
        that frame needed to face +z (``canonicaliser``) and its face part (``face_only``). The cache is an LRU of
        ``source_cache_size`` entries (0 = no cache: computed on every call);
        :meth:`clear_source_cache` empties it.
        """
        key = self._source_key(ref, neutral)
        if key in self._sources:
            self._sources.move_to_end(key)
            return self._sources[key]
        face = face_part(ref) if self.face_only else None
        own = ref if face is None else submesh(ref, face)   # the face alone
        if face is not None:
            check_head_like(own, "source")
        faces, cluster = own.faces, None
        if own.n_vertices > self.proxy_vertices:
            (_, faces), cluster = cluster_decimate(own.vertices, own.faces, self.proxy_vertices)
        pv = own.vertices if cluster is None else cluster_means(own.vertices, cluster)
        canon = self.canonicaliser(pv, faces, ref.name or "source")
        ops = load_or_compute_operators(canon.to_canonical(pv).astype(np.float32), faces,
                                        self.cfg.k_eig, cache_dir=self.cache_dir)
        src = SourceTopology(faces, cluster, canon, ops, ops.to_torch(self.device), face=face)
        if self.source_cache_size > 0:
            self._sources[key] = src
            while len(self._sources) > self.source_cache_size:
                self._sources.popitem(last=False)
        return src

    @staticmethod
    def _source_key(ref: Mesh, neutral: bool) -> tuple:
        """``source_topology``'s cache key of a reference mesh."""
        return (ref.n_vertices, _digest(ref.faces)) + ((_digest(ref.vertices),) if neutral else ())

    def clear_source_cache(self) -> None:
        """Forget the source topologies kept by :meth:`source_topology` (e.g. before streaming
        another performer of the same topology without a ``source_neutral``)."""
        self._sources.clear()

    @torch.no_grad()
    def encode(self, frames, source_neutral=None, progress: bool = False,
               blind: bool = True) -> np.ndarray:
        """Global expression codes z_GE of source frame(s): a mesh (a Mesh, a ``trimesh.Trimesh`` or
        a ``(vertices, faces)`` pair) or a list of frames sharing a topology -> (128,) or (T,128).

        The frames of a call share one canonical frame, that of ``source_neutral`` if given, else of
        the first frame; each frame's head motion against ``source_neutral``, or without it
        against the first frame, is removed first (``stabilise_frames``, unless ``stabilise`` is
        off). They share one set of operators (and, above ``proxy_vertices``, one
        vertex-clustered proxy: each frame's proxy vertex = the mean of its cluster), those of the
        source's topology, and the turn that faces it +z (``canonicaliser``): computed on
        ``source_neutral`` if given, else on the first frame of that
        topology this Retargeter saw, and kept for later calls (:meth:`source_topology`; bounded by
        ``source_cache_size``, emptied by :meth:`clear_source_cache`). So a stream of single-frame
        calls costs what one batched call does per frame. To switch to another performer of the same
        topology, pass their ``source_neutral`` or clear the cache. ``progress``: a tqdm bar.
        ``blind``: without ``source_neutral``, a model with a blind encoder
        (``NFSConfig.blind_encoder``) reads the frames by it (True) or by its neutral-aware
        encoder, its no-neutral flag set (False)."""
        from tqdm import tqdm

        frames, single = source_frames(frames)
        neutral = None if source_neutral is None else as_mesh(source_neutral, role="source neutral")
        if self.stabilise and (neutral is not None or len(frames) > 1):
            frames = self.stabilise_frames(frames, neutral or frames[0])[0]
        ref = neutral or frames[0]
        check_head_like(ref, "source")
        src = self.source_topology(ref, neutral=neutral is not None)
        canon = self._source_canon(src, ref, neutral is not None)
        use_neutral = self.cfg.neutral_channels and neutral is not None
        if use_neutral and src.neutral is None:
            # the neutral in its own canonical frame: the reference of the encoder's neutral channels
            base = canon.to_canonical(src.proxy(neutral).vertices).astype(np.float32)
            src.neutral = (base, vertex_normals(base.astype(np.float64), src.faces))
        codes = []
        for f in tqdm(frames, desc="encoding", unit="frame", disable=not progress or len(frames) < 2):
            if f.n_vertices != ref.n_vertices:
                raise RetargetError(f"{f.name or 'frame'}: {f.n_vertices} vertices, but the source has "
                                    f"{ref.n_vertices} ({ref.name or 'first frame'})")
            p = self._prepare(src.proxy(f), canon=canon, ops=src.ops)
            feat = torch.from_numpy(p.feat).to(self.device)
            img = torch.from_numpy(p.image)[None].to(self.device)
            channels = (torch.from_numpy(neutral_channels(p.vertices, src.neutral[0], p.faces,
                                                          p.normals, src.neutral[1]))
                        .to(self.device) if use_neutral else None)
            codes.append(self.model.encode_expression(feat, self.model.image_code(img)[0], src.ops_t,
                                                      channels, blind=blind))
        out = torch.stack(codes).cpu().numpy()
        return out[0] if single else out

    def _source_canon(self, src: SourceTopology, ref: Mesh, neutral: bool) -> Canonicaliser:
        """The canonical frame a source is read in: its neutral's (``src.canon``), or without a
        neutral the frame fitted on the take's first frame ``ref``, turned as the topology is."""
        if neutral:
            return src.canon
        return Canonicaliser.fit(src.proxy(ref).vertices, name=ref.name or "source",
                                 kind=self.cfg.canonical, faces=src.faces, rotation=src.canon.rotation)

    def carry_head_motion(self, frames, source_neutral, target, results):
        """Yield the results on ``target`` (an iterable of T frames (V,3), e.g. ``iter_decode``'s)
        one at a time, each moved as its source frame's head moved against ``source_neutral``
        (without one, against the first frame): the frame's motion (``stabilise_frames``)
        expressed in the source's canonical frame and applied in the target's
        (``retarget.stabilise.carry_motion``), to every vertex of the target mesh; (V,3) float64
        in the target's units."""
        frames, _ = source_frames(frames)
        neutral = None if source_neutral is None else as_mesh(source_neutral, role="source neutral")
        ref = neutral or frames[0]
        canon = self._source_canon(self.source_topology(ref, neutral=neutral is not None), ref,
                                   neutral is not None)
        target_canon = self.prepare(target).proxy.canon
        for motion, v in zip(self.stabilise_frames(frames, ref)[1], results):
            yield carry_motion(motion, canon, target_canon, v)

    def invert(self, frames, source_neutral: Mesh | None = None, smooth: str | None = None,
               fps: float = 30.0, progress: bool = False, refine: bool = False) -> np.ndarray:
        """Inverse rigging: frame(s) -> FACS weights (53,) or (T,53) in ICT order, clipped to [0,1].
        ``smooth``: None, "one_euro" (streaming) or "savgol" (offline) filtering over frames.
        ``refine``: analysis-by-synthesis on the source's own baked rig (needs ``source_neutral``;
        see ``refine``), the weights pulled towards the encoder's with ``REFINE_PRIOR_INVERT`` and
        towards 0 with ``REFINE_SPARSITY_INVERT``, reweighted by ``REFINE_REWEIGHT_INVERT``, each
        pull shared between the shapes by ``REFINE_BALANCE_INVERT``, a frame that moves many
        shapes fitted again by ``REFINE_DENSE_INVERT`` (``invert_fit``). A
        source with eyeballs (``source_eyes``) gives its eight look weights from their turn
        (``source_gaze``, ``retarget.eyes.weights_from_gaze``)."""
        z = self.encode(frames, source_neutral, progress)
        w = z[..., :N_FACS]
        if refine:
            w = self.invert_fit(frames, source_neutral, z).reshape(w.shape)
        eyes = self.source_eyes(frames, source_neutral)
        if eyes is not None:                                        # the looks its eyeballs show
            gaze = self._measured_gaze(eyes, frames, source_neutral)
            w = weights_from_gaze(gaze.reshape(w.shape[:-1] + (2, 2)), w)
        if smooth and w.ndim == 2:
            w = smooth_codes(w, smooth, fps)
        return np.clip(w, 0.0, 1.0).astype(np.float32)

    def invert_fit(self, frames, source_neutral: Mesh, z_ge: np.ndarray) -> np.ndarray:
        """Invert's weights by analysis-by-synthesis: ``refine_fit`` with invert's settings
        (``REFINE_PRIOR_INVERT``, ``REFINE_SPARSITY_INVERT``, ``REFINE_JOINT_INVERT``,
        ``REFINE_REWEIGHT_INVERT``, ``REFINE_BALANCE_INVERT``, ``REFINE_DENSE_INVERT``) -> (T,53)
        float32, as ``invert`` takes them before the gaze, smoothing and clipping."""
        return self.refine_fit(frames, source_neutral, z_ge, self.REFINE_PRIOR_INVERT,
                               self.REFINE_SPARSITY_INVERT, self.REFINE_JOINT_INVERT,
                               self.REFINE_REWEIGHT_INVERT, self.REFINE_BALANCE_INVERT,
                               self.REFINE_DENSE_INVERT)[0]

    # --------------------------------------------------------------------------- analysis by synthesis
    def source_rig(self, source_neutral: Mesh) -> SourceRig:
        """The 53 one-hot shapes decoded on ``source_neutral`` and their factorised normal equations,
        made once per neutral (cached by content, the last ``SOURCE_RIGS_KEPT``)."""
        source_neutral = as_mesh(source_neutral, role="source neutral")
        key = _rig_key(source_neutral)
        if key not in self._source_rigs:
            target = self.prepare(source_neutral)
            while len(self._source_rigs) >= self.SOURCE_RIGS_KEPT:
                self._source_rigs.pop(next(iter(self._source_rigs)))
            basis = target.codes.basis is not None         # the basis decoder: the free
            code_basis = basis_shapes(target, slice(None)) if basis else None    # dims' shapes too
            metric = None
            if (basis and self.code_map is not None and self.code_map_error is not None
                    and self.REFINE_METRIC_RHO is not None):    # the moments are the map's
                sigma = head_map_error(self.code_map_error, self.code_map_gate,
                                       target.codes.z_id.detach().cpu().numpy())
                metric = (code_basis, sigma, float(self.REFINE_METRIC_RHO))
            self._source_rigs[key] = SourceRig.make(
                target, self.bake(target, parts=False),
                None if code_basis is None else code_basis[N_FACS:], self.REFINE_FREE_PRIOR, metric)
        return self._source_rigs[key]

    def rest_vertices(self, source_neutral: Mesh) -> np.ndarray:
        """The indices (R,) int64 of a source neutral's rest vertices, on which its frames' head
        motion is fitted (``stabilise_frames``): those of its face the source's own rig moves
        least (``SourceRig.rest``). A neutral above ``proxy_vertices`` is not baked whole for this:
        the rig of its proxy is, and every vertex of the proxy's rest clusters is a rest vertex (at
        most ``MAX_REST``, evenly spaced). Kept with the neutral's source topology."""
        neutral = as_mesh(source_neutral, role="source neutral")
        if neutral.n_vertices <= self.proxy_vertices:        # encoded whole: its own rig's
            return self.source_rig(neutral).rest
        src = self.source_topology(neutral, neutral=True)
        if src.rest is None:
            if src.cluster is None:
                src.rest = self.source_rig(neutral).rest
            else:
                members = np.flatnonzero(np.isin(src.cluster, self.source_rig(src.proxy(neutral)).rest))
                members = members[np.unique(np.linspace(0, len(members) - 1, min(len(members), MAX_REST))
                                            .round().astype(np.int64))]
                src.rest = members if src.face is None else src.face[members]
        return src.rest

    def stabilise_frames(self, frames, source_neutral: Mesh) -> tuple[list[Mesh], list[RigidMotion]]:
        """The frames with their head motion against ``source_neutral`` removed, and that motion
        (``retarget.stabilise``): for each frame the rigid motion carrying the neutral onto it on
        the neutral's rest vertices, those the source's own rig (``source_rig``, baked once per
        neutral) moves least (``rest_vertices``), is fitted robustly and undone. Without a neutral
        mesh, ``encode`` and ``estimate_neutral`` pass a take's first frame as ``source_neutral``
        (its rig baked as if it were the neutral). A frame that does not move
        (``RigidMotion.still``) is returned as it is. frames: a Mesh or a list sharing the
        neutral's topology -> (list of Meshes in the neutral's frame, list of ``RigidMotion``).
        RetargetError naming the frame when its vertex count differs from the neutral's, or when
        even the best rigid fit leaves its vertices far from the neutral's (another vertex
        order, other units)."""
        frames, _ = source_frames(frames)
        neutral = as_mesh(source_neutral, role="source neutral")
        name = neutral.name or "the source neutral"
        for i, f in enumerate(frames):
            if f.n_vertices != neutral.n_vertices:
                raise RetargetError(f"{f.name or f'source frame {i}'}: {f.n_vertices} vertices, but "
                                    f"{name} has {neutral.n_vertices}; they must share a topology")
        rest = self.rest_vertices(neutral)
        out, motions = [], []
        for i, f in enumerate(frames):
            m = rigid_fit(f.vertices, neutral.vertices, rest)
            if m.mismatch > MISMATCH:
                raise RetargetError(
                    f"{f.name or f'source frame {i}'}: its vertices do not follow those of {name} one "
                    f"by one: even after the best rigid alignment the typical vertex lies "
                    f"{m.mismatch:.0%} of the head's size from its place on the neutral. Frames and "
                    f"neutral must share their vertex order and units")
            motions.append(m)
            out.append(f if m.still else Mesh(m.remove(f.vertices), f.faces, f.name))
        return out, motions

    def refine(self, frames, source_neutral: Mesh, z_ge: np.ndarray,
               prior: float | None = None, sparsity: float | None = None,
               joint: bool | None = None, reweight: tuple = (),
               balance: float | None = None) -> np.ndarray:
        """Analysis-by-synthesis (``refine_fit``), as the codes z_GE the decoder draws the fit with
        (``rig_codes``): (128,) or (T,128) like ``z_ge``, float32."""
        return self._refined(frames, source_neutral, z_ge, prior, sparsity, joint, reweight,
                             balance)[0]

    def _refined(self, frames, source_neutral: Mesh, z_ge: np.ndarray, prior=None, sparsity=None,
                 joint=None, reweight=(), balance=None) -> tuple[np.ndarray, np.ndarray]:
        """``refine``'s codes, shaped like ``z_ge``, and the fitted weights they stand for, (53,) or
        (T,53)."""
        w, f = self.refine_fit(frames, source_neutral, z_ge, prior, sparsity, joint, reweight,
                               balance)
        codes = self.rig_codes(w, f, self.source_rig(source_neutral).target).reshape(np.shape(z_ge))
        return codes, w.reshape(np.shape(z_ge)[:-1] + (N_FACS,))

    def rig_codes(self, w: np.ndarray, f: np.ndarray, target) -> np.ndarray:
        """The codes z_GE of weights w (T,53) on ``target``'s rig plus free dims f
        (T, code_dim − 53): ``weight_codes(w, target)`` with f added to its free dims ->
        (T, code_dim) float32. Decoded on another target, the code draws the weights with the
        first target's code map (the same map where the map has no gate, or for two heads the
        gate tells alike)."""
        z = self.weight_codes(w, target)
        z[:, N_FACS:] += f
        return z

    def refine_fit(self, frames, source_neutral: Mesh, z_ge: np.ndarray,
                   prior: float | None = None, sparsity: float | None = None,
                   joint: bool | None = None, reweight: tuple = (),
                   balance: float | None = None, dense: tuple = ()) -> tuple[np.ndarray, np.ndarray]:
        """Analysis-by-synthesis: the decoder's rig baked on the source's own neutral (once,
        ``source_rig``) is fitted to each frame by bounded least squares in [0,1] with the encoder's
        weights z_GE[:53] as the prior (``SourceRig.fit``); then the free dims of the code are
        fitted to what the weights leave, the weights held: for the basis decoder always and
        exactly, by ridge least squares on its rig (``SourceRig.fit_free``), for the MLP decoder
        by ``refine_steps`` Adam steps through the decoder on the source neutral (``REFINE_ROWS``
        fixed vertices; 0 = the code is [w, 0]). frames: a Mesh or a list sharing the neutral's
        topology; z_ge (128,) or (T,128) -> the weights w (T,53) and the free dims f
        (T, code_dim − 53), float32 (the rig's coordinates: with a ``code_map`` the code they
        stand for is ``rig_codes(w, f, source)``, not [w, f]). prior: the weights' pull
        towards the encoder (default ``REFINE_PRIOR``); sparsity: their L1 pull towards 0
        (``SourceRig.fit``; default ``REFINE_SPARSITY``). joint: weights and free dims fitted
        together (``SourceRig.fit_joint``, basis decoder; default ``REFINE_JOINT``). reweight:
        reweighted L1 of the weights-alone fit (``SourceRig.fit``; () = off); balance: how that
        fit shares its pulls between large and small shapes (``SourceRig.fit``; default
        ``REFINE_BALANCE``; the joint fit pulls every weight alike); dense: that fit's second fit
        of a frame that moves many shapes (``SourceRig.fit``; () = off). The frames' head
        motion is removed first (``stabilise_frames``, unless ``stabilise`` is off)."""
        if source_neutral is None:
            raise RetargetError("refine needs the source's neutral (source_neutral= in the API, "
                                "--source-neutral on the command line)")
        frames, _ = source_frames(frames)
        if self.stabilise:
            frames = self.stabilise_frames(frames, source_neutral)[0]
        z = np.asarray(z_ge, np.float32).reshape(len(frames), -1)
        rig = self.source_rig(source_neutral)
        prior = self.REFINE_PRIOR if prior is None else prior
        sparsity = self.REFINE_SPARSITY if sparsity is None else sparsity
        balance = self.REFINE_BALANCE if balance is None else balance
        joint = (self.REFINE_JOINT if joint is None else joint) and rig.free_basis is not None
        out = np.zeros_like(z)
        for i, frame in enumerate(frames):
            w0 = np.clip(z[i, :N_FACS], 0.0, 1.0)
            with one_blas_thread():
                if joint:
                    out[i, :N_FACS], out[i, N_FACS:] = rig.fit_joint(frame.vertices, w0, prior,
                                                                     sparsity)
                    continue
                out[i, :N_FACS] = rig.fit(frame.vertices, w0, prior, sparsity, reweight, balance,
                                          dense)
                if rig.free_basis is not None:
                    out[i, N_FACS:] = rig.fit_free(frame.vertices, out[i, :N_FACS])
            if rig.free_basis is None and self.refine_steps > 0:
                out[i, N_FACS:] = self._refine_free_dims(rig, frame.vertices, out[i, :N_FACS])
        return out[:, :N_FACS], out[:, N_FACS:]

    def fit_residuals(self, frames, source_neutral: Mesh, weights) -> tuple[np.ndarray, np.ndarray]:
        """How much of each frame the weights explain on the source's own rig (``source_rig``:
        the network's 53 shapes baked on ``source_neutral``, with the code map where the model
        has one): the RMS over vertices of the residual frame − ``BakedRig.evaluate(w)``, and of
        the frame's motion frame − source_neutral, both (T,) float32 in the source's units. Their
        ratio is the share of a frame's motion the weights leave unexplained (0: all of it
        explained; 1: as far off as the neutral). Frames far above a take's median are worth a look: an
        expression outside the 53 FACS shapes, a bad scan, a wrong neutral. The network's shapes
        are not the performer's exactly (docs/RESULTS.md, "What the weights' error is made of"),
        so even the true weights leave some residual. frames: a Mesh or a list sharing the
        neutral's topology; weights (53,) or (T,53), e.g. from ``invert``."""
        frames, neutral = _residual_frames(frames, source_neutral, weights, N_FACS, "fit_residuals",
                                           "weights")
        frames = self.stabilise_frames(frames, neutral)[0] if self.stabilise else frames
        rig = self.source_rig(neutral)
        w = np.asarray(weights, np.float32).reshape(len(frames), N_FACS)
        return _residual_rms(frames, rig.baked.evaluate(w), rig.target.mesh.vertices)

    def code_residuals(self, frames, source_neutral: Mesh, codes) -> tuple[np.ndarray, np.ndarray]:
        """How much of each frame the codes z_GE explain on the source itself: the codes decoded on
        ``source_neutral`` (what ``transfer`` sends to the target, drawn back on the performer),
        as ``fit_residuals`` measures it: the RMS over vertices of frame − decoded and of frame −
        source_neutral, both (T,) float32 in the source's units. codes (128,) or (T,128), e.g.
        ``expression_codes(frames, source_neutral, refine=True)``."""
        frames, neutral = _residual_frames(frames, source_neutral, codes, self.cfg.code_dim,
                                           "code_residuals", "codes")
        frames = self.stabilise_frames(frames, neutral)[0] if self.stabilise else frames
        rig = self._source_rigs.get(_rig_key(neutral))
        target = rig.target if rig is not None else self.prepare(neutral)   # refine's, if made
        z = np.asarray(codes, np.float32).reshape(len(frames), self.cfg.code_dim)
        return _residual_rms(frames, self._iter_decode_face(target, z), target.mesh.vertices)

    def estimate_neutral(self, frames, max_frames: int | None = None) -> Mesh:
        """The performer's neutral estimated from a take alone, for a source without its neutral
        mesh (``--estimate-neutral``; beyond the paper): each frame f_t is encoded without a
        neutral (z_t), the codes are decoded on the first frame taken as the identity, and the
        neutral is the per-coordinate median over the frames of f_t − D(f_1, z_t). Each frame's
        reading is off by the no-neutral error, but the errors of different expressions largely
        cancel in the median, so the estimate can then serve as ``source_neutral``, with
        ``refine`` (docs/RESULTS.md, "A neutral estimated from the take"). A take of one frame gives
        that frame's own reading back; the more varied the take, the better the estimate. A model
        with a blind encoder (``NFSConfig.blind_encoder``) reads the frames here by its
        neutral-aware encoder (``encode(..., blind=False)``): its estimates were the better ones
        (docs/RESULTS.md, "Stage 21").

        frames: a Mesh or a list of frames sharing a topology (at most ``max_frames``, default
        ``ESTIMATE_FRAMES``, evenly spaced, are used; their head motion against the first of them
        removed first, unless ``stabilise`` is off) -> a Mesh of their topology, in the first
        frame's place and units."""
        frames, _ = source_frames(frames)
        n = min(len(frames), int(max_frames or self.ESTIMATE_FRAMES))
        picked = [frames[i] for i in np.unique(np.linspace(0, len(frames) - 1, n).round().astype(int))]
        if self.stabilise and len(picked) > 1:        # in the first frame's place
            picked = self.stabilise_frames(picked, picked[0])[0]
        z = self.encode(picked, blind=False)                     # (T', 128): a list always
        first = picked[0]
        identity = self.prepare(first)
        readings = np.empty((len(picked),) + first.vertices.shape, np.float32)
        for i, (frame, decoded) in enumerate(zip(picked, self._iter_decode_face(identity, z))):
            readings[i] = frame.vertices - (decoded - first.vertices)   # f_t − D(f_1, z_t)
        return Mesh(np.median(readings, axis=0).astype(np.float64), first.faces, "estimated neutral")

    def _refine_free_dims(self, rig: SourceRig, frame: np.ndarray, w: np.ndarray) -> np.ndarray:
        """The free dims f of z_GE = [w, f] (f from 0) after ``refine_steps`` Adam steps on the
        canonical squared error of the decoded source neutral against ``frame`` (V,3), on up to
        ``REFINE_ROWS`` vertices -> (code_dim − 53,) float32."""
        t = rig.target
        n = len(t.feat)                                   # the face's vertices
        rows = (np.random.default_rng(0).choice(n, self.REFINE_ROWS, replace=False)
                if n > self.REFINE_ROWS else np.arange(n))
        goal = torch.from_numpy(t.proxy.canon.displacement_to_canonical(
            t.on_face(frame)[rows] - t.on_face(t.mesh.vertices)[rows]).astype(np.float32)).to(self.device)
        rows_t = torch.from_numpy(rows).to(self.device)
        w_t = torch.from_numpy(w).to(self.device)
        free = torch.zeros(self.cfg.code_dim - N_FACS, device=self.device, requires_grad=True)
        opt = torch.optim.Adam([free], lr=0.05)
        with torch.enable_grad():
            for _ in range(self.refine_steps):
                dv = self.model.decode_target(t.feat, t.c, t.codes, torch.cat([w_t, free]), rows_t)
                loss = (dv - goal).square().sum(-1).mean()
                opt.zero_grad(set_to_none=True)
                (grad,) = torch.autograd.grad(loss, free)
                free.grad = grad
                opt.step()
        return free.detach().cpu().numpy()

    # --------------------------------------------------------------------------- decoding
    def decode(self, target, z_ge, progress: bool = False, gaze=None) -> np.ndarray:
        """Target vertices for expression code(s) z_GE (128,) or (T,128) -> (V,3) or (T,V,3) float64,
        in the target's frame and units. ``progress``: a tqdm bar over frames. gaze: None, or
        (2,2) / (T,2,2) the gaze its eyes turn to (``iter_decode``). For long sequences on big
        targets, ``iter_decode`` yields the frames one at a time instead."""
        z = np.asarray(z_ge, np.float32)
        frames = np.stack(list(self.iter_decode(target, z.reshape(-1, z.shape[-1]), progress, gaze)))
        return frames[0] if z.ndim == 1 else frames

    def iter_decode(self, target, z_ge, progress: bool = False, gaze=None):
        """Yield the target's vertices (V,3) float64 for each code of z_GE (T,128), one frame at a
        time: the memory of one frame whatever T (a 1M-vertex frame is 24 MB). A target's parts
        that its jaw carries (``jaw_parts``) move with its chin; its eyeballs (``eyes``) turn to
        ``gaze`` (T,2,2) radians (``retarget.eyes``; None: they stay at rest, as its other parts do)."""
        target = self.prepare(target)
        jaw, eyes = self.jaw_parts(target), None
        if gaze is not None:
            eyes = self.eyes(target)
            gaze = np.asarray(gaze, np.float64).reshape(-1, 2, 2)
            if len(gaze) != len(z_ge):
                raise RetargetError(f"iter_decode: {len(gaze)} gazes for {len(z_ge)} codes")
        for t, frame in enumerate(self._iter_decode_face(target, z_ge, progress)):
            if jaw is not None:
                frame = jaw.carry(frame)
            yield frame if eyes is None else eyes.pose(frame, gaze[t])

    def _iter_decode_face(self, target: Target, z_ge, progress: bool = False):
        """``iter_decode`` with every part beside the face at rest (the decoder's output alone)."""
        from tqdm import tqdm

        z = torch.as_tensor(np.asarray(z_ge, np.float32), device=self.device)
        if z.dim() != 2:
            raise RetargetError(f"iter_decode: codes must be (T, {z.shape[-1]}), got {tuple(z.shape)}")
        for zi in tqdm(z, desc="decoding", unit="frame", disable=not progress or len(z) < 2):
            with torch.no_grad():
                dv = self.model.decode_target(target.feat, target.c, target.codes, zi, chunk=self.chunk)
            yield (target.mesh.vertices
                   + target.on_mesh(target.proxy.canon.displacement_from_canonical(dv.cpu().numpy())))

    def expression_codes(self, source, source_neutral: Mesh | None = None,
                         smooth: str | None = None, fps: float = 30.0,
                         progress: bool = False, refine: bool = False,
                         refine_prior: float | None = None,
                         refine_sparsity: float | None = None,
                         refine_joint: bool | None = None,
                         refine_reweight: tuple = (),
                         refine_balance: float | None = None) -> np.ndarray:
        """What ``transfer`` decodes: z_GE of the source frame(s), (128,) or (T,128), refined by
        analysis-by-synthesis when ``refine`` (``refine``, with ``refine_prior``,
        ``refine_sparsity``, ``refine_joint``, ``refine_reweight`` and ``refine_balance``),
        temporally filtered when ``smooth`` is given (see ``invert``)."""
        z = self._codes_weights(source, source_neutral, progress, refine, refine_prior,
                                refine_sparsity, refine_joint, refine_reweight, refine_balance)[0]
        if smooth and z.ndim == 2:
            z = smooth_codes(z, smooth, fps)
        return z

    def _codes_weights(self, source, source_neutral, progress: bool, refine: bool, prior=None,
                       sparsity=None, joint=None, reweight=(),
                       balance=None) -> tuple[np.ndarray, np.ndarray]:
        """``expression_codes`` before smoothing, and the FACS weights the codes stand for: with
        ``refine`` the fitted ones, else the encoder's clipped to [0,1] -> ((128,) or (T,128),
        (53,) or (T,53))."""
        z = self.encode(source, source_neutral, progress)
        if not refine:
            return z, np.clip(z[..., :N_FACS], 0.0, 1.0)
        return self._refined(source, source_neutral, z, prior, sparsity, joint, reweight, balance)

    def expression(self, source, source_neutral: Mesh | None = None, smooth: str | None = None,
                   fps: float = 30.0, progress: bool = False,
                   refine: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """What ``transfer`` draws on a target: the codes z_GE of ``expression_codes`` and the gaze
        its eyes turn to (``source_gaze``: of the source's eyeballs, or without them of the weights
        the codes stand for), both filtered alike when ``smooth`` is given -> ((128,) or (T,128),
        (2,2) or (T,2,2) radians)."""
        z, w = self._codes_weights(source, source_neutral, progress, refine)
        gaze = self.source_gaze(source, source_neutral, w).reshape(np.shape(z)[:-1] + (2, 2))
        if smooth and z.ndim == 2:
            z = smooth_codes(z, smooth, fps)
            gaze = smooth_codes(gaze.reshape(len(gaze), 4), smooth, fps).reshape(gaze.shape)
        return z, gaze

    def source_eyes(self, frames, source_neutral: Mesh | None = None) -> Eyes | None:
        """A source's eyeballs (``retarget.eyes``) at rest in its neutral, without one in the
        frames' first, found once per source topology; None for a source of one part, without
        ``turn_eyes`` or ``face_only``, or when no pair of its parts is a pair of eyeballs."""
        if not self.turn_eyes:
            return None
        frames, _ = source_frames(frames)
        neutral = None if source_neutral is None else as_mesh(source_neutral, role="source neutral")
        ref = neutral or frames[0]
        if (self._source_key(ref, neutral is not None) not in self._sources
                and (not self.face_only or face_part(ref) is None)):
            return None                     # one part: no eyes, and no operators computed for it
        src = self.source_topology(ref, neutral=neutral is not None)
        if src.face is None:
            return None
        if not src.eyes_found:
            src.eyes = find_eyes(ref.vertices, ref.faces, src.face, src.canon.to_canonical,
                                 src.canon.rotation)
            src.eyes_found = True
        return None if src.eyes is None else src.eyes.at(ref.vertices)

    def source_gaze(self, frames, source_neutral: Mesh | None = None, weights=None) -> np.ndarray:
        """The gaze (T,2,2) of source frame(s) (radians, ``retarget.eyes``): that of the source's
        eyeballs (``source_eyes``; ``Eyes.measure`` once the frames' head motion is removed) against
        its neutral; without one, against the frames' median gaze (the take looks ahead on
        average; a single frame looks ahead); for a source without eyeballs that of ``weights``
        (T,53) (``gaze_from_weights``; RetargetError when they are not given)."""
        eyes = self.source_eyes(frames, source_neutral)
        if eyes is None:
            if weights is None:
                raise RetargetError("source_gaze: the source has no eyeballs; give the weights")
            return gaze_from_weights(np.asarray(weights, np.float64).reshape(-1, N_FACS))
        return self._measured_gaze(eyes, frames, source_neutral)

    def _measured_gaze(self, eyes: Eyes, frames, source_neutral: Mesh | None) -> np.ndarray:
        """``source_gaze`` of a source with eyeballs ``eyes`` (``source_eyes``): (T,2,2) radians."""
        frames, _ = source_frames(frames)
        neutral = None if source_neutral is None else as_mesh(source_neutral, role="source neutral")
        if self.stabilise and (neutral is not None or len(frames) > 1):
            frames = self.stabilise_frames(frames, neutral or frames[0])[0]
        gaze = np.stack([eyes.measure(f.vertices) for f in frames])
        if neutral is None:     # against the take's median gaze: ahead is where it looks on average
            gaze -= np.median(gaze, axis=0)
        return gaze

    def transfer(self, source, target, source_neutral: Mesh | None = None,
                 smooth: str | None = None, fps: float = 30.0, progress: bool = False,
                 refine: bool = False, head_motion: bool = False) -> np.ndarray:
        """Clone the expression of source frame(s) onto a target neutral mesh (any topology).
        source: a Mesh or a list of frames -> (V_tgt,3) or (T,V_tgt,3) in the target's units.
        ``refine``: codes from analysis-by-synthesis on the source (needs ``source_neutral``).
        The source's head motion is removed (``stabilise``) and the results carry the expression
        alone; ``head_motion``: then carry the head motion onto the target too
        (``carry_head_motion``; needs ``stabilise``). A target's eyeballs turn with the source's
        (``expression``)."""
        if head_motion and not self.stabilise:
            raise RetargetError("head_motion needs stabilise: the head motion is what stabilisation "
                                "finds (--head-motion cannot go with --no-stabilise)")
        target = self.prepare(target)
        z, gaze = self.expression(source, source_neutral, smooth, fps, progress, refine)
        out = self.decode(target, z, progress, gaze)
        if not head_motion:
            return out
        return np.stack(list(self.carry_head_motion(source, source_neutral, target,
                                                    out.reshape(-1, *out.shape[-2:])))).reshape(out.shape)

    def animate(self, target, weights, progress: bool = False) -> np.ndarray:
        """Drive a target from FACS weights: (53,) or (T,53) arrays in ICT order, or a dict / list
        of dicts {ICT name: value} -> (V,3) or (T,V,3), decoded from ``weight_codes``; its
        eyeballs turn with the looks (``retarget.eyes.gaze_from_weights``)."""
        w = weights_array(weights)
        frames = np.stack(list(self.iter_animate(target, w.reshape(-1, N_FACS), progress)))
        return frames[0] if w.ndim == 1 else frames

    def iter_animate(self, target, weights, progress: bool = False):
        """``animate`` one frame at a time (``iter_decode``): weights (T,53) (as ``weights_array``
        takes them) -> yields (V,3) float64."""
        target = self.prepare(target)
        w = weights_array(weights).reshape(-1, N_FACS)
        yield from self.iter_decode(target, self.weight_codes(w, target), progress, gaze_from_weights(w))

    def weight_codes(self, weights, target) -> np.ndarray:
        """FACS weights (as ``weights_array`` takes them) -> the codes z_GE that draw them on
        ``target`` (a mesh or a prepared target), (128,) or (T,128) float32: z_GE = [w, 0] (the
        paper's), or M w with the target's code map M (``head_code_map``, (code_dim, 53): the
        code of each FACS shape, ``retarget.code_map``)."""
        if self.code_map is None:
            return weight_codes(weights)
        return (weights_array(weights) @ self.head_code_map(self.prepare(target)).T).astype(np.float32)

    def bake(self, target, parts: bool = True) -> BakedRig:
        """Decode the 53 one-hot expressions once: a linear blendshape rig for the target. With the
        basis decoder it is the decoder's own rig, ``codes.basis`` (exact for FACS-weight codes).
        Each shape moves the parts the target's jaw carries (``jaw_parts``) as it moves the chin,
        and each look shape turns the eyeballs (``eyes``) as a look at weight 1 does;
        ``parts=False``: every part beside the face at rest (the rig that refine fits)."""
        target = self.prepare(target)
        rig = self._bake_face(target)
        if not parts:
            return rig
        jaw, eyes = self.jaw_parts(target), self.eyes(target)
        deltas = rig.deltas if jaw is None else jaw.carry_shapes(rig.deltas, rig.neutral)
        deltas = deltas if eyes is None else eyes.pose_shapes(deltas)
        return rig if deltas is rig.deltas else BakedRig(rig.neutral, deltas)

    def _bake_face(self, target: Target, names=None) -> BakedRig:
        """``bake`` with every part beside the face at rest, of the FACS shapes ``names`` (default
        all 53, in ICT order)."""
        idx = np.arange(N_FACS) if names is None else np.array([FACS_INDEX[n] for n in names])
        if target.codes.basis is not None:            # the code of each shape: [e_k, 0] or M e_k
            cmap = self.head_code_map(target)
            codes = np.eye(self.cfg.code_dim, dtype=np.float32) if cmap is None else cmap
            return BakedRig(target.mesh.vertices.astype(np.float32),
                            basis_shapes(target, None, codes[:, idx]))
        onehot = np.zeros((len(idx) + 1, N_FACS), np.float32)
        onehot[np.arange(1, len(idx) + 1), idx] = 1.0
        shapes = np.stack(list(self._iter_decode_face(target, self.weight_codes(onehot, target))))
        return BakedRig(shapes[0].astype(np.float32), (shapes[1:] - shapes[0]).astype(np.float32))

    def jaw_parts(self, target) -> JawParts | None:
        """The parts beside a target's face that its jaw carries (lower teeth, a tongue;
        ``retarget.jaw``), found once per target from its own baked jaw and mouth shapes; None
        for a mesh of one part, without ``carry_jaw``, or when no part lies below the mouth."""
        target = self.prepare(target)
        if target.face is None or not self.carry_jaw:
            return None
        if not target.jaw_found:
            shapes = self._bake_face(target, JAW_SHAPES).deltas[:, target.face]
            target.jaw = find_jaw_parts(target.mesh.vertices, target.mesh.faces, target.face,
                                        shapes, target.proxy.canon.to_canonical)
            target.jaw_found = True
        return target.jaw

    def eyes(self, target) -> Eyes | None:
        """A target's eyeballs (``retarget.eyes``: two near-spheres beside the face, mirrored across
        it, with the parts inside them), found once per target; None for a mesh of one part (or
        without ``face_only``), without ``turn_eyes``, or when no pair of its parts is a pair of
        eyeballs."""
        target = self.prepare(target)
        if target.face is None or not self.turn_eyes:
            return None
        if not target.eyes_found:
            canon = target.proxy.canon
            target.eyes = find_eyes(target.mesh.vertices, target.mesh.faces, target.face,
                                    canon.to_canonical, canon.rotation)
            target.eyes_found = True
        return target.eyes


def weight_codes(weights) -> np.ndarray:
    """FACS weights (as ``weights_array`` takes them) -> expression codes z_GE = [w, 0], (128,) or
    (T,128) float32: what ``Retargeter.animate`` decodes."""
    return weights_to_code(torch.from_numpy(weights_array(weights))).numpy()


def weights_array(weights) -> np.ndarray:
    """(53,) / (T,53) arrays, or {name: value} dict(s) with ICT names -> float32 array."""
    if isinstance(weights, dict):
        return weights_array([weights])[0]
    if isinstance(weights, (list, tuple)) and weights and isinstance(weights[0], dict):
        out = np.zeros((len(weights), N_FACS), np.float32)
        for t, frame in enumerate(weights):
            unknown = sorted(set(frame) - set(FACS_INDEX))
            if unknown:
                raise RetargetError(f"unknown FACS weight names: {', '.join(unknown)}")
            for name, value in frame.items():
                out[t, FACS_INDEX[name]] = value
        return out
    w = np.asarray(weights, np.float32)
    if w.shape[-1] != N_FACS or w.ndim not in (1, 2):
        raise RetargetError(f"weights must be (53,) or (T,53) in ICT order, got shape {w.shape}")
    return w
