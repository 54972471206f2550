"""The inversion cases as invert's fit sees them, saved once so that fits can be studied offline
(docs/RESULTS.md, "What the weights' error is made of").

Per case (procedural ``inverse``, realistic ``head_inverse``, the ARKit rig's ``invert``), in the
source's units: A (53, 3V) the baked FACS shapes (``Retargeter.source_rig``, with the head's code
map), X (128, 3V) the decoder's rig (every code dim, no map), its identity code z_ID, the source
neutral, its frames (T, V, 3), the encoder's weights w0 (T, 53) read with the neutral, the true
weights (ICT; ARKit for the ARKit rig, with its ARKit → ICT matrix) and the true shapes (53 ICT or
52 ARKit, flattened).

    python docs/results/weight_mae/rig_span/cases.py --seed 100 --out runs/rig_span/tuning100.npz
    python docs/results/weight_mae/rig_span/cases.py --config configs/eval/validation.yaml --out runs/rig_span/val.npz

``--readings`` adds the expression encoder's reading (with the neutral) of each baked one-hot frame
neutral + B̂_k, minus its reading of the neutral itself: E (53, 53), row k; and for the ICT-rigged
suites E_true, the same on the true one-hot frames (docs/results/weight_mae/calibration/).

``--seed`` without ``--config``: the tuning set (configs/eval/study.yaml, test identities apart from
the eval's). ``load`` reads a file back; ``fit`` is invert's weights fit (``SourceRig.fit``) with
optional per-vertex weights; ``api_fit`` the API's own fit of a case's frames; ``weight_mae`` the
eval's MAE.
"""
from __future__ import annotations

import argparse

import numpy as np

KINDS = ("uniform", "onehot", "sparse")
SUITES = ("inverse", "head_inverse", "real_rig")


def dump(config: str | None, seed: int, checkpoint: str | None, out: str,
         readings: bool = False, more=None) -> None:
    """Write the cases (module docstring) to ``out``; ``more(r, neutral, index)`` -> dict, if given,
    adds its arrays to each case (``r`` the Retargeter, ``neutral`` the case's source neutral Mesh,
    ``index`` the case's number in the file)."""
    from retarget.api import Retargeter, basis_shapes
    from retarget.evaluate import EvalData, NetworkMethod, arkit_ict_matrix, load_eval_config
    from retarget.mesh import Mesh

    cfg = load_eval_config(config or "configs/eval/study.yaml")
    if config is None:
        cfg["seed"] = seed
    data = EvalData(cfg)
    r = Retargeter.load(checkpoint)
    method = NetworkMethod("network", r, "refine")
    store = {}

    def reading(neutral, deltas):
        frames = [Mesh(neutral.vertices + d.reshape(-1, 3), neutral.faces) for d in deltas]
        z = r.encode([neutral] + frames, source_neutral=neutral)[:, :53]
        return z[1:] - z[0]

    def put(suite, case, extra=None):
        frames, neutral = method._source(case)
        z = r.encode(frames, source_neutral=neutral)
        rig = r.source_rig(neutral)
        i = len({k.split("/")[0] for k in store})
        if more is not None:
            extra = {**(extra or {}), **more(r, neutral, i)}
        item = dict(suite=suite, A=rig.basis, neutral=rig.baked.neutral,
                    X=basis_shapes(rig.target, slice(None)).reshape(r.cfg.code_dim, -1),
                    z_id=rig.target.codes.z_id.detach().cpu().numpy(),
                    frames=np.stack([f.vertices for f in frames]), w0=z[:, :53],
                    gt=case.source_weights, true=case.source.deltas.reshape(len(case.source.deltas), -1),
                    **(extra or {}))
        if readings:
            item["E"] = reading(neutral, rig.basis)
            if suite != "real_rig":
                item["E_true"] = reading(neutral, item["true"])
        store.update({f"{i}/{k}": np.asarray(v) for k, v in item.items()})

    for suite in SUITES[:2]:
        for case in data.cases(suite):
            put(suite, case)
    put("real_rig", data.real_cases()["sampled"]["invert"],
        {"arkit_ict": arkit_ict_matrix(data.real_rig().names)})
    np.savez_compressed(out, **store)


def load(*paths) -> list[dict]:
    """The cases of one or more files of ``dump``."""
    cases = []
    for path in paths:
        z = np.load(path)
        n = len({k.split("/")[0] for k in z.files})
        cases += [{k.split("/")[1]: z[k] for k in z.files if k.startswith(f"{i}/")} for i in range(n)]
    return cases


