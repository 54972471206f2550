"""The accuracy suites of ``retarget eval`` (DESIGN.md section 6), as plain dicts and markdown.

Test data are procedural rigs of *test* identities (``sample_identity(i, split="test")``; an eval
config with ``split: val`` draws validation identities instead, e.g. ``configs/eval/validation.yaml``
for choosing between models), so every number below has exact ground truth unless a table says
otherwise:

- ``self``: source = target = one identity on one tessellation; GT = that rig with the source's weights.
- ``cross_identity``: source identity A → target identity B (same tessellation); GT = B's rig with A's
  weights.
- ``cross_topology``: as cross-identity, source and target tessellated differently (coarse ↔ fine,
  full head ↔ face crop, regular ↔ jittered).
- ``inverse``: weights predicted from a frame of an identity's rig, re-applied to that rig: MSE to
  the frame, and the weight MAE.
- ``animate``: the self cases driven from their FACS weights instead of a source mesh (z_GE =
  [w, 0], the user's "drive any mesh from weights" job); beside ``self`` on the same targets and
  weights it splits the error between the expression encoder and the decoder.
- ``jitter``: cross-identity transfer of a smooth weight sequence: the mean norm of the second
  difference of the vertex positions (mm), prediction vs GT, raw and with each temporal filter.
- ``real_rig``: the artist-made ARKit rig ``makehuman_arkit.npz`` (one MakeHuman identity):
  real → real self-retargeting and inversion of its frames (exact GT), procedural → real and
  real → procedural (GT = the other rig driven by the same FACS weights: *semantic*, not exact,
  because two artists' shapes of one name differ), per ARKit shape (one-hot) and on sampled weights;
  and the real rig's neutral driven from the true weights (mapped to ICT names; the decoder alone),
  with the do-nothing error (the neutral itself) beside it; and the floor, the unmoved neutral
  given as the source frame and transferred onto itself (doing nothing is exact there, so it has
  no ratio: an absolute error in mm²).

- ``head_self``, ``head_cross_identity``, ``head_cross_topology``, ``head_cross_crop``: realistic
  held-out heads (``data_synth.makehuman``: ``sample_head_identity(seed + i, split="test")``, the
  artist's ARKit shapes carried onto each by deformation transfer, ``head_tessellation`` crops and
  remeshes; the ``heads`` section of the config), exact GT as for the procedural suites: one
  identity on one tessellation; identity i -> i+1; i -> i+1 across tessellations; and one identity
  across crops (bust -> head, face mask -> bust). Shapes an identity lacks get weight 0.
  ``head_inverse`` and ``head_animate``: inverse rigging and driving from FACS weights on the
  realistic heads, as ``inverse`` and ``animate`` are on the procedural ones.
- ``frame``: no method, the canonical frames themselves (``retarget.canonical``): the MakeHuman head
  of ``data_synth/makehuman/data`` as face mask, head, head with eye sockets and mouth cavity, and
  bust (:func:`makehuman_crops`), and each test identity's procedural full head against its face
  crop: the scale of each crop relative to the reference and how far its canonical origin moves
  (mm), for the bounding-box and the face frame; and the same for each realistic test head
  (``heads``) as face, head, head_neck and bust crops.

Every transfer suite also reports the segment-averaged MSE of NFS Table 1 (mean over the L = 20
segments of each segment's MSE) and the per-segment MSE. Errors are in mm² (``retarget.metrics``).

Methods are rows: one per checkpoint (the model and its ablations) and three baselines that depend
only on the eval config:

- ``do nothing``: the target left neutral (inverse rigging: weights 0, re-applied to the rig), in
  every suite. Every error is also given as a ratio to the do-nothing error of the same cases
  (``ratios`` of each suite; jitter has none, doing nothing does not move);
- ``closest point``: each target vertex takes the displacement of the nearest source vertex once
  both neutrals are canonicalised in the face frame (``retarget.oracle.closest_point_transfer``).
  Every suite gives it the source rig's neutral, as the network gets it (``source_neutral``). It
  is exact on self-retargeting (one mesh) by construction, and the peer to beat across identities
  and topologies. Inverse rigging and driving from FACS weights need a rig: there it is the
  packaged MakeHuman ARKit rig carried onto the mesh by closest point, driven by the weights or
  fitted to each frame by bounded least squares (what an artist with an ARKit head tries first;
  on the real rig, which is that template, it is exact);
- ``oracle (u,v)``: displacement transfer through the known (u, v) correspondence
  (``retarget.oracle``), which needs (u, v) on both meshes and so has no real-rig, inverse-rigging
  or animate numbers.
"""
from __future__ import annotations

import copy
import hashlib
import math
import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from data_synth.facs import FACS_NAMES, N_FACS, arkit_to_ict
from data_synth.identity import sample_identity
from data_synth.makehuman.assets import DATA_DIR
from data_synth.rig import build_rig
from data_synth.sampling import sample_weights, smooth_sequence
from data_synth.tessellate import tessellate

from .canonical import FRAMES, Canonicaliser
from .config import configs_dir, find_config, merge, read_yaml
from .errors import RetargetError
from .io import regular_file
from .mesh import Mesh
from .metrics import (second_difference_jitter_mm, segment_mse_mm2, squared_errors_mm2, standard_error,
                      weight_mae)
from .oracle import (closest_point_rig, closest_point_transfer, displacement_transfer, fit_rig_weights,
                     uv_transfer_matrix)
from .smoothing import FILTERS, smooth_codes

#: Suite names; a suite's index seeds its weights, so new suites go at the end.
SUITES = ("self", "cross_identity", "cross_topology", "inverse", "jitter", "real_rig", "animate",
          "frame", "head_self", "head_cross_identity", "head_cross_topology", "head_cross_crop",
          "head_inverse", "head_animate")
TRANSFER_SUITES = ("self", "cross_identity", "cross_topology", "head_self", "head_cross_identity",
                   "head_cross_topology", "head_cross_crop")
#: Transfer suites whose cases come in named pairs of tessellations or crops (a column each).
PAIRED_SUITES = ("cross_topology", "head_cross_topology", "head_cross_crop")
REPO_ROOT = Path(__file__).resolve().parents[1]
ORACLE_NAME = "oracle (u,v)"
DO_NOTHING_NAME = "do nothing"
CLOSEST_POINT_NAME = "closest point"
#: The template rig of the closest-point baseline's weight-driven suites: the packaged MakeHuman
#: ARKit rig (MIT; data_synth/makehuman/data/LICENSES.md).
TEMPLATE_RIG = DATA_DIR / "makehuman_arkit.npz"
#: Rows that depend only on the eval config, in table order around the checkpoints' rows.
BASELINES_FIRST, BASELINES_LAST = (DO_NOTHING_NAME,), (CLOSEST_POINT_NAME, ORACLE_NAME)
#: How a checkpoint is given the source (``retarget eval --neutral-modes``): without its neutral
#: (frames canonicalised on the first), with it (the default: canonical frame, operators and, for a
#: neutral-aware model, the encoder's neutral channels), with it plus analysis-by-synthesis, and
#: without it but with one estimated from the case's own frames, then analysis-by-synthesis on that
#: (``Retargeter.estimate_neutral``: what ``--estimate-neutral --refine`` gives a user).
NEUTRAL_MODES = {"none": "no neutral", "neutral": "neutral", "refine": "neutral + refine",
                 "estimate": "estimated neutral + refine"}
