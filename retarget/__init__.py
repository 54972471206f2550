"""Mesh-agnostic facial expression retargeting (Neural Face Skinning). Public API: see README.md.

    from retarget import Retargeter, load_mesh, FACS_NAMES
"""
from data_synth.facs import FACS_NAMES  # noqa: F401

from .errors import RetargetError  # noqa: F401

_LAZY = {"Retargeter": "api", "BakedRig": "api", "Target": "api", "load_mesh": "io",
         "save_mesh": "io", "load_sequence": "io", "Mesh": "mesh", "read_weights": "weights_io",
         "write_weights_csv": "weights_io"}


def __getattr__(name):
    """Import the heavy parts (torch, trimesh) only when they are used."""
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'retarget' has no attribute {name!r}")


__all__ = ["FACS_NAMES", "RetargetError", *_LAZY]
