"""YAML configs: reading with clear errors, and overriding defaults key by key."""
from __future__ import annotations

import copy
from pathlib import Path

import yaml

from .errors import RetargetError

#: configs/ of a source checkout (DESIGN.md section 8); a wheel ships the same files as the
#: package ``retarget.configs`` (pyproject.toml maps the folder into the package).
CHECKOUT_CONFIGS = Path(__file__).resolve().parents[1] / "configs"


def configs_dir() -> Path:
    """The folder of the shipped configs (``train/``, ``eval/``, ``synth/``): the checkout's
    ``configs/`` when running from one, else the copy installed with the package."""
    if (CHECKOUT_CONFIGS / "train" / "default.yaml").is_file():
        return CHECKOUT_CONFIGS
    return Path(__file__).resolve().parent / "configs"


def find_config(spec, kind: str) -> Path:
    """A config file from a command line: ``spec`` itself when it is a file, else the shipped
    config of that name: ``NAME``, ``NAME.yaml`` or ``configs/<kind>/NAME.yaml`` (so
    ``--config no_skinning`` and the README's commands work after a plain pip install).
    RetargetError naming ``spec`` and the shipped names when neither exists."""
    path = Path(spec)
    if path.is_file():
        return path
    if path.exists():  # a folder, a FIFO, a device: named as such, not called missing
        from .io import regular_file
        regular_file(path, f"{kind} config file")
    name = path.name if path.suffix == ".yaml" else f"{path.name}.yaml"
    if path.parent == Path(".") or path.parent.as_posix().endswith(f"configs/{kind}"):
        shipped = configs_dir() / kind / name
        if shipped.is_file():
            return shipped
    names = sorted(p.stem for p in (configs_dir() / kind).glob("*.yaml"))
    raise RetargetError(f"{spec}: no such {kind} config file (the shipped {kind} configs, usable "
                        f"by name: {', '.join(names)})")


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
