"""Options and file handling shared by the mesh commands (transfer, animate, invert, export-rig)."""
from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

from ..errors import RetargetError
from ..io import READ_FORMATS, WRITE_FORMATS, axis_rotation, check_output, save_mesh


def add_model_args(p) -> None:
    p.add_argument("--checkpoint", help="model checkpoint (default: the bundled one)")
    p.add_argument("--device", help="cpu or cuda (default: cuda when present)")
    p.add_argument("--up", help="up axis of the input files, e.g. +z (default +y)")
    p.add_argument("--forward", help="forward axis of the input files, e.g. -y (default +z)")
    p.add_argument("--force", action="store_true", help="try meshes above the size limit anyway")


def add_smooth_arg(p) -> None:
    p.add_argument("--smooth", choices=("one_euro", "savgol"),
                   help="temporal filter of the codes of a sequence (streaming / offline)")
    p.add_argument("--fps", type=float, default=30.0, help="frame rate of the sequence (default 30)")


def retargeter(args):
    """The Retargeter of ``--checkpoint`` / ``--device``."""
    from ..api import Retargeter
    return Retargeter.load(args.checkpoint, device=args.device)


def rotation(args) -> np.ndarray:
    """(3,3) file-frame -> project-frame rotation of ``--up`` / ``--forward``."""
    return axis_rotation(args.up, args.forward)


def write_frames(out: str, frames: np.ndarray, faces: np.ndarray, inputs: list, args,
                 fps: float = 30.0) -> list[Path]:
    """Write (T,V,3) project-frame vertices in the input files' axes.

    OUT = a .obj/.ply file (one frame), a .glb (the frames as an animation) or a folder
    (frame_0000.obj, ...; ``--format``). Never overwrites an input; each file is written atomically.
    """
    frames = np.asarray(frames) @ rotation(args)  # back to the files' axes (R orthonormal)
    out_path = Path(out)
    ext = out_path.suffix.lower()
    if ext == ".glb":
        from ..glb import write_sequence_glb
        check_output(out_path, inputs)
        write_sequence_glb(out_path, frames, faces, fps=fps)
        return [out_path]
    if ext in WRITE_FORMATS:
        if len(frames) != 1:
            raise RetargetError(f"{out}: {len(frames)} frames cannot go into one {ext} file; give a "
                                f"folder or a .glb")
        check_output(out_path, inputs)
        save_mesh(out_path, frames[0], faces)
        return [out_path]
    if ext in READ_FORMATS or ext in (".csv", ".json"):
        raise RetargetError(f"{out}: cannot write {ext}; use .obj, .ply, .glb or a folder")
    if out_path.exists() and not out_path.is_dir():
        raise RetargetError(f"{out}: exists and is not a folder")
    paths = [out_path / f"frame_{t:04d}.{getattr(args, 'format', 'obj')}" for t in range(len(frames))]
    for p in paths:
        check_output(p, inputs)
    for p, f in zip(paths, frames):
        save_mesh(p, f, faces)
    return paths


def read_weights_file(path, clamp: bool):
    """Weights (T,53) and fps from a weight file; out-of-range values are reported on stderr."""
    from ..weights_io import WeightRangeWarning, read_weights
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", WeightRangeWarning)
        track = read_weights(path, clamp=clamp)
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    return track
