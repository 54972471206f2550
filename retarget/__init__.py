"""Mesh-agnostic facial expression retargeting. Public API: see README.md."""
from data_synth.facs import FACS_NAMES  # noqa: F401
from .errors import RetargetError  # noqa: F401
