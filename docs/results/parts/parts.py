"""Heads with eyes and teeth: the bundled model on heads given with separate parts (eyeballs and a
teeth arch beside the skin), face alone (the default) against the whole mesh (``--all-parts``),
beside doing nothing and closest-point transfer (docs/RESULTS.md, "Heads with eyes and teeth").

Cases (24 frames of the eval's mixed sampler, seed 7, ARKit weights of the artist's rig):
- self: the artist's ARKit head (``makehuman_arkit.npz``) driven by the weights, transferred onto
  itself given with parts; the source frames carry the same parts, unmoved;
- cross: the same frames onto three realistic test heads (``sample_head_identity(s, "test")``,
  head and neck, decimated to 4,000 vertices) given with parts; ground truth: each head's own rig
  (the artist's shapes carried by deformation transfer) driven by the same weights;
- invert: the ARKit frames with parts as the source, weights against the true ones.
Errors are on the skin only (plain MSE, mm²); "parts moved" is the largest displacement of a
part's vertex (mm; they are still in the ground truth). Modes: no neutral, neutral, neutral +
refine. The parts: two eyeballs (radius 1.2 cm, 642 vertices each) behind the lid openings and a
teeth arch (96 vertices) behind the lips, placed on each head by its own eye and mouth corners.

    OMP_NUM_THREADS=2 python docs/results/parts/parts.py > docs/results/parts/parts.md
"""
from __future__ import annotations

import numpy as np
import trimesh

from data_synth.facs import N_FACS
from data_synth.makehuman import (assets, base_head_rig, build_head_rig, head_tessellation,
                                  sample_head_identity)
from data_synth.makehuman.segmentation import EYE, MOUTH
from data_synth.sampling import sample_weights
from retarget.api import Retargeter
from retarget.evaluate import RealRig, arkit_ict_matrix, ict_to_arkit_weights
from retarget.mesh import Mesh
from retarget.oracle import closest_point_transfer

FRAMES, SEED, HEADS = 24, 7, (0, 1, 2)
MODES = (("no neutral", {}), ("neutral", {"neutral": True}),
         ("neutral + refine", {"neutral": True, "refine": True}))


def parts_at(eye_l: np.ndarray, eye_r: np.ndarray, mouth: np.ndarray):
    """(vertices (P,3), faces) of two eyeballs 1.15 cm behind the given lid-opening centres and a
    teeth arch 1 cm behind the given mouth centre (cm, the head's frame)."""
    vs, fs, n = [], [], 0
    for c in (eye_l, eye_r):
        s = trimesh.creation.icosphere(subdivisions=3, radius=1.2)
        vs.append(s.vertices + c - [0.0, 0.0, 1.15])
        fs.append(s.faces + n)
        n += len(s.vertices)
    ang = np.linspace(-1.1, 1.1, 24)
    radius = 2.6
    rows = [np.c_[r * np.sin(ang), np.full_like(ang, mouth[1] + dy), mouth[2] - 1.0 - radius + r * np.cos(ang)]
            for dy in (-0.5, 0.5) for r in (radius, radius - 0.4)]
    k = len(ang)
    f = [[a * k + i, b * k + i, a * k + i + 1] for a, b in ((0, 1), (2, 3), (0, 2), (1, 3)) for i in range(k - 1)]
    f += [[b * k + i, b * k + i + 1, a * k + i + 1] for a, b in ((0, 1), (2, 3), (0, 2), (1, 3)) for i in range(k - 1)]
    vs.append(np.concatenate(rows))
    fs.append(np.asarray(f) + n)
    return np.concatenate(vs), np.concatenate(fs)


def landmarks(base_neutral: np.ndarray):
    """The eye and mouth centres of a MakeHuman head (its base vertices (4326+,3) cm): the base
    head's (``segmentation.EYE``, ``MOUTH``) moved as the 8 nearest base vertices moved."""
    base = assets.heads()["full_neutral"]
    out = []
    for p in (EYE, EYE * [-1, 1, 1], MOUTH):
        near = np.argsort(np.linalg.norm(base - p, axis=1))[:8]
        out.append(p + (base_neutral[near] - base[near]).mean(0))
    return out


def test_heads(w53: np.ndarray):
    """Yield (seed, base rig, rig, weights) for each of the ``HEADS`` realistic test heads: the
    identity's base rig (ARKit shapes as authored), its head-and-neck rig decimated to 4,000
    vertices, and ``w53`` (T,53) with the shapes that rig lacks set to 0."""
    for s in HEADS:
        base = base_head_rig(sample_head_identity(s, "test"), "arkit")
        rig = build_head_rig(base, head_tessellation(seed=s, n_vertices=4000, kind="decimated",
                                                     crop="head_neck"), 20)
        w = w53.copy()
        w[:, ~rig.present] = 0.0
        yield s, base, rig, w


