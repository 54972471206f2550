"""Training samples from synthesised rigs — procedural (u, v) heads and realistic MakeHuman heads
(``data.sources`` gives their shares): a deterministic pool of prepared identities.

Preparing a target (rig, operators, frontal image) costs about a second on a CPU, a training step a
fraction of that, so targets are kept in a *pool* of ``pool_size`` slots. Each slot holds one
training identity tessellated two ways (so same-identity cross-topology pairs are free) and is
replaced by a fresh identity every ``pool_size * pool_refresh`` steps, the slots staggered so that
one slot changes every ``pool_refresh`` steps. Which identity and tessellations a slot holds at a
step is a pure function of (seed, slot, step), and each step draws its sample with
``numpy.random.default_rng([seed, step, rank])``: a resumed run sees exactly the samples it would
have seen, without saving any sampler state.

A sample (``Group``) is one target neutral and S sources with expressions, whose ground truth is the
target's rig driven by the sources' weights — exact for self-, cross-identity and cross-topology
pairs because every procedural tessellation samples the same (u, v) surface and every MakeHuman
tessellation is a fixed linear map of the same base vertices. Shapes that a rig lacks (the
MakeHuman expression units have 29 of the 53) get weight 0 in the sources and the ground truth.

Fine-tuning on the user's own rig (``data.rig``, ``retarget train --rig``) uses ``RigPool``: the
same groups drawn from that rig (self-retargeting only), mixed with procedural ones.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from data_synth.identity import sample_identity
from data_synth.rig import Rig, build_rig
from data_synth.sampling import sample_weights
from data_synth.tessellate import tessellate

from .errors import RetargetError
from .mesh import Mesh, face_part, submesh
from .canonical import Canonicaliser, axis_angle_rotation, rotation_angle, upright_rotation
from .prepare import IMAGE_CHANNELS, PreparedMesh, neutral_channels, prepare_mesh

PAIR_KINDS = ("self", "cross_topology", "cross_identity")
RIG_SOURCES = ("procedural", "makehuman")


@dataclass
class Entry:
    """One identity on one tessellation, prepared for the network.

    rig: the procedural rig (cm), or a ``user_rig.UserRig``. mesh: its neutral prepared in the
    canonical frame. basis: (53,V,3) float32 blendshape deltas in canonical units
    (rig.deltas · canon.scale). present: (53,) bool, the shapes the rig has (None = all 53).
    template: (V,3) float32, for a realistic head the point of the MakeHuman base bust each vertex
    lies on, in the base's own face frame (canonical units; ``template_positions``), the target of
    L_corr; None for rigs without that correspondence.
    """

    rig: Rig
    mesh: PreparedMesh
    basis: np.ndarray
    present: np.ndarray | None = None
    template: np.ndarray | None = None


@dataclass
class Source:
    """A source expression mesh: feat (V_s,6) and image (C,H,W) of the (augmented) frame in its own
    canonical frame (its neutral's when the neutral is given), the operators of its neutral,
    weights (53,) and its basis (53,V_s,3). neutral: (V_s,7) float32 channels relative to the
    neutral (``prepare.neutral_channels``), or None when the encoder is not given the neutral."""

    entry: Entry
    feat: np.ndarray
    image: np.ndarray
    weights: np.ndarray
    kind: str
    neutral: np.ndarray | None = None


@dataclass
class Group:
    """One target neutral and S sources. gt_dv: (S,V,3) canonical target displacements w·B_tgt.
    rig_targets: more heads of the pool on which L_rig also draws the FACS shapes this step
    (``data.rig_targets`` − 1 of them; none by default)."""

    target: Entry
    sources: list[Source]
    gt_dv: np.ndarray
    rig_targets: tuple[Entry, ...] = ()


@lru_cache(maxsize=1)
def base_template() -> np.ndarray:
    """(5472,3) float32: the MakeHuman base bust's neutral in its own face frame (canonical units)."""
    from data_synth.makehuman import assets

    z = assets.heads()
    canon = Canonicaliser.fit(z["bust_neutral"], "MakeHuman base bust", kind="face",
                              faces=z["bust_faces"])
    return canon.to_canonical(z["bust_neutral"]).astype(np.float32)


def template_positions(rig) -> np.ndarray | None:
    """(V,3) float32 ``Entry.template`` of a realistic head rig (its ``correspondence``, (V, 5472)
    rows of base bust vertex weights, applied to ``base_template``); None for other rigs."""
    corr = getattr(rig, "correspondence", None)
    if corr is None:
        return None
    return np.asarray(corr @ base_template(), np.float32)


def prepare_rig(rig, model_cfg) -> Entry:
    """Prepare a rig's neutral for the network: an ``Entry`` with its canonical basis (and, for a
    realistic head, its template positions)."""
    mesh = prepare_mesh(rig.neutral, rig.faces, model_cfg.k_eig, model_cfg.image_size,
                        IMAGE_CHANNELS[model_cfg.image_channels], canonical=model_cfg.canonical)
    return Entry(rig, mesh, (rig.deltas * mesh.canon.scale).astype(np.float32),
                 getattr(rig, "present", None), template_positions(rig))


def prepare_entry(identity: np.ndarray, tess_spec: dict, tess_seed: int, model_cfg,
                  n_segments: int) -> Entry:
    """Build the procedural rig of ``identity`` on a tessellation and prepare it."""
    tess = tessellate(seed=tess_seed, **tess_spec)
    return prepare_rig(build_rig(identity, tess, n_segments=n_segments), model_cfg)


def source_shares(data_cfg: dict) -> np.ndarray:
    """(2,) probabilities of ``RIG_SOURCES`` from ``data.sources``; RetargetError if invalid."""
    shares = data_cfg.get("sources") or {"procedural": 1.0}
    unknown = set(shares) - set(RIG_SOURCES)
    p = np.array([float(shares.get(k, 0.0)) for k in RIG_SOURCES])
    if unknown or (p < 0).any() or p.sum() <= 0:
        raise RetargetError(f"data.sources must give non-negative shares of {', '.join(RIG_SOURCES)}"
                            f" (got {shares})")
    return p / p.sum()


class MakeHumanRigs:
    """Realistic rigs of the ``data.makehuman`` section: an identity of ``split`` (its
    ``stylised_share``, ``partial_macro_share``), its shapes from ``expressions`` ({"arkit": p,
    "units": p, "units_full": p}, drawn per identity) with a per-rig ``style`` (or as authored),
    on the listed ``tessellations`` (``data_synth.makehuman.head_tessellation`` arguments)."""

    def __init__(self, mh_cfg: dict, split: str):
        self.cfg, self.split = mh_cfg, split
        self.specs = list(mh_cfg["tessellations"])
        kinds = sorted(mh_cfg["expressions"])
        self.expr_kinds = kinds
        p = np.array([float(mh_cfg["expressions"][k]) for k in kinds])
        if (p < 0).any() or p.sum() <= 0 or not set(kinds) <= {"arkit", "units", "units_full"}:
            raise RetargetError(f"data.makehuman.expressions must give shares of arkit, units, "
                                f"units_full "
                                f"(got {mh_cfg['expressions']})")
        self.expr_p = p / p.sum()

    def base(self, seed: int):
        """The identity of ``seed`` with its shapes (``data_synth.makehuman.BaseHeadRig``)."""
        from data_synth.makehuman import base_head_rig, sample_head_identity

        rng = np.random.default_rng([seed, 31])
        kind = self.expr_kinds[int(rng.choice(len(self.expr_kinds), p=self.expr_p))]
        ident = sample_head_identity(seed, self.split, float(self.cfg["stylised_share"]),
                                     float(self.cfg["partial_macro_share"]))
        return base_head_rig(ident, kind, seed if self.cfg["style"] else None)

    def rig(self, base, spec_index: int, tess_seed: int, n_segments: int):
        """``base`` on tessellation ``spec_index`` of the list."""
        from data_synth.makehuman import build_head_rig, head_tessellation

        return build_head_rig(base, head_tessellation(seed=tess_seed, **self.specs[spec_index]),
                              n_segments)


def random_rotation(rng: np.random.Generator, max_deg: float) -> np.ndarray:
    """A rotation (3,3) about a random axis by an angle uniform in [-max_deg, max_deg] degrees."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return axis_angle_rotation(axis, np.deg2rad(rng.uniform(-max_deg, max_deg)))


class TargetPool:
    """The deterministic pool of prepared training identities (see the module docstring).

    data_cfg: the ``data`` section of a training config; model_cfg: nets.model.NFSConfig. Each
    identity index belongs to one rig source, drawn with the shares of ``data.sources``:
    procedural (u, v) heads on ``data.tessellations``, or realistic MakeHuman heads
    (``data.makehuman``).
    """

    def __init__(self, data_cfg: dict, model_cfg, seed: int, split: str = "train"):
        self.cfg = data_cfg
        self.model_cfg = model_cfg
        self.seed = int(seed)
        self.split = split
        self.tess_specs = list(data_cfg["tessellations"])
        self.shares = source_shares(data_cfg)
        self.makehuman = MakeHumanRigs(data_cfg["makehuman"], split) if self.shares[1] > 0 else None
        self._slots: dict[int, tuple[tuple, tuple[Entry, Entry]]] = {}

    def identity_source(self, identity: int) -> str:
        """The rig source of identity index ``identity`` (a pure function of seed and index)."""
        if self.shares[1] <= 0:
            return "procedural"
        rng = np.random.default_rng([self.seed, identity, 13])
        return RIG_SOURCES[int(rng.random() < self.shares[1])]

    def slot_key(self, slot: int, step: int) -> tuple[int, int, int]:
        """(identity index, tessellation a, tessellation b) held by ``slot`` at ``step``."""
        size, refresh = self.cfg["pool_size"], self.cfg["pool_refresh"]
        generation = (step + slot * refresh) // (size * refresh)
        identity = (slot + size * generation) % self.cfg["n_identities"]
        rng = np.random.default_rng([self.seed, identity, generation, 7])
        n = len(self.tess_specs if self.identity_source(identity) == "procedural"
                else self.makehuman.specs)
        a, b = rng.choice(n, size=2, replace=n < 2)
        return int(identity), int(a), int(b)

    def slot(self, slot: int, step: int) -> tuple[Entry, Entry]:
        """The two prepared tessellations of the identity in ``slot`` at ``step`` (cached)."""
        key = self.slot_key(slot, step)
        cached = self._slots.get(slot)
        if cached is None or cached[0] != key:
            identity_index, a, b = key
            seed = self.seed * 1_000_003 + identity_index
            n_seg = self.model_cfg.n_segments
            if self.identity_source(identity_index) == "procedural":
                identity = sample_identity(seed, split=self.split)
                entries = tuple(
                    prepare_entry(identity, self.tess_specs[t], tess_seed=identity_index * 2 + i,
                                  model_cfg=self.model_cfg, n_segments=n_seg)
                    for i, t in enumerate((a, b)))
            else:
                base = self.makehuman.base(seed)
                entries = tuple(
                    prepare_rig(self.makehuman.rig(base, t, identity_index * 2 + i, n_seg),
                                self.model_cfg)
                    for i, t in enumerate((a, b)))
            self._slots[slot] = (key, entries)
        return self._slots[slot][1]

    def sample(self, step: int, rank: int = 0) -> Group:
        """The training group of ``step`` on process ``rank``: a target and S sources."""
        rng = np.random.default_rng([self.seed, step, rank])
        size = self.cfg["pool_size"]
        t_slot = int(rng.integers(size))
        pair = self.slot(t_slot, step)
        target = pair[int(rng.integers(2))]
        n_src = self.cfg["sources_per_target"]
        weights = sample_weights(rng, n_src, mode=self.cfg["weights"]).astype(np.float32)
        probs = np.array([self.cfg["pairs"][k] for k in PAIR_KINDS], np.float64)
        sources = []
        for w in weights:
            kind = PAIR_KINDS[int(rng.choice(3, p=probs / probs.sum()))]
            if kind == "self":
                entry = target
            elif kind == "cross_topology":
                entry = pair[1] if target is pair[0] else pair[0]
            else:
                entry = self.slot(other_slot(t_slot, size, rng), step)[int(rng.integers(2))]
            for present in (target.present, entry.present):   # shapes a rig lacks stay at 0
                if present is not None:
                    w *= present
            sources.append(make_source(entry, w, kind, rng, self.cfg.get("augment", {}),
                                       self.model_cfg, self.cfg.get("source_neutral_share", 0.0)))
        # drawn last, so that the rest of the group does not depend on data.rig_targets
        extra = []
        for _ in range(int(self.cfg.get("rig_targets", 1)) - 1):
            extra.append(self.slot(other_slot(t_slot, size, rng), step)[int(rng.integers(2))])
        return Group(target, sources, ground_truth(weights, target), tuple(extra))


def other_slot(t_slot: int, size: int, rng: np.random.Generator) -> int:
    """A pool slot other than ``t_slot``, uniform over the ``size - 1`` others (``t_slot`` itself
    when the pool has one slot; then no number is drawn from ``rng``)."""
    return (t_slot + 1 + int(rng.integers(size - 1))) % size if size > 1 else t_slot


def ground_truth(weights: np.ndarray, target: Entry) -> np.ndarray:
    """Canonical target displacements w·B_tgt: weights (S,53) -> (S,V,3) float32."""
    return np.einsum("sk,kvc->svc", weights, target.basis).astype(np.float32)


def make_source(entry: Entry, weights: np.ndarray, kind: str, rng: np.random.Generator,
                augment: dict, model_cfg, neutral_share: float = 0.0) -> Source:
    """The rig of ``entry`` driven by ``weights`` (53,), augmented by a small rotation
    (``augment["rotate_deg"]``), scale (log-uniform ±``scale``) and translation (normal,
    ``translate`` in the rig's units), then canonicalised on its own (as at inference, where no
    neutral is given).

    With ``model_cfg.neutral_channels``, a share ``neutral_share`` of sources also gets its neutral
    (the rig's neutral under the same augmentation): the frame is then canonicalised in the
    neutral's frame (as ``Retargeter.encode`` does with ``source_neutral``) and carries the neutral
    channels. The draw is made whenever ``neutral_share`` > 0, with or without the switch: a model
    without the neutral channels (the ``no_neutral`` ablation) sees the same sources as one with
    them, less their neutrals; with no share (the procedural configs) none is drawn."""
    frame = entry.rig.evaluate(weights).astype(np.float64)
    rot = random_rotation(rng, augment.get("rotate_deg", 0.0))
    scale = np.exp(rng.uniform(-1, 1) * augment.get("scale", 0.0))
    shift = rng.normal(size=3) * augment.get("translate", 0.0)
    frame = (frame @ rot.T) * scale + shift
    canon, channels = None, None
    if neutral_share > 0 and rng.random() < neutral_share and model_cfg.neutral_channels:
        neutral = (entry.rig.neutral.astype(np.float64) @ rot.T) * scale + shift
        canon = Canonicaliser.fit(neutral, kind=model_cfg.canonical, faces=entry.rig.faces)
        channels = neutral_channels(canon.to_canonical(frame), canon.to_canonical(neutral),
                                    entry.rig.faces)
    prepared = prepare_mesh(frame, entry.rig.faces, model_cfg.k_eig, model_cfg.image_size,
                            IMAGE_CHANNELS[model_cfg.image_channels], canon=canon,
                            ops=entry.mesh.ops, canonical=model_cfg.canonical)
    return Source(entry, prepared.feat, prepared.image, weights, kind, channels)



def face_rig(rig):
    """A user's rig (``retarget.user_rig.UserRig``) on its face alone when its neutral has separate
    parts (eyeballs, teeth, ...: ``retarget.mesh.face_part``; the rig itself otherwise), so that
    fine-tuning sees the head as ``Retargeter`` will: the neutral, its faces, shapes, identity
    shapes and segments restricted to the face's vertices."""
    import dataclasses

    face = face_part(Mesh(rig.neutral, rig.faces))
    if face is None:
        return rig
    print(f"{rig.name}: fine-tuning on the face alone ({len(face):,} of {rig.n_vertices:,} vertices, "
          "the part with the most); its other parts (eyes, teeth, ...) are left out", flush=True)
    return dataclasses.replace(
        rig, neutral=rig.neutral[face], faces=submesh(Mesh(rig.neutral, rig.faces), face).faces,
        deltas=rig.deltas[:, face], segments=None if rig.segments is None else rig.segments[face],
        identity_deltas=None if rig.identity_deltas is None else rig.identity_deltas[:, face])


def upright_rig(rig):
    """A user's rig (``retarget.user_rig.UserRig``) turned upright when its neutral is tilted
    (``retarget.canonical.upright_rotation``; the rig itself otherwise), so that fine-tuning sees
    the head as ``Retargeter`` will: the neutral, its shapes and its identity shapes turned alike."""
    import dataclasses

    rotation = upright_rotation(rig.neutral.astype(np.float64), rig.faces)
    if rotation is None:
        return rig
    print(f"{rig.name}: the head is turned {rotation_angle(rotation):.1f} degrees from facing +z; "
          "fine-tuning on it turned upright", flush=True)
    turn = rotation.T.astype(np.float32)
    return dataclasses.replace(
        rig, neutral=rig.neutral @ turn, deltas=rig.deltas @ turn,
        identity_deltas=None if rig.identity_deltas is None else rig.identity_deltas @ turn)


class RigPool:
    """Self-retargeting groups on the user's own rig (``data.rig``), mixed with procedural groups.

    With probability ``data.rig_mix`` a step's group is drawn from the rig: its neutral as the
    target and ``sources_per_target`` sources, the rig driven by weights sampled as for procedural
    rigs (``data.weights``) and zeroed on the shapes the rig lacks, augmented like procedural
    sources. Otherwise the step takes the procedural ``TargetPool`` group, so the model does not
    forget. Deterministic from (seed, step, rank), like ``TargetPool``: resuming is exact.
    """

    def __init__(self, data_cfg: dict, model_cfg, seed: int):
        from .user_rig import load_user_rig

        self.cfg, self.model_cfg, self.seed = data_cfg, model_cfg, int(seed)
        self.mix = float(data_cfg["rig_mix"])
        if not 0.0 <= self.mix <= 1.0:
            raise RetargetError(f"data.rig_mix must be in [0, 1], got {self.mix}")
        rig = load_user_rig(data_cfg["rig"], data_cfg["keep_vertices"],
                            strict=bool(data_cfg.get("rig_strict", False)))
        rig = face_rig(rig)                 # the face alone and upright, as Retargeter sees it
        if model_cfg.canonical == "face":
            rig = upright_rig(rig)
        if rig.segments is not None and rig.segments.max() >= model_cfg.n_segments:
            raise RetargetError(f"{rig.name}: segment labels reach {int(rig.segments.max())}, but the "
                                f"model has {model_cfg.n_segments} segments")
        mesh = prepare_mesh(rig.neutral, rig.faces, model_cfg.k_eig, model_cfg.image_size,
                            IMAGE_CHANNELS[model_cfg.image_channels], canonical=model_cfg.canonical)
        self.entry = Entry(rig, mesh, (rig.deltas * mesh.canon.scale).astype(np.float32),
                           rig.present)
        self.procedural = TargetPool(data_cfg, model_cfg, seed) if self.mix < 1.0 else None

    def sample(self, step: int, rank: int = 0) -> Group:
        """The training group of ``step`` on process ``rank``: from the rig or procedural."""
        rng = np.random.default_rng([self.seed, step, rank, 2])
        if self.procedural is not None and rng.random() >= self.mix:
            return self.procedural.sample(step, rank)
        weights = sample_weights(rng, self.cfg["sources_per_target"], mode=self.cfg["weights"])
        weights = (weights * self.entry.present).astype(np.float32)
        sources = [make_source(self.entry, w, "self", rng, self.cfg.get("augment", {}),
                               self.model_cfg, self.cfg.get("source_neutral_share", 0.0))
                   for w in weights]
        return Group(self.entry, sources, ground_truth(weights, self.entry))


def make_pool(data_cfg: dict, model_cfg, seed: int):
    """The trainer's sampler: ``RigPool`` when ``data.rig`` names a rig, else ``TargetPool``."""
    if data_cfg.get("rig"):
        return RigPool(data_cfg, model_cfg, seed)
    return TargetPool(data_cfg, model_cfg, seed)


def validation_entries(data_cfg: dict, model_cfg, seed: int) -> list[tuple[Entry, np.ndarray]]:
    """Fixed validation set: ``val_identities`` held-out identities (split "val"), each with
    ``val_expressions`` fixed weight vectors (53,). With both rig sources in ``data.sources`` they
    alternate (procedural first), each on the first tessellation of its list."""
    shares = source_shares(data_cfg)
    both = shares.min() > 0
    makehuman = MakeHumanRigs(data_cfg["makehuman"], "val") if shares[1] > 0 else None
    out = []
    for i in range(data_cfg["val_identities"]):
        ident_seed = seed * 1_000_003 + i
        if makehuman is None or (both and i % 2 == 0):
            entry = prepare_entry(sample_identity(ident_seed, split="val"),
                                  data_cfg["tessellations"][0], tess_seed=10_000 + i,
                                  model_cfg=model_cfg, n_segments=model_cfg.n_segments)
        else:
            rig = makehuman.rig(makehuman.base(ident_seed), 0, 10_000 + i, model_cfg.n_segments)
            entry = prepare_rig(rig, model_cfg)
        rng = np.random.default_rng([seed, 99, i])
        weights = sample_weights(rng, data_cfg["val_expressions"], mode="mixed")
        if entry.present is not None:
            weights = weights * entry.present
        out.append((entry, weights))
    return out
