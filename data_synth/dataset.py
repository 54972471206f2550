"""Synthetic rig datasets: config-driven generation and sharded npz storage.

An *item* is one identity on one tessellation with N sampled expressions:
  neutral (V,3) float32 cm, faces (F,3) int64, uv (V,2) float64, segments (V,) int64,
  identity (J,) float64, weights (N,53) float32, expressions (N,V,3) float32 cm
  (= neutral + weights . deltas), and, if the config stores them, deltas (53,V,3) float32 cm.
A shard `shard_XXXXX.npz` holds up to `shard_size` items under keys `"{i:04d}/{field}"`;
`index.json` lists the shards and their item counts. Every file is written to a temporary name and
renamed, so an interrupted run never leaves a truncated shard.
"""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np
import yaml

from .identity import SPLITS, sample_identity
from .rig import build_rig
from .sampling import MODES, sample_weights
from .segmentation import SEGMENT_LEVELS
from .tessellate import KINDS, REGIONS, tessellate

FIELDS = ("neutral", "faces", "uv", "segments", "identity", "weights", "expressions", "deltas")

DEFAULTS = {
    "split": "train", "n_identities": 8, "identity_seed": 0, "stylised_share": 0.2,
    "expressions_per_identity": 16, "weights": "mixed", "n_segments": 20, "shard_size": 8,
    "store_deltas": True, "seed": 0,
    "tessellations": [{"n_vertices": 3000, "kind": "regular", "region": "full", "holes": True}],
}


def _require(cond, key, message):
    if not cond:
        raise ValueError(f"synth config: bad value for '{key}': {message}")


def validate_config(cfg: dict) -> dict:
    """Config with defaults filled in; raises ValueError naming the first bad key."""
    unknown = set(cfg) - set(DEFAULTS)
    _require(not unknown, sorted(unknown)[0] if unknown else "", "unknown key")
    out = {**DEFAULTS, **cfg}
    _require(out["split"] in SPLITS, "split", f"must be one of {SPLITS}, got {out['split']!r}")
    for key in ("n_identities", "expressions_per_identity", "shard_size"):
        _require(isinstance(out[key], int) and out[key] >= 1, key,
                 f"must be an integer >= 1, got {out[key]!r}")
    for key in ("identity_seed", "seed"):
        _require(isinstance(out[key], int) and out[key] >= 0, key,
                 f"must be an integer >= 0, got {out[key]!r}")
    _require(isinstance(out["stylised_share"], (int, float)) and 0 <= out["stylised_share"] <= 1,
             "stylised_share", f"must be in [0, 1], got {out['stylised_share']!r}")
    _require(out["weights"] in MODES, "weights", f"must be one of {MODES}, got {out['weights']!r}")
    _require(out["n_segments"] in SEGMENT_LEVELS, "n_segments", f"must be one of {SEGMENT_LEVELS}")
    _require(isinstance(out["store_deltas"], bool), "store_deltas", "must be true or false")
    tess = out["tessellations"]
    _require(isinstance(tess, list) and tess, "tessellations", "must be a non-empty list")
    for i, spec in enumerate(tess):
        key = f"tessellations[{i}]"
        _require(isinstance(spec, dict) and set(spec) <= {"n_vertices", "kind", "region", "holes"},
                 key, "must be a mapping with n_vertices, kind, region, holes")
        n = spec.get("n_vertices", 5000)
        _require(isinstance(n, int) and 100 <= n <= 2_000_000, f"{key}.n_vertices",
                 "must be an integer in [100, 2000000]")
        _require(spec.get("kind", "regular") in KINDS, f"{key}.kind", f"must be one of {KINDS}")
        _require(spec.get("region", "full") in REGIONS, f"{key}.region", f"must be one of {REGIONS}")
        _require(isinstance(spec.get("holes", True), bool), f"{key}.holes", "must be true or false")
    return out


def load_config(path) -> dict:
    """Read and validate a synth YAML config."""
    with open(path) as f:
        cfg = yaml.safe_load(f) or {}
    if not isinstance(cfg, dict):
        raise ValueError(f"synth config {path}: must be a YAML mapping")
    return validate_config(cfg)


