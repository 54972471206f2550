"""PNG contact sheets of the synthesised rigs, for either source: the realistic MakeHuman heads
(``"makehuman"``) or the procedural (u, v) heads (``"procedural"``): the 53 shapes of one identity
as displacement heatmaps, the neutrals of several identities (the realistic ones also as crops),
and the segmentations.

All images come from `retarget.render.Renderer` (offscreen moderngl); heatmaps use YlOrRd on a fixed
centimetre scale so sheets of different identities compare.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from data_synth import FACS_NAMES
from data_synth.segmentation import SEGMENT_LEVELS

from .render import Renderer, contact_sheet, heatmap_colors, save_png

HEATMAP_MAX_CM = 1.5          # displacement that saturates the heatmap
SKIN = np.array([0.85, 0.85, 0.85], dtype=np.float32)
SOURCES = ("makehuman", "procedural")
CROP_TO_REGION = {"face": "face", "head_neck": "full"}   # procedural regions of the crops shown


def _segment_palette(n: int) -> np.ndarray:
    """(n,3) distinct colours: hues spread by the golden ratio, alternating brightness."""
    from matplotlib.colors import hsv_to_rgb

    i = np.arange(n)
    hsv = np.stack([(i * 0.618034) % 1.0, np.where(i % 2, 0.55, 0.8), np.where(i % 3, 0.95, 0.75)], -1)
    return hsv_to_rgb(hsv).astype(np.float32)


def preview_rig(source: str, seed: int, split: str = "test", n_vertices: int = 6000,
                crop: str = "head_neck", n_segments: int = 20):
    """The rig shown for identity ``seed`` of ``split``: crop "face", "head_neck" (both sources) or
    "head" / "bust" (makehuman only), on an adaptive tessellation of about ``n_vertices``."""
    if source == "makehuman":
        from data_synth.makehuman import build_head_rig, head_tessellation, sample_head_identity

        return build_head_rig(sample_head_identity(seed, split),
                              head_tessellation(n_vertices, "decimated", crop), n_segments)
    if source == "procedural":
        from data_synth.identity import sample_identity
        from data_synth.rig import build_rig
        from data_synth.tessellate import tessellate

        tess = tessellate(n_vertices, kind="adaptive", region=CROP_TO_REGION[crop], holes=True)
        return build_rig(sample_identity(seed, split), tess, n_segments)
    raise ValueError(f"source must be one of {SOURCES}, got {source!r}")


def shapes_sheet(rig, size: int = 192, view: str = "front") -> np.ndarray:
    """The neutral and the 53 shapes of one rig, coloured by the displacement magnitude (YlOrRd,
    0..HEATMAP_MAX_CM cm). Returns (H,W,3) float32."""
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


def identities_sheet(source: str, n: int = 12, split: str = "test", n_vertices: int = 8000,
                     size: int = 192) -> np.ndarray:
    """Neutral heads of identities 0..n-1 of ``split`` (front and three-quarter views); realistic
    heads cycle through the crops (head and neck, bust, head, face mask)."""
    crops = ("head_neck", "bust", "head", "face") if source == "makehuman" else ("head_neck",)
    renderer = Renderer(size)
    images, labels = [], []
    for seed in range(n):
        crop = crops[seed % len(crops)]
        rig = preview_rig(source, seed, split, n_vertices, crop)
        for view in ("front", "three_quarter"):
            images.append(renderer.render(rig.neutral, rig.faces, "colors",
                                          np.tile(SKIN, (len(rig.neutral), 1)), view))
            labels.append(f"{split} {seed} {crop if source == 'makehuman' else view[:5]}")
    return contact_sheet(images, labels, cols=8)


def segments_sheet(source: str, seed: int, split: str = "test", n_vertices: int = 8000,
                   size: int = 256) -> np.ndarray:
    """Segment colours at every level (6, 14, 20, 24), front and three-quarter views."""
    renderer = Renderer(size)
    images, labels = [], []
    for level in SEGMENT_LEVELS:
        rig = preview_rig(source, seed, split, n_vertices, "head_neck", level)
        colors = _segment_palette(level)[rig.segments]
        for view in ("front", "three_quarter"):
            images.append(renderer.render(rig.neutral, rig.faces, "colors", colors, view))
            labels.append(f"L={level} {view}")
    return contact_sheet(images, labels, cols=4)


def write_previews(out_dir, identity_seed: int = 0, split: str = "test",
                   source: str = "makehuman") -> list[Path]:
    """Write shapes.png, shapes_three_quarter.png, identities.png and segments.png to out_dir."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rig = preview_rig(source, identity_seed, split, 6000, "face")
    sheets = {
        "shapes.png": shapes_sheet(rig),
        "shapes_three_quarter.png": shapes_sheet(rig, view="three_quarter"),
        "identities.png": identities_sheet(source, 12, split),
        "segments.png": segments_sheet(source, identity_seed, split),
    }
    paths = []
    for name, img in sheets.items():
        save_png(out / name, img)
        paths.append(out / name)
    return paths
