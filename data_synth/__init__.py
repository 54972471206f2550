"""Procedural FACS blendshape rigs (numpy/scipy only, no torch). See DESIGN.md section 3.

    from data_synth import build_rig, sample_identity, tessellate
    rig = build_rig(sample_identity(0, split="test"), tessellate(5000, kind="adaptive"))
    frame = rig.evaluate(weights)          # (V,3) cm; weights (53,) in FACS_NAMES order
"""
from .facs import ARKIT_NAMES, FACS_NAMES, N_FACS, arkit_to_ict, ict_to_arkit  # noqa: F401
from .identity import IDENTITY_MODES, N_IDENTITY, sample_identity  # noqa: F401
from .rig import Rig, build_rig  # noqa: F401
from .sampling import sample_weights, smooth_sequence  # noqa: F401
from .segmentation import SEGMENT_NAMES, segment_labels  # noqa: F401
from .tessellate import Tessellation, tessellate  # noqa: F401
