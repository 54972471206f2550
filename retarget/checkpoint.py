"""Checkpoint files: plain types and tensors only, loaded with ``torch.load(weights_only=True)``
(a tampered file carrying pickled objects is refused), written atomically."""
from __future__ import annotations

import os
from pathlib import Path

import torch

from nets.model import NFSConfig, NFSModel

from .errors import RetargetError

CHECKPOINT_FORMAT = "retarget-checkpoint/1"


def save_checkpoint(path: Path, state: dict) -> None:
    """Write atomically (temporary file in the same folder, then rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)


def load_checkpoint(path) -> dict:
    """Load a checkpoint with ``weights_only=True``; RetargetError names the file and the problem."""
    path = Path(path)
    if not path.is_file():
        raise RetargetError(f"{path}: checkpoint not found")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises many types for a corrupt or tampered file
        raise RetargetError(f"{path}: not a loadable checkpoint ({type(e).__name__}: "
                            f"{str(e).splitlines()[0][:200]})") from None
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise RetargetError(f"{path}: not a retarget checkpoint (format "
                            f"{state.get('format') if isinstance(state, dict) else type(state).__name__!r})")
    return state


def model_from_checkpoint(state: dict, path="checkpoint") -> NFSModel:
    """Build the NFSModel of a loaded checkpoint and load its weights."""
    try:
        model = NFSModel(NFSConfig.from_dict(state["model_config"]))
        model.load_state_dict(state["model"])
    except (KeyError, ValueError, RuntimeError) as e:
        raise RetargetError(f"{path}: checkpoint does not match this version's model "
                            f"({str(e).splitlines()[0][:200]})") from None
    return model
