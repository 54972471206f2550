"""Error metrics of DESIGN.md section 6, in millimetres.

MSE = mean over vertices of the squared Euclidean distance, in mm²; the segment-averaged MSE of
NFS Table 1 is the mean over segments of each segment's MSE (segments without vertices are skipped).
"""
from __future__ import annotations

import numpy as np

CM_TO_MM = 10.0


def squared_errors_mm2(pred_cm: np.ndarray, gt_cm: np.ndarray) -> np.ndarray:
    """Per-vertex squared distance: pred_cm, gt_cm (..., V, 3) in cm -> (..., V) in mm²."""
    d = (np.asarray(pred_cm, np.float64) - np.asarray(gt_cm, np.float64)) * CM_TO_MM
    return (d * d).sum(-1)


def mse_mm2(pred_cm: np.ndarray, gt_cm: np.ndarray) -> float:
    """Mean over vertices (and frames) of the squared distance, mm². Inputs (..., V, 3) in cm."""
    return float(squared_errors_mm2(pred_cm, gt_cm).mean())


def segment_mse_mm2(pred_cm: np.ndarray, gt_cm: np.ndarray, segments: np.ndarray,
                    n_segments: int) -> tuple[float, np.ndarray]:
    """Segment-averaged MSE (NFS Table 1) and the per-segment MSE.

    pred_cm, gt_cm (..., V, 3) cm; segments (V,) int labels in [0, n_segments).
    Returns (mean over non-empty segments, (n_segments,) per-segment MSE in mm², NaN where empty).
    """
    err = squared_errors_mm2(pred_cm, gt_cm).reshape(-1, len(segments)).mean(0)  # (V,)
    counts = np.bincount(segments, minlength=n_segments)
    sums = np.bincount(segments, weights=err, minlength=n_segments)
    per_seg = np.divide(sums, counts, out=np.full(n_segments, np.nan), where=counts > 0)
    return float(np.nanmean(per_seg)), per_seg


def second_difference_jitter_mm(frames_cm: np.ndarray) -> float:
    """Jitter of a sequence: mean over frames and vertices of |x[t+1] - 2 x[t] + x[t-1]|, in mm.

    frames_cm (T, V, 3) in cm, T >= 3.
    """
    f = np.asarray(frames_cm, np.float64)
    if f.shape[0] < 3:
        raise ValueError(f"jitter needs at least 3 frames, got {f.shape[0]}")
    acc = f[2:] - 2.0 * f[1:-1] + f[:-2]
    return float(np.linalg.norm(acc, axis=-1).mean() * CM_TO_MM)


def weight_mae(pred: np.ndarray, true: np.ndarray) -> float:
    """Mean absolute error of FACS weights: pred, true (..., K) (unitless, in [0, 1])."""
    return float(np.abs(np.asarray(pred, np.float64) - np.asarray(true, np.float64)).mean())


def standard_error(values) -> float | None:
    """Standard error of the mean of ``values`` (n,): sample standard deviation / √n; None for
    fewer than 2 values. The eval gives it over the units a suite draws independently (the
    identities of an inverse-rigging suite, the frames of the one real rig)."""
    v = np.asarray(values, np.float64).reshape(-1)
    if len(v) < 2:
        return None
    return float(v.std(ddof=1) / np.sqrt(len(v)))

