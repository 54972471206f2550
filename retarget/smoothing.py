"""Temporal filtering of per-frame codes (DESIGN.md section 4: per-frame cloning jitters).

``one_euro`` is causal (streaming; Casiez et al. 2012: a low-pass filter whose cut-off rises with the
signal's speed, so slow motion is smoothed and fast motion keeps little lag); ``savgol`` is offline
(Savitzky–Golay: a local polynomial fit, which keeps peaks better than a moving average).
"""
from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

from .errors import RetargetError
from .io import check_fps

FILTERS = ("one_euro", "savgol")


def one_euro(x: np.ndarray, fps: float, min_cutoff: float = 1.5, beta: float = 0.3,
             d_cutoff: float = 1.0) -> np.ndarray:
    """Causal One Euro filter along axis 0: x (T, D) -> (T, D). Cut-offs in Hz."""
    x = np.asarray(x, np.float64)
    out = np.empty_like(x)
    out[0] = x[0]
    dx_prev = np.zeros_like(x[0])
    te = 1.0 / fps

    def alpha(cutoff):
        r = 2 * np.pi * cutoff * te
        return r / (r + 1)

    for t in range(1, len(x)):
        dx = (x[t] - out[t - 1]) * fps
        a_d = alpha(d_cutoff)
        dx_hat = a_d * dx + (1 - a_d) * dx_prev
        a = alpha(min_cutoff + beta * np.abs(dx_hat))
        out[t] = a * x[t] + (1 - a) * out[t - 1]
        dx_prev = dx_hat
    return out


def savgol(x: np.ndarray, window: int = 9, order: int = 2) -> np.ndarray:
    """Savitzky–Golay filter along axis 0: x (T, D) -> (T, D); the window shrinks for short clips."""
    x = np.asarray(x, np.float64)
    w = min(window, len(x) if len(x) % 2 else len(x) - 1)
    if w <= order:
        return x.copy()
    return savgol_filter(x, w, order, axis=0, mode="interp")


def smooth_codes(z: np.ndarray, method: str, fps: float = 30.0) -> np.ndarray:
    """Filter codes (T, D) over time with ``method`` in FILTERS -> (T, D) float64; RetargetError for
    another method, or an fps that is not a finite number above 0."""
    fps = check_fps(fps)
    if method == "one_euro":
        return one_euro(z, fps)
    if method == "savgol":
        return savgol(z)
    raise RetargetError(f"unknown smoothing {method!r}; choose one of {', '.join(FILTERS)}")
