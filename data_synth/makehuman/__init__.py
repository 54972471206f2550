"""Realistic head rigs from the MakeHuman head (CC0) and an artist's ARKit shapes (MIT).

    from data_synth.makehuman import sample_head_identity, head_tessellation, build_head_rig
    rig = build_head_rig(sample_head_identity(0, split="test"), head_tessellation(3000))

Identities (``identity``), the 53 shapes carried onto them by deformation transfer
(``expressions``, ``transfer``), tessellations and crops as barycentric maps of the base vertices
(``tessellate``), regions (``segmentation``), the rig (``rig``). The data files ship in
``data/`` with their licence notice (LICENSES.md) and documentation (README.md).
"""
from .identity import HeadIdentity, head_neutral, sample_head_identity
from .rig import BaseHeadRig, base_head_rig, build_head_rig
from .tessellate import CROPS, KINDS, HeadTessellation, head_tessellation

__all__ = ["BaseHeadRig", "CROPS", "HeadIdentity", "HeadTessellation", "KINDS", "base_head_rig",
           "build_head_rig", "head_neutral", "head_tessellation", "sample_head_identity"]
