"""Options and file handling shared by the mesh commands (transfer, animate, invert, export-rig)."""
from __future__ import annotations

import os
import re
import shutil
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from ..errors import RetargetError
from ..io import (READ_FORMATS, WRITE_FORMATS, axis_rotation, check_fps, check_output,
                  remove_stale_temporaries, save_mesh, temporary_prefix)
from ..smoothing import FILTERS
from ..usd import USD_FORMATS


def add_model_args(p, target: bool = True) -> None:
    """The model's options; ``target``: the command writes results on a target mesh."""
    p.add_argument("--checkpoint", help="model checkpoint (default: the bundled one)")
    p.add_argument("--device", help="cpu or cuda (default: cuda when present)")
    p.add_argument("--up", help="up axis of the input files, e.g. +z (default +y)")
    p.add_argument("--forward", help="forward axis of the input files, e.g. -y (default +z)")
    p.add_argument("--force", action="store_true", help="try meshes above the size limit anyway")
    p.add_argument("--no-code-map", action="store_true",
                   help="leave the checkpoint's code map out: FACS weights drawn as the paper's "
                        "[w, 0], and invert's fit tuned without a map (docs/RESULTS.md, \"The code map\")")
    p.add_argument("--no-upright", action="store_true",
                   help="take every mesh as it faces: do not turn a head pitched 9 degrees or more, "
                        "or turned sideways 4 or more, upright first (docs/RESULTS.md, \"Heads that "
                        "do not face +z\")")
    p.add_argument("--all-parts", action="store_true",
                   help="the whole mesh is the face: do not leave separate parts (eyes, teeth, a "
                        "tongue, lashes: every part but the one with the most vertices) out of the "
                        "network (docs/RESULTS.md, \"Heads with eyes and teeth\")")
    if not target:
        return
    p.add_argument("--still-parts", action="store_true",
                   help="leave every separate part of a target at rest: do not move its lower teeth "
                        "and tongue (the parts below the mouth corners) with its jaw, nor turn its "
                        "eyeballs with the gaze")


def add_neutral_args(p) -> None:
    p.add_argument("--source-neutral", metavar="FILE",
                   help="the performer's neutral mesh (same topology as the frames): the canonical "
                        "frame and operators, and for a neutral-aware model the encoder's input")
    p.add_argument("--estimate-neutral", action="store_true",
                   help="without a neutral mesh: estimate the performer's neutral from the frames "
                        "themselves (a take of varied expressions), then use it as --source-neutral")
    p.add_argument("--refine", action="store_true",
                   help="analysis-by-synthesis: fit the weights to each frame on the decoder's rig "
                        "baked on the source neutral (bounded least squares; needs --source-neutral "
                        "or --estimate-neutral)")
    p.add_argument("--refine-steps", type=int, default=0, metavar="N",
                   help="with --refine and an MLP decoder, then fit the free dims of z_GE by N gradient "
                        "steps (default 0); a basis decoder always solves them exactly")
    p.add_argument("--no-stabilise", action="store_true",
                   help="take the frames as they are: do not remove their head motion (the head "
                        "turning or moving as a whole) against the source neutral before reading "
                        "them (docs/RESULTS.md, \"Frames that move as a whole\")")


def add_residuals_arg(p, what: str) -> None:
    """--residuals CSV: how well ``what`` (the weights, the codes) explain each source frame."""
    p.add_argument("--residuals", metavar="CSV",
                   help=f"also write how well {what} explain each frame on the source's own "
                        "neutral (RMS residual and motion in the frames' units, and their ratio, the "
                        "share left unexplained); needs --source-neutral or --estimate-neutral")


def check_side_csv(path, flag: str, args, inputs: list, taken=()) -> None:
    """RetargetError, before any work, for a side output CSV (``flag``: --residuals, --head-poses)
    onto an input, not a .csv, or onto -o or another side output (``taken``: (flag, path))."""
    check_output(path, inputs, formats=(".csv",))
    for other, other_path in (("-o", args.out), *taken):
        if other_path and Path(path).resolve() == Path(other_path).resolve():
            raise RetargetError(f"{path}: {flag} and {other} name the same file; give each its own")


