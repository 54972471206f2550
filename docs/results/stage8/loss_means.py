"""Mean of training-loss columns of a train_log.csv over blocks of steps (2,000 by default).

    python docs/results/stage8/loss_means.py retarget/checkpoints/default_realistic_stage8_log.csv [BLOCK]
"""
import csv
import sys

import numpy as np

KEYS = ("total", "L_dec", "L_v", "L_Exp", "L_rig", "L_ID", "L_nll")


def main(path: str, block: int = 2000) -> None:
    blocks: dict[int, list[list[float]]] = {}
    with open(path) as f:
        for row in csv.DictReader(f):
            blocks.setdefault(int(row["step"]) // block, []).append([float(row[k]) for k in KEYS])
    print("| steps | " + " | ".join(KEYS) + " |")
    print("| --- | " + " | ".join("---:" for _ in KEYS) + " |")
    for b, rows in sorted(blocks.items()):
        print(f"| {b * block}–{(b + 1) * block - 1} | "
              + " | ".join(f"{v:.4f}" for v in np.mean(rows, 0)) + " |")


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 2000)
