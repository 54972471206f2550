"""Baked rigs averaged over re-tessellations of the source neutral (issue 10 study).

The baked shapes' in-span error is each head's own, and about half of it follows the mesh rather
than the identity (docs/RESULTS.md, "Code maps per head"). If that half is like noise from one
tessellation to the next, the mean of the rigs baked on several re-tessellations of the same
neutral surface is closer to the true shapes than any one of them. This script measures it on the
tuning set's inversion cases (``rig_span/cases.py``'s cases, same seeds):

per case it bakes the rig on the neutral as given (A0) and on ``--variants`` re-tessellations of
it (``--kind remesh``: one level of midpoint subdivision, quadric edge collapse back to about the
neutral's vertex count, every vertex slid inside one of its triangles; ``jitter``: the slide alone,
on the neutral's own faces; a different random seed each), carries
each variant's shapes back to the neutral's vertices (closest point on the variant's surface,
barycentric), and saves them beside the case.

    python docs/results/weight_mae/tta/tta.py --seed 100 --variants 8 --checkpoint runs/stage22.pt --out runs/tta/v8_100.npz
    python docs/results/weight_mae/tta/tta.py --seed 100 --variants 4 --kind jitter --out runs/tta/j4_100.npz
    python docs/results/weight_mae/tta/tta.py --report runs/tta/v8_10{0,1,2,3,4}.npz

The report gives, per suite, the median relative error of the baked shapes and invert's weight
MAE (the API's fit, ``Retargeter.REFINE_INVERT_FITS[True]``) for the rig as given, each variant alone, and
the means of the first 1..K variants with and without the rig as given.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "rig_span"))
import cases as rig_cases  # noqa: E402


def retessellate(vertices: np.ndarray, faces: np.ndarray, seed: int, kind: str = "remesh"):
    """A new tessellation of the same piecewise-linear surface -> (vertices (V',3), faces (F',3)).
    ``remesh``: subdivide once, collapse back to about the input's vertex count, jitter inside
    triangles; ``jitter``: the input's faces, every vertex slid inside one of its triangles."""
    import scipy.sparse as sp

    from data_synth.makehuman.tessellate import _decimate, _jitter, _subdivide

    rng = np.random.default_rng(seed)
    n = len(vertices)
    w, f = sp.identity(n, format="csr"), np.asarray(faces, np.int64)
    if kind == "remesh":
        w, f = _subdivide(w, f)
        w, f = _decimate(w, f, np.asarray(w @ vertices), n)
    w = _jitter(w, f, rng)
    used = np.unique(f)
    remap = np.full(w.shape[0], -1, np.int64)
    remap[used] = np.arange(len(used))
    return np.asarray(w[used] @ vertices), remap[f]


def closest_barycentric(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, k: int = 8):
    """For each point (N,3): the face (N,) of (vertices, faces) nearest to it and the barycentric
    coordinates (N,3) of its closest point there (candidates: faces around the k nearest vertices)."""
    import trimesh
    from scipy.spatial import cKDTree

    faces = np.asarray(faces, np.int64)
    corner_faces = np.repeat(np.arange(len(faces)), 3)
    order = np.argsort(faces.reshape(-1), kind="stable")
    valence = np.bincount(faces.reshape(-1), minlength=len(vertices))
    start = np.r_[0, np.cumsum(valence)[:-1]]
    slot = np.arange(len(order)) - np.repeat(start, valence)
    incident = np.full((len(vertices), valence.max()), -1, np.int64)
    incident[faces.reshape(-1)[order], slot] = corner_faces[order]
    _, near = cKDTree(vertices).query(points, k=min(k, len(vertices)))
    cand = incident[near].reshape(len(points), -1)                      # (N, k*valence), -1 = none
    owner, col = np.nonzero(cand >= 0)
    cf = cand[owner, col]
    tris = vertices[faces[cf]]
    cp = trimesh.triangles.closest_point(tris, points[owner])
    dist = np.linalg.norm(cp - points[owner], axis=1)
    pick = np.lexsort((dist, owner))
    first = pick[np.r_[True, owner[pick][1:] != owner[pick][:-1]]]      # nearest candidate of each
    bary = trimesh.triangles.points_to_barycentric(tris[first], cp[first])
    bary = np.clip(bary, 0.0, 1.0)
    return cf[first], bary / bary.sum(1, keepdims=True)


