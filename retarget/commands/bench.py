"""``retarget bench``: the performance benchmark of DESIGN.md section 6 (``retarget.bench``)."""
from __future__ import annotations

HELP = "performance: target preparation 1k-1M vertices, per-frame latency/throughput, training speed"
EXAMPLE = """retarget bench --out results/bench
retarget bench --sizes 1000,10000 --sections prepare,frames --out results/bench_quick
retarget bench --checkpoint runs/full/model.pt --peer runs/no_skinning/model.pt --device cpu"""

SECTIONS = ("prepare", "frames", "train")


def _ints(text: str) -> list[int]:
    from ..errors import RetargetError
    try:
        values = [int(float(x)) for x in text.split(",") if x.strip()]
    except ValueError:
        raise RetargetError(f"--sizes: expected comma-separated vertex counts, got {text!r}") from None
    if not values or min(values) < 100:
        raise RetargetError(f"--sizes: vertex counts must be >= 100, got {text!r}")
    return values


def _sections(text: str) -> list[str]:
    from ..errors import RetargetError
    out = [s.strip() for s in text.split(",") if s.strip()]
    bad = sorted(set(out) - set(SECTIONS))
    if bad:
        raise RetargetError(f"--sections: unknown {bad}; choose from {', '.join(SECTIONS)}")
    return out


def add_arguments(p):
    p.add_argument("--checkpoint", help="checkpoint to time (default: the bundled one)")
    p.add_argument("--peer", help="checkpoint of the no-skinning ablation (default: an untrained "
                                  "use_skinning=False model of the same config; timings do not "
                                  "depend on weights)")
    p.add_argument("--sizes", default="1000,10000,100000,1000000",
                   help="target sizes (vertices) for the preparation section, comma-separated")
    p.add_argument("--vertices", type=int, default=11000, help="target size of the per-frame section")
    p.add_argument("--frames", type=int, default=20, help="frames per latency/throughput measurement")
    p.add_argument("--repeats", type=int, default=3, help="runs per figure (median)")
    p.add_argument("--train-config", help="training config for samples/s (default: the built-in "
                                          "defaults of retarget.train)")
    p.add_argument("--train-steps", type=int, default=10, help="training steps timed")
    p.add_argument("--sections", default=",".join(SECTIONS), help="which sections, comma-separated")
    p.add_argument("--device", action="append", choices=("cpu", "cuda"),
                   help="device(s) (default: the CPU, and CUDA when present)")
    p.add_argument("--out", help="folder for bench.json and bench.md")


def run(args) -> int:
    from ..bench import run_bench, to_markdown
    from ..evaluate import parse_checkpoints, write_results

    (_, checkpoint), = parse_checkpoints([args.checkpoint] if args.checkpoint else None)
    results = run_bench(checkpoint, _ints(args.sizes), n_vertices=args.vertices,
                        n_frames=args.frames, repeats=args.repeats, train_config=args.train_config,
                        train_steps=args.train_steps, peer=args.peer, device_list=args.device,
                        sections=_sections(args.sections),
                        progress=lambda msg: print(msg, flush=True))
    markdown = to_markdown(results)
    print(markdown)
    if args.out:
        for path in write_results(args.out, "bench", results, markdown):
            print(f"wrote {path}")
    return 0
