"""Realistic blendshape rigs: a MakeHuman identity, its 53 FACS shapes, on one tessellation/crop.

    from data_synth.makehuman import sample_head_identity, head_tessellation, build_head_rig
    ident = sample_head_identity(7, split="test")
    rig = build_head_rig(ident, head_tessellation(5000, kind="decimated", crop="bust"))
    frame = rig.evaluate(weights)            # (V,3) cm; weights (53,) in FACS_NAMES order

``base_head_rig`` does the costly part (the identity's neutral and the deformation transfer of its
shapes, about a second) once; ``build_head_rig`` then puts it on any number of tessellations.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rig import Rig
from ..segmentation import SEGMENT_NAMES
from . import assets
from .expressions import identity_expressions
from .identity import HeadIdentity, head_neutral
from .segmentation import base_segments
from .tessellate import HeadTessellation


@dataclass
class BaseHeadRig:
    """One identity's rig on the base bust vertices: neutral (5472,3) float32 cm, deltas
    (53,5472,3) float32 cm (zero on the 1146 bust vertices below the head), present (53,) bool."""

    neutral: np.ndarray
    deltas: np.ndarray
    present: np.ndarray
    identity: HeadIdentity


def base_head_rig(identity: HeadIdentity, expressions: str = "arkit",
                  style_seed: int | None = None) -> BaseHeadRig:
    """The identity's neutral and shapes (``expressions.identity_expressions``) on the base bust."""
    neutral = head_neutral(identity, "bust")
    head_deltas, present = identity_expressions(neutral[:assets.N_HEAD], identity.macros["race"],
                                                expressions, style_seed)
    deltas = np.zeros((len(head_deltas), assets.N_BUST, 3), np.float32)
    deltas[:, :assets.N_HEAD] = head_deltas
    return BaseHeadRig(neutral.astype(np.float32), deltas, present, identity)


def build_head_rig(identity: HeadIdentity | BaseHeadRig, tess: HeadTessellation,
                   n_segments: int = 20, expressions: str = "arkit",
                   style_seed: int | None = None) -> Rig:
    """The rig on ``tess``: a ``data_synth.rig.Rig`` with uv None, identity None (L_ID needs the
    procedural coefficients), ``present`` and ``correspondence`` = tess.weights. An identity is
    first made into a ``BaseHeadRig`` with ``expressions`` / ``style_seed``."""
    base = identity if isinstance(identity, BaseHeadRig) else base_head_rig(identity, expressions,
                                                                            style_seed)
    labels = base_segments(n_segments)
    owner = np.asarray(tess.weights.argmax(axis=1)).ravel()
    return Rig(neutral=tess.apply(base.neutral), deltas=tess.apply(base.deltas),
               faces=tess.faces.copy(), uv=None, segments=labels[owner].astype(np.int64),
               identity=None, segment_names=SEGMENT_NAMES[n_segments],
               present=base.present.copy(), correspondence=tess.weights)


def benchmark_head_rigs(n_identities: int = 3, sizes=(2500, 20000)) -> dict[str, float]:
    """Median seconds of ``base_head_rig`` (identity + 53 transferred shapes, styled) and of
    ``head_tessellation`` + ``build_head_rig`` per tessellation size (decimated head and neck)."""
    import time

    from .identity import sample_head_identity
    from .tessellate import head_tessellation

    times: dict[str, list[float]] = {}
    for seed in range(n_identities):
        start = time.perf_counter()
        base = base_head_rig(sample_head_identity(seed), style_seed=seed)
        times.setdefault("identity + 53 shapes", []).append(time.perf_counter() - start)
        for n in sizes:
            start = time.perf_counter()
            build_head_rig(base, head_tessellation(n, "decimated", seed=seed))
            times.setdefault(f"tessellate + rig at {n} vertices", []).append(
                time.perf_counter() - start)
    return {k: float(np.median(v)) for k, v in times.items()}


if __name__ == "__main__":  # python -m data_synth.makehuman.rig: the realistic synthesis benchmark
    for what, seconds in benchmark_head_rigs().items():
        print(f"{what}: {seconds:.3f} s (median of 3 identities)")
