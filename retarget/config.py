"""YAML configs: reading with clear errors, and overriding defaults key by key."""
from __future__ import annotations

import copy
from pathlib import Path

import yaml

from .errors import RetargetError


def read_yaml(path, what: str = "config") -> dict:
    """A YAML mapping from ``path``; RetargetError naming the file if it is unreadable, not YAML,
    or not a mapping. ``what`` names the kind of file in the message."""
    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text()) or {}
    except OSError as e:
        raise RetargetError(f"{path}: cannot read {what} ({e.strerror})") from None
    except yaml.YAMLError as e:
        raise RetargetError(f"{path}: not valid YAML ({e})") from None
    if not isinstance(raw, dict):
        raise RetargetError(f"{path}: a {what} must be a mapping")
    return raw


def merge(defaults: dict, overrides: dict, where: str, replace: tuple[str, ...] = ()) -> dict:
    """``defaults`` with ``overrides`` applied key by key, recursing into mappings; keys named in
    ``replace`` are taken whole. Unknown keys raise RetargetError naming ``where`` (e.g. the file)."""
    out = copy.deepcopy(defaults)
    for key, value in (overrides or {}).items():
        if key not in defaults:
            raise RetargetError(f"{where}: unknown key {key!r} (known: {', '.join(defaults)})")
        if isinstance(defaults[key], dict) and key not in replace:
            if not isinstance(value, dict):
                raise RetargetError(f"{where}: {key!r} must be a mapping")
            out[key] = merge(defaults[key], value, f"{where}.{key}", replace)
        else:
            out[key] = value
    return out
