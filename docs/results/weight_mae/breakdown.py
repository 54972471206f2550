"""Inverse rigging's weight MAE split by the kind of expression, and a study of the weights' fit
(issue 10).

The eval's weights are ``mixed`` (data_synth.sampling): 30 % "uniform" rows (every shape ~U(0, 1)),
20 % one-hot rows, 50 % sparse rows (1-5 shapes ~U(0.2, 1)). For each variant of invert's fit
(``retarget.api.Retargeter.REFINE_*_INVERT``), this re-runs the inversion cases (procedural
``inverse``, realistic ``head_inverse``, the ARKit rig's ``invert``) in refine mode and reports, per
kind of row, the weight MAE and the plain rig MSE (mm²) of the inverted weights applied back to the
rig, beside predicting 0 (doing nothing) on the same rows.

    # tuning set (configs/eval/study.yaml, seed 100: apart from the eval's test set), every variant
    python docs/results/weight_mae/breakdown.py --out docs/results/weight_mae/tuning.json
    # the test set (configs/eval/default.yaml), the bundled fit and the chosen one
    python docs/results/weight_mae/breakdown.py --test --variants bundled CHOSEN --out docs/results/weight_mae/test.json
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from retarget.api import Retargeter
from retarget.evaluate import (EvalData, NetworkMethod, arkit_ict_matrix, ict_to_arkit_weights,
                               load_eval_config)
from retarget.metrics import squared_errors_mm2

KINDS = ("uniform", "onehot", "sparse")
#: invert's fit from stage 7 until the code map's retune (the variants before that one change it)
FIT_BEFORE_CODE_MAP = {"REFINE_PRIOR_INVERT": 0.1, "REFINE_SPARSITY_INVERT": 0.02,
                       "REFINE_REWEIGHT_INVERT": (0.1, 0.05, 2)}


def _before(**attributes) -> dict:
    return {**FIT_BEFORE_CODE_MAP, **attributes}


#: (prior, sparsity, reweight μ_max) of the retune on the larger validation sample
VALIDATION_GRID = [(p, s0, mu) for p in (0.002, 0.005, 0.01, 0.02) for s0 in (0.0, 0.001, 0.002)
                   for mu in (0.0, 0.02)]
#: name -> Retargeter attributes (the rest as bundled; "bundled": the fit the loaded checkpoint gets,
#: Retargeter.REFINE_INVERT_FITS: the one tuned for the code map when it has one)
VARIANTS = {
    "bundled": {},
    "fit before the code map's retune": _before(),
    "fit retuned for the code map": {"REFINE_PRIOR_INVERT": 0.01, "REFINE_SPARSITY_INVERT": 0.002,
                                     "REFINE_REWEIGHT_INVERT": (0.02, 0.05, 2)},
    "before (no reweighting)": _before(REFINE_REWEIGHT_INVERT=()),
    **{f"sparsity {mu}, no reweighting": _before(REFINE_SPARSITY_INVERT=mu, REFINE_REWEIGHT_INVERT=())
       for mu in (0.0, 0.05, 0.1)},
    **{f"reweight {mu}, eps {eps}": _before(REFINE_REWEIGHT_INVERT=(mu, eps, 2))
       for mu in (0.05, 0.1, 0.2, 0.5) for eps in (0.05, 0.2)},
    **{f"reweight {mu}, eps {eps}, {n} passes": _before(REFINE_REWEIGHT_INVERT=(mu, eps, n))
       for mu, eps, n in ((0.1, 0.05, 1), (0.1, 0.05, 4), (0.1, 0.02, 2), (0.07, 0.05, 2))},
    **{f"sparsity {s0}, reweight 0.1, eps 0.05": _before(REFINE_SPARSITY_INVERT=s0)
       for s0 in (0.0, 0.05)},
    **{f"prior {p}, reweight 0.1, eps 0.05": _before(REFINE_PRIOR_INVERT=p)
       for p in (0.01, 0.02, 0.05, 0.2)},
    # stage 14's retune: its baked shapes are off by 0.24-0.42 of their size (stage 10: ~0.8), and
    # rig_accuracy.md's α table has the bundled fit's strong prior as the limit once they are
    # below ~0.4, so weaker priors and pulls
    **{f"prior {p}, sparsity {s0}, reweight {mu}": {
        "REFINE_PRIOR_INVERT": p, "REFINE_SPARSITY_INVERT": s0,
        "REFINE_REWEIGHT_INVERT": (mu, 0.05, 2) if mu else ()}
       for p in (0.003, 0.01, 0.03) for s0, mu in ((0.0, 0.0), (0.005, 0.02), (0.02, 0.1))},
    # the code map's retune (stage 17 with its map, whose shapes are 0.29 of their size on the
    # realistic validation heads, 0.36 without): around the one of the rows above that won on
    # every suite of the tuning set with the map
    **{f"prior {p}, sparsity {s0}, reweight {mu}": {
        "REFINE_PRIOR_INVERT": p, "REFINE_SPARSITY_INVERT": s0, "REFINE_REWEIGHT_INVERT": (mu, 0.05, 2)}
       for p in (0.005, 0.01, 0.02) for s0 in (0.002, 0.005, 0.01) for mu in (0.02, 0.05)},
    # the weights and the free dims fitted together, as transfer does (reweighting is of the
    # weights-alone fit, so none)
    **{f"joint, prior {p}, sparsity {s0}": {"REFINE_JOINT_INVERT": True, "REFINE_PRIOR_INVERT": p,
                                            "REFINE_SPARSITY_INVERT": s0}
       for p in (0.01, 0.1) for s0 in (0.0, 0.002, 0.02)},
    # the retune on the larger validation sample (validation_large.yaml: 40 + 40 validation
    # identities, 120 ARKit frames), around the code map's retune: weaker priors and pulls too
    **{f"prior {p}, sparsity {s0}, reweight {mu}": {
        "REFINE_PRIOR_INVERT": p, "REFINE_SPARSITY_INVERT": s0,
        "REFINE_REWEIGHT_INVERT": (mu, 0.05, 2) if mu else ()}
       for p, s0, mu in VALIDATION_GRID},
}
#: the variants were run before invert's fit had its balance and its second fit for dense frames
#: (docs/RESULTS.md, "Invert's pulls in proportion to each shape", "Frames that move many
#: shapes"): every one but "bundled" keeps both off, so its rows come out as they were written
VARIANTS = {name: attributes if name == "bundled" else
            {"REFINE_BALANCE_INVERT": 0.0, "REFINE_DENSE_INVERT": (), **attributes}
            for name, attributes in VARIANTS.items()}
#: the variants of the code map's retune (``--variants`` of its command in docs/RESULTS.md)
CODE_MAP_RETUNE = ["fit before the code map's retune"] + [f"prior {p}, sparsity {s0}, reweight {mu}" for p in (0.005, 0.01, 0.02)
                                 for s0 in (0.002, 0.005, 0.01) for mu in (0.02, 0.05)]
#: the variants of the retune on the larger validation sample (``--variants validation-retune``)
VALIDATION_RETUNE = ["bundled"] + [f"prior {p}, sparsity {s0}, reweight {mu}" for p, s0, mu in VALIDATION_GRID]


def row_kind(w: np.ndarray) -> str:
    """The kind of one ICT weight row (53,): 'uniform' (more than 5 shapes active), 'onehot' (one
    at 1) or 'sparse'."""
    nnz = int((w > 0).sum())
    if nnz > 5:
        return "uniform"
    return "onehot" if nnz == 1 and w.max() == 1.0 else "sparse"


def inversion_rows(method: NetworkMethod, data: EvalData, cfg: dict) -> dict:
    """suite -> {"kind": [str], "mae": (N,), "mae_0": (N,), "rig": (N,), "rig_0": (N,)}, one entry
    per weight row: weight MAE of the method and of predicting 0, and the plain rig MSE (mm²) of
    each's weights applied back to the rig."""
    out = {}
    for suite in ("inverse", "head_inverse"):
        rows = {"kind": [], "mae": [], "mae_0": [], "rig": [], "rig_0": []}
        for case in data.cases(suite):
            w, gt = method.invert(case), case.source_weights
            rows["kind"] += [row_kind(g) for g in gt]
            rows["mae"] += list(np.abs(w - gt).mean(1))
            rows["mae_0"] += list(np.abs(gt).mean(1))
            rows["rig"] += list(squared_errors_mm2(case.source.evaluate(w), case.source_frames).mean(1))
            rows["rig_0"] += list(squared_errors_mm2(case.source.evaluate(0 * w), case.source_frames).mean(1))
        out[suite] = rows
    case = data.real_cases()["sampled"]["invert"]
    m = arkit_ict_matrix(data.real_rig().names)
    used = m.sum(1) > 0                                  # tongueOut has no ICT shape
    ict = data.weights("real_rig", 0, cfg["real_rig"]["expressions"])
    a, g = ict_to_arkit_weights(method.invert(case), m), case.source_weights
    out["real_rig"] = {
        "kind": [row_kind(w) for w in ict], "mae": list(np.abs(a - g)[:, used].mean(1)),
        "mae_0": list(np.abs(g)[:, used].mean(1)),
        "rig": list(squared_errors_mm2(case.source.evaluate(a), case.source_frames).mean(1)),
        "rig_0": list(squared_errors_mm2(case.source.evaluate(0 * a), case.source_frames).mean(1))}
    return out