def check_residuals_arg(args, inputs: list) -> None:
    """RetargetError, before any work, for --residuals without a neutral, or onto a file it may not
    write (``check_side_csv``)."""
    if not args.residuals:
        return
    if not (args.source_neutral or args.estimate_neutral):
        raise RetargetError("--residuals needs --source-neutral (the source's neutral mesh) or "
                            "--estimate-neutral: the residual is measured on the source's neutral")
    check_side_csv(args.residuals, "--residuals", args, inputs)


def write_head_poses(path, motions, fps: float) -> None:
    """Write frame, time, the head's rotation as a unit quaternion qw, qx, qy, qz, its translation
    tx, ty, tz (frame ≈ neutral · Rᵀ + t, the frames' units) and angle_degrees, one row per
    ``retarget.stabilise.RigidMotion``, as CSV, atomically."""
    import csv

    from scipy.spatial.transform import Rotation

    from ..io import atomic_output

    with atomic_output(path) as tmp, open(tmp, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["frame", "time", "qw", "qx", "qy", "qz", "tx", "ty", "tz", "angle_degrees"])
        for t, m in enumerate(motions):
            x, y, z, w = Rotation.from_matrix(m.rotation).as_quat()
            out.writerow([str(t), f"{t / fps:.6f}"] + [f"{v:.9g}" for v in (w, x, y, z, *m.translation)]
                         + [f"{m.angle_degrees():.6g}"])
    print(f"wrote {len(motions)} head pose(s) to {path}")


