"""Procedural FACS blendshape rigs (numpy/scipy only, no torch). See DESIGN.md section 3."""
from .facs import FACS_NAMES, N_FACS, ARKIT_NAMES, arkit_to_ict, ict_to_arkit  # noqa: F401
