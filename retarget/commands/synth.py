"""``retarget synth``: synthesise a procedural rig dataset (sharded npz), or preview the rigs as PNG
contact sheets (the 53 shapes as displacement heatmaps, 12 identities, the segmentations)."""
from __future__ import annotations

from pathlib import Path

HELP = "synthesise a procedural FACS rig dataset (sharded npz) or PNG previews of the rigs"
EXAMPLE = """retarget synth --config configs/synth/default.yaml --out data/synth
retarget synth --config configs/synth/tiny.yaml --out /tmp/tiny --overwrite
retarget synth --preview --out previews --identity-seed 3
retarget synth --preview --source procedural --out previews_uv"""



def add_arguments(p):
    p.add_argument("--config", default="default",
                   help="synth YAML config: a file or a shipped name (default, tiny; default: "
                        "configs/synth/default.yaml)")
    p.add_argument("--out", required=True, help="output folder (shards + index.json, or PNGs)")
    p.add_argument("--preview", action="store_true",
                   help="write PNG contact sheets instead of a dataset")
    p.add_argument("--identity-seed", type=int, default=0,
                   help="preview: the test identity whose 53 shapes are shown (default 0)")
    p.add_argument("--source", choices=("makehuman", "procedural"), default="makehuman",
                   help="preview: realistic MakeHuman heads (default) or procedural (u, v) heads")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a dataset already in --out (default: refuse)")


def run(args) -> int:
    from ..errors import RetargetError

    from ..io import check_output

    out = Path(args.out)
    check_output(out, [])  # not "-" (standard output), not a symlink loop
    if out.exists() and not out.is_dir():
        raise RetargetError(f"{out}: exists and is not a folder")
    if args.preview:
        from ..synth_preview import write_previews

        for path in write_previews(out, identity_seed=args.identity_seed,
                                   source=args.source):
            print(path)
        return 0

    from tqdm import tqdm

    from data_synth.dataset import generate_items, load_config, write_shards

    from ..config import find_config

    config = find_config(args.config, "synth")
    if not config.is_file():
        raise RetargetError(f"{config}: config file not found")
    try:
        cfg = load_config(config)
    except ValueError as e:
        raise RetargetError(f"{config}: {e}") from None
    if (out / "index.json").exists() and not args.overwrite:
        raise RetargetError(f"{out}: already holds a dataset (index.json); pass --overwrite to replace it")
    with tqdm(total=cfg["n_identities"], unit="rig", desc="synth") as bar:
        paths = write_shards(out, generate_items(cfg), cfg["shard_size"], progress=bar.update, config=cfg)
    print(f"wrote {cfg['n_identities']} rigs x {cfg['expressions_per_identity']} expressions in "
          f"{len(paths)} shards to {out}")
    return 0