def dump(seed: int, checkpoint: str | None, out: str, n_variants: int, kind: str = "remesh") -> None:
    """``rig_span/cases.py``'s cases of the tuning seed ``seed``, each with ``A_var``
    (n_variants, 53, 3V): the rig baked on each variant, carried back to the neutral's vertices."""
    from retarget.mesh import Mesh

    def variants(r, neutral, index):
        out = []
        for j in range(n_variants):
            vv, vf = retessellate(neutral.vertices, neutral.faces, 1000 * seed + 97 * j + index, kind)
            a = r.source_rig(Mesh(vv, vf)).basis.reshape(53, -1, 3)
            face, bary = closest_barycentric(np.asarray(neutral.vertices, np.float64), vv, vf)
            out.append(np.einsum("kvcd,vc->kvd", a[:, vf[face]], bary).reshape(53, -1))
        return {"A_var": np.stack(out)}

    rig_cases.dump(None, seed, checkpoint, out, more=variants)


def relative_error(case: dict, shapes: np.ndarray) -> float:
    """Median over shapes of |Â_k − B_k| / |B_k| (ICT-rigged suites; nan for the ARKit rig)."""
    if str(case["suite"]) == "real_rig":
        return float("nan")
    true = case["true"]
    norm = np.linalg.norm(true, axis=1)
    ok = norm > 1e-9
    return float(np.median(np.linalg.norm(shapes - true, axis=1)[ok] / norm[ok]))


def report(paths) -> None:
    from retarget.api import Retargeter

    def bundled_fit(case, shapes):
        return rig_cases.api_fit({**case, "A": shapes}, *Retargeter.REFINE_INVERT_FITS[True])

    cases = rig_cases.load(*paths)
    k = min(len(c["A_var"]) for c in cases)
    rigs = {"as given": lambda c: c["A"]}
    for j in range(k):
        rigs[f"variant {j + 1} alone"] = lambda c, j=j: c["A_var"][j]
    for m in range(1, k + 1):
        rigs[f"mean of {m} variants"] = lambda c, m=m: c["A_var"][:m].mean(0)
        rigs[f"mean of the rig as given and {m} variants"] = (
            lambda c, m=m: (c["A"] + c["A_var"][:m].sum(0)) / (m + 1))
    print("| rig | shapes' median relative error, procedural / realistic | weight MAE (uniform rows): "
          + " | ".join(rig_cases.SUITES) + " |")
    print("| --- | ---: | " + " | ".join("---:" for _ in rig_cases.SUITES) + " |")
    print(rig_cases.table_row(cases, "predicting 0", zero=True).replace("| predicting 0 |", "| predicting 0 | — |"))
    for name, of in rigs.items():
        rel = [np.nanmedian([relative_error(c, of(c)) for c in cases if str(c["suite"]) == s])
               for s in rig_cases.SUITES[:2]]
        row = rig_cases.table_row(cases, name, shapes_of=of, fit_fn=bundled_fit)
        print(row.replace(f"| {name} |", f"| {name} | {rel[0]:.3f} / {rel[1]:.3f} |"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--checkpoint", default=None)
    ap.add_argument("--variants", type=int, default=4)
    ap.add_argument("--out")
    ap.add_argument("--kind", choices=("remesh", "jitter"), default="remesh",
                    help="how each variant is made (retessellate)")
    ap.add_argument("--report", nargs="+")
    args = ap.parse_args()
    if args.report:
        report(args.report)
    else:
        dump(args.seed, args.checkpoint, args.out, args.variants, args.kind)


if __name__ == "__main__":
    main()
