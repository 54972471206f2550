"""One head on three tessellations: how far its identity code z_ID and its decoder's in-span error
move with the mesh alone (study, issue 10).

For ``--identities`` validation identities of each kind, the head is built on each of the code
map's training tessellations (``retarget.code_map.HEAD_TESSELLATIONS`` / ``UV_TESSELLATIONS``),
and the decoder's rows X and z_ID are read on its neutral (``decoder_rows``). Printed per kind:

- z_ID: the mean distance between two tessellations of one head, and between two heads on one
  tessellation, each relative to the mean |z_ID|;
- the baked shapes' median relative error |Xᵀ m_k − B_k| / |B_k| with the paper's map e_k, with
  the head's own best map on the same tessellation (the oracle), and with the same head's best
  map from another of its tessellations.

    OMP_NUM_THREADS=1 python docs/results/code_map/head_maps/tessellations.py --identities 20 > docs/results/code_map/head_maps/tessellations.md
"""
from __future__ import annotations

import argparse
import sys
from itertools import permutations
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fit import relative_errors  # noqa: E402

from retarget.api import Retargeter  # noqa: E402
from retarget.code_map import HEAD_TESSELLATIONS, UV_TESSELLATIONS, decoder_rows  # noqa: E402


def head_on(kind: str, seed: int, spec: dict):
    from data_synth.identity import sample_identity
    from data_synth.makehuman import build_head_rig, head_tessellation, sample_head_identity
    from data_synth.rig import build_rig
    from data_synth.tessellate import tessellate

    if kind == "makehuman":
        return build_head_rig(sample_head_identity(seed, "val"), head_tessellation(seed=seed, **spec), 20)
    return build_rig(sample_identity(seed, "val"), tessellate(seed=seed, **spec), 20)


def best_map(gram, cross):
    dims = len(gram)
    return np.linalg.solve(gram + 1e-6 * np.trace(gram) / dims * np.eye(dims), cross)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    ap.add_argument("--identities", type=int, default=20)
    args = ap.parse_args()
    r = Retargeter.load(args.checkpoint)
    print(f"{args.identities} validation identities of each kind, on each of three tessellations; "
          f"checkpoint {args.checkpoint}\n")
    print("| heads | tessellations | z_ID: between tessellations of a head | z_ID: between heads | "
          "shapes, paper's map | shapes, own best map (oracle) | shapes, best map of another tessellation |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
    for kind, specs in (("procedural", UV_TESSELLATIONS), ("makehuman", HEAD_TESSELLATIONS)):
        z = np.zeros((args.identities, len(specs), r.cfg.code_dim))
        paper, own, other = [], [], []
        for i in range(args.identities):
            heads = []
            for j, spec in enumerate(specs):
                rig = head_on(kind, i, spec)
                x, z[i, j] = decoder_rows(r, rig)
                x = x.astype(np.float64)
                b = np.asarray(rig.deltas, np.float64).reshape(len(rig.deltas), -1)
                heads.append({"gram": (x @ x.T)[None], "cross": (x @ b.T)[None], "norm2": (b ** 2).sum(1)[None]})
            maps = [best_map(h["gram"][0], h["cross"][0]) for h in heads]
            eye = np.eye(r.cfg.code_dim, 53)[None]
            for j, h in enumerate(heads):
                paper.append(np.nanmedian(relative_errors(eye, h)))
                own.append(np.nanmedian(relative_errors(maps[j][None], h)))
            for j, k in permutations(range(len(specs)), 2):
                other.append(np.nanmedian(relative_errors(maps[k][None], heads[j])))
        scale = np.linalg.norm(z, axis=-1).mean()
        within = np.mean([np.linalg.norm(z[:, a] - z[:, b], axis=-1).mean() for a, b in permutations(range(len(specs)), 2)])
        between = np.mean([np.linalg.norm(z[a, :] - z[b, :], axis=-1).mean()
                           for a, b in permutations(range(args.identities), 2)])
        names = " / ".join(f"{s['kind']} {s.get('region', s.get('crop'))}" for s in specs)
        print(f"| {kind} | {names} | {within / scale:.3f} | {between / scale:.3f} | {np.mean(paper):.3f} | "
              f"{np.mean(own):.3f} | {np.mean(other):.3f} |", flush=True)


if __name__ == "__main__":
    main()
