"""The user's own blendshape rig, for fine-tuning (``retarget train --rig PATH --init CKPT``).

Three layouts are read, all mapped to the 53 ICT slots (ICT-FaceKit order, ``FACS_NAMES``):

- an ``.npz`` with ``neutral (V,3)``, ``faces (F,3)``, ``names (K,)``, ``deltas (K,V,3)`` and
  optionally ``identity_deltas (J,V,3)`` and ``segments`` ((V,) integer labels, or (V,L)
  memberships whose arg-max is the label); other keys are ignored;
- a folder with ``neutral.obj`` and one mesh per shape (``<name>.obj``, the full shaped mesh, same
  vertex order), optionally ``identity<NNN>.obj`` identity shapes;
- ICT-FaceKit's ``FaceXModel`` folder as published: the same with the neutral named
  ``generic_neutral_mesh.obj`` (quads are triangulated, vertex order kept).

Shape names are ICT names or ARKit names, matched case-insensitively. Other shapes (a rig's
correctives, visemes, ICT-FaceKit's ``PupilDilate_L/R`` and ``cheekRaiser_L/R``) are left out and
reported in one :class:`UnknownShapeWarning` (``strict=True``: refused). ARKit ``tongueOut`` has no ICT
slot and is dropped. ARKit ``browInnerUp`` and ``cheekPuff`` each feed two ICT slots; they are
split *spatially*: the ``_L`` half keeps the motion on the character's left (+x) of the neutral's
mid-plane, the ``_R`` half the rest, with a smooth cross-over ``MIDLINE_BAND`` of the head width
wide, so ``_L + _R`` is the ARKit shape and each half acts on its own side, as the procedural
rigs' ICT halves do. Shapes the rig lacks are marked absent (``present``) and not supervised.

Identity shapes are kept (``identity_deltas``) but never supervised as expressions; the rig has no
coefficients in the procedural identity space, so fine-tuning skips L_ID on it.
"""
from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from data_synth.facs import ARKIT_NAMES, FACS_INDEX, N_FACS, arkit_to_ict, left_weight, split_to_ict

from .errors import RetargetError
from .io import load_mesh, regular_file

#: Width of the left/right cross-over when an ARKit shape is split into its two ICT halves, as a
#: fraction of the neutral's x extent (0.05 of a 16 cm head: 8 mm).
MIDLINE_BAND = 0.05
NEUTRAL_FILES = ("neutral", "generic_neutral_mesh")
SHAPE_SUFFIXES = (".obj", ".ply", ".off")
_IDENTITY_FILE = re.compile(r"identity\d+$", re.IGNORECASE)
LISTED_NAMES = 12  # names spelled out in one message; the rest are counted


class UnknownShapeWarning(UserWarning):
    """Shapes of a rig with neither an ICT nor an ARKit name, left out (:func:`known_names`)."""


@dataclass
class UserRig:
    """A blendshape rig in ICT order, in the user's frame and units (+y up, +z forward).

    neutral: (V,3) float32. faces: (F,3) int64. deltas: (53,V,3) float32, zeros where absent.
    present: (53,) bool, the ICT shapes the rig has. segments: (V,) int64 labels or None.
    identity_deltas: (J,V,3) float32 identity shapes or None. name: where it came from.
    identity: always None (no coefficients in the procedural identity space: L_ID is skipped).
    """

    neutral: np.ndarray
    faces: np.ndarray
    deltas: np.ndarray
    present: np.ndarray
    segments: np.ndarray | None = None
    identity_deltas: np.ndarray | None = None
    name: str = ""
    identity: None = None

    @property
    def n_vertices(self) -> int:
        return len(self.neutral)

    def evaluate(self, weights) -> np.ndarray:
        """neutral + weights · deltas: weights (53,) -> (V,3), or (T,53) -> (T,V,3); float32."""
        w = np.asarray(weights, np.float32)
        if w.shape[-1] != N_FACS or w.ndim not in (1, 2):
            raise RetargetError(f"{self.name}: weights must have shape (53,) or (T, 53), got {w.shape}")
        return self.neutral + np.tensordot(w, self.deltas, axes=(-1, 0))


def load_user_rig(path, keep_vertices=None, strict: bool = False) -> UserRig:
    """Read a rig in any of the three layouts (module docstring).

    keep_vertices: "A:B" keeps vertices A..B-1 (Python slice; either end may be left out), e.g. the
    skin of a model that also has eyeballs and teeth; faces are restricted to the range and
    re-indexed. strict: refuse shapes with neither an ICT nor an ARKit name instead of leaving them
    out with one :class:`UnknownShapeWarning`. RetargetError names the file and the problem
    (unknown shape names under ``strict``, listed; no known shape at all; vertex counts that
    differ; a bad range).
    """
    path = Path(path)
    if path.is_dir():
        neutral, faces, named, identity, segments = _read_folder(path, strict)
    else:
        regular_file(path, "rig file", missing="no such rig (expected an .npz or a folder of OBJs)")
        neutral, faces, named, identity, segments = _read_npz(path, strict)
    deltas, present = ict_deltas(named, neutral, path)
    rig = UserRig(neutral.astype(np.float32), faces.astype(np.int64), deltas, present, segments,
                  identity, str(path))
    return rig if keep_vertices is None else keep_range(rig, keep_vertices)