def api_fit(case: dict, *fit_args, **fit_kwargs) -> np.ndarray:
    """The API's own ``SourceRig.fit`` of every frame of ``case`` on its baked rig A, the encoder's
    weights clipped to [0, 1] as the estimate: ``SourceRig.fit(frame, w0, *fit_args,
    **fit_kwargs)`` per frame -> weights (T, 53)."""
    from types import SimpleNamespace

    from retarget.api import SourceRig

    a = np.ascontiguousarray(case["A"], np.float32)
    rig = SourceRig(None, SimpleNamespace(neutral=np.asarray(case["neutral"], np.float32)), a,
                    a.astype(np.float64) @ a.T.astype(np.float64))
    return np.array([rig.fit(frame, np.clip(w0, 0.0, 1.0), *fit_args, **fit_kwargs)
                     for frame, w0 in zip(case["frames"], case["w0"])])


def _bounded(chol, h, mu, mean_diag):
    from scipy.linalg import solve_triangular
    from scipy.optimize import lsq_linear

    h = h - 0.5 * np.asarray(mu) * mean_diag
    rhs = solve_triangular(chol, h, trans="T")
    w = solve_triangular(chol, rhs)
    if w.min() < 0 or w.max() > 1:
        w = lsq_linear(chol, rhs, bounds=(0, 1), method="bvls").x
    return np.clip(w, 0, 1)


def fit(case: dict, shapes=None, prior=0.01, sparsity=0.002, reweight=(0.02, 0.05, 2),
        vertex_weights=None) -> np.ndarray:
    """Invert's fit (``SourceRig.fit``, the bundled constants by default) of every frame of ``case``
    on ``shapes`` (53, 3V; default the baked A), each vertex's squared residual weighted by
    ``vertex_weights(case)`` (V,) if given -> weights (T, 53)."""
    a = np.asarray(case["A"] if shapes is None else shapes, np.float64)
    aw = a if vertex_weights is None else a * np.repeat(vertex_weights(case), 3)
    gram = aw @ a.T
    mean_diag = np.trace(gram) / len(gram)
    ridge = prior * mean_diag + 1e-12
    chol = np.linalg.cholesky(gram + ridge * np.eye(len(gram))).T
    out = []
    for frame, w0 in zip(case["frames"], case["w0"]):
        h = aw @ (frame - case["neutral"]).reshape(-1).astype(np.float64) + ridge * np.clip(w0, 0, 1)
        w = _bounded(chol, h, sparsity, mean_diag)
        if reweight:
            mu, eps, passes = reweight
            for _ in range(passes):
                w = _bounded(chol, h, mu * eps / (w + eps), mean_diag)
        out.append(w)
    return np.array(out)


def weight_mae(case: dict, w: np.ndarray) -> np.ndarray:
    """The eval's weight MAE of each frame (T,): ICT weights, or for the ARKit rig the ARKit
    weights (each the mean of the ICT weights it feeds) over the shapes with an ICT shape."""
    if str(case["suite"]) != "real_rig":
        return np.abs(w - case["gt"]).mean(1)
    m = case["arkit_ict"]
    used = m.sum(1) > 0
    return np.abs(w @ m.T / np.maximum(m.sum(1), 1) - case["gt"])[:, used].mean(1)


def row_kinds(case: dict) -> np.ndarray:
    """'uniform' / 'onehot' / 'sparse' per frame (breakdown.py's ``row_kind``)."""
    gt = case["gt"] @ case["arkit_ict"] if str(case["suite"]) == "real_rig" else case["gt"]
    nnz = (gt > 0).sum(1)
    return np.where(nnz > 5, "uniform", np.where((nnz == 1) & (gt.max(1) == 1), "onehot", "sparse"))


def table_row(cases, name: str, shapes_of=None, suites=SUITES, zero: bool = False, fit_fn=None,
              cell=None, **fit_args) -> str:
    """One markdown row: per suite the MAE over all rows (and over the uniform rows) of ``fit``,
    or of ``fit_fn(case, shapes, **fit_args)`` -> (T, 53) when given (or of predicting 0:
    ``zero``); "—" for a suite without cases. ``cell(errors (N,), kinds (N,))`` -> str, given the
    suite's per-frame MAE and ``row_kinds``, writes another cell instead."""
    fit_fn = fit if fit_fn is None else fit_fn
    cells = []
    for suite in suites:
        errs, kinds = [], []
        for c in cases:
            if str(c["suite"]) != suite:
                continue
            w = (np.zeros_like(c["w0"]) if zero else
                 fit_fn(c, None if shapes_of is None else shapes_of(c), **fit_args))
            errs.append(weight_mae(c, w))
            kinds.append(row_kinds(c))
        if not errs:
            cells.append("—")
            continue
        e, k = np.concatenate(errs), np.concatenate(kinds)
        cells.append(cell(e, k) if cell else f"{e.mean():.4f} ({e[k == 'uniform'].mean():.3f})")
    return f"| {name} | " + " | ".join(cells) + " |"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=None)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--checkpoint", default=None)
    ap.add_argument("--out", required=True)
    ap.add_argument("--readings", action="store_true", help="add the encoder's readings E, E_true")
    args = ap.parse_args()
    dump(args.config, args.seed, args.checkpoint, args.out, args.readings)


if __name__ == "__main__":
    main()
