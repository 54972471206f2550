"""Realistic head rigs from the MakeHuman head (CC0) and an artist's ARKit shapes (MIT).

    from data_synth.makehuman import sample_head_identity, head_tessellation, build_head_rig
    rig = build_head_rig(sample_head_identity(0, split="test"), head_tessellation(3000))

Identities (``identity``), the 53 shapes carried onto them by deformation transfer
(``expressions``, ``transfer``), tessellations and crops as barycentric maps of the base vertices
(``tessellate``), regions (``segmentation``), the rig (``rig``). The data files ship in
``data/`` with their licence notice (LICENSES.md) and documentation (README.md).
"""
import importlib

# public name -> submodule; loaded on first use, so ``python -m data_synth.makehuman.rig`` runs its
# module once (no public name equals a submodule's name)
_EXPORTS = {"HeadIdentity": "identity", "head_neutral": "identity",
            "sample_head_identity": "identity", "BaseHeadRig": "rig", "base_head_rig": "rig",
            "build_head_rig": "rig", "CROPS": "tessellate", "KINDS": "tessellate",
            "HeadTessellation": "tessellate", "head_tessellation": "tessellate"}
__all__ = sorted(_EXPORTS)


def __getattr__(name):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'data_synth.makehuman' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