def generate_items(cfg: dict) -> Iterator[dict]:
    """Items (see module docstring) for a validated config, deterministic from its seeds.

    Identity i uses seed identity_seed + i in the config's split, tessellation spec
    tessellations[i % len] with tessellation seed i, and weights from
    default_rng([seed, identity_seed + i]).
    """
    specs = cfg["tessellations"]
    for i in range(cfg["n_identities"]):
        ident_seed = cfg["identity_seed"] + i
        identity = sample_identity(ident_seed, cfg["split"], cfg["stylised_share"])
        tess = tessellate(seed=i, **specs[i % len(specs)])
        rig = build_rig(identity, tess, cfg["n_segments"])
        rng = np.random.default_rng([cfg["seed"], ident_seed])
        weights = sample_weights(rng, cfg["expressions_per_identity"], cfg["weights"]).astype(np.float32)
        item = dict(neutral=rig.neutral, faces=rig.faces, uv=rig.uv, segments=rig.segments,
                    identity=rig.identity, weights=weights, expressions=rig.evaluate(weights))
        if cfg["store_deltas"]:
            item["deltas"] = rig.deltas
        yield item


def _atomic_write(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def _write_shard(path: Path, items: list[dict]) -> None:
    arrays = {f"{i:04d}/{k}": v for i, item in enumerate(items) for k, v in item.items() if k in FIELDS}

    def write(tmp):
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)
    _atomic_write(path, write)


def write_shards(out_dir, items_iter: Iterable[dict], shard_size: int, progress=None,
                 config: dict | None = None) -> list[Path]:
    """Write items into `out_dir/shard_XXXXX.npz` (shard_size items each) and `index.json`.

    progress: optional callable(n_items) (e.g. a tqdm update); config: the generating config, kept
    in index.json for reproducibility. Returns the shard paths.
    """
    if shard_size < 1:
        raise ValueError(f"write_shards: shard_size must be >= 1, got {shard_size}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths, counts, batch = [], [], []

    def flush():
        path = out / f"shard_{len(paths):05d}.npz"
        _write_shard(path, batch)
        paths.append(path)
        counts.append(len(batch))
        batch.clear()

    for item in items_iter:
        batch.append(item)
        if progress is not None:
            progress(1)
        if len(batch) == shard_size:
            flush()
    if batch:
        flush()
    index = {"shards": [p.name for p in paths], "counts": counts, "fields": list(FIELDS),
             "config": config}
    _atomic_write(out / "index.json", lambda tmp: Path(tmp).write_text(json.dumps(index, indent=1)))
    return paths


class ShardReader:
    """Random access to the items of a shard directory written by `write_shards`.

    len(reader), reader[i] -> dict of arrays, iteration in order; .config: the generating config
    (or None). Keeps one shard open.
    """

    def __init__(self, directory):
        self.dir = Path(directory)
        index_path = self.dir / "index.json"
        if not index_path.is_file():
            raise ValueError(f"ShardReader: {index_path} not found (not a shard directory?)")
        index = json.loads(index_path.read_text())
        self.shards = index["shards"]
        self.config = index.get("config")
        self.offsets = np.concatenate([[0], np.cumsum(index["counts"])]).astype(int)
        self._open = (None, None)

    def __len__(self) -> int:
        return int(self.offsets[-1])

    def __getitem__(self, i: int) -> dict:
        if not -len(self) <= i < len(self):
            raise IndexError(f"item {i} out of range ({len(self)} items)")
        i %= len(self)
        s = int(np.searchsorted(self.offsets, i, side="right") - 1)
        if self._open[0] != s:
            self._open = (s, np.load(self.dir / self.shards[s]))
        data, k = self._open[1], i - self.offsets[s]
        prefix = f"{k:04d}/"
        return {name[len(prefix):]: data[name] for name in data.files if name.startswith(prefix)}

    def __iter__(self):
        return (self[i] for i in range(len(self)))
