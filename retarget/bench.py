"""The performance benchmark of ``retarget bench`` (DESIGN.md section 6).

Sections (each figure the median of several runs; devices: the CPU, and CUDA when present):

- ``prepare``: ``Retargeter.prepare`` of procedural heads of 1k … 1M vertices (and the frame
  section's target size). Each run is a fresh process (``python -m retarget.bench prepare-child``)
  with an empty operator cache, so it measures a cold preparation. Memory = that process's peak
  resident set (``resource.getrusage(...).ru_maxrss``), reported whole and as the increase over its
  peak just before ``prepare`` (after imports, model load and mesh construction); on CUDA also
  ``torch.cuda.max_memory_allocated``. Sizes above ``LARGE`` run once. A size that misses its
  target is run once more under cProfile and the functions taking the most time are reported.
- ``frames``: per-call latency (median of single-frame calls after a warm-up call) and batched
  throughput (frames / wall time of one call over all frames, median of ``repeats``) of transfer,
  animate (full decoder), the baked rig (``Retargeter.bake``) and invert on an 11k-vertex target.
  Transfer and ``invert_no_neutral`` take the source frames as a user streaming them would: no ``source_neutral``,
  so each single-frame call finds its topology's operators in the Retargeter's source cache (filled
  by the warm-up call; ``Retargeter.source_topology``). The floor is
  linear blendshape evaluation (numpy, neutral + w·deltas) of the target's procedural rig, the peer
  the no-skinning ablation (``use_skinning=False``, the same config otherwise: timings do not
  depend on trained weights, so an untrained peer is used unless ``peer`` names a checkpoint). The
  other decoder (``model.decoder`` "mlp" or "basis", the same config otherwise, untrained) is timed
  the same way, with the warm preparation of the target (operators computed, no cache), so the
  table by decoder gives each decoder's per-frame and preparation cost.
  Invert is timed with the source's neutral, without it, and with analysis-by-synthesis
  (``refine=True``): the one-off bake of the source's rig, and what ``Retargeter.refine`` adds per
  frame once it is baked.
- ``train``: training samples/s of a config (``Trainer``, ``log_every`` 1, median over steps after
  the first). The pool is shrunk to 2 identities and validation to 1 so that target preparation,
  which real runs amortise over ``pool_refresh`` steps, is not timed.

Targets (``TARGETS``): prepare 11k ≤ 2 s, 100k ≤ 15 s, 1M ≤ 120 s at ≤ 8 GB; animate (full network)
(and transfer) ≥ 5 frames/s and baked rig ≥ 60 frames/s at 11k vertices; invert ≥ 10
frames/s; transfer ≥ 5 and invert ≥ 10 frames/s also per single-frame call; refine ≤ 20 ms a frame after the bake. Every network operation is also run once under cProfile; the markdown shows where the
time goes for each missed target.
"""
from __future__ import annotations

import copy
import csv
import dataclasses
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from .errors import RetargetError
from .mesh import Mesh
from .metrics import mse_mm2

LARGE = 200_000             # sizes above this are prepared once (minutes each)
BASE_MAX = 30_000           # largest tessellation; bigger heads are subdivided in (u, v)
PROFILE_TOP = 8             # functions reported when a target is missed
TARGETS = (  # (key, measured quantity, op, threshold, unit)
    ("prepare_11k_s", "prepare 11k vertices", "<=", 2.0, "s"),
    ("prepare_100k_s", "prepare 100k vertices", "<=", 15.0, "s"),
    ("prepare_1M_s", "prepare 1M vertices", "<=", 120.0, "s"),
    ("prepare_1M_peak_gb", "prepare 1M vertices: peak memory", "<=", 8.0, "GB"),
    ("transfer_fps", "transfer (full network), 11k", ">=", 5.0, "frames/s"),
    ("animate_fps", "animate (full network), 11k", ">=", 5.0, "frames/s"),
    ("baked_fps", "baked rig, 11k", ">=", 60.0, "frames/s"),
    ("invert_fps", "invert with the source neutral, 11k", ">=", 10.0, "frames/s"),
    ("transfer_call_fps", "transfer, one frame per call, 11k", ">=", 5.0, "frames/s"),
    ("invert_neutral_call_fps", "invert with the source neutral, one frame per call, 11k", ">=", 10.0,
     "frames/s"),
    ("invert_call_fps", "invert without the neutral, one frame per call, 11k", ">=", 10.0, "frames/s"),
    ("refine_added_ms", "refine (transfer's joint fit): added per frame after the bake, 11k", "<=",
     20.0, "ms"),
    ("refine_added_invert_ms", "refine (invert's fit of the weights): added per frame after the "
     "bake, 11k", "<=", 20.0, "ms"),
)
TARGETS_BY_KEY = {t[0]: t for t in TARGETS}
TARGET_SIZES = {"prepare_11k_s": 11_000, "prepare_100k_s": 100_000, "prepare_1M_s": 1_000_000}
FRAME_TARGET_SIZE = 11_000  # the per-frame targets hold for this target size
REFINE_STEPS = 10           # gradient steps on the free dims of z_GE timed beside the plain refine


