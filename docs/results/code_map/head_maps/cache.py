"""Normal equations of each head's own code map, cached head by head (study: a code map predicted
per head, issue 10).

For each identity seed of ``--split`` and each kind of head asked for, the rig is built as
``retarget.code_map.training_rigs`` builds it (shapes as authored, the same tessellations in turn),
the model's decoder rows X (code_dim, 3V) and identity code z_ID are read on its neutral
(``decoder_rows``; no code map applied), and what a map's fit needs of that head is kept:
G = X Xᵀ (code_dim, code_dim), C = X Bᵀ (code_dim, 53), n = |B_k|² (53,). A head's best map is
M* = G⁻¹ C, and any map M costs that head Σ_k |Xᵀ m_k − B_k|² / n_k
= Σ_k (m_kᵀ G m_k − 2 m_kᵀ C_k + n_k) / n_k.

    OMP_NUM_THREADS=1 python docs/results/code_map/head_maps/cache.py --kind procedural --split train --seeds 0 400 --out runs/head_maps/proc_train.npz
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from retarget.api import Retargeter
from retarget.code_map import HEAD_TESSELLATIONS, UV_TESSELLATIONS, decoder_rows


def rigs(kind: str, split: str, first: int, last: int, n_segments: int):
    from data_synth.identity import sample_identity
    from data_synth.makehuman import base_head_rig, build_head_rig, head_tessellation, sample_head_identity
    from data_synth.rig import build_rig
    from data_synth.tessellate import tessellate

    for s in range(first, last):
        if kind == "makehuman":
            base = base_head_rig(sample_head_identity(s, split), "arkit")
            spec = HEAD_TESSELLATIONS[s % len(HEAD_TESSELLATIONS)]
            yield s, build_head_rig(base, head_tessellation(seed=s, **spec), n_segments)
        else:
            spec = UV_TESSELLATIONS[s % len(UV_TESSELLATIONS)]
            yield s, build_rig(sample_identity(s, split), tessellate(seed=s, **spec), n_segments)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    ap.add_argument("--kind", choices=["makehuman", "procedural"], required=True)
    ap.add_argument("--split", default="train")
    ap.add_argument("--seeds", type=int, nargs=2, required=True, metavar=("FIRST", "END"))
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    r = Retargeter.load(args.checkpoint)
    seeds, z, g, c, n = [], [], [], [], []
    t0 = time.time()
    for s, rig in rigs(args.kind, args.split, *args.seeds, r.cfg.n_segments):
        x, z_id = decoder_rows(r, rig)
        x = x.astype(np.float64)
        b = np.asarray(rig.deltas, np.float64).reshape(len(rig.deltas), -1)
        seeds.append(s); z.append(z_id); g.append(x @ x.T); c.append(x @ b.T); n.append((b ** 2).sum(1))
        if len(seeds) % 20 == 0:
            print(f"{args.kind} {args.split}: {len(seeds)} heads, {time.time() - t0:.0f} s", flush=True)
            np.savez(args.out, seeds=seeds, z_id=z, gram=g, cross=c, norm2=n)
    np.savez(args.out, seeds=seeds, z_id=z, gram=g, cross=c, norm2=n)
    print(f"done: {len(seeds)} heads in {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
