"""Two checks of section "Frames that move many shapes" (docs/RESULTS.md), offline on the inversion
cases of docs/results/weight_mae/rig_span/cases.py, and on the demo.

``counts``: how many weights invert's first fit puts above 0.05, per suite and kind of row (one-hot,
sparse, uniform), with the first fit before the retune and as bundled: the second fit's rule
(more than 20) must split the kinds.

``blink``: on the rows of one to five shapes with eyeBlink_L above 0.5 (the ICT-rigged suites), the
fitted eyeBlink_L and eyeLookDown_L of the fit before the section, with the second fit, and
bundled; with ``--demo`` instead on the realistic demo's source (``retarget demo``'s head and
performance), by ``Retargeter.invert`` with those fits and the one before the balanced pulls, after
the sizes (L2 norms of the (3V,) deltas, cm) of the true and baked eyeBlink_L and eyeLookDown_L and
the true blink fitted by least squares on the two baked shapes.

    python docs/results/weight_mae/dense/checks.py counts runs/fitstudy/tuning10{0,1,2,3,4}.npz
    python docs/results/weight_mae/dense/checks.py blink runs/fitstudy/val_large.npz
    python docs/results/weight_mae/dense/checks.py blink --demo
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "rig_span"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from cases import api_fit, load, row_kinds  # noqa: E402
from dense import FIRST  # noqa: E402

from retarget.api import Retargeter  # noqa: E402

#: (prior, sparsity, reweight, balance, dense) of invert's fit: before the section (dense.py's
#: first fit), with its second fit, and as bundled now
BUNDLED = Retargeter.REFINE_INVERT_FITS[True]
BEFORE = FIRST + ((),)
SECOND = FIRST + (BUNDLED[4],)


def counts(cases) -> None:
    for name, fit in (("first fit before the retune", BEFORE), ("first fit bundled", BUNDLED[:4] + ((),))):
        found = {}
        for c in cases:
            n = (api_fit(c, *fit) > 0.05).sum(1)
            for kind, k in zip(row_kinds(c), n):
                found.setdefault((str(c["suite"]), str(kind)), []).append(k)
        for (suite, kind), v in sorted(found.items()):
            v = np.array(v)
            print(f"{name}: {suite} {kind}: {len(v)} frames, {v.min()}-{v.max()} weights above 0.05, "
                  f"{(v > 20).sum()} with more than 20")


def blink(cases) -> None:
    from data_synth.facs import FACS_INDEX

    b, d = FACS_INDEX["eyeBlink_L"], FACS_INDEX["eyeLookDown_L"]
    fitted, truth = {"before": [], "second fit": [], "bundled": []}, []
    for c in cases:
        if str(c["suite"]) == "real_rig":
            continue
        keep = (c["gt"][:, b] > 0.5) & (row_kinds(c) != "uniform")
        if not keep.any():
            continue
        part = {**c, "frames": c["frames"][keep], "w0": c["w0"][keep]}
        for name, fit in zip(fitted, (BEFORE, SECOND, BUNDLED)):
            fitted[name].append(api_fit(part, *fit)[:, [b, d]])
        truth.append(c["gt"][keep][:, [b, d]])
    t = np.concatenate(truth)
    print(f"{len(t)} frames; true eyeBlink_L {t[:, 0].mean():.3f}, eyeLookDown_L {t[:, 1].mean():.3f}")
    for name, v in fitted.items():
        v = np.concatenate(v)
        print(f"{name}: eyeBlink_L {v[:, 0].mean():.3f}, eyeLookDown_L {v[:, 1].mean():.3f}")


def demo_blink() -> None:
    from data_synth.facs import FACS_INDEX
    from retarget.commands.demo import HEADS, demo_mesh, performance
    from retarget.mesh import Mesh

    r = Retargeter.load()
    rig, neutral, _ = demo_mesh("makehuman", HEADS["makehuman"][0], r.cfg.n_segments)
    w = performance(90)
    frames = [Mesh(v, rig.faces) for v in rig.evaluate(w)]
    keep = w[:, FACS_INDEX["eyeBlink_L"]] > 0.5
    print(f"demo: {keep.sum()} frames with eyeBlink_L above 0.5 (true eyeLookDown_L there "
          f"{w[keep, FACS_INDEX['eyeLookDown_L']].mean():.3f})")
    baked = np.asarray(r.source_rig(neutral).basis, np.float64)           # (53, 3V)
    true = np.asarray(rig.deltas, np.float64).reshape(len(rig.deltas), -1)
    b, d = FACS_INDEX["eyeBlink_L"], FACS_INDEX["eyeLookDown_L"]
    mix = np.linalg.lstsq(baked[[b, d]].T, true[b], rcond=None)[0]
    print(f"eyeBlink_L: true size {np.linalg.norm(true[b]):.2f}, baked {np.linalg.norm(baked[b]):.2f}; "
          f"eyeLookDown_L: true {np.linalg.norm(true[d]):.2f}, baked {np.linalg.norm(baked[d]):.2f}; the true "
          f"blink by least squares on the two baked shapes: {mix[0]:.2f} blink + {mix[1]:.2f} look down")
    for name, fit in (("before the balanced pulls", BEFORE[:3] + (0.0, ())), ("before", BEFORE),
                      ("second fit", SECOND), ("bundled", BUNDLED)):
        (r.REFINE_PRIOR_INVERT, r.REFINE_SPARSITY_INVERT, r.REFINE_REWEIGHT_INVERT,
         r.REFINE_BALANCE_INVERT, r.REFINE_DENSE_INVERT) = fit
        inverted = r.invert(frames, source_neutral=neutral, refine=True)
        print(f"{name}: fitted eyeLookDown_L {inverted[keep, FACS_INDEX['eyeLookDown_L']].mean():.3f}, "
              f"weight MAE {np.abs(inverted - w).mean():.4f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("check", choices=("counts", "blink"))
    ap.add_argument("cases", nargs="*")
    ap.add_argument("--demo", action="store_true", help="blink: on the realistic demo's source")
    args = ap.parse_args()
    if args.check == "blink" and args.demo:
        demo_blink()
        return
    cases = load(*args.cases)
    counts(cases) if args.check == "counts" else blink(cases)


if __name__ == "__main__":
    main()