def _read_npz(path: Path, strict: bool):
    """(neutral (V,3), faces (F,3), {name: delta (V,3)}, identity_deltas or None, segments or None)."""
    try:
        with np.load(path, allow_pickle=False) as d:
            arrays = {k: d[k] for k in ("neutral", "faces", "names", "deltas", "identity_deltas",
                                        "segments") if k in d.files}
    except Exception as e:  # numpy raises many types for a file that is not an npz
        raise RetargetError(f"{path}: not a readable rig npz ({type(e).__name__}: {e})") from None
    missing = [k for k in ("neutral", "faces", "names", "deltas") if k not in arrays]
    if missing:
        raise RetargetError(f"{path}: rig npz lacks {', '.join(missing)} "
                            f"(needs neutral, faces, names, deltas)")
    neutral, names, deltas = arrays["neutral"], [str(n) for n in arrays["names"]], arrays["deltas"]
    if neutral.ndim != 2 or neutral.shape[1] != 3:
        raise RetargetError(f"{path}: neutral must be (V, 3), got {neutral.shape}")
    if deltas.shape != (len(names), *neutral.shape):
        raise RetargetError(f"{path}: deltas {deltas.shape} do not match {len(names)} names and "
                            f"neutral {neutral.shape}")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise RetargetError(f"{path}: shape names given twice: {', '.join(repeated)}")
    if not (np.isfinite(neutral).all() and np.isfinite(deltas).all()):
        raise RetargetError(f"{path}: neutral or deltas hold NaN or infinite values")
    faces = arrays["faces"]
    if faces.ndim != 2 or faces.shape[1] != 3 or not len(faces) or faces.min() < 0 \
            or faces.max() >= len(neutral):
        raise RetargetError(f"{path}: faces must be (F, 3) indices into the {len(neutral)} "
                            f"vertices, got {faces.shape}")
    identity = arrays.get("identity_deltas")
    if identity is not None and identity.shape[1:] != neutral.shape:
        raise RetargetError(f"{path}: identity_deltas {identity.shape} do not match neutral "
                            f"{neutral.shape}")
    segments = arrays.get("segments")
    if segments is not None:
        if len(segments) != len(neutral) or segments.ndim not in (1, 2):
            raise RetargetError(f"{path}: segments {segments.shape} must be (V,) or (V, L) with "
                                f"V = {len(neutral)}")
        segments = (segments.argmax(1) if segments.ndim == 2 else segments).astype(np.int64)
    kept = set(known_names(names, path, strict))
    return (neutral, faces, {n: d for n, d in zip(names, deltas) if n in kept},
            None if identity is None else identity.astype(np.float32), segments)


def _read_folder(path: Path, strict: bool):
    """The folder layouts: (neutral, faces, {name: delta}, identity_deltas or None, None)."""
    files = sorted(f for f in path.iterdir() if f.suffix.lower() in SHAPE_SUFFIXES)
    neutral_files = [f for f in files if f.stem in NEUTRAL_FILES]
    if len(neutral_files) != 1:
        raise RetargetError(f"{path}: a rig folder needs exactly one neutral mesh "
                            f"({' or '.join(n + '.obj' for n in NEUTRAL_FILES)}), found "
                            f"{len(neutral_files)}")
    neutral = load_mesh(neutral_files[0])

    def delta(f: Path) -> np.ndarray:
        v = load_mesh(f).vertices
        if len(v) != neutral.n_vertices:
            raise RetargetError(f"{f}: {len(v)} vertices, but the neutral {neutral_files[0].name} "
                                f"has {neutral.n_vertices}")
        return (v - neutral.vertices).astype(np.float32)

    shapes = [f for f in files if f not in neutral_files]
    identity_files = [f for f in shapes if _IDENTITY_FILE.match(f.stem)]
    named = {f.stem: f for f in shapes if f not in identity_files}
    named = {n: named[n] for n in known_names(named, path, strict)}  # before reading the shapes
    ict_slots(named, path)  # two shapes for one slot: refused before reading every shape
    identity = np.stack([delta(f) for f in identity_files]) if identity_files else None
    return neutral.vertices, neutral.faces, {n: delta(f) for n, f in named.items()}, identity, None


