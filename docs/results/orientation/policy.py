"""When to turn a head upright: cross-identity transfer (the upright ARKit head's frames, with its
neutral and refine) onto MakeHuman test heads turned by known angles, under thresholds of
``retarget.canonical.upright_rotation`` (docs/RESULTS.md, "Heads that do not face +z").

A head is read as turned by its own tilt plus what its shape reads (upright heads read up to 10° of
pitch); turning it by that reading leaves it off its own pose by the latter. Each policy is a
(pitch, sideways) threshold pair in degrees; "never" is ``upright=False``. Per policy and turn the
MSE (mm²) over the heads; the markdown table also gives doing nothing and closest-point
displacement transfer (both heads turned upright as the bundled policy turns them). "always" turns
every head whose face model fits (``UPRIGHT_MAX_RMS``), however little it reads.

    OMP_NUM_THREADS=1 python docs/results/orientation/policy.py --heads 0 4 --out runs/policy_a.json
    OMP_NUM_THREADS=1 python docs/results/orientation/policy.py --heads 4 8 --out runs/policy_b.json
    python docs/results/orientation/policy.py --summary runs/policy_a.json runs/policy_b.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from orientation import mse_mm2, turn  # noqa: E402

POLICIES = {"never": None, "9 / 4 (bundled)": (9.0, 4.0), "5 / 2.5": (5.0, 2.5), "always": (0.0, 0.0)}
BUNDLED = "9 / 4 (bundled)"
TURNS = (("x", -15), ("x", -10), ("x", -5), ("x", 0), ("x", 5), ("x", 10), ("x", 15),
         ("y", -10), ("y", -5), ("y", 5), ("y", 10))


def measure(heads: range, frames: int = 12) -> list[dict]:
    import retarget.canonical as canonical
    from data_synth.makehuman import (base_head_rig, build_head_rig, head_tessellation,
                                      sample_head_identity)
    from data_synth.sampling import sample_weights
    from retarget.api import Retargeter
    from retarget.evaluate import RealRig, arkit_ict_matrix, ict_to_arkit_weights
    from retarget.mesh import Mesh
    from retarget.oracle import closest_point_transfer

    repo = Path(__file__).resolve().parents[3]
    rig = RealRig.load(repo / "data_synth/makehuman/data/makehuman_arkit.npz")
    m = arkit_ict_matrix(rig.names)
    a = ict_to_arkit_weights(sample_weights(np.random.default_rng(0), frames, mode="mixed"), m)
    a = a.astype(np.float32)
    source = Mesh(rig.neutral.astype(np.float64), rig.faces, "source neutral")
    source_frames = [Mesh(f, rig.faces, "frame") for f in rig.evaluate(a).astype(np.float64)]
    tess = head_tessellation(seed=0, n_vertices=5000, kind="decimated", crop="head_neck")
    models = {name: Retargeter.load(upright=policy is not None) for name, policy in POLICIES.items()}
    regular = [s for s in range(200) if not sample_head_identity(s, "test").stylised]
    out = []
    for seed in (regular[i] for i in heads):
        other = build_head_rig(base_head_rig(sample_head_identity(seed, "test"), "arkit"), tess, 6)
        gt0 = other.evaluate(a @ m).astype(np.float64)
        centre = 0.5 * (other.neutral.min(0) + other.neutral.max(0))
        for axis, deg in TURNS:
            target = turn(other.neutral, axis, deg, centre)
            gt = turn(gt0, axis, deg, centre)
            row = {"head": seed, "axis": axis, "deg": deg, "nothing": mse_mm2(target[None], gt)}
            canonical.UPRIGHT_MIN_PITCH, canonical.UPRIGHT_MIN_SIDE = POLICIES[BUNDLED]
            row["closest"] = mse_mm2(closest_point_transfer(           # turned as the bundled policy
                source.vertices, source.faces, np.stack([f.vertices for f in source_frames]),
                target, other.faces, upright=True), gt)
            for name, policy in POLICIES.items():
                if policy is not None:
                    canonical.UPRIGHT_MIN_PITCH, canonical.UPRIGHT_MIN_SIDE = policy
                row[name] = mse_mm2(models[name].transfer(source_frames, Mesh(target, other.faces),
                                                          source_neutral=source, refine=True), gt)
            print(json.dumps(row), flush=True)
            out.append(row)
    return out


def summary(paths) -> str:
    rows = [r for p in paths for r in json.loads(Path(p).read_text())]
    names = ["nothing", "closest"] + list(POLICIES)
    lines = [f"{len({r['head'] for r in rows})} regular MakeHuman test heads; mean MSE (mm²) over "
             "them of each turn, geometric mean over the turns", "",
             "| turn | " + " | ".join(["do nothing", "closest point"] + list(POLICIES)) + " |",
             "| --- |" + " ---: |" * len(names)]
    for axis, deg in TURNS:
        sel = [r for r in rows if r["axis"] == axis and r["deg"] == deg]
        name = f"{'pitch' if axis == 'x' else 'yaw'} {deg:+d}°"
        lines.append(f"| {name} | " + " | ".join(f"{np.mean([r[n] for r in sel]):.4g}" for n in names) + " |")
    geo = [np.exp(np.mean([np.log(np.mean([r[n] for r in rows if (r["axis"], r["deg"]) == t]))
                           for t in TURNS])) for n in names]
    lines.append("| geometric mean | " + " | ".join(f"**{g:.4g}**" for g in geo) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--heads", type=int, nargs=2, default=(0, 8), metavar=("FIRST", "END"),
                    help="the regular test heads FIRST..END-1 (stylised ones skipped)")
    ap.add_argument("--out", type=Path, help="per-case JSON")
    ap.add_argument("--summary", nargs="+", type=Path, help="JSON files -> a markdown table")
    args = ap.parse_args(argv)
    if args.summary:
        print(summary(args.summary), end="")
        return 0
    rows = measure(range(*args.heads))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
