"""FACS weight files in and out: (T,53) float32 arrays in ICT order (``data_synth.facs.FACS_NAMES``).

Readable layouts (names matched case-insensitively, ICT or ARKit names, even mixed):

- CSV with a header row of names, one row per frame; ``frame``/``time`` columns are not weights
  (a ``time`` column in seconds gives the fps);
- Live Link Face CSV: ``Timecode,BlendShapeCount,`` then PascalCase ARKit names, then head and eye
  rotations (ignored); the fps is estimated from the timecodes;
- JSON: ``{name: value}`` (one frame), ``[{name: value}, ...]`` (frames), or
  ``{"names": [...], "frames": [[...], ...], "fps": 30}`` (``frames`` may also hold dicts).

ARKit ``browInnerUp`` and ``cheekPuff`` feed both ICT halves, ``tongueOut`` is dropped, names absent
from the file are 0. Unknown names, missing cells and text where a number belongs raise
RetargetError naming the file (and row and column); values outside [0, 1] give a
:class:`WeightRangeWarning` unless ``clamp=True``, which clips them.
"""
from __future__ import annotations

import csv
import json
import math
import re
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from data_synth.facs import ARKIT_NAMES, FACS_INDEX, FACS_NAMES, N_FACS, arkit_to_ict

from .errors import RetargetError
from .io import atomic_output, check_fps, read_text, regular_file

# columns that are not blendshape weights (lower case): frame/time stamps, Live Link Face extras
NON_WEIGHT_COLUMNS = frozenset(
    ["frame", "time", "timecode", "blendshapecount"]
    + [f"{part}{axis}" for part in ("head", "lefteye", "righteye") for axis in ("yaw", "pitch", "roll")]
)


RANGE_TOLERANCE = 1e-6  # rounding noise around 0 and 1 is not worth a warning
MAX_ABS_WEIGHT = 1e3    # beyond this a value is no weight (and float32 results would overflow)


def _name_table() -> dict:
    """lower-case ICT or ARKit name -> tuple of ICT indices it feeds."""
    table = {n.lower(): (i,) for n, i in FACS_INDEX.items()}
    for n in ARKIT_NAMES:
        table[n.lower()] = tuple(FACS_INDEX[m] for m in arkit_to_ict(n))
    return table


NAME_TABLE = _name_table()


class WeightRangeWarning(UserWarning):
    """Weights outside [0, 1] were read and kept (pass clamp=True to clip them)."""


class WeightTrack(NamedTuple):
    """weights: (T,53) float32 in ICT order; fps: frames per second if the file tells, else None."""

    weights: np.ndarray
    fps: float | None


def read_weights(path, clamp: bool = False) -> WeightTrack:
    """Read a weight file (CSV, Live Link Face CSV or JSON; see the module docstring)."""
    path = regular_file(path, "weight file")
    ext = path.suffix.lower()
    if ext not in (".csv", ".json"):
        raise RetargetError(f"{path}: unknown weight format {ext or '(no extension)'}; expected .csv or .json")
    try:
        text = read_text(path)
    except OSError as e:
        raise RetargetError(f"{path}: cannot read as text ({e.strerror or e})") from None
    if not text.strip():
        raise RetargetError(f"{path}: is empty")
    names, values, fps = _parse_csv(text, path) if ext == ".csv" else _parse_json(text, path)
    weights = _to_ict(names, values, path)
    outside = (weights < -RANGE_TOLERANCE) | (weights > 1 + RANGE_TOLERANCE)
    if outside.any():
        if clamp:
            np.clip(weights, 0.0, 1.0, out=weights)
        else:
            warnings.warn(
                f"{path}: {int(outside.sum())} weights outside [0, 1] (min {weights.min():.3g}, "
                f"max {weights.max():.3g}); kept as they are (clamp to clip them)",
                WeightRangeWarning, stacklevel=2,
            )
    return WeightTrack(weights, fps)


def _number(cell, where: str, column: str) -> float:
    """One weight value; RetargetError naming ``where`` (file and row) and the column if it is
    missing or not a finite number."""
    if cell is None or (isinstance(cell, str) and not cell.strip()):
        raise RetargetError(f"{where}, column {column!r}: missing value")
    if isinstance(cell, bool):
        raise RetargetError(f"{where}, column {column!r}: {_short(cell)} is not a number")
    try:
        value = float(cell)
    except OverflowError:
        value = math.inf
    except (TypeError, ValueError):
        raise RetargetError(f"{where}, column {column!r}: {_short(cell)} is not a number") from None
    if not math.isfinite(value):
        raise RetargetError(f"{where}, column {column!r}: {_short(cell)} is not a finite number")
    if abs(value) > MAX_ABS_WEIGHT:
        raise RetargetError(f"{where}, column {column!r}: {_short(cell)} is far outside [0, 1] "
                            f"(|w| > {MAX_ABS_WEIGHT:g})")
    return value