def write_residuals(path, residual: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """Write frame, residual_rms, motion_rms, unexplained (residual ÷ motion; 0 for a frame that
    does not move and is matched) as CSV, atomically, and print the median share and the worst
    frames -> the unexplained shares (T,)."""
    import csv

    from ..io import atomic_output

    still = np.where(residual > 0, np.inf, 0.0)
    share = np.where(motion > 0, residual / np.maximum(motion, 1e-12), still)
    with atomic_output(path) as tmp, open(tmp, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["frame", "residual_rms", "motion_rms", "unexplained"])
        for t, row in enumerate(zip(residual, motion, share)):
            out.writerow([str(t)] + [f"{x:.6g}" for x in row])
    worst = np.argsort(-share)[:3]
    print(f"wrote the fit's residuals to {path}: median share unexplained {np.median(share):.3f}; "
          "worst frames " + ", ".join(f"{i} ({share[i]:.3f})" for i in worst))
    return share


def check_neutral_args(args) -> None:
    """RetargetError for --refine without a neutral (--source-neutral or --estimate-neutral), for
    both of those, or a negative --refine-steps."""
    if args.source_neutral and args.estimate_neutral:
        raise RetargetError("give either --source-neutral or --estimate-neutral, not both")
    if args.refine and not (args.source_neutral or args.estimate_neutral):
        raise RetargetError("--refine needs --source-neutral (the source's neutral mesh) or "
                            "--estimate-neutral (one estimated from the frames)")
    if args.refine_steps < 0:
        raise RetargetError(f"--refine-steps must be >= 0, got {args.refine_steps}")


def neutral_hint(args) -> str | None:
    """The advice printed when transfer / invert run without the most accurate inputs: without
    ``--source-neutral`` the expression is read from the frames alone; with it but without
    ``--refine`` the frames are not fitted on the source's own rig (docs/RESULTS.md: several
    times the error of both together)."""
    if not (args.source_neutral or args.estimate_neutral):
        return ("note: no --source-neutral: the expression is read from the frames alone, several "
                "times less accurately than with the performer's neutral mesh and --refine, or, "
                "for a take without one, --estimate-neutral --refine (docs/RESULTS.md)")
    if not args.refine:
        return ("note: without --refine the frames are not fitted on the network's rig of the "
                "source neutral; --refine is several times more accurate (docs/RESULTS.md)")
    return None


def print_neutral_hint(args) -> None:
    """``neutral_hint`` on stderr, if any."""
    hint = neutral_hint(args)
    if hint:
        print(hint, file=sys.stderr)


def print_notes(r, target=None, target_name: str = "", frames=None, neutral=None,
                source_name: str = "") -> None:
    """Notes on stderr on what ``r`` did to a head before the network saw it: turned it upright
    (``Retargeter.canonicaliser``), took its face alone from a mesh with separate parts
    (``Retargeter.face_only``), or removed the source frames' head motion
    (``Retargeter.stabilise_frames``). ``target`` a prepared Target, and the source (``frames`` with
    their ``neutral`` or None, after they were encoded: their topology is cached)."""
    from ..canonical import rotation_angle

    heads = []
    if target is not None:
        jaw, eyes = r.jaw_parts(target), r.eyes(target)
        moving = ([f"{len(jaw.carried):,} vertices in {jaw.parts} part(s) below the mouth (lower "
                   "teeth, tongue), which move with the jaw"] if jaw is not None else [])
        if eyes is not None:
            moving.append(f"{sum(map(len, eyes.vertices)):,} vertices in {eyes.parts} part(s) of "
                          "two eyeballs, which turn with the gaze")
        parts = "keep their place in the results"
        if moving:
            parts += f", but for {' and '.join(moving)} (--still-parts: keep them at rest too)"
        heads.append((target_name, target.proxy.canon, target.face, target.n_vertices, parts))
    if frames is not None:
        ref = neutral if neutral is not None else frames[0]
        src = r.source_topology(ref, neutral=neutral is not None)
        eyes = r.source_eyes(frames, neutral)
        heads.append((source_name, src.canon, src.face, ref.n_vertices, "are left out" + (
            "" if eyes is None else f", but for the turn of its two eyeballs ({eyes.parts} part(s)), "
                                    "which gives the gaze")))
    for name, canon, face, n, parts in heads:
        if face is not None:
            print(f"{name}: the network saw the face alone ({len(face):,} of {n:,} vertices, the "
                  f"part with the most); the other {n - len(face):,} vertices (separate parts: "
                  f"eyes, teeth, ...) {parts} (--all-parts: the whole mesh is the face)",
                  file=sys.stderr)
        if canon.rotation is not None:
            print(f"{name}: the head is turned {rotation_angle(canon.rotation):.1f} degrees from facing "
                  "+z; the network saw it upright, the results are in its own frame (--no-upright: "
                  "take it as it faces)", file=sys.stderr)
    if frames is not None and r.stabilise and (neutral is not None or len(frames) > 1):
        moving = [m for m in r.stabilise_frames(frames, neutral or frames[0])[1] if not m.still]
        if moving:
            against = "neutral" if neutral is not None else "first frame"
            print(f"source: {len(moving)} of {len(frames)} frame(s) move as a whole against the "
                  f"{against} (turned up to {max(m.angle_degrees() for m in moving):.1f} degrees, "
                  f"vertices carried up to {100 * max(m.moved for m in moving):.1f} % of the head's "
                  "size); that head motion was removed before reading the expressions "
                  "(--no-stabilise: keep it)", file=sys.stderr)


def estimated_neutral(args, r, frames, neutral):
    """The source neutral to use: with ``--estimate-neutral`` the one ``Retargeter.estimate_neutral``
    makes from ``frames`` (a note on stderr when the take is a single frame: there is nothing to
    estimate from), else ``neutral`` (that of ``load_source_neutral``)."""
    if not args.estimate_neutral:
        return neutral
    if len(frames) < 2:
        print("note: --estimate-neutral on a single frame only gives its own reading back; a take "
              "of varied expressions is needed", file=sys.stderr)
    neutral = r.estimate_neutral(frames)
    print(f"estimated the source neutral from {min(len(frames), r.ESTIMATE_FRAMES)} of "
          f"{len(frames)} frame(s)")
    return neutral


def load_source_neutral(args, frames):
    """The ``--source-neutral`` mesh (None without it); RetargetError naming it when its vertex
    count is not the frames' (checked before the model is loaded)."""
    from ..io import load_mesh

    if not args.source_neutral:
        return None
    neutral = load_mesh(args.source_neutral, up=args.up, forward=args.forward, force=args.force)
    if frames and neutral.n_vertices != frames[0].n_vertices:
        raise RetargetError(f"{args.source_neutral}: the source neutral has {neutral.n_vertices} "
                            f"vertices, but the frames have {frames[0].n_vertices}; it must share "
                            f"their topology")
    return neutral


def add_smooth_arg(p) -> None:
    p.add_argument("--smooth", choices=FILTERS,
                   help="temporal filter of the codes of a sequence (streaming / offline)")
    p.add_argument("--fps", type=check_fps, default=30.0, help="frame rate of the sequence (default 30)")


def retargeter(args):
    """The Retargeter of ``--checkpoint`` / ``--device``."""
    from ..api import Retargeter
    extra = {"code_map": None} if getattr(args, "no_code_map", False) else {}
    return Retargeter.load(args.checkpoint, device=args.device,
                           refine_steps=getattr(args, "refine_steps", 0),
                           upright=not getattr(args, "no_upright", False),
                           face_only=not getattr(args, "all_parts", False),
                           carry_jaw=not getattr(args, "still_parts", False),
                           turn_eyes=not getattr(args, "still_parts", False),
                           stabilise=not getattr(args, "no_stabilise", False), **extra)


def rotation(args) -> np.ndarray:
    """(3,3) file-frame -> project-frame rotation of ``--up`` / ``--forward``."""
    return axis_rotation(args.up, args.forward)


#: Above this, a sequence GLB (held in memory whole while it is written) is refused unless --force.
MAX_GLB_BYTES = 4 * 2**30
_FRAME_FILE = re.compile(r"frame_\d+\.(obj|ply)", re.IGNORECASE)


def output_bytes(ext: str, n_frames: int, n_vertices: int, n_faces: int) -> int:
    """Rough size (bytes) of ``n_frames`` frames of a (V, F) mesh written as ``ext``: a sequence
    GLB (12·T·V of morph targets, 4·T² of weights, built in memory whole), or T OBJ (about 40 bytes
    a vertex, 20 a face) or PLY (12 and 13) files."""
    if ext == ".glb":
        return 12 * n_frames * n_vertices + 4 * n_frames ** 2 + 12 * n_vertices + 12 * n_faces
    per_vertex, per_face = (12, 13) if ext == ".ply" else (40, 20)
    return n_frames * (per_vertex * n_vertices + per_face * n_faces)


def check_output_size(paths: list[Path], n: int, n_vertices: int, n_faces: int,
                      force: bool = False) -> None:
    """RetargetError, before any work, when ``n`` frames would not fit into ``paths``: a sequence
    GLB above MAX_GLB_BYTES, or files larger than the free space of their disk (``force`` skips
    this)."""
    if force:
        return
    ext = paths[0].suffix.lower()
    size = output_bytes(ext, n, n_vertices, n_faces)
    what = f"{n:,} frame(s) of {n_vertices:,} vertices"
    if ext == ".glb" and n > 1 and size > MAX_GLB_BYTES:
        raise RetargetError(f"{paths[0]}: {what} as one GLB would need about {size / 1e9:.1f} GB "
                            f"(the limit is {MAX_GLB_BYTES / 2**30:.0f} GiB); write a folder of frames, "
                            "or export-rig --weights for a 53-shape rig (--force to try anyway)")
    folder = next((p for p in paths[0].parents if p.is_dir()), Path("."))
    free = shutil.disk_usage(folder).free
    if size > free:
        raise RetargetError(f"{paths[0]}: {what} would take about {size / 1e9:.1f} GB but {folder} "
                            f"has {free / 1e9:.1f} GB free (--force to try anyway)")


def output_paths(out: str, n_frames: int, inputs: list, fmt: str = "obj", n_vertices: int = 0,
                 n_faces: int = 0, force: bool = False) -> list[Path]:
    """The files that OUT will receive for ``n_frames`` frames, checked before any work is done.

    OUT = a .obj/.ply file (one frame), a .glb (the frames as an animation) or a folder
    (frame_0000.<fmt>, ...). RetargetError for ``-``, an output that is an input, several frames into
    one mesh file, an unwritable extension, a file where a folder is meant, a folder that holds
    frames already (a take is never mixed with an older one's), or (when the target's ``n_vertices``
    and ``n_faces`` are given) an output too large (:func:`check_output_size`; ``force`` skips it).
    """
    out_path = Path(out)
    ext = out_path.suffix.lower()
    check_output(out_path, inputs)  # "-", symlink loops, an input given as the output
    if ext == ".glb" or ext in WRITE_FORMATS:
        if ext != ".glb" and n_frames != 1:
            raise RetargetError(f"{out}: {n_frames} frames cannot go into one {ext} file; give a "
                                f"folder or a .glb")
        paths = [out_path]
    elif ext in USD_FORMATS:
        raise RetargetError(f"{out}: cannot write {ext} frames; use .obj, .ply, .glb or a folder (USD "
                            f"rigs: retarget export-rig / animate)")
    elif ext in READ_FORMATS or ext in (".csv", ".json"):
        raise RetargetError(f"{out}: cannot write {ext}; use .obj, .ply, .glb or a folder")
    elif out_path.exists() and not out_path.is_dir():
        raise RetargetError(f"{out}: exists and is not a folder")
    else:
        older = sorted(p for p in out_path.iterdir() if _FRAME_FILE.fullmatch(p.name)) if out_path.is_dir() else []
        if older:
            raise RetargetError(f"{older[0]}: the folder {out} holds frames already ({len(older)} "
                                "frame files); a take is written into a new or empty folder, never "
                                "mixed with an older one")
        paths = [out_path / f"frame_{t:04d}.{fmt}" for t in range(n_frames)]
    for p in paths:
        check_output(p, inputs)
    if n_vertices:
        check_output_size(paths, n_frames, n_vertices, n_faces, force)
    return paths


def write_frames(out: str, frames, faces: np.ndarray, inputs: list, args, fps: float = 30.0,
                 n_frames: int | None = None) -> list[Path]:
    """Write project-frame vertices in the input files' axes to OUT (see :func:`output_paths`).

    ``frames``: a (T,V,3) array, or an iterable of (V,3) frames with ``n_frames`` = T (e.g.
    ``Retargeter.iter_decode``), which a folder output writes one frame at a time, so a long sequence
    on a huge target never sits in memory whole. Never overwrites an input. Files are written
    atomically; the frames of a folder are first written to a hidden staging folder beside it and
    moved in only when all of them are written, so an error leaves no partial sequence behind."""
    if isinstance(frames, np.ndarray):
        n_frames = len(frames)
    elif n_frames is None:
        raise ValueError("write_frames: n_frames is needed when frames is not an array")
    rot = rotation(args)                          # back to the files' axes (R orthonormal)
    paths = output_paths(out, n_frames, inputs, getattr(args, "format", "obj"))
    if paths[0].suffix.lower() == ".glb":
        from ..glb import write_sequence_glb
        write_sequence_glb(paths[0], np.stack([np.asarray(f, np.float32) for f in frames]) @ rot,
                           faces, fps=fps)
        return paths
    if len(paths) == 1 and paths[0].parent != Path(out):
        save_mesh(paths[0], np.asarray(next(iter(frames))) @ rot, faces)
        return paths
    folder = Path(out)
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(folder.parent)  # a killed run's staging folder
        staging = Path(tempfile.mkdtemp(prefix=temporary_prefix(folder), suffix=".tmp", dir=folder.parent))
    except OSError as e:
        raise RetargetError(f"{out}: cannot write the output folder ({e.strerror})") from None
    try:
        for p, f in zip(paths, frames):
            save_mesh(staging / p.name, np.asarray(f) @ rot, faces)
        folder.mkdir(exist_ok=True)
        for p in paths:
            os.replace(staging / p.name, p)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
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
