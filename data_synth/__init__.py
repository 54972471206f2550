"""Procedural FACS blendshape rigs (numpy/scipy only, no torch). See DESIGN.md section 3.

    from data_synth import build_rig, sample_identity, tessellate
    rig = build_rig(sample_identity(0, split="test"), tessellate(5000, kind="adaptive"))
    frame = rig.evaluate(weights)          # (V,3) cm; weights (53,) in FACS_NAMES order

The public names are loaded on first use, so ``python -m data_synth.rig`` runs the module once.
"""
import importlib

_EXPORTS = {
    "ARKIT_NAMES": "facs", "FACS_NAMES": "facs", "N_FACS": "facs", "arkit_to_ict": "facs",
    "ict_to_arkit": "facs",
    "IDENTITY_MODES": "identity", "N_IDENTITY": "identity", "sample_identity": "identity",
    "Rig": "rig", "build_rig": "rig",
    "sample_weights": "sampling", "smooth_sequence": "sampling",
    "SEGMENT_NAMES": "segmentation", "segment_labels": "segmentation",
    "Tessellation": "tessellate", "tessellate": "tessellate",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'data_synth' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