# ------------------------------------------------------------------------------------- meshes
def procedural_head(n_vertices: int, identity_seed: int = 0) -> Mesh:
    """A procedural head (test identity ``identity_seed``) with about ``n_vertices`` vertices, cm.

    Up to ``BASE_MAX`` vertices: an adaptive tessellation of the (u, v) domain. Above: a smaller
    tessellation midpoint-subdivided in (u, v) (about 4× vertices per level, trimesh) and evaluated
    on the exact head surface, so large meshes are as smooth as small ones.
    """
    import trimesh

    from data_synth.head import surface
    from data_synth.identity import sample_identity
    from data_synth.tessellate import tessellate

    levels = 0
    while n_vertices / 4 ** levels > BASE_MAX:
        levels += 1
    tess = tessellate(n_vertices=max(100, round(n_vertices / 4 ** levels)), kind="adaptive")
    uv3, faces = np.c_[tess.uv, np.zeros(len(tess.uv))], tess.faces
    for _ in range(levels):
        uv3, faces = trimesh.remesh.subdivide(uv3, faces)
    verts = surface(uv3[:, :2], sample_identity(identity_seed, split="test"))
    return Mesh(verts, faces, f"procedural head {len(verts)} vertices")


# ------------------------------------------------------------------------------------- helpers
def median_time(fn, repeats: int) -> tuple[float, list[float]]:
    """(median, all) wall-clock seconds of ``repeats`` calls of ``fn()``."""
    times = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fn()
        _sync()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), times


def _sync():
    if torch.cuda.is_available():
        torch.cuda.synchronize()


def profile_call(fn, top: int = PROFILE_TOP) -> list[dict]:
    """Run ``fn()`` once under cProfile: the ``top`` functions by own time, as
    [{"function": "file:line(name)", "own_s", "cumulative_s"}]."""
    import cProfile
    import pstats

    prof = cProfile.Profile()
    prof.runcall(fn)
    stats = pstats.Stats(prof).stats
    rows = sorted(stats.items(), key=lambda kv: -kv[1][2])[:top]
    return [{"function": f[2] if f[0] == "~" else f"{Path(f[0]).name}:{f[1]}({f[2]})",
             "own_s": round(st[2], 4),
             "cumulative_s": round(st[3], 4)} for f, st in rows]