def _short(value, limit: int = 40) -> str:
    """repr of a cell, cut to ``limit`` characters (a hostile cell can be megabytes long)."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _listing(names, limit: int = 10) -> str:
    """The first ``limit`` names, comma separated, and how many more."""
    names = [str(n)[:40] for n in names]
    more = f" and {len(names) - limit:,} more" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more


def _parse_csv(text: str, path: Path):
    """-> (weight column names, (T, n) float64 values, fps or None), one row at a time (a long take
    never sits in memory as text cells). Blank lines are skipped; a row of only commas is an error."""
    header, weight_cols, values, stamps, stamp_col = None, [], [], [], None
    try:
        for line, r in enumerate(csv.reader(text.splitlines()), start=1):
            if not (len(r) > 1 or (r and r[0].strip())):
                continue
            if not any(c.strip() for c in r):
                raise RetargetError(f"{path}: row {line} holds only commas (no values)")
            if header is None:
                header = [h.strip() for h in r]
                if all(re.fullmatch(r"[-+.\deE]+", h) for h in header if h):
                    raise RetargetError(f"{path}: the first row must name the blendshapes (ICT or ARKit names)")
                while header and not header[-1]:  # a trailing comma in the header
                    header.pop()
                weight_cols = [(j, h) for j, h in enumerate(header) if h.lower() not in NON_WEIGHT_COLUMNS]
                _check_names([h for _, h in weight_cols], path)
                lower = [h.lower() for h in header]
                stamp_col = next((lower.index(c) for c in ("timecode", "time") if c in lower), None)
                continue
            cells = [c.strip() for c in r]
            while len(cells) > len(header) and not cells[-1]:
                cells.pop()
            if len(cells) > len(header):
                raise RetargetError(f"{path}: row {line} has {len(cells):,} cells but the header has "
                                    f"{len(header):,}")
            cells += [""] * (len(header) - len(cells))
            values.append(_row_values(cells, weight_cols, f"{path}: row {line}"))
            if stamp_col is not None:
                stamps.append(cells[stamp_col])
    except csv.Error as e:
        raise RetargetError(f"{path}: not a CSV file ({e})") from None
    if not values:
        raise RetargetError(f"{path}: has a header but no frames")
    fps = None
    if stamp_col is not None:
        timecode = header[stamp_col].lower() == "timecode"
        fps = _fps_from_timecodes(stamps) if timecode else _fps_from_seconds(stamps)
    return [h for _, h in weight_cols], np.array(values, np.float64).reshape(len(values), -1), fps


def _row_values(cells, weight_cols, where: str) -> np.ndarray:
    """The weight cells of one CSV row as (n,) float64: all at once when they are all plain finite
    numbers in range, else cell by cell with :func:`_number` (which names the bad one)."""
    try:
        row = np.array([cells[j] for j, _ in weight_cols], np.float64)
        if np.isfinite(row).all() and (np.abs(row) <= MAX_ABS_WEIGHT).all():
            return row
    except ValueError:
        pass
    return np.array([_number(cells[j], where, h) for j, h in weight_cols], np.float64)


def _fps_from_timecodes(codes) -> float | None:
    """Frame rate of Live Link Face timecodes ``HH:MM:SS:FF(.sss)``: rows per second counted between
    the first and last change of the seconds field; None if fewer than two changes or unparseable."""
    try:
        secs = np.array([int(h) * 3600 + int(m) * 60 + int(s)
                         for h, m, s, *_ in (str(c).strip().split(":") for c in codes)])
    except ValueError:
        return None
    changes = np.nonzero(np.diff(secs))[0] + 1
    if len(changes) < 2 or secs[changes[-1]] == secs[changes[0]]:
        return None
    return float((changes[-1] - changes[0]) / (secs[changes[-1]] - secs[changes[0]]))


def _fps_from_seconds(times) -> float | None:
    """Frame rate from a column of times in seconds (1 / median step); None if not usable."""
    try:
        t = np.array([float(x) for x in times])
    except ValueError:
        return None
    steps = np.diff(t)
    if len(steps) == 0 or not np.all(steps > 0):
        return None
    return float(1.0 / np.median(steps))


def _parse_json(text: str, path: Path):
    """-> (names, (T, n) float64 values, fps or None) from the three JSON layouts."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise RetargetError(f"{path}: not valid JSON ({e.msg} at line {e.lineno})") from None
    except ValueError as e:  # an integer of more digits than Python converts
        raise RetargetError(f"{path}: not usable JSON ({str(e).split(';')[0][:100]})") from None
    except RecursionError:
        raise RetargetError(f"{path}: not usable JSON (nested too deeply)") from None
    shape_help = ('expected {name: value}, [{name: value}, ...] or '
                  '{"names": [...], "frames": [[...], ...]}')
    fps = None
    if isinstance(data, dict) and "frames" in data:
        fps = data.get("fps")
        if fps is not None:
            fps = check_fps(_number(fps, str(path), "fps"), f"{path}: \"fps\"")
        frames = data["frames"]
        if not isinstance(frames, list) or not frames:
            raise RetargetError(f"{path}: \"frames\" must be a non-empty list; {shape_help}")
        if all(isinstance(f, list) for f in frames):
            names = data.get("names")
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise RetargetError(f"{path}: frames given as lists need \"names\": [...]; {shape_help}")
            for i, f in enumerate(frames):
                if len(f) != len(names):
                    raise RetargetError(f"{path}: frame {i} has {len(f)} values but there are {len(names)} names")
            frames = [dict(zip(names, f)) for f in frames]
    elif isinstance(data, dict):
        frames = [{k: v for k, v in data.items() if k != "fps"}]
        fps = (check_fps(_number(data["fps"], str(path), "fps"), f"{path}: \"fps\"")
               if "fps" in data else None)
    elif isinstance(data, list) and data:
        frames = data
    else:
        raise RetargetError(f"{path}: wrong JSON layout; {shape_help}")
    if not all(isinstance(f, dict) for f in frames):
        raise RetargetError(f"{path}: wrong JSON layout (frames must all be objects or all lists); {shape_help}")
    names = list(dict.fromkeys(k for f in frames for k in f))
    _check_names(names, path)
    column = {n: j for j, n in enumerate(names)}
    values = np.zeros((len(frames), len(names)))  # names absent from a frame are 0
    for i, f in enumerate(frames):
        for k, v in f.items():
            values[i, column[k]] = _number(v, f"{path}: frame {i}", k)
    return names, values, fps


