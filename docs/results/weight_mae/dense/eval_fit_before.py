"""``retarget eval`` with invert's fit as it was before section "Frames that move many shapes"
(docs/RESULTS.md): prior 0.01, sparsity 0.002, reweighted L1 (0.02, 0.05, 2), balance 0.5, no
second fit for dense frames; every argument goes to ``retarget`` as given.

    python docs/results/weight_mae/dense/eval_fit_before.py eval --config docs/results/weight_mae/dense/weights_200.yaml --checkpoint balanced=retarget/checkpoints/default.pt --neutral-modes refine --no-oracle --no-progress --suite inverse head_inverse real_rig --out runs/w200_bal
"""
import sys

from retarget.api import Retargeter
from retarget.cli import main

Retargeter.REFINE_INVERT_FITS[True] = (0.01, 0.002, (0.02, 0.05, 2), 0.5, ())

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