def peak_rss_mb() -> float:
    """Peak resident set of this process so far, MB (ru_maxrss is in KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def machine() -> dict:
    """Where the benchmark ran."""
    info = {"platform": platform.platform(), "python": platform.python_version(),
            "torch": torch.__version__, "cpu_count": os.cpu_count(),
            "torch_threads": torch.get_num_threads(),
            "omp_num_threads": os.environ.get("OMP_NUM_THREADS")}
    if torch.cuda.is_available():
        info["cuda_device"] = torch.cuda.get_device_name(0)
    return info


def devices(requested=None) -> list[str]:
    """The CPU, plus CUDA when present (or exactly ``requested``)."""
    if requested:
        if "cuda" in requested and not torch.cuda.is_available():
            raise RetargetError("--device cuda: no CUDA device is available")
        return list(requested)
    return ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


# ------------------------------------------------------------------------------------- prepare
def prepare_once(checkpoint, n_vertices: int, device: str, profile: bool = False) -> dict:
    """One cold ``Retargeter.prepare`` in this process (run it in a fresh one: see module doc)."""
    from .api import Retargeter

    mesh = procedural_head(n_vertices)
    with tempfile.TemporaryDirectory() as cache:
        r = Retargeter.load(checkpoint, device=device, cache_dir=cache)
        if device == "cuda":
            torch.cuda.reset_peak_memory_stats()
        before = peak_rss_mb()
        if profile:
            return {"n_vertices": mesh.n_vertices,
                    "profile_by_own_time": profile_call(lambda: r.prepare(mesh))}
        seconds, _ = median_time(lambda: r.prepare(mesh), 1)
        out = {"n_vertices": mesh.n_vertices, "seconds": seconds, "peak_rss_mb": peak_rss_mb(),
               "rss_increase_mb": peak_rss_mb() - before}
        if device == "cuda":
            out["cuda_peak_mb"] = torch.cuda.max_memory_allocated() / 2 ** 20
        return out


def _child(checkpoint, n_vertices: int, device: str, profile: bool = False) -> dict:
    cmd = [sys.executable, "-m", "retarget.bench", "prepare-child", str(checkpoint),
           str(n_vertices), device] + (["--profile"] if profile else [])
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RetargetError(f"bench: preparing {n_vertices:,} vertices on {device} failed:\n"
                            f"{proc.stderr.strip()[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def bench_prepare(checkpoint, sizes, device: str, repeats: int, progress=print) -> list[dict]:
    """Cold preparation time and peak memory per size (median of fresh processes)."""
    rows = []
    for n in sizes:
        runs = [_child(checkpoint, n, device) for _ in range(1 if n > LARGE else repeats)]
        row = {"n_vertices": runs[0]["n_vertices"], "runs": len(runs),
               "seconds": float(np.median([r["seconds"] for r in runs])),
               "seconds_all": [round(r["seconds"], 3) for r in runs],
               "peak_rss_mb": float(np.median([r["peak_rss_mb"] for r in runs])),
               "rss_increase_mb": float(np.median([r["rss_increase_mb"] for r in runs]))}
        if device == "cuda":
            row["cuda_peak_mb"] = float(np.median([r["cuda_peak_mb"] for r in runs]))
        limit = next((TARGETS_BY_KEY[k][3] for k, size in TARGET_SIZES.items()
                      if _near(row["n_vertices"], size)), None)
        if limit is not None and row["seconds"] > limit:
            row["profile_by_own_time"] = _child(checkpoint, n, device, profile=True)["profile_by_own_time"]
        progress(f"prepare {row['n_vertices']:,} vertices on {device}: {row['seconds']:.2f} s, "
                 f"peak {row['peak_rss_mb']:.0f} MB")
        rows.append(row)
    return rows


def _near(n: int, size: int) -> bool:
    """A generated head's vertex count stands for a nominal size within 5 % (tessellations land
    within a few per cent of the requested count; 10k and 11k stay apart)."""
    return abs(n - size) <= 0.05 * size


# ------------------------------------------------------------------------------------- frames
def throughput(fn, frames: int, repeats: int) -> float:
    """Frames per second of one batched call ``fn()`` over ``frames`` frames (median time)."""
    return frames / median_time(fn, repeats)[0]


def latency(fn_single, items, warmup: int = 1) -> float:
    """Median seconds of ``fn_single(item)`` over ``items`` (after ``warmup`` untimed calls)."""
    for item in items[:warmup]:
        fn_single(item)
    times = []
    for item in items:
        t0 = time.perf_counter()
        fn_single(item)
        _sync()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def _rate(fn_single, fn_batch, items, repeats: int) -> dict:
    lat = latency(fn_single, items)
    return {"latency_ms": 1000 * lat, "throughput_fps": throughput(fn_batch, len(items), repeats)}


def bench_network(r, target, frames, source_neutral, weights, repeats: int) -> dict:
    """Latency and throughput of transfer / animate / baked rig / invert with one Retargeter.

    frames: list of source meshes of one topology, given without a source neutral to transfer and
    invert_no_neutral (the source cache starts empty; the warm-up call fills it) and with
    ``source_neutral`` (their topology) to invert and invert_refine; weights (T,53).
    """
    w_list = list(weights)
    r.clear_source_cache()
    out = {
        "transfer": _rate(lambda f: r.transfer(f, target), lambda: r.transfer(frames, target),
                          frames, repeats),
        "animate": _rate(lambda w: r.animate(target, w), lambda: r.animate(target, weights),
                         w_list, repeats),
        "invert": _rate(lambda f: r.invert(f, source_neutral=source_neutral),
                        lambda: r.invert(frames, source_neutral=source_neutral), frames, repeats),
        "invert_no_neutral": _rate(r.invert, lambda: r.invert(frames), frames, repeats),
    }
    out["prepare_s"], _ = median_time(lambda: r.prepare(target.mesh), repeats)
    r._source_rigs.clear()                                  # a cold bake of the source's rig
    source_bake_s, _ = median_time(lambda: r.source_rig(source_neutral), 1)
    out["invert_refine"] = {
        **_rate(lambda f: r.invert(f, source_neutral=source_neutral, refine=True),
                lambda: r.invert(frames, source_neutral=source_neutral, refine=True), frames, repeats),
        "source_bake_s": source_bake_s}
    codes = [r.encode(f, source_neutral=source_neutral) for f in frames]  # refine's own cost:
    out["invert_refine"]["added_ms"] = 1000 * latency(                     # the fit, bake reused
        lambda i: r.refine(frames[i], source_neutral, codes[i]), list(range(len(frames))))
    out["invert_refine"]["added_invert_ms"] = 1000 * latency(              # invert's own fit
        lambda i: r.invert_fit(frames[i], source_neutral, codes[i]), list(range(len(frames))))
    if r.cfg.decoder == "mlp":   # and with gradient steps on the free dims (a basis decoder solves
        steps, r.refine_steps = r.refine_steps, REFINE_STEPS   # them in the plain refine already)
        out["invert_refine"][f"added_ms_{REFINE_STEPS}_steps"] = 1000 * latency(
            lambda i: r.refine(frames[i], source_neutral, codes[i]), list(range(len(frames))))
        r.refine_steps = steps
    # a take without its neutral: the neutral estimated from the frames (once per take)
    out["estimate_neutral_s"], _ = median_time(lambda: r.estimate_neutral(frames), 1)
    bake_s, _ = median_time(lambda: r.bake(target), 1)
    baked = r.bake(target)
    out["baked"] = {**_rate(baked.evaluate, lambda: baked.evaluate(weights), w_list, repeats),
                    "bake_s": bake_s,
                    # the linear blend of the 53 decoded shapes against the full decoder (cm target)
                    "vs_full_decoder_mse_mm2": mse_mm2(baked.evaluate(weights), r.animate(target, weights))}
    out["transfer"]["profile_by_own_time"] = profile_call(lambda: r.transfer(frames[0], target))
    out["animate"]["profile_by_own_time"] = profile_call(lambda: r.animate(target, weights[0]))
    out["invert"]["profile_by_own_time"] = profile_call(lambda: r.invert(frames[0]))
    return out


def bench_frames(checkpoint, device: str, n_vertices: int, n_frames: int, repeats: int,
                 peer=None) -> dict:
    """The per-frame section on a procedural target of ``n_vertices`` (see module doc)."""
    from data_synth.identity import sample_identity
    from data_synth.rig import build_rig
    from data_synth.sampling import sample_weights
    from data_synth.tessellate import tessellate

    from nets.model import NFSModel

    from .api import Retargeter

    net = Retargeter.load(checkpoint, device=device)
    if peer:
        peer_r = Retargeter.load(peer, device=device)
    else:
        torch.manual_seed(0)
        cfg = dataclasses.replace(net.cfg, use_skinning=False)
        peer_r = Retargeter(NFSModel(cfg), device=device)
    torch.manual_seed(0)
    other = "basis" if net.cfg.decoder == "mlp" else "mlp"
    other_r = Retargeter(NFSModel(dataclasses.replace(net.cfg, decoder=other)), device=device)
    tess = tessellate(n_vertices=n_vertices, kind="adaptive")
    rig_t = build_rig(sample_identity(0, split="test"), tess)       # target identity
    rig_s = build_rig(sample_identity(1, split="test"), tess)       # source identity
    weights = sample_weights(np.random.default_rng(0), n_frames, "mixed").astype(np.float32)
    source_neutral = Mesh(rig_s.neutral, rig_s.faces, "source")
    frames = [Mesh(f, rig_s.faces, "frame") for f in rig_s.evaluate(weights)]
    target_mesh = Mesh(rig_t.neutral, rig_t.faces, "target")
    out = {"n_vertices": len(rig_t.neutral), "frames": n_frames, "decoder": net.cfg.decoder,
           "other_decoder_name": other}
    for name, r in (("model", net), ("peer_no_skinning", peer_r), ("other_decoder", other_r)):
        target = r.prepare(target_mesh)
        out[name] = bench_network(r, target, frames, source_neutral, weights, repeats)
    out["floor_linear_blendshapes"] = _rate(rig_t.evaluate, lambda: rig_t.evaluate(weights),
                                            list(weights), repeats)
    return out


# ------------------------------------------------------------------------------------- training
#: The training-speed tricks of the sampling (issue "Sampling and speed"), each measured by undoing
#: it: (name, what changes without it, data-config overrides).
TRAIN_TRICKS = (
    ("operators and images cached", "a new identity and its two tessellations prepared every step "
     "(rig, operators, renders)", {"pool_size": 1, "pool_refresh": 1}),
    ("target encoded once for S sources", "one source per target: z_ID, z_Skin and the image code "
     "per sample", {"sources_per_target": 1}),
    ("decoding a random subset of faces", "every face and vertex of the target decoded",
     {"decode_faces": 0}),
)


def train_samples_per_s(cfg: dict, steps: int) -> tuple[float, str, int]:
    """(median samples/s over ``steps`` steps after the first, device, sources per step) of a
    training config (the pool is built before the timing, except what each step prepares)."""
    from .train import Trainer

    cfg = copy.deepcopy(cfg)
    cfg["train"].update(steps=steps + 1000, max_minutes=0, log_every=1, val_every=10 ** 9,
                        ckpt_minutes=10 ** 6)
    with tempfile.TemporaryDirectory() as out:
        trainer = Trainer(cfg, out, progress=False)
        trainer.run(stop_at=steps + 1)
        with open(Path(out) / "train_log.csv") as f:
            rates = [float(row["samples_per_s"]) for row in csv.DictReader(f)][1:]
    return float(np.median(rates)), str(trainer.device), cfg["data"]["sources_per_target"]


def bench_train(config, steps: int, tricks: bool = True) -> dict:
    """Training samples/s of a config (``retarget.train``; None = the built-in defaults) and, with
    ``tricks``, of the same config with each of ``TRAIN_TRICKS`` undone."""
    from .train import DEFAULTS, load_config, merge, model_cfg

    cfg = load_config(config) if config else merge(DEFAULTS, {}, "defaults")
    cfg["data"].update(pool_size=2, val_identities=1, val_expressions=1)
    rate, device, per_target = train_samples_per_s(cfg, steps)
    out = {"config": str(config or "retarget.train.DEFAULTS"), "device": device,
           "preset": model_cfg(cfg).to_dict(), "steps_timed": steps,
           "samples_per_target": per_target, "samples_per_s": rate, "without": []}
    for name, change, overrides in TRAIN_TRICKS if tricks else ():
        undone = copy.deepcopy(cfg)
        undone["data"].update(overrides)
        out["without"].append({"trick": name, "change": change,
                               "samples_per_s": train_samples_per_s(undone, steps)[0]})
    return out


# ------------------------------------------------------------------------------------- report
def check_targets(results: dict) -> list[dict]:
    """Each target of ``TARGETS`` that the results measure: measured value and whether it is met."""
    measured = {}
    for device, rows in results.get("prepare", {}).items():
        for row in rows:
            for key, size in TARGET_SIZES.items():
                if _near(row["n_vertices"], size):
                    measured[(key, device)] = row["seconds"]
                    if key == "prepare_1M_s":
                        measured[("prepare_1M_peak_gb", device)] = row["peak_rss_mb"] / 1024
    for device, fr in results.get("frames", {}).items():
        if not _near(fr["n_vertices"], FRAME_TARGET_SIZE):
            continue
        m = fr["model"]
        measured[("transfer_fps", device)] = m["transfer"]["throughput_fps"]
        measured[("animate_fps", device)] = m["animate"]["throughput_fps"]
        measured[("baked_fps", device)] = m["baked"]["throughput_fps"]
        measured[("invert_fps", device)] = m["invert"]["throughput_fps"]
        measured[("transfer_call_fps", device)] = 1000.0 / m["transfer"]["latency_ms"]
        measured[("invert_neutral_call_fps", device)] = 1000.0 / m["invert"]["latency_ms"]
        measured[("invert_call_fps", device)] = 1000.0 / m["invert_no_neutral"]["latency_ms"]
        if "invert_refine" in m:
            measured[("refine_added_ms", device)] = m["invert_refine"]["added_ms"]
            if "added_invert_ms" in m["invert_refine"]:
                measured[("refine_added_invert_ms", device)] = m["invert_refine"]["added_invert_ms"]
    out = []
    for key, what, op, limit, unit in TARGETS:
        for (k, device), value in measured.items():
            if k == key:
                ok = value <= limit if op == "<=" else value >= limit
                out.append({"target": key, "what": what, "device": device, "measured": value,
                            "op": op, "limit": limit, "unit": unit, "met": bool(ok)})
    return out


def _profile_table(what: str, profile: list[dict]) -> str:
    from .evaluate import fmt, md_table
    return (f"Where the time goes ({what}; cProfile, functions by own time):\n\n"
            + md_table(["function", "own s", "cumulative s"],
                       [[p["function"], fmt(p["own_s"]), fmt(p["cumulative_s"])] for p in profile]) + "\n")


def to_markdown(results: dict) -> str:
    """The benchmark as markdown tables."""
    from .evaluate import fmt, md_table

    out = [f"Machine: {results['machine']['platform']}, {results['machine']['cpu_count']} CPUs, "
           f"torch {results['machine']['torch']} ({results['machine']['torch_threads']} threads)"
           + (f", GPU {results['machine']['cuda_device']}" if "cuda_device" in results["machine"] else "")
           + ".\n"]
    for device, rows in results.get("prepare", {}).items():
        out.append(f"### Target preparation ({device}; cold: fresh process, empty operator cache)\n")
        header = ["vertices", "runs", "seconds (median)", "peak RSS (MB)", "RSS increase (MB)"]
        header += ["CUDA peak (MB)"] if device == "cuda" else []
        table = [[f"{r['n_vertices']:,}", r["runs"], fmt(r["seconds"]), f"{r['peak_rss_mb']:.0f}",
                  f"{r['rss_increase_mb']:.0f}"] + ([f"{r['cuda_peak_mb']:.0f}"] if device == "cuda" else [])
                 for r in rows]
        out.append(md_table(header, table) + "\n")
        for r in rows:
            if "profile_by_own_time" in r:
                out.append(_profile_table(f"prepare {r['n_vertices']:,} vertices", r["profile_by_own_time"]))
    for device, fr in results.get("frames", {}).items():
        out.append(f"### Per frame, {fr['n_vertices']:,}-vertex target ({device}; {fr['frames']} frames; "
                   f"per call = median single-frame call, batched = one call over all frames; "
                   f"sources without source_neutral)\n")
        rows = []
        floor = fr["floor_linear_blendshapes"]
        for op in ("transfer", "animate", "baked", "invert", "invert_no_neutral", "invert_refine"):
            if op not in fr["model"]:                       # results of an older version
                continue
            m, p = fr["model"][op], fr["peer_no_skinning"][op]
            rows.append([op, fmt(m["latency_ms"]), fmt(1000.0 / m["latency_ms"]),
                         fmt(m["throughput_fps"]), fmt(p["latency_ms"]), fmt(p["throughput_fps"]),
                         fmt(m["throughput_fps"] / p["throughput_fps"]),
                         fmt(m["throughput_fps"] / floor["throughput_fps"])])
        rows.append(["linear blendshapes (floor)", fmt(floor["latency_ms"]),
                     fmt(1000.0 / floor["latency_ms"]), fmt(floor["throughput_fps"]), "", "", "", "1"])
        out.append(md_table(["operation", "per call (ms)", "per call frames/s", "batched frames/s",
                             "peer per call (ms)", "peer batched frames/s", "÷ peer", "÷ floor"],
                            rows) + "\n")
        baked = fr["model"]["baked"]
        out.append(f"Baking the rig (53 decoded shapes): {fmt(baked['bake_s'])} s; the baked rig "
                   f"differs from the full decoder by an MSE of {fmt(baked['vs_full_decoder_mse_mm2'])} "
                   f"mm² on the same weights.\n")
        if "other_decoder" in fr:
            out.append(f"By decoder (the model's, {fr['decoder']}, and an untrained {fr['other_decoder_name']} "
                       "decoder of the same config; prepare = warm, operators recomputed):\n")
            out.append(md_table(
                ["decoder", "prepare (s)", "animate latency (ms)", "animate frames/s", "bake (s)",
                 "baked frames/s", "baked vs decoder (mm²)"],
                [[d, fmt(m["prepare_s"]), fmt(m["animate"]["latency_ms"]),
                  fmt(m["animate"]["throughput_fps"]), fmt(m["baked"]["bake_s"]),
                  fmt(m["baked"]["throughput_fps"]), fmt(m["baked"]["vs_full_decoder_mse_mm2"])]
                 for d, m in ((fr["decoder"], fr["model"]),
                              (fr["other_decoder_name"], fr["other_decoder"]))]) + "\n")
        if "invert_refine" in fr["model"]:
            ref = fr["model"]["invert_refine"]
            out.append(f"Inversion modes: invert = with the source neutral, invert_no_neutral = "
                       f"without, invert_refine = with it plus analysis-by-synthesis; baking the "
                       f"source's rig once: {fmt(ref['source_bake_s'])} s, then refine adds "
                       f"{fmt(ref['added_ms'])} ms a frame for transfer and "
                       f"{fmt(ref.get('added_invert_ms'))} ms for invert (median of Retargeter.refine alone"
                       + ("; transfer solves the weights and the free dims together, exactly, on "
                          "the basis decoder's rig, invert the weights alone)."
                          if fr["decoder"] == "basis" else
                          f"), {fmt(ref.get(f'added_ms_{REFINE_STEPS}_steps'))} ms with "
                          f"{REFINE_STEPS} gradient steps on the free dims.") + "\n")
        if "estimate_neutral_s" in fr["model"]:
            out.append(f"A take without its neutral (`--estimate-neutral`): estimating the neutral "
                       f"from the {fr['frames']} frames takes {fmt(fr['model']['estimate_neutral_s'])} s "
                       f"once, then the frames cost what invert_refine's do.\n")
        missed = {t["target"] for t in results.get("targets", []) if t["device"] == device and not t["met"]}
        for op in [op for op in ("transfer", "animate", "invert")
                   if {f"{op}_fps", f"{op}_call_fps"} & missed]:
            out.append(_profile_table(f"{op}, one frame", fr["model"][op]["profile_by_own_time"]))
    if "train" in results:
        t = results["train"]
        out.append(f"### Training ({t['device']}, {t['config']})\n\n{fmt(t['samples_per_s'])} samples/s "
                   f"(median over {t['steps_timed']} steps of {t['samples_per_target']} sources each).\n")
        if t.get("without"):
            out.append("Each speed trick of the sampling, measured by undoing it (same config "
                       "otherwise, median samples/s):\n\n" + md_table(
                           ["trick", "without it", "samples/s without", "speed-up"],
                           [[w["trick"], w["change"], fmt(w["samples_per_s"]),
                             f"{t['samples_per_s'] / w['samples_per_s']:.2f}x"] for w in t["without"]])
                       + "\n")
    if results.get("targets"):
        out.append("### Targets\n")
        out.append(md_table(["target", "device", "measured", "limit", "met"],
                            [[t["what"], t["device"], f"{fmt(t['measured'])} {t['unit']}",
                              f"{t['op']} {t['limit']:g} {t['unit']}", "yes" if t["met"] else "**no**"]
                             for t in results["targets"]]) + "\n")
    return "\n".join(out)


def run_bench(checkpoint, sizes, n_vertices: int = 11_000, n_frames: int = 20, repeats: int = 3,
              train_config=None, train_steps: int = 10, peer=None, device_list=None,
              sections=("prepare", "frames", "train"), progress=print) -> dict:
    """All sections; returns the results dict (``to_markdown`` renders it)."""
    results = {"machine": machine(), "checkpoint": str(checkpoint), "repeats": repeats}
    for device in devices(device_list):
        if "prepare" in sections:
            all_sizes = sorted(set(sizes) | {n_vertices})
            results.setdefault("prepare", {})[device] = bench_prepare(checkpoint, all_sizes, device,
                                                                      repeats, progress)
        if "frames" in sections:
            results.setdefault("frames", {})[device] = bench_frames(checkpoint, device, n_vertices,
                                                                    n_frames, repeats, peer)
            progress(f"per-frame section on {device} done")
    if "train" in sections:
        results["train"] = bench_train(train_config, train_steps)
    results["targets"] = check_targets(results)
    return results


def _main(argv) -> int:
    """``python -m retarget.bench prepare-child CKPT N DEVICE [--profile]``: one cold preparation,
    printed as one JSON line (used by ``bench_prepare``)."""
    if len(argv) < 4 or argv[0] != "prepare-child":
        print(_main.__doc__, file=sys.stderr)
        return 2
    print(json.dumps(prepare_once(argv[1], int(argv[2]), argv[3], "--profile" in argv)))
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
