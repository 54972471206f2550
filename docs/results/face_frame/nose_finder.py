"""Build the nose finder that the face frame ships (``retarget.canonical.nose_finder``;
docs/RESULTS.md, "The face frame's nose tip") and measure it.

Meshes of each identity seed (``head_cases``): a MakeHuman head (``sample_head_identity``) twice
(a crop and kind by its seed at 2,500 vertices; another crop, decimated, 2,000), every sixth seed
also one of its expression frames (the artist's ARKit shapes at the eval's mixed weights), and a
procedural head (a full head or a face crop; an expression frame for odd seeds). Each mesh's
height field and nose-tip candidates are read as the face frame reads them (``face_field``,
``nose_candidates``), and the candidate nearest its true nose tip (MakeHuman: the base head's
nose-tip vertex, moved with the identity and the expression; procedural: the surface at the nose
bulb's template angles) is its label, when one lies within 0.04 window depths of it. A scorer
(features -> 32 tanh units -> 1) is trained on the training split (seeds 0-2999) by the softmax of
each mesh's candidates (Adam, lr 3e-3, weight decay 1e-4, 60 epochs, batches of 256, torch seed
0) and written to ``--out``; then the face frame's nose tip (the front-most point; the finder with
the shipped margin) is checked against the true tips on the validation split (seeds 0-599).
MakeHuman data: CC0 (data_synth/makehuman/data/LICENSES.md). About five minutes on two processes;
``--check-only`` checks the shipped finder without training:

    python docs/results/face_frame/nose_finder.py --out data_synth/makehuman/data/nose_finder.npz > docs/results/face_frame/nose_finder.txt
"""
from __future__ import annotations

import argparse
from multiprocessing import Pool

import numpy as np

LABEL_RADIUS = 0.04          # window depths: a candidate this near the true tip is the nose
KINDS = ("regular", "stylised", "expression", "procedural", "procedural expression")


def head_cases(seed: int, split: str):
    """The meshes of one identity seed and each one's true nose tip: [(kind, vertices, faces,
    tip (3,))], kind "regular" / "stylised" (MakeHuman neutrals), "expression" (a MakeHuman
    expression frame), "procedural" / "procedural expression". Every seed: the MakeHuman head
    twice (a crop and kind by its seed at 2,500 vertices; another crop, decimated, 2,000) and a
    procedural head (a full head or a face crop, 2,000 vertices; an expression frame for odd
    seeds); every sixth seed also a MakeHuman expression frame. Expression frames: the eval's
    mixed weights; the tip moves with them."""
    from data_synth.identity import sample_identity
    from data_synth.makehuman import (CROPS, base_head_rig, build_head_rig, head_neutral,
                                      head_tessellation, sample_head_identity)
    from data_synth.rig import build_rig
    from data_synth.sampling import sample_weights
    from data_synth.tessellate import tessellate

    rng = np.random.default_rng([seed, 5])
    ident = sample_head_identity(seed, split)
    bust = head_neutral(ident, "bust")
    tip_vertex = nose_tip_vertex()
    kind = "stylised" if ident.stylised else "regular"
    out = []
    specs = [(CROPS[seed % 4], ("decimated", "jittered", "subdivided")[seed % 3], 2500),
             (CROPS[(seed + 2) % 4], "decimated", 2000)]
    for i, (crop, tess_kind, n) in enumerate(specs):
        t = head_tessellation(seed=seed * 2 + i, n_vertices=n, kind=tess_kind, crop=crop)
        out.append((kind, t.apply(bust).astype(np.float64), t.faces, bust[tip_vertex]))
    if seed % 6 == 0:
        base = base_head_rig(ident, "arkit")
        rig = build_head_rig(base, head_tessellation(seed=seed * 2, n_vertices=2500, kind="decimated",
                                                     crop=specs[0][0]), 6)
        w = sample_weights(rng, 1, mode="mixed")[0].astype(np.float32) * base.present
        out.append(("expression", rig.evaluate(w).astype(np.float64), rig.faces,
                    base.neutral[tip_vertex] + w @ base.deltas[:, tip_vertex]))
    identity = sample_identity(seed, split)
    rig = build_rig(identity, tessellate(seed=seed, n_vertices=2000, kind=("regular", "jittered", "adaptive")[seed % 3],
                                         region=("full", "face")[seed % 2]), 20)
    near = int(np.argmin(np.linalg.norm(rig.neutral - procedural_nose_tip(identity), axis=1)))
    if seed % 2:
        frame = rig.evaluate(sample_weights(rng, 1, mode="mixed")[0].astype(np.float32))
        out.append(("procedural expression", frame.astype(np.float64), rig.faces, frame[near]))
    else:
        out.append(("procedural", rig.neutral.astype(np.float64), rig.faces, rig.neutral[near]))
    return out


def procedural_nose_tip(identity) -> np.ndarray:
    """A procedural head's nose tip (3,) cm: its surface at the nose bulb's template angles."""
    from data_synth.head import surface, template_to_uv
    from data_synth.identity import head_params

    uv = template_to_uv(np.array([0.0]), np.array([head_params(identity)["nose_tip_e"] - 0.015]))
    uv = np.stack(uv, -1) if isinstance(uv, tuple) else np.asarray(uv)
    return np.asarray(surface(uv.reshape(-1, 2), identity)).reshape(3)