def _slot_lookup() -> dict[str, tuple[int, ...]]:
    """{lower-case ICT or ARKit name: ICT slot indices} (``tongueout`` -> ())."""
    lookup = {n.lower(): (FACS_INDEX[n],) for n in FACS_INDEX}
    for n in ARKIT_NAMES:
        lookup.setdefault(n.lower(), tuple(FACS_INDEX[i] for i in arkit_to_ict(n)))
    return lookup


def _listed(names) -> str:
    """Names for one message line: the first ``LISTED_NAMES``, then how many more."""
    names = list(names)
    more = len(names) - LISTED_NAMES
    return ", ".join(names[:LISTED_NAMES]) + (f" and {more} more" if more > 0 else "")


def known_names(names, where, strict: bool = False) -> list[str]:
    """The names (in their order) that are ICT or ARKit names (case-insensitive).

    The others are left out with one :class:`UnknownShapeWarning` naming ``where`` and them, or,
    with ``strict``, refused (RetargetError). RetargetError too if no name is known."""
    lookup = _slot_lookup()
    names = list(names)
    known = [n for n in names if n.lower() in lookup]
    unknown = sorted(n for n in names if n.lower() not in lookup)
    if unknown and (strict or not known):
        raise RetargetError(f"{where}: unknown blendshape names {_listed(unknown)} (expected ICT "
                            f"names such as browDown_L or ARKit names such as browDownLeft)")
    if unknown:
        warnings.warn(f"{where}: left out {len(unknown)} shapes that have no ICT or ARKit name: "
                      f"{_listed(unknown)}", UnknownShapeWarning, stacklevel=2)
    return known


def ict_slots(names, where) -> dict[str, tuple[int, ...]]:
    """{name: ICT slot indices} for ICT or ARKit names (case-insensitive; ``tongueOut`` -> ()).

    RetargetError (naming ``where``) listing every unknown name (:func:`known_names` leaves them
    out first), or naming two shapes that fill the same slot."""
    lookup = _slot_lookup()
    known_names(names, where, strict=True)
    slots = {n: lookup[n.lower()] for n in names}
    owner: dict[int, str] = {}
    for n, idx in slots.items():
        for i in idx:
            if i in owner:
                raise RetargetError(f"{where}: shapes {owner[i]!r} and {n!r} both give the ICT "
                                    f"shape {list(FACS_INDEX)[i]}")
            owner[i] = n
    return slots


def ict_deltas(named: dict, neutral: np.ndarray, where) -> tuple[np.ndarray, np.ndarray]:
    """Named deltas {name: (V,3)} -> (deltas (53,V,3) float32 in ICT order, present (53,) bool).

    A name feeding two ICT slots (ARKit browInnerUp, cheekPuff) is split between them by
    :func:`side_weights` of the neutral (V,3)."""
    slots = ict_slots(named, where)
    return split_to_ict(((slots[n], named[n]) for n in slots), side_weights(neutral))


def side_weights(neutral: np.ndarray) -> np.ndarray:
    """(V,) float32 in [0,1]: 1 on the character's left (+x) of the mid-plane x = bounding-box
    centre, 0 on the right, a smoothstep across a band ``MIDLINE_BAND`` of the x extent wide."""
    x = np.asarray(neutral, np.float64)[:, 0]
    lo, hi = x.min(), x.max()
    return left_weight(x, 0.5 * (lo + hi), 0.5 * MIDLINE_BAND * max(hi - lo, 1e-12))


def keep_range(rig: UserRig, spec: str) -> UserRig:
    """The rig restricted to the vertex range ``spec`` = "A:B" (faces with all three corners in the
    range, re-indexed). RetargetError for a malformed or empty range."""
    m = re.fullmatch(r"\s*(\d*)\s*:\s*(\d*)\s*", str(spec))
    if not m:
        raise RetargetError(f"{rig.name}: --keep-vertices {spec!r} is not a range A:B")
    a = int(m.group(1)) if m.group(1) else 0
    b = int(m.group(2)) if m.group(2) else rig.n_vertices
    if not 0 <= a < b <= rig.n_vertices:
        raise RetargetError(f"{rig.name}: vertex range {a}:{b} is empty or outside 0:{rig.n_vertices}")
    faces = rig.faces[np.all((rig.faces >= a) & (rig.faces < b), axis=1)] - a
    if not len(faces):
        raise RetargetError(f"{rig.name}: no face lies inside the vertex range {a}:{b}")
    cut = slice(a, b)
    return UserRig(rig.neutral[cut], faces, rig.deltas[:, cut], rig.present,
                   None if rig.segments is None else rig.segments[cut],
                   None if rig.identity_deltas is None else rig.identity_deltas[:, cut], rig.name)