#: The modes that fit the frames on the source's rig (``Retargeter.refine``).
REFINE_MODES = ("refine", "estimate")


# ------------------------------------------------------------------------------------- config
#: The identity splits an eval config may draw its rigs from (``split``): the test set, or the
#: validation identities, to choose between models without looking at the test set. Never train.
EVAL_SPLITS = ("test", "val")


def load_eval_config(path=None) -> dict:
    """The eval config: ``configs/eval/default.yaml`` (every key, the committed settings), with the
    keys of ``path`` (a file, e.g. ``configs/eval/tiny.yaml``, or a shipped name such as ``tiny``)
    overriding it. RetargetError names the file and the unknown key."""
    default = configs_dir() / "eval" / "default.yaml"
    base = read_yaml(default, "eval config")
    if path is None:
        return base
    path = find_config(path, "eval")
    if path.resolve() == default.resolve():
        return base
    cfg = merge(base, read_yaml(path, "eval config"), str(path))
    if cfg["split"] not in EVAL_SPLITS:
        raise RetargetError(f"{path}: split must be one of {', '.join(EVAL_SPLITS)}, got {cfg['split']!r}")
    return cfg


def real_rig_path(cfg: dict) -> Path:
    """The eval config's real rig: ``real_rig.path``, relative to the repository root."""
    return REPO_ROOT / cfg["real_rig"]["path"]


# ------------------------------------------------------------------------------------- ARKit
def arkit_ict_matrix(arkit_names) -> np.ndarray:
    """(K_arkit, 53) 0/1 matrix M: ICT weights = ARKit weights @ M (``browInnerUp`` and
    ``cheekPuff`` feed both ICT halves, ``tongueOut`` none). Raises RetargetError for unknown names."""
    index = {n: i for i, n in enumerate(FACS_NAMES)}
    m = np.zeros((len(arkit_names), N_FACS))
    for k, name in enumerate(arkit_names):
        try:
            for ict in arkit_to_ict(str(name)):
                m[k, index[ict]] = 1.0
        except KeyError:
            raise RetargetError(f"real rig: {name!r} is not an ARKit blendshape name") from None
    return m


def ict_to_arkit_weights(w: np.ndarray, m: np.ndarray) -> np.ndarray:
    """ICT weights (..., 53) -> ARKit weights (..., K): each ARKit shape takes the mean of the ICT
    weights it feeds (so ``browInnerUp`` = mean of the two halves; ``tongueOut`` = 0)."""
    return np.asarray(w, np.float64) @ m.T / np.maximum(m.sum(axis=1), 1.0)


