"""Test-time augmentation of the baked rig (issue 10 study): does averaging the decoder's rig over
the mirrored source neutral and small rotations of it bring the baked shapes closer to the true
ones, and does that lower inversion's weight MAE?

Mirror: the neutral with x negated (faces flipped) is baked, its deltas mirrored back and its
left/right shapes swapped (eyeBlink_L <-> eyeBlink_R, jawLeft <-> jawRight, ...). Rotations: the
neutral turned by ±3° about x and y around its centroid, the deltas turned back.

    # median relative error of the baked shapes per variant (validation heads)
    OMP_NUM_THREADS=2 python docs/results/weight_mae/bake_augment/bake_augment.py --checkpoint retarget/checkpoints/default.pt
    # breakdown.py with Retargeter.bake replaced by the plain + mirror average
    OMP_NUM_THREADS=2 python docs/results/weight_mae/bake_augment/bake_augment.py --breakdown --config configs/eval/validation.yaml --shapes --variants bundled --out breakdown_val_mirror.json
"""
from __future__ import annotations

import argparse
import runpy
import sys

import numpy as np

from data_synth import FACS_NAMES
from retarget.api import BakedRig, Retargeter
from retarget.evaluate import EvalData, arkit_ict_matrix, load_eval_config
from retarget.mesh import Mesh

BREAKDOWN = "docs/results/weight_mae/breakdown.py"
MIRROR = np.array([-1.0, 1.0, 1.0])


def partner(name: str) -> str:
    """The ICT name of a shape's mirror image (itself for a central shape)."""
    for a, b in (("_L", "_R"), ("_R", "_L"), ("Left", "Right"), ("Right", "Left")):
        if name.endswith(a):
            return name[: -len(a)] + b
    return name


SWAP = np.array([FACS_NAMES.index(partner(n)) for n in FACS_NAMES])


def rotation(axis: str, degrees: float) -> np.ndarray:
    """(3,3) rotation about the x or y axis."""
    t = np.deg2rad(degrees)
    c, s = np.cos(t), np.sin(t)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def deltas(bake, v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """bake(Mesh) -> BakedRig; its deltas (53,V,3) float64."""
    return bake(Mesh(v.astype(np.float32), f)).deltas.astype(np.float64)


def mirrored_deltas(bake, v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The rig baked on the mirrored neutral, mirrored back onto the neutral's own shapes (53,V,3)."""
    return (deltas(bake, v * MIRROR, f[:, ::-1].copy()) * MIRROR)[SWAP]


def rotated_deltas(bake, v: np.ndarray, f: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """The rig baked on the neutral turned by rot about its centroid, turned back (53,V,3)."""
    c = v.mean(0)
    return deltas(bake, (v - c) @ rot.T + c, f) @ rot


def relative_error(baked: np.ndarray, rig, ict_sums: bool) -> float:
    """Median over the rig's shapes of |B̂_k − B_k| / |B_k| (the ARKit rig against ICT sums)."""
    b, t = baked.reshape(53, -1), rig.deltas.reshape(len(rig.deltas), -1)
    if ict_sums:
        m = arkit_ict_matrix(rig.names)
        b, t = (m @ b)[m.sum(1) > 0], t[m.sum(1) > 0]
    n = np.linalg.norm(t, axis=1)
    return float(np.median(np.linalg.norm(b[n > 0] - t[n > 0], axis=1) / n[n > 0]))


def shape_table(checkpoint: str, config: str) -> None:
    data = EvalData(load_eval_config(config))
    r = Retargeter.load(checkpoint)
    rigs = {"inverse": [c.source for c in data.cases("inverse")],
            "head_inverse": [c.source for c in data.cases("head_inverse")],
            "real_rig": [data.real_rig()]}
    names = ("plain", "mirror only", "plain + mirror", "plain + 4 rotations", "plain + mirror + 4 rotations")
    table = {}
    for suite, sources in rigs.items():
        errs = {k: [] for k in names}
        for rig in sources:
            v, f = np.asarray(rig.neutral, np.float64), np.asarray(rig.faces)
            b0, bm = deltas(r.bake, v, f), mirrored_deltas(r.bake, v, f)
            rots = sum(rotated_deltas(r.bake, v, f, rotation(a, s * 3.0)) for a in "xy" for s in (-1, 1))
            for k, b in zip(names, (b0, bm, (b0 + bm) / 2, (b0 + rots) / 5, (b0 + bm + rots) / 6)):
                errs[k].append(relative_error(b, rig, suite == "real_rig"))
        table[suite] = {k: np.mean(e) for k, e in errs.items()}
    print("| bake | " + " | ".join(table) + " |\n| --- |" + " ---: |" * len(table))
    for k in names:
        print(f"| {k} | " + " | ".join(f"{table[s][k]:.3f}" for s in table) + " |")


def mirror_averaged_bake(bake):
    """Retargeter.bake replaced by the mean of the plain and the mirrored bake."""
    def averaged(self, target):
        plain = bake(self, target)
        t = self.prepare(target)
        v, f = t.mesh.vertices.astype(np.float64), t.mesh.faces
        mirrored = mirrored_deltas(lambda m: bake(self, m), v, f)
        return BakedRig(plain.neutral, ((plain.deltas + mirrored) / 2).astype(np.float32))
    return averaged


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    ap.add_argument("--config", default="configs/eval/validation.yaml")
    ap.add_argument("--breakdown", action="store_true",
                    help="run breakdown.py (the remaining arguments) with the mirror-averaged bake")
    args, rest = ap.parse_known_args()
    if args.breakdown:
        Retargeter.bake = mirror_averaged_bake(Retargeter.bake)
        sys.argv = [BREAKDOWN, "--checkpoint", args.checkpoint, "--config", args.config] + rest
        runpy.run_path(BREAKDOWN, run_name="__main__")
    else:
        shape_table(args.checkpoint, args.config)


if __name__ == "__main__":
    main()
