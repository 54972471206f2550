"""One head on three tessellations: how far its identity code z_ID and its decoder's in-span error
move with the mesh alone (study, issue 10).

For ``--identities`` validation identities of each kind, the head is built on each of the code
map's training tessellations (``retarget.code_map.HEAD_TESSELLATIONS`` / ``UV_TESSELLATIONS``),
and the decoder's rows X and z_ID are read on its neutral (``decoder_rows``). Printed per kind:

- z_ID: the mean distance between two tessellations of one head, and between two heads on one
  tessellation, each relative to the mean |z_ID|;
- the baked shapes' median relative error |Xᵀ m_k − B_k| / |B_k| with the paper's map e_k, with
  the head's own best map on the same tessellation (the oracle), and with the same head's best
  map from another of its tessellations;
- with ``--mean-code``, also the paper's map with each tessellation's rig drawn from the mean of
  the head's three identity codes instead of its own (the rest of the network as it is): what
  one code per head, whatever its mesh, would give.

    OMP_NUM_THREADS=1 python docs/results/code_map/head_maps/tessellations.py --identities 20 > docs/results/code_map/head_maps/tessellations.md
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from itertools import permutations
from pathlib import Path

import numpy as np
import torch

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


def rows_with_code(r, rig, z_id) -> np.ndarray:
    """The decoder's rows (code_dim, 3V) float64 on ``rig``'s neutral with the identity code
    ``z_id`` (code_dim,) in place of the one the identity encoder reads there."""
    from retarget.api import basis_shapes
    from retarget.mesh import Mesh

    target = r.prepare(Mesh(rig.neutral, rig.faces))
    codes = dataclasses.replace(target.codes, z_id=z_id.to(target.codes.z_id))
    with torch.no_grad():
        codes = r.model.with_basis(target.feat, target.c, codes, r.chunk)
    target = dataclasses.replace(target, codes=codes)
    return basis_shapes(target, slice(None)).reshape(r.cfg.code_dim, -1).astype(np.float64)


def best_map(gram, cross):
    dims = len(gram)
    return np.linalg.solve(gram + 1e-6 * np.trace(gram) / dims * np.eye(dims), cross)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    ap.add_argument("--identities", type=int, default=20)
    ap.add_argument("--mean-code", action="store_true")
    args = ap.parse_args()
    r = Retargeter.load(args.checkpoint)
    print(f"{args.identities} validation identities of each kind, on each of three tessellations; "
          f"checkpoint {args.checkpoint}\n")
    extra = " shapes, paper's map, the head's mean z_ID |" if args.mean_code else ""
    print("| heads | tessellations | z_ID: between tessellations of a head | z_ID: between heads | "
          "shapes, paper's map | shapes, own best map (oracle) | shapes, best map of another tessellation |"
          + extra)
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: |" + (" ---: |" if args.mean_code else ""))
    for kind, specs in (("procedural", UV_TESSELLATIONS), ("makehuman", HEAD_TESSELLATIONS)):
        z = np.zeros((args.identities, len(specs), r.cfg.code_dim))
        paper, own, other, mean_code = [], [], [], []
        for i in range(args.identities):
            heads, rigs = [], []
            for j, spec in enumerate(specs):
                rig = head_on(kind, i, spec)
                rigs.append(rig)
                x, z[i, j] = decoder_rows(r, rig)
                x = x.astype(np.float64)
                b = np.asarray(rig.deltas, np.float64).reshape(len(rig.deltas), -1)
                heads.append({"gram": (x @ x.T)[None], "cross": (x @ b.T)[None], "norm2": (b ** 2).sum(1)[None]})
            if args.mean_code:
                z_mean = torch.as_tensor(z[i].mean(0), dtype=torch.float32)
                for rig in rigs:
                    x = rows_with_code(r, rig, z_mean)
                    b = np.asarray(rig.deltas, np.float64).reshape(len(rig.deltas), -1)
                    mean_code.append(np.nanmedian(relative_errors(
                        np.eye(r.cfg.code_dim, 53)[None],
                        {"gram": (x @ x.T)[None], "cross": (x @ b.T)[None], "norm2": (b ** 2).sum(1)[None]})))
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
              f"{np.mean(own):.3f} | {np.mean(other):.3f} |"
              + (f" {np.mean(mean_code):.3f} |" if args.mean_code else ""), flush=True)


if __name__ == "__main__":
    main()