def _check_names(names, path: Path) -> None:
    """RetargetError listing unknown names, or names that set the same ICT shape twice."""
    unknown = [n for n in names if n.lower() not in NAME_TABLE]
    if unknown:
        raise RetargetError(f"{path}: unknown blendshape names: {_listing(unknown)} (expected ICT or ARKit names)")
    seen = {}
    for n in names:
        for i in NAME_TABLE[n.lower()]:
            if i in seen:
                raise RetargetError(f"{path}: {_short(seen[i])} and {_short(n)} both set {FACS_NAMES[i]}")
            seen[i] = n


def _to_ict(names, values: np.ndarray, path: Path) -> np.ndarray:
    """(T, n) values of the named columns -> (T,53) float32 in ICT order (absent names 0)."""
    if not len(values):
        raise RetargetError(f"{path}: has no frames")
    out = np.zeros((len(values), N_FACS), dtype=np.float32)
    for j, name in enumerate(names):
        out[:, list(NAME_TABLE[name.lower()])] = values[:, j:j + 1]
    return out


def write_weights_csv(path, weights, names: str = "ict", fps: float | None = None) -> None:
    """Write (T,53) ICT-order weights as CSV, atomically.

    names: "ict" (53 columns, ICT names) or "arkit" (52 ARKit names; browInnerUp and cheekPuff are
    the mean of the two ICT halves, tongueOut 0). A leading ``frame`` column, and ``time`` (seconds)
    when ``fps`` is given.
    """
    w = np.asarray(weights, dtype=np.float64).reshape(-1, N_FACS)
    if fps is not None:
        check_fps(fps)
    if names == "ict":
        columns, values = list(FACS_NAMES), w
    elif names == "arkit":
        columns = list(ARKIT_NAMES)
        values = np.zeros((len(w), len(columns)))
        for j, a in enumerate(columns):
            feeds = [FACS_INDEX[m] for m in arkit_to_ict(a)]
            if feeds:
                values[:, j] = w[:, feeds].mean(axis=1)
    else:
        raise ValueError(f"names must be 'ict' or 'arkit', got {names!r}")
    stamps = ["frame"] + (["time"] if fps else [])
    with atomic_output(path) as tmp, open(tmp, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(stamps + columns)
        for t, row in enumerate(values):
            lead = [str(t)] + ([f"{t / fps:.6f}"] if fps else [])
            out.writerow(lead + [f"{x:.6g}" for x in row])
