"""`retarget eval` with a per-head code map fitted from the cached training heads (``cache.py``)
in place of the checkpoint's map (study, issue 10): the map of 16 whitened principal components
(``fit.py``, ridge 0.001) on the first ``--heads`` (400) heads of each cache given, drawn on every head from its
own z_ID; with ``--gated`` given to each head as the checkpoint's gate says, with ``--clip C`` its
components clipped to ±C. The rest of the command line goes to ``retarget eval``. The map equals the
one `retarget train` fits from the same heads (``HeadMapFit``: within 1e-7 on the ARKit head).

    OMP_NUM_THREADS=1 python docs/results/code_map/head_maps/eval_with_map.py --caches runs/head_maps/makehuman_train.npz runs/head_maps/procedural_train.npz -- eval --config docs/results/weight_mae/validation_large.yaml --checkpoint perhead=retarget/checkpoints/default.pt --neutral-modes refine --suite inverse cross_identity animate --no-oracle --out runs/ph_val_proc
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fit import Features, fit_linear, load  # noqa: E402

import retarget.api as api  # noqa: E402
from retarget.code_map import gate_probability  # noqa: E402


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
    feats = Features(train["z_id"], 16)
    a = fit_linear(train, feats, 0.001)
    eye = np.eye(a.shape[1], 53)

    def head_code_map(self, target):
        if self.code_map is None:
            return None
        z = target.codes.z_id.detach().cpu().numpy().astype(np.float64)
        phi = feats(z[None])[0]
        if args.clip is not None:
            phi[1:] = np.clip(phi[1:], -args.clip, args.clip)
        m = np.einsum("kip,p->ik", a, phi)
        if args.gated:
            m = eye + gate_probability(self.code_map_gate, z) * (m - eye)
        return m.astype(np.float32)

    api.Retargeter.head_code_map = head_code_map
    from retarget.cli import main as cli
    rest = args.rest[1:] if args.rest[:1] == ["--"] else args.rest
    sys.exit(cli(rest))


if __name__ == "__main__":
    main()