def by_kind(rows: dict) -> dict:
    """{kind or "all": {"rows", "weight_mae", "predict_0_mae", "rig_mse_mm2", "predict_0_rig"}}."""
    kinds = np.array(rows["kind"])
    out = {}
    for kind in KINDS + ("all",):
        sel = np.ones(len(kinds), bool) if kind == "all" else kinds == kind
        if sel.any():
            out[kind] = {"rows": int(sel.sum()), "weight_mae": float(np.mean(np.array(rows["mae"])[sel])),
                         "predict_0_mae": float(np.mean(np.array(rows["mae_0"])[sel])),
                         "rig_mse_mm2": float(np.mean(np.array(rows["rig"])[sel])),
                         "predict_0_rig": float(np.mean(np.array(rows["rig_0"])[sel]))}
    return out


def baked_and_true(r: Retargeter, rig, ict_sums: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The decoder's baked one-hot shapes B̂ on ``rig``'s neutral and the rig's true shapes B, both
    flattened (K, V·3) in mm over the K shapes the rig has (|B_k| > 0), with |B_k| (K,).
    ict_sums: an ARKit rig, its shapes against the sums of their ICT shapes (``arkit_ict_matrix``)."""
    from retarget.mesh import Mesh

    baked = r.source_rig(Mesh(rig.neutral, rig.faces)).baked.deltas.reshape(53, -1)
    true = rig.deltas.reshape(len(rig.deltas), -1)
    if ict_sums:
        m = arkit_ict_matrix(rig.names)
        baked, true = (m @ baked)[m.sum(1) > 0], true[m.sum(1) > 0]
    norm = np.linalg.norm(true, axis=1)
    keep = norm > 0
    return baked[keep], true[keep], norm[keep]


def shape_errors(r: Retargeter, data: EvalData) -> dict:
    """How far the decoder's baked rig on each source neutral of the inversion cases is from that
    rig's true shapes: suite -> {"median", "mean", "small", "large"} of the relative error
    |B̂_k − B_k| / |B_k| over the shapes (small / large: the half of the shapes with the smaller /
    larger |B_k|), averaged over the cases' identities; the ARKit rig's shapes against the sums
    of their ICT shapes (``arkit_ict_matrix``)."""
    out = {}
    rigs = {"inverse": [c.source for c in data.cases("inverse")],
            "head_inverse": [c.source for c in data.cases("head_inverse")],
            "real_rig": [data.real_rig()]}
    for suite, sources in rigs.items():
        stats = []
        for rig in sources:
            baked, true, norm = baked_and_true(r, rig, ict_sums=suite == "real_rig")
            rel = np.linalg.norm(baked - true, axis=1) / norm
            small = norm <= np.median(norm)
            stats.append((np.median(rel), rel.mean(), rel[small].mean(), rel[~small].mean()))
        out[suite] = dict(zip(("median", "mean", "small", "large"), np.mean(stats, 0).tolist()))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    ap.add_argument("--test", action="store_true", help="the eval's test set instead of the tuning set")
    ap.add_argument("--config", default=None, help="an eval config instead (e.g. configs/eval/validation.yaml)")
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS),
                    help="names of VARIANTS, or 'code-map-retune' / 'validation-retune' for those lists")
    ap.add_argument("--shapes", action="store_true", help="also the baked rig's relative error per shape")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    if args.variants == ["code-map-retune"]:
        args.variants = CODE_MAP_RETUNE
    elif args.variants == ["validation-retune"]:
        args.variants = VALIDATION_RETUNE
    if args.config:
        cfg = load_eval_config(args.config)
    elif args.test:
        cfg = load_eval_config()
    else:
        cfg = load_eval_config("configs/eval/study.yaml")
        cfg["seed"] = 100
    data = EvalData(cfg)
    r = Retargeter.load(args.checkpoint)
    results = {}
    if args.shapes:
        results["shape_errors"] = shape_errors(r, data)
        for suite, v in results["shape_errors"].items():
            print(f"baked rig vs true shapes, {suite}: relative error " +
                  ", ".join(f"{k} {x:.3f}" for k, x in v.items()))
    print("| variant | suite | " + " | ".join(f"{k}: MAE / rig" for k in KINDS + ("all",)) + " |")
    print("| --- | --- |" + " ---: |" * (len(KINDS) + 1))
    for name in ["predict 0"] + args.variants:
        saved = {key: getattr(r, key) for key in VARIANTS.get(name, {})}
        for key, value in VARIANTS.get(name, {}).items():
            setattr(r, key, value)
        if name != "predict 0":
            tables = {s: by_kind(rows) for s, rows in
                      inversion_rows(NetworkMethod(name, r, "refine"), data, cfg).items()}
            results[name] = tables
            if "predict 0" not in results:
                results["predict 0"] = {s: {k: {"weight_mae": v["predict_0_mae"], "rig_mse_mm2": v["predict_0_rig"],
                                                "rows": v["rows"]} for k, v in t.items()}
                                        for s, t in tables.items()}
                for s, t in results["predict 0"].items():
                    print(f"| predict 0 | {s} | " + " | ".join(
                        f"{t[k]['weight_mae']:.4f} / {t[k]['rig_mse_mm2']:.4g}" if k in t else "—"
                        for k in KINDS + ("all",)) + " |")
            for s, t in tables.items():
                print(f"| {name} | {s} | " + " | ".join(
                    f"{t[k]['weight_mae']:.4f} / {t[k]['rig_mse_mm2']:.4g}" if k in t else "—"
                    for k in KINDS + ("all",)) + " |", flush=True)
        for key, value in saved.items():
            setattr(r, key, value)
        if args.out:
            Path(args.out).write_text(json.dumps({"checkpoint": args.checkpoint, "test": args.test,
                                                  "results": results}, indent=1))


if __name__ == "__main__":
    main()
