"""PNG contact sheets of the procedural rigs: the 53 shapes of one identity as displacement
heatmaps, the neutrals of several identities, and the segmentations.

All images come from `retarget.render.Renderer` (offscreen moderngl); heatmaps use YlOrRd on a fixed
centimetre scale so sheets of different identities compare.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from data_synth import FACS_NAMES
from data_synth.identity import sample_identity
from data_synth.rig import build_rig
from data_synth.segmentation import SEGMENT_LEVELS, segment_labels
from data_synth.tessellate import tessellate

from .render import Renderer, contact_sheet, heatmap_colors, save_png

HEATMAP_MAX_CM = 1.5          # displacement that saturates the heatmap
SKIN = np.array([0.85, 0.85, 0.85], dtype=np.float32)


def _segment_palette(n: int) -> np.ndarray:
    """(n,3) distinct colours: hues spread by the golden ratio, alternating brightness."""
    from matplotlib.colors import hsv_to_rgb

    i = np.arange(n)
    hsv = np.stack([(i * 0.618034) % 1.0, np.where(i % 2, 0.55, 0.8), np.where(i % 3, 0.95, 0.75)], -1)
    return hsv_to_rgb(hsv).astype(np.float32)


def shapes_sheet(identity, n_vertices: int = 6000, size: int = 192, view: str = "front") -> np.ndarray:
    """The neutral and the 53 shapes of one identity on a face-crop tessellation, coloured by the
    displacement magnitude (YlOrRd, 0..HEATMAP_MAX_CM cm). Returns (H,W,3) float32."""
    tess = tessellate(n_vertices, kind="adaptive", region="face", holes=True)
    rig = build_rig(identity, tess)
    renderer = Renderer(size)
    box = np.stack([rig.neutral.min(0) - 1.5, rig.neutral.max(0) + 1.5])  # one camera for all
    skin = np.tile(SKIN, (len(rig.neutral), 1))
    images = [renderer.render(rig.neutral, rig.faces, "colors", skin, view, box)]
    labels = ["neutral"]
    for name, delta in zip(FACS_NAMES, rig.deltas):
        mag = np.linalg.norm(delta, axis=1)
        images.append(renderer.render(rig.neutral + delta, rig.faces, "colors",
                                      heatmap_colors(mag, HEATMAP_MAX_CM), view, box))
        labels.append(f"{name} {mag.max():.1f}")
    return contact_sheet(images, labels, cols=9)


def identities_sheet(n: int = 12, split: str = "test", n_vertices: int = 8000, size: int = 192) -> np.ndarray:
    """Neutral heads of identities 0..n-1 of `split` (front and three-quarter views)."""
    tess = tessellate(n_vertices, kind="adaptive", region="full", holes=True)
    renderer = Renderer(size)
    images, labels = [], []
    for seed in range(n):
        rig = build_rig(sample_identity(seed, split), tess)
        for view in ("front", "three_quarter"):
            images.append(renderer.render(rig.neutral, rig.faces, "colors",
                                          np.tile(SKIN, (len(rig.neutral), 1)), view))
            labels.append(f"{split} {seed} {view[:5]}")
    return contact_sheet(images, labels, cols=8)


def segments_sheet(identity, n_vertices: int = 8000, size: int = 256) -> np.ndarray:
    """Segment colours at every level (6, 14, 20, 24), front and three-quarter views."""
    tess = tessellate(n_vertices, kind="adaptive", region="full", holes=True)
    rig = build_rig(identity, tess)
    renderer = Renderer(size)
    images, labels = [], []
    for level in SEGMENT_LEVELS:
        colors = _segment_palette(level)[segment_labels(tess.uv, level)]
        for view in ("front", "three_quarter"):
            images.append(renderer.render(rig.neutral, rig.faces, "colors", colors, view))
            labels.append(f"L={level} {view}")
    return contact_sheet(images, labels, cols=4)


def write_previews(out_dir, identity_seed: int = 0, split: str = "test") -> list[Path]:
    """Write shapes.png, shapes_three_quarter.png, identities.png and segments.png to out_dir."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    identity = sample_identity(identity_seed, split)
    sheets = {
        "shapes.png": shapes_sheet(identity),
        "shapes_three_quarter.png": shapes_sheet(identity, view="three_quarter"),
        "identities.png": identities_sheet(12, split),
        "segments.png": segments_sheet(identity),
    }
    paths = []
    for name, img in sheets.items():
        save_png(out / name, img)
        paths.append(out / name)
    return paths
