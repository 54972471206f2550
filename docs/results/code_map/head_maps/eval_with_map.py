"""`retarget eval` with a per-head code map fitted from the cached training heads (``cache.py``)
in place of the checkpoint's map (study, issue 10): the map of 16 whitened principal components
(``fit.py``: ``retarget.code_map.HeadMapFit``, ridge 0.001) on the first ``--heads`` (400) heads of
each cache given, drawn on every head from its own z_ID (``Retargeter.code_map_per_head``); with
``--gated`` given to each head as the checkpoint's gate says, with ``--clip C`` its components
clipped to ±C. The rest of the command line goes to ``retarget eval``.

    OMP_NUM_THREADS=1 python docs/results/code_map/head_maps/eval_with_map.py --caches runs/head_maps/makehuman_train.npz runs/head_maps/procedural_train.npz -- eval --config docs/results/weight_mae/validation_large.yaml --checkpoint perhead=retarget/checkpoints/default.pt --neutral-modes refine --suite inverse cross_identity animate --no-oracle --out runs/ph_val_proc
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fit import fit_map, load  # noqa: E402

import retarget.api as api  # noqa: E402
from retarget.code_map import head_code_map  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--caches", nargs="+", required=True)
    ap.add_argument("--gated", action="store_true")
    ap.add_argument("--clip", type=float, default=None)
    ap.add_argument("--heads", type=int, default=400, help="heads of each cache the map is fitted on")
    ap.add_argument("rest", nargs=argparse.REMAINDER)
    args = ap.parse_args()
    parts = [load([p]) for p in args.caches]
    train = {k: np.concatenate([p[k][:args.heads] for p in parts]) for k in parts[0]}
    m0, per_head = fit_map(train, 16, 0.001)
    checkpoint_code_map = api.checkpoint_code_map

    def with_per_head_map(state):
        """The map fitted here, with the checkpoint's gate when ``--gated``."""
        return m0, checkpoint_code_map(state)[1] if args.gated else None, per_head, None

    api.checkpoint_code_map = with_per_head_map
    if args.clip is not None:
        def clipped(code_map, gate, z_id, head):
            """``head_code_map`` with the per-head components clipped to ±``--clip``."""
            features, slopes = head
            phi = np.clip(features[1:].astype(np.float64) @ (np.asarray(z_id, np.float64) - features[0]),
                          -args.clip, args.clip)
            return head_code_map((code_map + np.tensordot(phi, slopes, axes=1)).astype(np.float32),
                                 gate, z_id)

        api.head_code_map = clipped
    from retarget.cli import main as cli
    rest = args.rest[1:] if args.rest[:1] == ["--"] else args.rest
    sys.exit(cli(rest))


if __name__ == "__main__":
    main()
