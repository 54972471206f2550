"""Torch modules and tensor maths of Neural Face Skinning (never imports ``retarget``).

The public names are loaded on first use, so ``import nets.geometry`` does not import the model.
"""
import importlib

_EXPORTS = {
    "Operators": "geometry", "TorchOperators": "geometry", "compute_operators": "geometry",
    "load_or_compute_operators": "geometry",
    "DiffusionNet": "diffusion_net",
    "FrontalCNN": "cnn",
    "NFSConfig": "model", "NFSModel": "model", "TargetCodes": "model",
    "weights_to_code": "model",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'nets' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
