"""Procedural FACS blendshape rigs (numpy/scipy only, no torch). See DESIGN.md section 3.

    from data_synth import N_FACS, build_rig, sample_identity, tessellate
    rig = build_rig(sample_identity(0, split="test"), tessellate(5000, kind="adaptive"))
    weights = [0.5] * N_FACS               # (53,) in FACS_NAMES order
    frame = rig.evaluate(weights)          # (V,3) cm

The public names are loaded on first use, so ``python -m data_synth.rig`` runs the module once.
``data_synth.tessellate`` is always the function, even once the module of the same name has been
imported (``from data_synth.tessellate import Tessellation`` reaches the module).
"""
import importlib
import sys
import types

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


class _Package(types.ModuleType):
    """The import system binds a submodule as an attribute of its package when it is first
    imported; for a public name that is also its module's name (``tessellate``) that binding would
    hide the export behind the module. It is skipped, so the name always means the export."""

    def __setattr__(self, name, value):
        if not (isinstance(value, types.ModuleType) and _EXPORTS.get(name) == name):
            super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
