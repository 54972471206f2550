"""Validation error against training time, one line per run, from the runs' ``train_log.csv``.

    python -m retarget.training_plot docs/results/validation.png default=retarget/checkpoints/default_train_log.csv mix=runs/mix/train_log.csv

Each run's segment-averaged validation MSE (mm², ``val_seg_mse_mm2``) is drawn against its
training hours (``elapsed_s``); a run resumed from another (fine-tuning) starts at 0 hours. The
validation sets of runs with other ``data`` sections differ, so lines compare trends, not levels.
"""
from __future__ import annotations

import csv
import sys
from pathlib import Path

from .errors import RetargetError


def validation_points(log_path) -> list[tuple[float, float]]:
    """[(hours, val_seg_mse_mm2)] of the rows of a training log that carry a validation."""
    path = Path(log_path)
    try:
        rows = list(csv.DictReader(path.open()))
    except OSError as e:
        raise RetargetError(f"{path}: cannot read the training log ({e.strerror})") from None
    if rows and "val_seg_mse_mm2" not in rows[0]:
        raise RetargetError(f"{path}: not a train_log.csv of `retarget train` (no val_seg_mse_mm2)")
    return [(float(r["elapsed_s"]) / 3600.0, float(r["val_seg_mse_mm2"]))
            for r in rows if r.get("val_seg_mse_mm2")]


def plot_validation(runs: dict[str, str], out_png) -> Path:
    """Write a PNG (atomically) of each run's validation curve; runs: {name: train_log.csv}."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .io import atomic_output

    fig, ax = plt.subplots(figsize=(7, 4), dpi=110)
    for name, log in runs.items():
        pts = validation_points(log)
        if pts:
            ax.plot(*zip(*pts), marker="o", ms=3, label=f"{name} ({len(pts)} validations)")
    ax.set_xlabel("training hours")
    ax.set_ylabel("validation segment-averaged MSE (mm²)")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    out_png = Path(out_png)
    with atomic_output(out_png) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return out_png


def main(argv=None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) < 2:
        print("usage: python -m retarget.training_plot OUT.png NAME=train_log.csv ...", file=sys.stderr)
        return 2
    runs = {}
    for spec in args[1:]:
        name, sep, path = spec.partition("=")
        runs[name if sep else Path(spec).parent.name] = path if sep else spec
    try:
        print(plot_validation(runs, args[0]))
    except RetargetError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