def crop_heads(split: str, seeds, make_parts, assemble):
    """Yield (name, mesh, part indices) for the ``split`` heads ``seeds`` in every crop (decimated to
    4,000 vertices), each given ``make_parts(*landmarks)`` by ``assemble(neutral, faces, parts)``."""
    from data_synth.makehuman.tessellate import CROPS

    for s in seeds:
        base = base_head_rig(sample_head_identity(s, split), "arkit")
        parts = make_parts(*landmarks(base.neutral))
        for crop in CROPS:
            rig = build_head_rig(base, head_tessellation(seed=s, n_vertices=4000, kind="decimated",
                                                         crop=crop), 20)
            mesh, idx = assemble(rig.neutral, rig.faces, parts)
            yield f"head {s} {crop}", mesh, idx


def add(neutral: np.ndarray, faces: np.ndarray, parts) -> Mesh:
    pv, pf = parts
    return Mesh(np.concatenate([neutral, pv]), np.concatenate([faces, pf + len(neutral)]))


def run():
    real = RealRig.load("../shared/rigs/makehuman_arkit.npz")
    m = arkit_ict_matrix(real.names)
    w53 = sample_weights(np.random.default_rng(SEED), FRAMES, mode="mixed").astype(np.float32)
    a = ict_to_arkit_weights(w53, m).astype(np.float32)
    src = real.evaluate(a)                                            # (T, V, 3) skin frames
    arkit_parts = parts_at(EYE, EYE * [-1, 1, 1], MOUTH)
    cases = [("self: ARKit head", real.neutral, real.faces, src, arkit_parts)]
    for s, base, rig, w in test_heads(w53):
        cases.append((f"cross: test head {s}", rig.neutral, rig.faces, rig.evaluate(w),
                      parts_at(*landmarks(base.neutral))))
    src_neutral = add(real.neutral, real.faces, arkit_parts)
    src_frames = [add(f, real.faces, arkit_parts) for f in src]
    # eyeballs kept at rest (turn_eyes=False): these source frames' eyeballs do not turn with their
    # looks, and the study is of the face alone (eyes.py studies the eyes' turn)
    nets = {"face alone (default)": Retargeter.load(None, turn_eyes=False),
            "whole mesh (--all-parts)": Retargeter.load(None, face_only=False, turn_eyes=False)}
    lines = ["| case | method | no neutral | neutral | neutral + refine |", "| --- | --- | ---: | ---: | ---: |"]

    def skin_mse(pred, gt):
        return float((((np.asarray(pred)[:, :len(gt[0])] - gt) * 10) ** 2).sum(-1).mean())

    for name, neutral, faces, gt, parts in cases:
        v = len(neutral)
        tgt = add(neutral, faces, parts)
        nothing = skin_mse(np.broadcast_to(neutral, gt.shape), gt)
        cp = closest_point_transfer(real.neutral, real.faces, src, neutral, faces)
        lines.append(f"| {name} | do nothing | {nothing:.3f} | | |")
        lines.append(f"| {name} | closest point (skin alone) | | {skin_mse(cp, gt):.3f} | |")
        for label, r in nets.items():
            cells = []
            for _, kw in MODES:
                out = r.transfer(src_frames, tgt, source_neutral=src_neutral if kw.get("neutral") else None,
                                 refine=kw.get("refine", False))
                moved = 10 * float(np.abs(out[:, v:] - tgt.vertices[v:]).max())
                cells.append(f"{skin_mse(out, gt):.3f} (parts moved {moved:.1f} mm)")
            lines.append(f"| {name} | {label} | " + " | ".join(cells) + " |")
        print(name, flush=True, file=__import__("sys").stderr)
    used = m.sum(1) > 0
    lines.append(f"| invert: ARKit frames with parts (weight MAE) | predicting 0 | {float(np.abs(a[:, used]).mean()):.4f} | | |")
    for label, r in nets.items():
        cells = []
        for _, kw in MODES:
            w = r.invert(src_frames, source_neutral=src_neutral if kw.get("neutral") else None,
                         refine=kw.get("refine", False))
            cells.append(f"{float(np.abs(ict_to_arkit_weights(w, m) - a)[:, used].mean()):.4f}")
        lines.append(f"| invert: ARKit frames with parts (weight MAE) | {label} | " + " | ".join(cells) + " |")
    print("\n".join(lines))


if __name__ == "__main__":
    assert N_FACS == 53
    run()
