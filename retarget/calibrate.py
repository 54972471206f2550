"""Calibration of the procedural expressions against a real ARKit rig (shared/rigs/makehuman_arkit.npz).

For every ARKit shape with ICT counterparts (XLeft = X_L; browInnerUp and cheekPuff = the sum of
both ICT halves; tongueOut skipped), the procedural shape on the mean identity is compared with the
real one after scaling the procedural head to the real head's face width:
- max displacement (cm) of each and their ratio (procedural / real);
- area fraction moved > 1 mm, of the front of the head (vertices less than FRONT_DEPTH_CM behind the
  nose tip, the same region on both heads);
- main direction of motion: unit area-weighted mean displacement of each, and their cosine.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from data_synth.facs import ARKIT_NAMES, FACS_INDEX, arkit_to_ict
from data_synth.identity import mean_identity
from data_synth.makehuman.assets import DATA_DIR
from data_synth.rig import build_rig
from data_synth.tessellate import tessellate

# the packaged copy of the MakeHuman ARKit rig (MIT; data_synth/makehuman/data/LICENSES.md)
DEFAULT_RIG = DATA_DIR / "makehuman_arkit.npz"
FACE_SLAB_CM = 7.0        # face width: x extent of the vertices within this depth of the nose tip
FRONT_DEPTH_CM = 10.0     # area fractions are taken over the vertices within this depth
MOVED_CM = 0.1            # "moved" threshold (1 mm)
MAGNITUDE_BAND = (0.5, 2.0)
COSINE_OK = 0.7


@dataclass
class ShapeStats:
    """Statistics of one shape on one head: max (cm), area fraction moved > 1 mm, unit direction."""

    max_cm: float
    moved_fraction: float
    direction: np.ndarray


@dataclass
class Row:
    arkit: str
    ict: tuple
    real: ShapeStats
    procedural: ShapeStats

    @property
    def ratio(self) -> float:
        return self.procedural.max_cm / max(self.real.max_cm, 1e-9)

    @property
    def cosine(self) -> float:
        return float(self.procedural.direction @ self.real.direction)


def vertex_areas(verts, faces) -> np.ndarray:
    """(V,) one third of the area of the triangles around each vertex (cm^2)."""
    tri = verts[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    out = np.zeros(len(verts))
    np.add.at(out, faces.ravel(), np.repeat(area / 3.0, 3))
    return out


def face_width(verts) -> float:
    """x extent (cm) of the vertices within FACE_SLAB_CM of the nose tip (max z): ears excluded."""
    front = verts[:, 2] > verts[:, 2].max() - FACE_SLAB_CM
    return float(np.ptp(verts[front, 0]))


def shape_stats(verts, faces, delta) -> ShapeStats:
    """ShapeStats of one displacement field delta (V,3) on a head (verts (V,3), faces (F,3))."""
    area = vertex_areas(verts, faces)
    front = verts[:, 2] > verts[:, 2].max() - FRONT_DEPTH_CM
    mag = np.linalg.norm(delta, axis=1)
    moved = float(area[front & (mag > MOVED_CM)].sum() / area[front].sum())
    mean = (area[:, None] * delta).sum(0) / area.sum()
    direction = mean / max(np.linalg.norm(mean), 1e-12)
    return ShapeStats(float(mag.max()), moved, direction)


def compare(rig_path=DEFAULT_RIG, n_vertices: int = 12000) -> list[Row]:
    """One Row per ARKit shape with an ICT counterpart (51), procedural head scaled to the real one."""
    from .evaluate import RealRig

    real = RealRig.load(rig_path, hint="give --rig")
    names = list(real.names)
    tess = tessellate(n_vertices, kind="adaptive", region="full", holes=True)
    proc = build_rig(mean_identity(), tess)
    scale = face_width(real.neutral) / face_width(proc.neutral)
    p_verts = proc.neutral.astype(np.float64) * scale
    rows = []
    for arkit in ARKIT_NAMES:
        ict = arkit_to_ict(arkit)
        if not ict:
            continue
        p_delta = scale * sum(proc.deltas[FACS_INDEX[n]].astype(np.float64) for n in ict)
        r_delta = real.deltas[names.index(arkit)].astype(np.float64)
        rows.append(Row(arkit, ict, shape_stats(real.neutral.astype(np.float64), real.faces, r_delta),
                        shape_stats(p_verts, proc.faces, p_delta)))
    return rows


def _vec(d):
    return "(" + ", ".join(f"{x:+.2f}" for x in d) + ")"


def markdown_table(rows: list[Row]) -> str:
    """The comparison as a markdown table."""
    lines = ["| ARKit shape | max real (cm) | max proc (cm) | ratio | moved >1mm real | moved >1mm proc "
             "| direction real | direction proc | cosine |",
             "| --- | ---: | ---: | ---: | ---: | ---: | --- | --- | ---: |"]
    for r in rows:
        lines.append(f"| {r.arkit} | {r.real.max_cm:.2f} | {r.procedural.max_cm:.2f} | {r.ratio:.2f} | "
                     f"{r.real.moved_fraction:.1%} | {r.procedural.moved_fraction:.1%} | "
                     f"{_vec(r.real.direction)} | {_vec(r.procedural.direction)} | {r.cosine:+.2f} |")
    return "\n".join(lines)


def summary(rows: list[Row]) -> dict:
    """Counts of shapes within MAGNITUDE_BAND of the real magnitude and with cosine > COSINE_OK."""
    lo, hi = MAGNITUDE_BAND
    in_band = [r.arkit for r in rows if lo <= r.ratio <= hi]
    aligned = [r.arkit for r in rows if r.cosine > COSINE_OK]
    return {"n_shapes": len(rows), "magnitude_within_0.5_2x": len(in_band),
            "direction_cosine_gt_0.7": len(aligned),
            "outside_band": [r.arkit for r in rows if r.arkit not in in_band],
            "misaligned": [r.arkit for r in rows if r.arkit not in aligned]}