def nose_tip_vertex() -> int:
    """The base head's nose tip: its front-most vertex near the midline at the nose's height."""
    from data_synth.makehuman import assets

    base = assets.heads()["full_neutral"]
    near = np.flatnonzero((np.abs(base[:, 0]) < 0.3) & (np.abs(base[:, 1] - 69.09) < 1.5))
    return int(near[np.argmax(base[near, 2])])


def head_rows(args) -> list[dict]:
    """Candidates, features and distances to the true tip (window depths) of one head's meshes."""
    seed, split = args
    from retarget.canonical import face_field, nose_candidates

    rows = []
    for kind, v, f, tip in head_cases(seed, split):
        field = face_field(v, f)
        cells, features = nose_candidates(field)
        dist = np.hypot(*(field.cell_xy(cells) - tip[:2]).T) / field.depth
        rows.append({"seed": seed, "kind": kind, "features": features, "dist": dist})
    return rows


def dataset(seeds, split: str) -> list[dict]:
    with Pool(2) as pool:
        return [r for rows in pool.map(head_rows, [(s, split) for s in seeds], chunksize=20) for r in rows]


def train(rows: list[dict]) -> dict:
    """The scorer's weights {w1 (F,32), b1 (32,), w2 (32,), b2 ()} float32."""
    import torch

    torch.manual_seed(0)
    keep = [r for r in rows if r["dist"].min() < LABEL_RADIUS]
    k = max(len(r["features"]) for r in keep)
    x = torch.zeros(len(keep), k, keep[0]["features"].shape[1])
    mask = torch.zeros(len(keep), k, dtype=torch.bool)
    for i, r in enumerate(keep):
        x[i, :len(r["features"])] = torch.from_numpy(r["features"])
        mask[i, :len(r["features"])] = True
    y = torch.tensor([int(np.argmin(r["dist"])) for r in keep])
    net = torch.nn.Sequential(torch.nn.Linear(x.shape[-1], 32), torch.nn.Tanh(), torch.nn.Linear(32, 1))
    opt = torch.optim.Adam(net.parameters(), lr=3e-3, weight_decay=1e-4)
    for _ in range(60):
        order = torch.randperm(len(keep))
        for b in range(0, len(keep), 256):
            idx = order[b:b + 256]
            score = net(x[idx]).squeeze(-1).masked_fill(~mask[idx], -1e9)
            loss = torch.nn.functional.cross_entropy(score, y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
    print(f"trained on {len(keep)} of {len(rows)} meshes (the others have no candidate within "
          f"{LABEL_RADIUS} window depths of the true tip); last batch loss {loss.item():.4f}")
    (l1, _, l2) = net
    return {"w1": l1.weight.detach().numpy().T, "b1": l1.bias.detach().numpy(),
            "w2": l2.weight.detach().numpy()[0], "b2": l2.bias.detach().numpy()[0]}


def check(rows: list[dict]) -> None:
    """How often the face frame's nose tip is the true one (within LABEL_RADIUS window depths)
    with the front-most point and with the finder, by kind of head."""
    from retarget.canonical import NOSE_MARGIN, nose_probabilities

    print(f"| meshes | count | tip right: front-most point | with the nose finder (margin {NOSE_MARGIN}) | fixed | broken |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for name in KINDS:
        sel = [r for r in rows if r["kind"] == name]
        old = np.array([r["dist"][0] < LABEL_RADIUS for r in sel])
        new = []
        for r in sel:
            p = nose_probabilities(r["features"])
            pick = int(np.argmax(p)) if p.max() - p[0] > NOSE_MARGIN else 0
            new.append(r["dist"][pick] < LABEL_RADIUS)
        new = np.array(new)
        print(f"| {name} | {len(sel)} | {old.sum()} | {new.sum()} | {(~old & new).sum()} | {(old & ~new).sum()} |")


def timing(seeds=range(20)) -> None:
    """Median milliseconds (one thread, warm) of the face frame's height field and of the finder
    (candidates, features, scores) on the validation split's first heads' meshes."""
    import time

    from retarget.canonical import face_field, nose_candidates, nose_probabilities

    field_ms, finder_ms = [], []
    for s in seeds:
        for _, v, f, _ in head_cases(s, "val"):
            t0 = time.perf_counter()
            field = face_field(v, f)
            t1 = time.perf_counter()
            nose_probabilities(nose_candidates(field)[1])
            t2 = time.perf_counter()
            field_ms.append(1e3 * (t1 - t0))
            finder_ms.append(1e3 * (t2 - t1))
    print(f"\ntime per mesh ({len(field_ms)} meshes of 2,000-2,500 vertices, median): height field "
          f"{np.median(field_ms):.1f} ms, nose finder {np.median(finder_ms):.1f} ms")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", help="where to write the nose finder (npz)")
    ap.add_argument("--check-only", action="store_true", help="check the shipped finder on the validation heads")
    args = ap.parse_args()
    if not args.check_only:
        from retarget.io import atomic_output

        weights = train(dataset(range(3000), "train"))
        with atomic_output(args.out) as tmp:
            np.savez_compressed(tmp, **weights)
        from retarget import canonical
        canonical.NOSE_FINDER_PATH = type(canonical.NOSE_FINDER_PATH)(args.out)
        canonical.nose_finder.cache_clear()
    check(dataset(range(600), "val"))
    timing()


if __name__ == "__main__":
    main()
