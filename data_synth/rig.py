"""A procedural blendshape rig: one identity's neutral head and its 53 FACS deltas on one
tessellation (ARCHITECTURE.md, `data_synth.rig`)."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .expressions import expression_deltas
from .facs import N_FACS
from .head import surface
from .identity import sample_identity
from .segmentation import SEGMENT_NAMES, segment_labels
from .tessellate import Tessellation, tessellate


@dataclass
class Rig:
    """neutral (V,3) float32 cm; deltas (53,V,3) float32 cm (ICT order); faces (F,3) int64;
    uv (V,2) float64, the (u, v) of a procedural head (None for a realistic head); segments (V,)
    int64 in [0, L); identity (J,) float64, the procedural identity coefficients that L_ID
    supervises (None for a realistic head); segment_names (L,); present (53,) bool, the shapes
    the rig has (None = all 53); correspondence: for a realistic head its (V, 5472) sparse map
    from the MakeHuman base vertices (``data_synth.makehuman.tessellate``), else None."""

    neutral: np.ndarray
    deltas: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None
    segments: np.ndarray
    identity: np.ndarray | None
    segment_names: tuple
    present: np.ndarray | None = None
    correspondence: object = None

    def evaluate(self, weights) -> np.ndarray:
        """neutral + weights . deltas: weights (53,) -> (V,3) or (T,53) -> (T,V,3), float32 cm."""
        w = np.asarray(weights, dtype=np.float32)
        if w.shape[-1] != N_FACS or w.ndim not in (1, 2):
            raise ValueError(f"weights must have shape (53,) or (T, 53), got {w.shape}")
        return self.neutral + np.tensordot(w, self.deltas, axes=(-1, 0))


def build_rig(identity, tess: Tessellation, n_segments: int = 20) -> Rig:
    """Evaluate the head and the 53 expression operators of identity z_ID (J,) on `tess`."""
    identity = np.asarray(identity, dtype=np.float64)
    return Rig(
        neutral=surface(tess.uv, identity).astype(np.float32),
        deltas=expression_deltas(tess.uv, identity).astype(np.float32),
        faces=np.asarray(tess.faces, dtype=np.int64),
        uv=np.asarray(tess.uv, dtype=np.float64),
        segments=segment_labels(tess.uv, n_segments),
        identity=identity,
        segment_names=SEGMENT_NAMES[n_segments],
    )


def benchmark_build(sizes=(5000, 30000), repeats: int = 5) -> dict[int, float]:
    """Median seconds of ``build_rig`` (one identity, all 53 shapes) per tessellation size."""
    out = {}
    for n in sizes:
        tess = tessellate(n, kind="adaptive")
        times = []
        for seed in range(repeats):
            start = time.perf_counter()
            build_rig(sample_identity(seed), tess)
            times.append(time.perf_counter() - start)
        out[tess.n_vertices] = float(np.median(times))
    return out


if __name__ == "__main__":  # python -m data_synth.rig: the rig synthesis benchmark
    for n_vertices, seconds in benchmark_build().items():
        print(f"53-shape rig at {n_vertices} vertices: {seconds:.3f} s (median of 5 identities)")
