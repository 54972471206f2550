"""Frames that move as a whole: the eval's realistic heads and the ARKit rig with a head motion
added to every source frame (docs/RESULTS.md, "Frames that move as a whole").

Each source frame is turned about a random axis through the head's centre by an angle drawn
from N(0, DEGREES²) and shifted by N(0, (SHIFT · diagonal)²) per axis (fixed seed); the ground
truth is unchanged (the expression on the target, unmoved; the true weights). Rows, on the same
cases, moved and unmoved: doing nothing; the bundled model with the neutral and refine, with and
without stabilisation (``Retargeter(stabilise=...)``); closest-point transfer of the raw frames, and
of the frames first aligned to the neutral by a plain least-squares rigid fit on every vertex
(what a DCC tool's align does).

    python docs/results/stabilise/moving.py --out docs/results/stabilise/moving.md
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

DEGREES = (2.0, 5.0, 10.0)   # the head turn's standard deviation, one table column each
SHIFT = 0.01                  # translation's standard deviation per axis, of the head's diagonal


def head_motion(frames: np.ndarray, degrees: float, rng) -> np.ndarray:
    """frames (T,V,3) each turned and shifted as the module docstring says -> (T,V,3)."""
    out = np.empty_like(frames, dtype=np.float64)
    for i, f in enumerate(frames):
        centre = f.mean(0)
        diag = np.linalg.norm(f.max(0) - f.min(0))
        axis = rng.normal(size=3)
        q = Rotation.from_rotvec(np.radians(rng.normal() * degrees) * axis / np.linalg.norm(axis)).as_matrix()
        out[i] = (f - centre) @ q.T + centre + rng.normal(size=3) * SHIFT * diag
    return out


def plain_align(frames: np.ndarray, neutral: np.ndarray) -> np.ndarray:
    """Each frame rigidly aligned to the neutral by least squares on every vertex (Kabsch)."""
    from retarget.stabilise import _kabsch

    out = np.empty_like(frames, dtype=np.float64)
    for i, f in enumerate(frames):
        r, t = _kabsch(neutral.astype(np.float64), f.astype(np.float64), np.ones(len(f)))
        out[i] = (f - t) @ r
    return out


def source_neutral(r, row: str, frames, neutral):
    """The neutral a row gives the network: the case's, one estimated from the frames, or none."""
    if "estimated" in row:
        return r.estimate_neutral(frames)
    return None if "no neutral" in row else neutral


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    args = ap.parse_args()

    from retarget.api import Retargeter
    from retarget.evaluate import EvalData, ict_to_arkit_weights, arkit_ict_matrix, load_eval_config
    from retarget.mesh import Mesh
    from retarget.metrics import segment_mse_mm2, squared_errors_mm2
    from retarget.oracle import closest_point_transfer

    data = EvalData(load_eval_config(None))
    nets = {True: Retargeter.load(), False: Retargeter.load(stabilise=False)}
    real = data.real_rig()
    arkit_ict = arkit_ict_matrix(real.names)
    used = arkit_ict.sum(1) > 0
    real_case = data.real_cases()["sampled"]["real_to_real"]
    cases = [("realistic cross-identity", c) for c in data.cases("head_cross_identity")]
    cases += [("realistic inverse rigging", c) for c in data.cases("head_inverse")]
    cases += [("ARKit rig real → real", real_case), ("ARKit rig inversion", real_case)]
    columns = [("unmoved", 0.0)] + [(f"{d:g}°", d) for d in DEGREES]
    rows = ("do nothing", "network, neutral + refine", "network, neutral + refine, no stabilisation",
            "network, estimated neutral + refine", "network, estimated neutral + refine, no stabilisation",
            "network, no neutral", "network, no neutral, no stabilisation",
            "closest point, raw frames", "closest point, frames aligned on every vertex")
    table: dict = {}
    for c_i, (suite, case) in enumerate(cases):
        inverse = "inversion" in suite or "inverse" in suite
        arkit = suite.startswith("ARKit")
        src_neutral = Mesh(case.source.neutral, case.source.faces)
        for col, degrees in columns:
            rng = np.random.default_rng([c_i, int(degrees * 10)])
            frames = head_motion(case.source_frames, degrees, rng) if degrees else case.source_frames
            meshes = [Mesh(f, case.source.faces) for f in frames]
            for r in nets.values():      # each take a new performance: no turn kept from the last
                r.clear_source_cache()  # take of this topology (Retargeter.encode)
            for row in rows:
                key = (suite, row, col)
                if inverse:
                    if row == "do nothing":
                        w = np.zeros((len(frames), 53))
                    elif row.startswith("network"):
                        r = nets["no stabilisation" not in row]
                        w = r.invert(meshes, source_neutral(r, row, meshes, src_neutral),
                                     refine="refine" in row)
                    else:
                        continue
                    if arkit:
                        a = ict_to_arkit_weights(w, arkit_ict)
                        err = np.abs(a - case.source_weights)[:, used].mean()
                    else:
                        err = np.abs(w - case.source_weights).mean()
                else:
                    tgt = case.target
                    if row == "do nothing":
                        pred = np.broadcast_to(tgt.neutral, case.gt.shape)
                    elif row.startswith("network"):
                        r = nets["no stabilisation" not in row]
                        pred = r.transfer(meshes, r.prepare(Mesh(tgt.neutral, tgt.faces)),
                                          source_neutral(r, row, meshes, src_neutral),
                                          refine="refine" in row)
                    else:
                        src = frames if "raw" in row else plain_align(frames, case.source.neutral)
                        pred = closest_point_transfer(case.source.neutral, case.source.faces, src,
                                                      tgt.neutral, tgt.faces)
                    err = (float(squared_errors_mm2(pred, case.gt).mean()) if arkit else
                           segment_mse_mm2(pred, case.gt, tgt.segments, 20)[0])
                table.setdefault(key, []).append(float(err))
            print(suite, col, "done", flush=True)

    lines = ["Segment-averaged MSE in mm² (the ARKit rig: plain MSE) for transfer, weight MAE for "
             "inversion; the head turn's standard deviation per column, shift 1 % of the head's "
             "diagonal per axis (unmoved: none).", "",
             "| suite | method | " + " | ".join(c for c, _ in columns) + " |",
             "| --- | --- |" + " ---: |" * len(columns)]
    for suite in dict.fromkeys(s for s, _ in cases):
        for row in rows:
            cells = [table.get((suite, row, c)) for c, _ in columns]
            if cells[0] is None:
                continue
            lines.append(f"| {suite} | {row} | " + " | ".join(f"{np.mean(v):.4g}" for v in cells) + " |")
    text = "\n".join(lines) + "\n"
    print(text)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
