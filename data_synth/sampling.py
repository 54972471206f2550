"""Expression weight sampling as in NFS: uniform weights, one-hot extremes, sparse combinations of
a few active shapes, and smooth random sequences for temporal tests."""
from __future__ import annotations

import numpy as np

from .facs import N_FACS

MODES = ("uniform", "onehot", "sparse", "neutral", "subtle", "mixed", "calm")
MIXED_SHARES = {"uniform": 0.3, "onehot": 0.2, "sparse": 0.5}
#: "calm": "mixed" with a share of neutral frames (every weight 0) and of subtle ones (1-5 active
#: shapes at weights ~U(0, 0.3)), the small motions around the neutral that most captured frames are
CALM_SHARES = {"uniform": 0.2, "onehot": 0.15, "sparse": 0.4, "neutral": 0.1, "subtle": 0.15}


def sample_weights(rng: np.random.Generator, n: int, mode: str = "mixed") -> np.ndarray:
    """(n, 53) float64 weights in [0, 1].

    uniform: every weight ~U(0,1); onehot: one shape at 1; sparse: 1-5 active shapes with weights
    ~U(0.2, 1); neutral: every weight 0; subtle: 1-5 active shapes with weights ~U(0, 0.3); mixed:
    each row drawn from the first three modes with MIXED_SHARES; calm: from all five with
    CALM_SHARES.
    """
    if mode not in MODES:
        raise ValueError(f"sample_weights: mode must be one of {MODES}, got {mode!r}")
    if mode == "uniform":
        return rng.random((n, N_FACS))
    out = np.zeros((n, N_FACS))
    if mode == "onehot":
        out[np.arange(n), rng.integers(0, N_FACS, n)] = 1.0
        return out
    if mode in ("sparse", "subtle"):
        lo, hi = (0.2, 1.0) if mode == "sparse" else (0.0, 0.3)
        for row, k in zip(out, rng.integers(1, 6, n)):
            row[rng.choice(N_FACS, k, replace=False)] = rng.uniform(lo, hi, k)
        return out
    if mode == "neutral":
        return out
    shares = MIXED_SHARES if mode == "mixed" else CALM_SHARES
    kinds = rng.choice(len(shares), n, p=list(shares.values()))
    for i, name in enumerate(shares):
        rows = kinds == i
        out[rows] = sample_weights(rng, int(rows.sum()), name)
    return out


def smooth_sequence(rng: np.random.Generator, n_frames: int, fps: float = 30.0,
                    active_per_second: float = 1.5) -> np.ndarray:
    """(n_frames, 53) float64 weights in [0, 1], smooth in time.

    Each shape is a sum of raised-cosine bumps (0.3-1.5 s long, peak ~U(0.3, 1)) at random times,
    about `active_per_second` bumps per second over all shapes; overlaps are clipped to 1.
    """
    if n_frames < 1 or fps <= 0:
        raise ValueError(f"smooth_sequence: need n_frames >= 1 and fps > 0, got {n_frames}, {fps}")
    t = np.arange(n_frames) / fps
    duration = n_frames / fps
    out = np.zeros((n_frames, N_FACS))
    n_bumps = rng.poisson(active_per_second * duration) + 1
    for _ in range(n_bumps):
        k = rng.integers(N_FACS)
        width = rng.uniform(0.3, 1.5)
        centre = rng.uniform(-0.25 * width, duration + 0.25 * width)
        x = np.clip((t - centre) / width, -0.5, 0.5)
        out[:, k] += rng.uniform(0.3, 1.0) * 0.5 * (1.0 + np.cos(2.0 * np.pi * x))
    return np.clip(out, 0.0, 1.0)
