"""The shipped MakeHuman head data, loaded once per process.

``heads()``: ``makehuman_heads.npz`` (CC0): the hm08 head cut (4326 vertices: 3386 skin, then the
mouth cavity and eye sockets), 796 shape targets, modifiers, macros, expression units, and the bust
(5472 vertices, the head's 4326 first). ``arkit()``: ``makehuman_arkit.npz`` (MIT targets on the
CC0 mesh): 52 ARKit shapes on the same 4326 vertices. Centimetres, +y up, +z forward, +x = the
character's left. Licences: ``data/LICENSES.md`` (it travels with the files); documentation of
every key: ``data/README.md``.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

DATA_DIR = Path(__file__).resolve().parent / "data"
N_SKIN = 3386     # skin vertices: the first rows of every vertex array
N_HEAD = 4326     # skin + mouth cavity + eye sockets: the first rows of the bust
N_BUST = 5472


def _load(name: str) -> dict:
    path = DATA_DIR / name
    if not path.is_file():
        raise FileNotFoundError(f"{path}: the packaged MakeHuman data file is missing "
                                f"(reinstall the package)")
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


@lru_cache(maxsize=1)
def heads() -> dict:
    """The arrays of ``makehuman_heads.npz`` (see data/README.md for each key)."""
    return _load("makehuman_heads.npz")


@lru_cache(maxsize=1)
def arkit() -> dict:
    """The arrays of ``makehuman_arkit.npz`` (see data/README.md for each key)."""
    return _load("makehuman_arkit.npz")


@lru_cache(maxsize=1)
def bust_targets() -> np.ndarray:
    """Every head-shape target on the whole bust: (T, 5472, 3) float32 cm (T = 796)."""
    z = heads()
    q = np.concatenate([z["target_deltas_q"], z["bust_target_deltas_q"]], axis=1)
    return q.astype(np.float32) * np.float32(z["deltas_scale_cm"])


@lru_cache(maxsize=1)
def bust_extra_targets() -> np.ndarray:
    """The 34 macro targets that move only the bust, on the whole bust: (E, 5472, 3) float32 cm
    (exactly 0 on the head's 4326 vertices)."""
    z = heads()
    extra = z["bust_extra_deltas_q"].astype(np.float32) * np.float32(z["deltas_scale_cm"])
    return np.concatenate([np.zeros((len(extra), N_HEAD, 3), np.float32), extra], axis=1)