# ------------------------------------------------------------------------------------- crops
def makehuman_crops() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The MakeHuman base head (``data_synth/makehuman/data``, cm) as users have it:
    {"face mask", "head", "full head", "bust": (vertices (V,3) float64, faces (F,3) int64)}.

    head: skin of the head and upper neck (``neutral`` of makehuman_arkit.npz); full head: with eye
    sockets and mouth cavity (``full_*``); bust: with neck, shoulders and upper chest (``bust_*`` of
    makehuman_heads.npz); face mask: the head's skin triangles less than 8.8 cm behind the nose tip
    and from 10 cm below to 13 cm above it (chin to forehead, cheeks to the front of the ears)."""
    from importlib import resources

    data = resources.files("data_synth.makehuman") / "data"
    with np.load(str(data / "makehuman_arkit.npz"), allow_pickle=False) as a, \
            np.load(str(data / "makehuman_heads.npz"), allow_pickle=False) as h:
        out = {"head": (a["neutral"], a["faces"]), "full head": (a["full_neutral"], a["full_faces"]),
               "bust": (h["bust_neutral"], h["bust_faces"])}
        out = {k: (np.asarray(v, np.float64), np.asarray(f, np.int64)) for k, (v, f) in out.items()}
    v, f = out["head"]
    tip = v[np.argmax(v[:, 2])]
    corner = v[f]
    keep = ((corner[..., 2] > tip[2] - 8.8) & (corner[..., 1] > tip[1] - 10.0)
            & (corner[..., 1] < tip[1] + 13.0)).all(axis=1)
    used = np.unique(f[keep])
    remap = np.full(len(v), -1)
    remap[used] = np.arange(len(used))
    return {"face mask": (v[used], remap[f[keep]]), **out}


def frame_agreement(meshes: dict, reference: str) -> dict:
    """For each frame kind and mesh (name -> (vertices, faces), one head in one unit): its
    canonical scale / the reference's, and how far its canonical origin is from the reference's
    (mm; the meshes are in cm). {kind: {name: {"scale_ratio", "centre_mm"}}}."""
    out = {}
    for kind in FRAMES:
        fits = {n: Canonicaliser.fit(v, n, kind=kind, faces=f) for n, (v, f) in meshes.items()}
        ref = fits[reference]
        out[kind] = {n: {"scale_ratio": c.scale / ref.scale,
                         "centre_mm": 10.0 * float(np.linalg.norm(c.centre - ref.centre))}
                     for n, c in fits.items()}
    return out


# ------------------------------------------------------------------------------------- rigs
@dataclass
class RealRig:
    """An ARKit blendshape rig read from an npz (``shared/rigs/makehuman_arkit.npz`` layout).

    neutral (V,3) float32 cm; deltas (K,V,3) float32 cm; faces (F,3) int64; names (K,) ARKit names;
    uv and segments are None (no parameter domain, no segmentation labels).
    """

    neutral: np.ndarray
    deltas: np.ndarray
    faces: np.ndarray
    names: tuple
    uv: None = None
    segments: None = None

    @classmethod
    def load(cls, path, hint: str = "set real_rig.path in the eval config or pass --real-rig"
             ) -> "RealRig":
        """The rig of an npz with neutral (V,3), deltas (K,V,3), faces (F,3), names (K,), in cm;
        RetargetError naming the file (``hint``: how to give another) when it is missing, not a
        regular file or not such an npz."""
        path = regular_file(path, "real rig", missing=f"real rig not found ({hint})")
        try:
            with np.load(path, allow_pickle=False) as d:
                rig = cls(d["neutral"].astype(np.float32), d["deltas"].astype(np.float32),
                          d["faces"].astype(np.int64), tuple(str(n) for n in d["names"]))
        except (OSError, ValueError, KeyError) as e:
            raise RetargetError(f"{path}: not a readable rig npz with neutral, deltas, faces and "
                                f"names ({e})") from None
        if rig.deltas.shape != (len(rig.names), *rig.neutral.shape):
            raise RetargetError(f"{path}: deltas {rig.deltas.shape} do not match neutral "
                                f"{rig.neutral.shape} and {len(rig.names)} names")
        return rig

    def evaluate(self, weights) -> np.ndarray:
        """neutral + weights·deltas: (K,) -> (V,3) or (T,K) -> (T,V,3), float32 cm."""
        return self.neutral + np.tensordot(np.asarray(weights, np.float32), self.deltas,
                                           axes=(-1, 0))


def template_rig(rig: RealRig | None = None) -> tuple[RealRig, np.ndarray]:
    """The closest-point baseline's template rig: ``rig`` (default the packaged MakeHuman ARKit rig,
    ``TEMPLATE_RIG``) with its ARKit shapes that have an ICT counterpart (all but tongueOut), and
    their (K, 53) ARKit → ICT matrix (``arkit_ict_matrix``)."""
    rig = rig or RealRig.load(TEMPLATE_RIG, hint="the package's data is missing")
    keep = [k for k, n in enumerate(rig.names) if arkit_to_ict(n)]
    rig = RealRig(rig.neutral, rig.deltas[keep], rig.faces, tuple(rig.names[k] for k in keep))
    return rig, arkit_ict_matrix(rig.names)


@dataclass(eq=False)
class Case:
    """One test: a source rig driven by ``source_weights``, a target rig whose neutral is the target
    mesh, and GT = the target rig driven by ``target_weights`` (the same FACS weights, in the
    target rig's convention). ``exact``: the GT is exact (same surface) or only semantic."""

    label: str
    source: object
    source_weights: np.ndarray
    target: object
    target_weights: np.ndarray
    exact: bool = True

    @cached_property
    def source_frames(self) -> np.ndarray:
        """(T,Vs,3) float32 cm."""
        return self.source.evaluate(self.source_weights)

    @cached_property
    def gt(self) -> np.ndarray:
        """(T,Vt,3) float32 cm."""
        return self.target.evaluate(self.target_weights)


class EvalData:
    """The fixed test rigs and weights of one eval config (built lazily, cached)."""

    def __init__(self, cfg: dict):
        self.cfg = cfg
        self._rigs: dict = {}
        self._tess: dict = {}
        self._real = None
        self._head_bases: dict = {}

    def tessellation(self, spec: dict):
        key = tuple(sorted(spec.items()))
        if key not in self._tess:
            self._tess[key] = tessellate(seed=self.cfg["seed"], **spec)
        return self._tess[key]

    def rig(self, identity: int, spec: dict | None = None):
        """The rig of test identity ``identity`` on tessellation ``spec`` (default: the config's)."""
        spec = spec or self.cfg["tessellation"]
        key = (identity, tuple(sorted(spec.items())))
        if key not in self._rigs:
            z_id = sample_identity(self.cfg["seed"] + identity, split=self.cfg["split"])
            self._rigs[key] = build_rig(z_id, self.tessellation(spec), self.cfg["n_segments"])
        return self._rigs[key]

    def head_rig(self, identity: int, spec: dict | None = None):
        """The realistic rig of test head ``identity`` on ``head_tessellation(**spec)`` (default:
        the config's ``heads.tessellation``); the identity's shapes are made once."""
        from data_synth.makehuman import base_head_rig, build_head_rig, head_tessellation, sample_head_identity

        h = self.cfg["heads"]
        spec = spec or h["tessellation"]
        if identity not in self._head_bases:
            z = sample_head_identity(self.cfg["seed"] + identity, split=self.cfg["split"])
            self._head_bases[identity] = base_head_rig(z, h["shapes"])
        key = ("head", identity, tuple(sorted(spec.items())))
        if key not in self._rigs:
            tess = head_tessellation(seed=self.cfg["seed"], **spec)
            self._rigs[key] = build_head_rig(self._head_bases[identity], tess, self.cfg["n_segments"])
        return self._rigs[key]

    def weights(self, suite: str, index: int, n: int | None = None) -> np.ndarray:
        """(n,53) float32 weights of case ``index`` of ``suite`` (fixed seed per suite and case)."""
        rng = np.random.default_rng([self.cfg["seed"], SUITES.index(suite), index])
        return sample_weights(rng, n or self.cfg["expressions"], self.cfg["weights_mode"]).astype(np.float32)

    def real_rig(self) -> RealRig:
        if self._real is None:
            self._real = RealRig.load(real_rig_path(self.cfg))
        return self._real

    # ---- suites
    def cases(self, suite: str) -> list[Case]:
        """The cases of a transfer / inverse / jitter suite."""
        n = self.cfg["identities"]
        if suite in ("self", "inverse"):
            return [Case(f"id {i}", self.rig(i), w, self.rig(i), w)
                    for i in range(n) for w in [self.weights(suite, i)]]
        if suite == "cross_identity":
            return [Case(f"id {i} -> id {(i + 1) % n}", self.rig(i), w, self.rig((i + 1) % n), w)
                    for i in range(n) for w in [self.weights(suite, i)]]
        if suite == "cross_topology":
            out = []
            for p, pair in enumerate(self.cfg["cross_topology"]):
                for i in range(self.cfg["cross_topology_identities"]):
                    w = self.weights(suite, p * 1000 + i)
                    out.append(Case(f"{pair['name']}: id {i} -> id {(i + 1) % n}",
                                    self.rig(i, pair["source"]), w,
                                    self.rig((i + 1) % n, pair["target"]), w))
            return out
        if suite == "jitter":
            j = self.cfg["jitter"]
            out = []
            for i in range(j["identities"]):
                rng = np.random.default_rng([self.cfg["seed"], SUITES.index(suite), i])
                w = smooth_sequence(rng, j["frames"], j["fps"]).astype(np.float32)
                out.append(Case(f"id {i} -> id {(i + 1) % n}", self.rig(i), w,
                                self.rig((i + 1) % n), w))
            return out
        if suite.startswith("head_"):
            return self.head_cases(suite)
        raise ValueError(f"no generic cases for suite {suite!r}")

    def head_cases(self, suite: str) -> list[Case]:
        """The cases of a realistic-head suite (see the module docstring)."""
        h = self.cfg["heads"]
        n = h["identities"]

        def case(label, src, tgt, index):
            w = self.weights(suite, index, h["expressions"]) * (src.present & tgt.present)
            return Case(label, src, w.astype(np.float32), tgt, w.astype(np.float32))

        if suite in ("head_self", "head_inverse"):
            return [case(f"head {i}", self.head_rig(i), self.head_rig(i), i) for i in range(n)]
        if suite == "head_cross_identity":
            return [case(f"head {i} -> head {(i + 1) % n}", self.head_rig(i), self.head_rig((i + 1) % n), i)
                    for i in range(n)]
        kind = "topology" if suite == "head_cross_topology" else "crop"
        out = []
        for p, pair in enumerate(h[f"cross_{kind}"]):
            for i in range(h[f"cross_{kind}_identities"]):
                j = (i + 1) % n if kind == "topology" else i
                out.append(case(f"{pair['name']}: head {i} -> head {j}", self.head_rig(i, pair["source"]),
                                self.head_rig(j, pair["target"]), p * 1000 + i))
        return out

    def real_cases(self) -> dict[str, dict[str, Case]]:
        """Real-rig cases by direction, each as one case of sampled weights and one of one-hot
        ARKit shapes (``per_shape``); and with the sampled ones ``unmoved``, the rig's neutral as
        the source frame transferred onto itself (the floor: doing nothing is exact there). ICT
        weights are symmetrised on browInnerUp / cheekPuff so both rigs receive equivalent
        weights."""
        real, proc = self.real_rig(), self.rig(0)
        m = arkit_ict_matrix(real.names)
        sampled = ict_to_arkit_weights(self.weights("real_rig", 0, self.cfg["real_rig"]["expressions"]), m)
        shapes = self.per_shape_names()
        onehot = np.eye(len(real.names))[[real.names.index(s) for s in shapes]]
        out = {}
        for tag, a in (("sampled", sampled), ("per_shape", onehot)):
            a = a.astype(np.float32)
            w = (a @ m).astype(np.float32)
            out[tag] = {
                "real_to_real": Case("real -> real", real, a, real, a, exact=True),
                "procedural_to_real": Case("procedural id 0 -> real", proc, w, real, a, exact=False),
                "real_to_procedural": Case("real -> procedural id 0", real, a, proc, w, exact=False),
                "invert": Case("invert real", real, a, real, a, exact=True),
                "animate": Case("animate real", real, a, real, a, exact=True),
            }
        still = np.zeros((1, len(real.names)), np.float32)
        out["sampled"]["unmoved"] = Case("real unmoved -> real", real, still, real, still, exact=True)
        return out

    def per_shape_names(self) -> list[str]:
        """ARKit shapes of the per-shape table: all with an ICT shape (tongueOut has none), or the
        config's list."""
        real = self.real_rig()
        spec = self.cfg["real_rig"]["per_shape"]
        names = [n for n in real.names if arkit_to_ict(n)] if spec == "all" else list(spec)
        unknown = sorted(set(names) - set(real.names))
        if unknown:
            raise RetargetError(f"eval config: real_rig.per_shape names not in the rig: {unknown}")
        return names


# ------------------------------------------------------------------------------------- methods
class NetworkMethod:
    """A checkpoint, through the public API (``retarget.api.Retargeter``), in one of the
    ``NEUTRAL_MODES``. ``targets``: a prepared-target cache to share between the modes of one
    checkpoint (default: its own)."""

    def __init__(self, name: str, retargeter, mode: str = "neutral", targets: dict | None = None):
        if mode not in NEUTRAL_MODES:
            raise RetargetError(f"unknown neutral mode {mode!r}; choose from {', '.join(NEUTRAL_MODES)}")
        self.name = name
        self.r = retargeter
        self.mode = mode
        self._targets: dict = {} if targets is None else targets
        self._estimates: dict = {}        # mode "estimate": digest of a take's frames -> neutral

    def _target(self, rig):
        if id(rig) not in self._targets:
            self._targets[id(rig)] = (rig, self.r.prepare(Mesh(rig.neutral, rig.faces)))
        return self._targets[id(rig)][1]

    def _source(self, case: Case) -> tuple[list[Mesh], Mesh | None]:
        """(source frames, source neutral) as meshes; frames are encoded in the neutral's frame
        and with its operators (``Retargeter.encode``); no neutral in mode "none", the one
        estimated from the frames in mode "estimate"."""
        frames = [Mesh(f, case.source.faces) for f in case.source_frames]
        if self.mode == "none":
            return frames, None
        if self.mode == "estimate":      # once per take: several cases share their frames
            key = hashlib.sha1(np.ascontiguousarray(case.source_frames).tobytes()).hexdigest()
            if key not in self._estimates:
                self._estimates[key] = self.r.estimate_neutral(frames)
            return frames, self._estimates[key]
        return frames, Mesh(case.source.neutral, case.source.faces)

    def transfer(self, case: Case, filters=(None,), fps: float = 30.0) -> dict:
        """{filter: (T,Vt,3) cm prediction} for each temporal filter (None = raw codes); the
        frames are encoded once and decoded once per filter (= ``Retargeter.transfer(smooth=f)``)."""
        frames, neutral = self._source(case)
        z = self.r.expression_codes(frames, source_neutral=neutral, refine=self.mode in REFINE_MODES)
        target = self._target(case.target)
        return {f: self.r.decode(target, z if f is None else smooth_codes(z, f, fps)) for f in filters}

    def animate(self, case: Case, weights: np.ndarray | None = None) -> np.ndarray:
        """(T,Vt,3) cm: the target driven by FACS weights (``Retargeter.animate``): (T,53) ICT
        ``weights``, by default the case's target weights."""
        return self.r.animate(self._target(case.target),
                              case.target_weights if weights is None else weights)

    def invert(self, case: Case) -> np.ndarray:
        """(T,53) ICT weights in [0,1] predicted from the source frames."""
        frames, neutral = self._source(case)
        return self.r.invert(frames, source_neutral=neutral, refine=self.mode in REFINE_MODES)


class DoNothingMethod:
    """The target left neutral; inverse rigging predicts weights 0."""

    name = DO_NOTHING_NAME

    def transfer(self, case: Case, filters=(None,), fps: float = 30.0) -> dict:
        pred = np.broadcast_to(case.target.neutral, case.gt.shape)
        return {f: pred for f in filters}

    def animate(self, case: Case, weights: np.ndarray | None = None) -> np.ndarray:
        return np.broadcast_to(case.target.neutral, case.gt.shape)

    def invert(self, case: Case) -> np.ndarray:
        return np.zeros((len(case.source_weights), N_FACS), np.float32)


class ClosestPointMethod:
    """Closest-point displacement transfer in the face frame (``retarget.oracle``), given the
    source rig's neutral. Driving from FACS weights and inverse rigging start from a rig, so there
    it is the template's: the packaged MakeHuman ARKit rig (``TEMPLATE_RIG``, its shapes with an
    ICT counterpart) carried onto the mesh's neutral by closest point
    (``retarget.oracle.closest_point_rig``), driven by the ICT weights mapped to ARKit ones
    (``ict_to_arkit_weights``), or fitted to each frame by bounded least squares
    (``retarget.oracle.fit_rig_weights``) and mapped back to ICT weights."""

    name = CLOSEST_POINT_NAME

    def __init__(self, template: RealRig | None = None):
        self._template = template
        self._rigs: dict = {}           # id(rig) -> (rig, its template shapes (K,V,3) cm)

    def transfer(self, case: Case, filters=(None,), fps: float = 30.0) -> dict:
        return {None: closest_point_transfer(case.source.neutral, case.source.faces,
                                             case.source_frames, case.target.neutral,
                                             case.target.faces, frame="face")}

    @cached_property
    def template(self) -> tuple[RealRig, np.ndarray]:
        """``template_rig`` of the rig given, by default the packaged one."""
        return template_rig(self._template)

    def _shapes(self, rig) -> np.ndarray:
        if id(rig) not in self._rigs:
            t = self.template[0]
            self._rigs[id(rig)] = (rig, closest_point_rig(t.neutral, t.faces, t.deltas, rig.neutral,
                                                          rig.faces))
        return self._rigs[id(rig)][1]

    def animate(self, case: Case, weights: np.ndarray | None = None) -> np.ndarray:
        """(T,Vt,3) cm: the target's template rig driven by (T,53) ICT ``weights`` (default the
        case's target weights)."""
        w = case.target_weights if weights is None else weights
        a = ict_to_arkit_weights(w, self.template[1])
        return case.target.neutral + np.tensordot(a, self._shapes(case.target), axes=(-1, 0))

    def invert(self, case: Case) -> np.ndarray:
        """(T,53) ICT weights in [0,1] fitted to the source frames on the source's template rig."""
        a = fit_rig_weights(self._shapes(case.source), case.source.neutral, case.source_frames)
        return np.clip(a @ self.template[1], 0.0, 1.0).astype(np.float32)


class OracleMethod:
    """Displacement transfer through the known (u, v) correspondence (``retarget.oracle``)."""

    name = ORACLE_NAME

    def __init__(self):
        self._maps: dict = {}

    def transfer(self, case: Case, filters=(None,), fps: float = 30.0) -> dict | None:
        if case.source.uv is None or case.target.uv is None:
            return None
        key = (id(case.source), id(case.target))
        if key not in self._maps:
            self._maps[key] = (case, uv_transfer_matrix(case.source.uv, case.source.faces,
                                                        case.target.uv))
        pred = displacement_transfer(self._maps[key][1], case.source.neutral, case.source_frames,
                                     case.target.neutral)
        return {None: pred}

    def animate(self, case: Case, weights: np.ndarray | None = None):
        return None

    def invert(self, case: Case):
        return None


# ------------------------------------------------------------------------------------- metrics
def case_errors(pred: np.ndarray, gt: np.ndarray, segments, n_segments: int) -> dict:
    """Errors of one case: pred, gt (T,V,3) cm; segments (V,) or None.

    Returns {"frame_mse_mm2": (T,), "per_segment_mm2": (L,) or None}.
    """
    sq = squared_errors_mm2(pred, gt)                                 # (T,V)
    out = {"frame_mse_mm2": sq.mean(axis=1), "per_segment_mm2": None}
    if segments is not None:
        out["per_segment_mm2"] = segment_mse_mm2(pred, gt, segments, n_segments)[1]
    return out


def summarise(errors: list[dict]) -> dict:
    """Pool case errors: MSE = mean over all frames of all cases; per-segment MSE = mean over cases
    of each segment's MSE (NaN where no case has the segment); segment-averaged MSE = mean over
    segments of the per-segment MSE; ``case_mse_mm2``: each case's MSE, in the suite's case order
    (for paired comparisons of two methods on the same cases)."""
    out = {"mse_mm2": float(np.mean(np.concatenate([e["frame_mse_mm2"] for e in errors]))),
           "n_frames": int(sum(len(e["frame_mse_mm2"]) for e in errors)),
           "case_mse_mm2": [float(np.mean(e["frame_mse_mm2"])) for e in errors]}
    segs = [e["per_segment_mm2"] for e in errors if e["per_segment_mm2"] is not None]
    if segs:
        per_seg = np.stack(segs)
        with np.errstate(all="ignore"):
            valid = ~np.isnan(per_seg)
            mean = np.where(valid.any(0), np.nansum(per_seg, 0) / np.maximum(valid.sum(0), 1), np.nan)
        out["per_segment_mm2"] = [None if np.isnan(x) else float(x) for x in mean]
        out["seg_mse_mm2"] = float(np.nanmean(mean))
    return out


# ------------------------------------------------------------------------------------- suites
@dataclass
class Evaluation:
    """Runs the suites of one config for several methods; collects results and heatmap samples."""

    cfg: dict
    methods: list
    progress: bool = True
    data: EvalData = None
    samples: list = field(default_factory=list)   # (suite, case, {method: (Vt,3) prediction})

    def __post_init__(self):
        self.data = self.data or EvalData(self.cfg)

    def _bar(self, items, desc):
        from tqdm import tqdm
        return tqdm(items, desc=desc, disable=not self.progress, leave=False, dynamic_ncols=True)

    def run(self, suites=SUITES) -> dict:
        """{"config", "methods", "suites": {suite: {...}}} (see each ``suite_*`` method)."""
        unknown = sorted(set(suites) - set(SUITES))
        if unknown:
            raise RetargetError(f"unknown eval suite(s) {unknown}; choose from {', '.join(SUITES)}")
        out = {"config": copy.deepcopy(self.cfg), "methods": [m.name for m in self.methods],
               "segment_names": list(self.data.rig(0).segment_names), "suites": {}}
        for suite in [s for s in SUITES if s in suites]:
            t0 = time.monotonic()
            out["suites"][suite] = getattr(self, f"suite_{suite}")()
            out["suites"][suite]["seconds"] = round(time.monotonic() - t0, 1)
        return add_ratios(out)

    def _transfer_suite(self, suite: str) -> dict:
        cases = self.data.cases(suite)
        n_keep = self.cfg["heatmaps"]["samples"]
        keep = [{} for _ in cases[:n_keep]]
        res = {"exact_gt": True, "cases": [c.label for c in cases], "methods": {}}
        for m in self.methods:
            errs, by_group = [], {}
            for i, case in enumerate(self._bar(cases, f"{suite} [{m.name}]")):
                preds = m.transfer(case)
                if preds is None:
                    break
                pred = preds[None]                                       # raw codes, (T,Vt,3)
                e = case_errors(pred, case.gt, case.target.segments, self.cfg["n_segments"])
                errs.append(e)
                by_group.setdefault(case.label.split(":")[0], []).append(e)
                if i < n_keep:
                    keep[i][m.name] = pred[0]
            if errs:
                res["methods"][m.name] = summarise(errs)
                if suite in PAIRED_SUITES:
                    res["methods"][m.name]["pairs"] = {g: summarise(v) for g, v in by_group.items()}
        self.samples += [(suite, c, k) for c, k in zip(cases, keep)]
        return res

    def suite_self(self) -> dict:
        return self._transfer_suite("self")

    def suite_cross_identity(self) -> dict:
        return self._transfer_suite("cross_identity")

    def suite_cross_topology(self) -> dict:
        return self._transfer_suite("cross_topology")

    def suite_head_self(self) -> dict:
        return self._transfer_suite("head_self")

    def suite_head_cross_identity(self) -> dict:
        return self._transfer_suite("head_cross_identity")

    def suite_head_cross_topology(self) -> dict:
        return self._transfer_suite("head_cross_topology")

    def suite_head_cross_crop(self) -> dict:
        return self._transfer_suite("head_cross_crop")

    def suite_head_inverse(self) -> dict:
        return self.suite_inverse("head_inverse")

    def suite_head_animate(self) -> dict:
        return self.suite_animate("head_self")

    def suite_animate(self, cases_of: str = "self") -> dict:
        """Driving from FACS weights: the ``cases_of`` self-retargeting cases (same targets, same
        weights) decoded from z_GE = [w, 0]; MSE and segment-averaged MSE in mm² against the rig."""
        res = {"exact_gt": True, "methods": {}}
        cases = self.data.cases(cases_of)
        for m in self.methods:
            errs = []
            for case in self._bar(cases, f"animate {cases_of} [{m.name}]"):
                pred = m.animate(case)
                if pred is None:
                    break
                errs.append(case_errors(pred, case.gt, case.target.segments, self.cfg["n_segments"]))
            if errs:
                res["methods"][m.name] = summarise(errs)
        return res

    def suite_inverse(self, suite: str = "inverse") -> dict:
        """Inverse rigging: rig MSE of the re-evaluated predicted weights, and the weight MAE with
        its standard error over the suite's cases (identities: ``standard_error``)."""
        res = {"exact_gt": True, "methods": {}}
        for m in self.methods:
            errs, maes = [], []
            for case in self._bar(self.data.cases(suite), f"{suite} [{m.name}]"):
                w = m.invert(case)
                if w is None:
                    break
                errs.append(case_errors(case.source.evaluate(w), case.source_frames,
                                        case.source.segments, self.cfg["n_segments"]))
                maes.append(weight_mae(w, case.source_weights))
            if errs:
                res["methods"][m.name] = {**summarise(errs), "weight_mae": float(np.mean(maes)),
                                          "weight_mae_se": standard_error(maes)}
        return res

    def suite_jitter(self) -> dict:
        """Jitter (mm) and MSE (mm²) of a smooth sequence transferred across identities, raw and
        with each temporal filter of ``retarget.smoothing``; the GT's own jitter for reference."""
        cases = self.data.cases("jitter")
        fps = self.cfg["jitter"]["fps"]
        res = {"exact_gt": True, "fps": fps, "frames": self.cfg["jitter"]["frames"],
               "gt_jitter_mm": float(np.mean([second_difference_jitter_mm(c.gt) for c in cases])),
               "methods": {}}
        filters = (None, *FILTERS)
        for m in self.methods:
            rows: dict = {}
            for case in self._bar(cases, f"jitter [{m.name}]"):
                preds = m.transfer(case, filters, fps)
                for f, pred in preds.items():
                    rows.setdefault(f or "raw", []).append(
                        (second_difference_jitter_mm(pred), float(squared_errors_mm2(pred, case.gt).mean())))
            res["methods"][m.name] = {f: {"jitter_mm": float(np.mean([r[0] for r in v])),
                                          "mse_mm2": float(np.mean([r[1] for r in v]))}
                                      for f, v in rows.items()}
        return res

    def suite_frame(self) -> dict:
        """The canonical frames of one head under several crops (see the module docstring)."""
        res = {"exact_gt": True, "methods": {}, "reference": "head",
               "makehuman": frame_agreement(makehuman_crops(), "head"), "procedural": {}}
        face_crop = {**self.cfg["tessellation"], "region": "face"}
        for i in range(self.cfg["identities"]):
            full, face = self.data.rig(i), self.data.rig(i, face_crop)
            res["procedural"][f"id {i}"] = frame_agreement(
                {"full": (full.neutral, full.faces), "face crop": (face.neutral, face.faces)},
                "full")
        res["heads"] = {}
        for i in range(self.cfg["heads"]["identities"]):
            rigs = {crop: self.data.head_rig(i, {"n_vertices": 3386, "kind": "base", "crop": crop})
                    for crop in ("face", "head", "head_neck", "bust")}
            res["heads"][f"head {i}"] = frame_agreement(
                {c: (r.neutral, r.faces) for c, r in rigs.items()}, "head")
        return res

    def suite_real_rig(self) -> dict:
        """The real ARKit rig (see the module docstring); ``per_shape``: one-hot ARKit shapes."""
        real_cases = self.data.real_cases()
        shapes = self.data.per_shape_names()
        m_arkit = arkit_ict_matrix(self.data.real_rig().names)
        res = {"path": str(self.cfg["real_rig"]["path"]), "shapes": shapes,
               "exact_gt": {k: c.exact for k, c in real_cases["sampled"].items()}, "methods": {}}
        for m in self.methods:
            entry = {}
            for tag, cases in real_cases.items():
                block = {}
                for key, case in self._bar(list(cases.items()), f"real rig {tag} [{m.name}]"):
                    if key == "invert":
                        w = m.invert(case)
                        if w is None:
                            continue
                        a = ict_to_arkit_weights(w, m_arkit)
                        frame_mse = squared_errors_mm2(case.source.evaluate(a), case.source_frames).mean(1)
                        used = m_arkit.sum(1) > 0          # tongueOut has no ICT shape
                        mae = np.abs(a - case.source_weights)[:, used].mean(1)
                        block[key] = {"rig_mse_mm2": frame_mse, "weight_mae": mae}
                    elif key == "animate":
                        pred = m.animate(case, (case.target_weights @ m_arkit).astype(np.float32))
                        if pred is None:
                            continue
                        block[key] = {"mse_mm2": squared_errors_mm2(pred, case.gt).mean(1)}
                    else:
                        preds = m.transfer(case)
                        if preds is None:                  # the oracle: the real rig has no (u, v)
                            continue
                        block[key] = {"mse_mm2": squared_errors_mm2(preds[None], case.gt).mean(1)}
                if not block:
                    break
                if tag == "sampled":                       # and each frame's, for paired comparisons
                    entry[tag] = {k: {**{n: float(np.mean(v)) for n, v in b.items()},
                                      **{f"frame_{n}": [float(x) for x in v] for n, v in b.items()}}
                                  for k, b in block.items()}
                    if "invert" in block:                  # one rig: the error over its frames
                        entry[tag]["invert"]["weight_mae_se"] = standard_error(
                            block["invert"]["weight_mae"])
                else:
                    entry[tag] = {s: {f"{k}.{n}": float(v[j]) for k, b in block.items() for n, v in b.items()}
                                  for j, s in enumerate(shapes)}
            if entry:
                res["methods"][m.name] = entry
        return res


# ------------------------------------------------------------------------------------- ratios
def is_error_key(key: str) -> bool:
    """Leaves that are errors (mm² or weight MAE) and so get a do-nothing ratio; jitter does not."""
    return key.endswith("_mm2") or key.endswith("weight_mae")


def ratio_tree(d, base):
    """The error leaves of ``d`` divided by the same leaves of ``base`` (nested dicts, lists per
    segment); None where ``base`` lacks the leaf or is 0."""
    if isinstance(d, dict):
        out = {}
        for k, v in d.items():
            b = base.get(k) if isinstance(base, dict) else None
            if isinstance(v, dict):
                sub = ratio_tree(v, b)
                if sub:
                    out[k] = sub
            elif is_error_key(k):
                out[k] = ratio_tree(v, b)
        return out
    if isinstance(d, list):
        return [ratio_tree(x, base[i] if isinstance(base, list) else None) for i, x in enumerate(d)]
    if d is None or not isinstance(base, (int, float)) or base <= 0:
        return None
    return float(d) / float(base)


def add_ratios(results: dict) -> dict:
    """Set ``suites[s]["ratios"][method]``: every error of every method as a ratio to the do-nothing
    error of the same cases (suites without a do-nothing row get none). Returns ``results``."""
    for suite in results["suites"].values():
        base = suite.get("methods", {}).get(DO_NOTHING_NAME)
        if base is None:
            suite.pop("ratios", None)
            continue
        suite["ratios"] = {m: ratio_tree(v, base) for m, v in suite["methods"].items()}
    return results


# ------------------------------------------------------------------------------------- markdown
def fmt(x) -> str:
    """A number for a table: 4 significant digits; '—' for missing."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "—"
    return f"{x:.4g}"


def md_table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |",
             "| " + " | ".join(["---"] + ["---:"] * (len(header) - 1)) + " |"]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def fmt_ratio(x, ratio) -> str:
    """An error and its ratio to doing nothing: '7.29 (0.27×)'; the error alone without a ratio."""
    return fmt(x) if ratio is None or x is None else f"{fmt(x)} ({ratio:.2f}×)"


def to_markdown(results: dict) -> str:
    """All suites of ``Evaluation.run`` as markdown tables (mm² unless stated); each error is
    followed by its ratio to the do-nothing row's error of the same cases, e.g. 7.29 (0.27×)."""
    s, methods = results["suites"], results["methods"]
    out = []
    if results.get("config", {}).get("split", "test") != "test":
        out.append(f"**Identities of the {results['config']['split']!r} split, not the test set** "
                   f"(eval config ``split``; the real rig is the same one).\n")

    def dig(d, keys):
        for k in keys:
            if isinstance(k, int):
                d = d[k] if isinstance(d, list) and k < len(d) else None
            else:
                d = d.get(k) if isinstance(d, dict) else None
        return d

    def get(suite, m, *keys):
        return dig(s.get(suite, {}).get("methods", {}).get(m), keys)

    def cell(suite, m, *keys):
        """The error at ``keys`` with its do-nothing ratio."""
        return fmt_ratio(get(suite, m, *keys), dig(s.get(suite, {}).get("ratios", {}).get(m), keys))

    def mae_cell(suite, m, *keys):
        """A weight MAE with its standard error (``<keys>_se``) where the eval gave one."""
        se = get(suite, m, *keys[:-1], keys[-1] + "_se")
        return cell(suite, m, *keys) + ("" if se is None else f" ± {se:.2g}")

    for suite, title in (("self", "Self-retargeting"), ("cross_identity", "Cross-identity"),
                         ("cross_topology", "Cross-topology"),
                         ("head_self", "Realistic heads: self-retargeting"),
                         ("head_cross_identity", "Realistic heads: cross-identity"),
                         ("head_cross_topology", "Realistic heads: cross-topology"),
                         ("head_cross_crop", "Realistic heads: cross-crop")):
        if suite not in s:
            continue
        out.append(f"### {title} (exact GT; MSE in mm², segment-averaged as NFS Table 1)\n")
        groups = list(dict.fromkeys(g for v in s[suite]["methods"].values() for g in v.get("pairs", {})))
        header = ["method", "MSE", "segment-avg MSE"] + [f"{g} (MSE / seg)" for g in groups]
        rows = [[m, cell(suite, m, "mse_mm2"), cell(suite, m, "seg_mse_mm2")]
                + [f"{cell(suite, m, 'pairs', g, 'mse_mm2')} / {cell(suite, m, 'pairs', g, 'seg_mse_mm2')}"
                   for g in groups] for m in methods]
        out.append(md_table(header, rows) + "\n")
        seg_rows = [[f"{i}: {name}"] + [cell(suite, m, "per_segment_mm2", i) for m in methods]
                    for i, name in enumerate(results["segment_names"])]
        out.append(f"<details><summary>{title}: MSE per segment (mm²)</summary>\n\n"
                   + md_table(["segment"] + methods, seg_rows) + "\n\n</details>\n")
    for inv, heads in (("inverse", ""), ("head_inverse", "Realistic heads: ")):
        if inv not in s:
            continue
        out.append(f"### {heads}Inverse rigging (exact GT: predicted weights re-applied to the "
                   f"identity's rig)\n")
        out.append("do nothing = weights 0 applied to the rig (the neutral), and the MAE of "
                   "predicting 0.\n")
        rows = [[m, cell(inv, m, "mse_mm2"), cell(inv, m, "seg_mse_mm2"),
                 mae_cell(inv, m, "weight_mae")] for m in methods]
        out.append(md_table(["method", "rig MSE", "segment-avg MSE",
                             "weight MAE ± standard error over identities"], rows) + "\n")
    for anim, own, heads in (("animate", "self", ""), ("head_animate", "head_self", "Realistic heads: ")):
        if anim not in s:
            continue
        out.append(f"### {heads}Driving from FACS weights (animate: the self-retargeting targets and "
                   f"weights, decoded from z_GE = [w, 0]; exact GT)\n")
        rows = [[m, cell(anim, m, "mse_mm2"), cell(anim, m, "seg_mse_mm2"),
                 cell(own, m, "mse_mm2")] for m in methods if m in s[anim]["methods"]]
        out.append(md_table(["method", "MSE", "segment-avg MSE", "self-retargeting MSE (same cases)"],
                            rows) + "\n")
    if "jitter" in s:
        j = s["jitter"]
        filters = ["raw", *FILTERS]
        out.append(f"### Jitter (smooth {j['frames']}-frame sequences at {j['fps']:g} fps, cross-identity; "
                   f"mean |second difference| in mm, GT: {fmt(j['gt_jitter_mm'])} mm; the baselines "
                   f"have no codes to filter)\n")
        header = ["method"] + [f"{f} jitter (mm) / MSE" for f in filters]
        rows = [[m] + [f"{fmt(get('jitter', m, f, 'jitter_mm'))} / {cell('jitter', m, f, 'mse_mm2')}"
                       for f in filters] for m in methods]
        out.append(md_table(header, rows) + "\n")
    if "real_rig" in s:
        r = s["real_rig"]
        out.append("### Real ARKit rig (makehuman_arkit.npz; sampled weights; MSE in mm²)\n\n"
                   "real → real and inversion have exact GT; procedural ↔ real GT is the other rig "
                   "driven by the same weights (semantic, not exact).\n")
        header = ["method", "real→real MSE (exact)", "invert: rig MSE (exact)",
                  "invert: weight MAE ± standard error over frames (exact)",
                  "procedural→real MSE (semantic)",
                  "real→procedural MSE (semantic)", "animate from true weights MSE (exact)",
                  "unmoved → itself MSE (the floor, exact)"]
        keys = [("real_to_real", "mse_mm2"), ("invert", "rig_mse_mm2"), ("invert", "weight_mae"),
                ("procedural_to_real", "mse_mm2"), ("real_to_procedural", "mse_mm2"),
                ("animate", "mse_mm2"), ("unmoved", "mse_mm2")]
        rows = [[m] + [(mae_cell if k[1] == "weight_mae" else cell)("real_rig", m, "sampled", *k)
                       for k in keys] for m in methods if m in r["methods"]]
        out.append(md_table(header, rows) + "\n")
        networks = [m for m in methods if m in r["methods"] and m not in BASELINES_FIRST + BASELINES_LAST]
        for m in networks[:1]:
            cols = ["real_to_real.mse_mm2", "invert.rig_mse_mm2", "invert.weight_mae",
                    "procedural_to_real.mse_mm2", "real_to_procedural.mse_mm2", "animate.mse_mm2"]
            rows = [[shape] + [cell("real_rig", m, "per_shape", shape, c) for c in cols]
                    for shape in r["shapes"]]
            one_hot = [h.replace(" ± standard error over frames", "") for h in header[1:-1]]
            out.append(f"<details><summary>Real rig per ARKit shape (one-hot), {m}</summary>\n\n"
                       + md_table(["shape"] + one_hot, rows) + "\n\n</details>\n")
    if "frame" in s:
        f = s["frame"]
        out.append("### Canonical frame under crops (no method: scale / the reference's, and the "
                   "shift of the canonical origin in mm)\n\nThe MakeHuman head of "
                   "data_synth/makehuman/data (reference: head):\n")
        rows = [[name] + [f"{f['makehuman'][k][name]['scale_ratio']:.3f} / "
                          f"{f['makehuman'][k][name]['centre_mm']:.1f}" for k in FRAMES]
                for name in f["makehuman"][FRAMES[0]]]
        out.append(md_table(["crop"] + [f"{k} frame: scale ratio / shift (mm)" for k in FRAMES],
                            rows) + "\n")
        out.append("Procedural test identities, face crop against the full head:\n")
        rows = [[i] + [f"{p[k]['face crop']['scale_ratio']:.3f} / {p[k]['face crop']['centre_mm']:.1f}"
                       for k in FRAMES] for i, p in f["procedural"].items()]
        out.append(md_table(["identity"] + [f"{k} frame: scale ratio / shift (mm)" for k in FRAMES],
                            rows) + "\n")
        if f.get("heads"):
            crops = [c for c in next(iter(f["heads"].values()))[FRAMES[0]] if c != "head"]
            out.append("Realistic test heads (data_synth.makehuman, base tessellation), each crop "
                       "against the head crop:\n")
            rows = [[i] + [" · ".join(f"{p[k][c]['scale_ratio']:.3f} / {p[k][c]['centre_mm']:.1f}"
                                      for c in crops) for k in FRAMES] for i, p in f["heads"].items()]
            out.append(md_table(["head"] + [f"{k} frame ({', '.join(crops)}): scale ratio / shift (mm)"
                                            for k in FRAMES], rows) + "\n")
    return "\n".join(out)


# ------------------------------------------------------------------------------------- heatmaps
def write_heatmaps(samples, out_dir, vmax_mm: float, size: int = 256) -> list[Path]:
    """One PNG per sample: the GT expression (shaded) then each method's per-vertex error
    (distance in mm, YlOrRd on the fixed scale [0, vmax_mm]) on its prediction."""
    from .render import Renderer, contact_sheet, heatmap_colors, save_png

    renderer = Renderer(size)
    out_dir = Path(out_dir)
    paths = []
    for n, (suite, case, preds) in enumerate(samples):
        if not preds:
            continue
        faces, gt = case.target.faces, case.gt[0]
        images = [renderer.render(gt, faces, mode="shaded")]
        labels = [f"{suite} GT (0-{vmax_mm:g} mm)"]
        for name, pred in preds.items():
            err = np.sqrt(squared_errors_mm2(pred, gt))
            images.append(renderer.render(pred, faces, mode="colors",
                                          vertex_colors=heatmap_colors(err, vmax_mm)))
            labels.append(f"{name}: MSE {np.mean(err ** 2):.3g} mm^2")   # the label font has no ²
        path = out_dir / f"{n:02d}_{suite}.png"
        save_png(path, contact_sheet(images, labels, cols=len(images)))
        paths.append(path)
    return paths


# ------------------------------------------------------------------------------------- CLI helpers
def network_methods(checkpoints, modes, device=None, refine_steps: int = 0) -> list[NetworkMethod]:
    """One method per (checkpoint, neutral mode): checkpoints [(name, path)], modes a list of
    ``NEUTRAL_MODES`` keys. Rows are named NAME, or "NAME (MODE)" unless the only mode is the
    default "neutral"; the modes of a checkpoint share one model and its prepared targets.
    ``refine_steps``: ``Retargeter.refine_steps`` of the "refine" mode."""
    from .api import Retargeter

    out = []
    for name, path in checkpoints:
        r, targets = Retargeter.load(path, device=device, refine_steps=refine_steps), {}
        for mode in modes:
            label = name if list(modes) == ["neutral"] else f"{name} ({NEUTRAL_MODES[mode]})"
            out.append(NetworkMethod(label, r, mode, targets))
    return out


def parse_checkpoints(specs) -> list[tuple[str, Path]]:
    """``--checkpoint`` values ``NAME=PATH`` or ``PATH`` (named by the file stem) -> [(name, path)].
    None or empty: the bundled default checkpoint. RetargetError for a missing file or a repeated
    name."""
    from .api import default_checkpoint_path

    out = []
    for spec in specs or [str(default_checkpoint_path())]:
        name, sep, path = spec.partition("=")
        if not sep or Path(spec).exists():
            name, path = Path(spec).stem, spec
        path = Path(path)
        if not path.is_file():
            raise RetargetError(f"{path}: checkpoint not found (train one with `retarget train`, or "
                                f"pass --checkpoint [NAME=]PATH)")
        if name in [n for n, _ in out]:
            raise RetargetError(f"checkpoint name {name!r} given twice; use NAME=PATH to tell them apart")
        out.append((name, path))
    return out


def merge_results(paths) -> dict:
    """One results dict from several ``eval.json`` files of the same eval config (e.g. checkpoints
    evaluated as their trainings finished, or one checkpoint's suites evaluated in parallel runs):
    their methods side by side, suite by suite, in the order given (``sort_methods``). The baselines
    depend only on the config, so the first file's rows are kept; the do-nothing ratios are
    recomputed. RetargetError naming the file for an unreadable file, another config, a method
    that two files both have in one suite, or one checkpoint name given to two checkpoints."""
    import json

    merged = None
    for path in paths:
        path = Path(path)
        try:
            res = json.loads(path.read_text())
            config, methods, suites = res["config"], res["methods"], res["suites"]
            config.setdefault("split", "test")  # eval.json files from before the key: the test split
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise RetargetError(f"{path}: not an eval.json written by `retarget eval` ({e})") from None
        if merged is None:
            merged = copy.deepcopy(res)
            merged.setdefault("checkpoints", {})
            continue
        if config != merged["config"]:
            raise RetargetError(f"{path}: evaluated with another eval config than {paths[0]}; only "
                                f"results of the same config can share a table")
        baselines = BASELINES_FIRST + BASELINES_LAST   # the same config gives the same rows
        twice = sorted({m for name, suite in suites.items() if name in merged["suites"]
                        for m in set(suite["methods"]) & set(merged["suites"][name]["methods"])}
                       - set(baselines))
        if twice:
            raise RetargetError(f"{path}: method(s) {twice} already in the merged table (rename one "
                                f"with --checkpoint NAME=PATH)")
        for name, ckpt in res.get("checkpoints", {}).items():
            if merged["checkpoints"].get(name, ckpt) != ckpt:
                raise RetargetError(f"{path}: checkpoint name {name!r} is {ckpt}, but "
                                    f"{merged['checkpoints'][name]} in an earlier file (rename one "
                                    f"with --checkpoint NAME=PATH)")
        merged["methods"] += [m for m in methods if m not in merged["methods"]]
        merged["checkpoints"].update(res.get("checkpoints", {}))
        for name, suite in suites.items():
            if name not in merged["suites"]:
                merged["suites"][name] = copy.deepcopy(suite)
            else:
                for m, v in suite["methods"].items():
                    merged["suites"][name]["methods"].setdefault(m, copy.deepcopy(v))
    if merged is None:
        raise RetargetError("--merge needs at least one eval.json")
    merged["methods"] = sort_methods(merged["methods"])
    return add_ratios(merged)


def sort_methods(names) -> list:
    """Table order: do nothing, the checkpoints (in the order given), closest point, the oracle."""
    def key(m):
        if m in BASELINES_FIRST:
            return -1
        return BASELINES_LAST.index(m) + 1 if m in BASELINES_LAST else 0
    return sorted(names, key=key)


def write_results(out_dir, stem: str, results: dict, markdown: str) -> tuple[Path, Path]:
    """Write ``OUT/stem.json`` and ``OUT/stem.md`` atomically; returns both paths."""
    import json

    from .io import atomic_output

    paths = Path(out_dir) / f"{stem}.json", Path(out_dir) / f"{stem}.md"
    with atomic_output(paths[0]) as tmp:
        Path(tmp).write_text(json.dumps(results, indent=1, allow_nan=False) + "\n")
    with atomic_output(paths[1]) as tmp:
        Path(tmp).write_text(markdown + "\n")
    return paths
