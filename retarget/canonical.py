"""Canonicalisation: the network sees every mesh centred and at one size, whatever its units.

The canonical frame puts the centre of the mesh's axis-aligned bounding box at the origin and scales
the mesh uniformly so its width (x extent, ear to ear) is ``CANONICAL_WIDTH`` = 16 canonical units,
about the width of a real head in centimetres (the unit of the synthetic training rigs). Axes are
not changed (the input must already be +y up, +z forward; see ``retarget.io.axis_rotation``).

Network outputs (positions or displacements in canonical units) are mapped back to the input's
frame and units with :meth:`Canonicaliser.from_canonical` / :meth:`displacement_from_canonical`.
Hence a head given in metres, centimetres or millimetres yields the same expression, in its own
units: the result for the millimetre head is the centimetre result times ten. This is the
robustness to scale and translation that NFS lacks (paper Fig. 11).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import RetargetError

CANONICAL_WIDTH = 16.0


@dataclass(frozen=True)
class Canonicaliser:
    """Similarity (translation + uniform scale) from a mesh's frame to the canonical frame.

    centre: (3,) float64 bounding-box centre, input units. scale: canonical units per input unit.
    canonical = (points − centre) · scale.
    """

    centre: np.ndarray
    scale: float

    @classmethod
    def fit(cls, vertices, name: str = "mesh") -> "Canonicaliser":
        """Fit to vertices (V,3): bounding-box centre, and scale making the x extent 16 units.
        RetargetError (naming ``name``) for a mesh with no width."""
        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        lo, hi = v.min(axis=0), v.max(axis=0)
        width = float(hi[0] - lo[0])
        if not np.isfinite(width) or width <= 1e-12 * max(1.0, float(np.abs(v).max())):
            raise RetargetError(f"{name}: has no width along x (extent {width:g}); "
                                "is it a face mesh in the +y up, +z forward frame?")
        return cls(centre=0.5 * (lo + hi), scale=CANONICAL_WIDTH / width)

    def to_canonical(self, points) -> np.ndarray:
        """(..., 3) points in input units -> (..., 3) float64 canonical."""
        return (np.asarray(points, dtype=np.float64) - self.centre) * self.scale

    def from_canonical(self, points) -> np.ndarray:
        """(..., 3) canonical points -> (..., 3) float64 in the input's frame and units."""
        return np.asarray(points, dtype=np.float64) / self.scale + self.centre

    def displacement_from_canonical(self, d) -> np.ndarray:
        """(..., 3) canonical displacements -> (..., 3) float64 input units (scale only)."""
        return np.asarray(d, dtype=np.float64) / self.scale

    def displacement_to_canonical(self, d) -> np.ndarray:
        """(..., 3) displacements in input units -> (..., 3) float64 canonical (scale only)."""
        return np.asarray(d, dtype=np.float64) * self.scale
