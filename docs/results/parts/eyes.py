"""Eyeballs that turn with the gaze (docs/RESULTS.md, "Eyeballs that turn with the gaze").

The artist's ARKit head driven by two takes of 24 frames (seed 7): the eval's mixed weights, and
gazes alone (both eyes one way, each axis uniform over a look's range), transferred onto itself and
onto the first realistic test head of ``jaw.py``, each head given two eyeballs, upper and lower
teeth, a tongue and, over each eye, a lash strip (separate parts placed by its own landmarks).

Ground truth: each head's eyeballs turned about their centres by the gaze of the frame's true
weights (``retarget.eyes.gaze_from_weights``: a look at weight 1 turns the eye by ``GAZE_DEGREES``,
a convention, the only definition of a look's turn the project has; the artist's shapes move the
lids alone). The source is the ARKit head's frames either with its eyeballs turned so ("source
with eyeballs") or as the skin alone ("source without eyeballs": the gaze then comes from the
look weights the network reads off the lids); with eyeballs also without a neutral (the gaze then
measured against the take's median) and with the neutral ``estimate_neutral`` makes. Errors: the angle between an eye's true and drawn
pupil direction (degrees) and the mean distance of the eyeballs' vertices from their true place
(mm), over both eyes and all frames; "at rest" is what ``--still-parts`` (and the tool before)
does. Then invert's eight look weights (mean absolute error; the gaze they turn to against the
true one, degrees per axis; the other 45 weights), how often ``Retargeter.eyes`` finds
exactly the two eyeballs on 20 validation and 20 test heads in each crop, and the cost.

    OMP_NUM_THREADS=2 python docs/results/parts/eyes.py > docs/results/parts/eyes.md
"""
from __future__ import annotations

import sys
import time

import numpy as np
import trimesh

from data_synth.makehuman.segmentation import EYE, MOUTH
from data_synth.sampling import sample_weights
from retarget.api import Retargeter
from retarget.evaluate import RealRig, arkit_ict_matrix, ict_to_arkit_weights
from retarget.eyes import LOOK_INDEX, gaze_from_weights, gaze_rotation
from retarget.mesh import Mesh

sys.path.insert(0, "docs/results/parts")
from jaw import arch  # noqa: E402
from parts import FRAMES, SEED, crop_heads, landmarks, test_heads  # noqa: E402

EYE_BACK, EYE_RADIUS = 1.15, 1.2       # cm: an eyeball's centre behind the lid opening, its radius
PARTS = ("left eye", "right eye", "upper teeth", "lower teeth", "tongue", "left lashes", "right lashes")


def lashes(eye: np.ndarray):
    """A lash strip (a thin curved band, 2.4 cm wide) along the upper lid of the eye at ``eye``."""
    ang = np.linspace(-0.6, 0.6, 12)
    rows = [np.c_[eye[0] + 1.4 * np.sin(ang), np.full_like(ang, eye[1] + 0.55 + dy),
                  eye[2] - 1.0 + 1.4 * np.cos(ang) + dz] for dy, dz in ((0.0, 0.0), (0.15, 0.35))]
    k = len(ang)
    f = [[i, k + i, i + 1] for i in range(k - 1)] + [[k + i, k + i + 1, i + 1] for i in range(k - 1)]
    return np.concatenate(rows), np.asarray(f)


def head_parts(eye_l, eye_r, mouth):
    """[(vertices, faces)] of PARTS, placed by the lid openings' and the mouth's centres (cm)."""
    out = []
    for c in (eye_l, eye_r):
        s = trimesh.creation.icosphere(subdivisions=3, radius=EYE_RADIUS)
        out.append((np.asarray(s.vertices) + c - [0.0, 0.0, EYE_BACK], np.asarray(s.faces)))
    t = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    tongue = (np.asarray(t.vertices) * [1.6, 0.45, 2.0] + [0.0, mouth[1] - 0.8, mouth[2] - 3.2], t.faces)
    return out + [arch(mouth, 0.5), arch(mouth, -0.5), tongue, lashes(eye_l), lashes(eye_r)]


def assemble(neutral, faces, parts):
    """The head with its parts: (Mesh, {part name: vertex indices})."""
    vs, fs, idx, n = [neutral], [faces], {}, len(neutral)
    for name, (pv, pf) in zip(PARTS, parts):
        vs.append(pv)
        fs.append(np.asarray(pf) + n)
        idx[name] = np.arange(n, n + len(pv))
        n += len(pv)
    return Mesh(np.concatenate(vs), np.concatenate(fs)), idx


def turned(vertices, idx, gaze):
    """vertices (V,3) with the two eyeballs (idx) turned to gaze (2,2) about their centres (the
    heads face +z upright, so their canonical frame's axes are the mesh's)."""
    out = np.array(vertices, np.float64, copy=True)
    for e, name in enumerate(PARTS[:2]):
        v = vertices[idx[name]]
        centre = v.mean(0)
        out[idx[name]] = (v - centre) @ gaze_rotation(*gaze[e]).T + centre
    return out


def errors(pred, truth, rest, idx):
    """(mean pupil angle (degrees), mean eyeball vertex distance (mm)) of predicted frames
    (T,V,3) against the true ones, over both eyes."""
    angles, dists = [], []
    for name in PARTS[:2]:
        i = idx[name]
        front = i[np.argmax(rest[i, 2])]
        for p, t in zip(pred, truth):
            a, b = p[front] - p[i].mean(0), t[front] - t[i].mean(0)
            angles.append(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))
            dists.append(10 * np.linalg.norm(p[i] - t[i], axis=1).mean())
    return float(np.mean(angles)), float(np.mean(dists))


def gaze_weights(rng, n: int) -> np.ndarray:
    """(n,53) FACS weights of gazes alone: both eyes one way, each axis U(−1, 1) of a look's range."""
    yaw, pitch = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    w = np.zeros((n, 53), np.float32)
    for eye in range(2):
        w[:, LOOK_INDEX[eye, 0]], w[:, LOOK_INDEX[eye, 1]] = np.maximum(yaw, 0), np.maximum(-yaw, 0)
        w[:, LOOK_INDEX[eye, 2]], w[:, LOOK_INDEX[eye, 3]] = np.maximum(pitch, 0), np.maximum(-pitch, 0)
    return w


def run():
    real = RealRig.load("../shared/rigs/makehuman_arkit.npz")
    to_arkit = arkit_ict_matrix(real.names)
    takes = {"mixed (the eval's)": sample_weights(np.random.default_rng(SEED), FRAMES, mode="mixed"),
             "gaze alone": gaze_weights(np.random.default_rng(SEED), FRAMES)}
    src_parts = head_parts(EYE, EYE * [-1, 1, 1], MOUTH)
    src_mesh, src_idx = assemble(real.neutral, real.faces, src_parts)
    n_src = len(real.neutral)
    skin_neutral = Mesh(real.neutral, real.faces)
    targets = [("ARKit head", real.neutral, real.faces, src_parts)]
    for s, base, rig, _ in test_heads(np.zeros((1, 53), np.float32)):
        targets.append((f"test head {s}", rig.neutral, rig.faces, head_parts(*landmarks(base.neutral))))
        break
    r, still = Retargeter.load(None), Retargeter.load(None, turn_eyes=False)
    table = ["| weights | target | path | eyes found | pupil angle (degrees) | eyeball vertices (mm) |",
             "| --- | --- | --- | --- | ---: | ---: |"]
    inv = ["| weights | source, mode | look weights' MAE | gaze error (degrees) | other weights' MAE |",
           "| --- | --- | ---: | ---: | ---: |"]
    looks, others = LOOK_INDEX.ravel(), np.setdiff1d(np.arange(53), LOOK_INDEX.ravel())
    for take, w53 in takes.items():
        w53 = w53.astype(np.float32)
        gaze = gaze_from_weights(w53)
        src = real.evaluate(ict_to_arkit_weights(w53, to_arkit).astype(np.float32))
        with_eyes = [Mesh(turned(np.concatenate([f, src_mesh.vertices[n_src:]]), src_idx, g), src_mesh.faces)
                     for f, g in zip(src, gaze)]
        skin = [Mesh(f, real.faces) for f in src]
        estimated = r.estimate_neutral(with_eyes)
        for name, neutral, faces, parts in targets:
            mesh, idx = assemble(neutral, faces, parts)
            rest = mesh.vertices
            truth = np.stack([turned(rest, idx, g) for g in gaze])
            eyes = r.eyes(mesh)
            found = eyes is not None and [list(v) for v in eyes.vertices] == [list(idx[p]) for p in PARTS[:2]]
            paths = {
                "at rest (--still-parts)": lambda: still.animate(mesh, w53),
                "transfer, source without eyeballs, no neutral": lambda: r.transfer(skin, mesh),
                "transfer, source without eyeballs, neutral":
                    lambda: r.transfer(skin, mesh, source_neutral=skin_neutral),
                "transfer, source without eyeballs, neutral + refine":
                    lambda: r.transfer(skin, mesh, source_neutral=skin_neutral, refine=True),
                "transfer, source with eyeballs, no neutral (against the take's median gaze)":
                    lambda: r.transfer(with_eyes, mesh),
                "transfer, source with eyeballs, estimated neutral + refine":
                    lambda: r.transfer(with_eyes, mesh, source_neutral=estimated, refine=True),
                "transfer, source with eyeballs, neutral + refine":
                    lambda: r.transfer(with_eyes, mesh, source_neutral=src_mesh, refine=True),
                "animate (true weights)": lambda: r.animate(mesh, w53),
                "baked rig (export-rig)": lambda: r.bake(mesh).evaluate(w53),
            }
            for label, run_path in paths.items():
                angle, dist = errors(run_path(), truth, rest, idx)
                table.append(f"| {take} | {name} | {label} | {'yes' if found else 'NO'} | {angle:.2f} | {dist:.2f} |")
            print(take, name, file=sys.stderr, flush=True)
        zero = np.zeros_like(w53)
        rows = [("predicting 0", zero)]
        for label, frames, neutral in (("without eyeballs", skin, skin_neutral),
                                       ("with eyeballs", with_eyes, src_mesh)):
            for mode, kw in (("neutral", {}), ("neutral + refine", {"refine": True})):
                rows.append((f"{label}, {mode}", r.invert(frames, source_neutral=neutral, **kw)))
        rows.append(("with eyeballs, no neutral", r.invert(with_eyes)))
        for label, w in rows:
            turn = np.degrees(np.abs(gaze_from_weights(w) - gaze)).mean()
            inv.append(f"| {take} | {label} | {np.abs(w[:, looks] - w53[:, looks]).mean():.4f} | {turn:.2f} | "
                       f"{np.abs(w[:, others] - w53[:, others]).mean():.4f} |")
    print("\n".join(table))
    print()
    print("\n".join(inv))
    print()
    print(found_on("val", range(20)))
    print(found_on("test", range(20)))
    print(closed_head())
    print()
    print(cost(targets[0], with_eyes))


def found_on(split: str, seeds) -> str:
    """How often ``Retargeter.eyes`` finds exactly the two eyeballs (nothing else) on the ``split``
    heads ``seeds`` in every crop (decimated to 4,000 vertices), each given PARTS by its landmarks."""
    r = Retargeter.load(None)
    wrong, total = [], 0
    for name, mesh, idx in crop_heads(split, seeds, head_parts, assemble):
        eyes = r.eyes(mesh)
        total += 1
        if eyes is None or [list(v) for v in eyes.vertices] != [list(idx[p]) for p in PARTS[:2]]:
            wrong.append(f"{name}: " + ("none" if eyes is None else
                         ", ".join(p for p in PARTS if np.isin(idx[p], np.concatenate(eyes.vertices)).any())))
    return (f"{split} heads {min(seeds)}-{max(seeds)}: exactly the two eyeballs found on "
            f"{total - len(wrong)} of {total} head crops" + (f" (wrong: {'; '.join(wrong)})" if wrong else ""))


def closed_head() -> str:
    """What ``Retargeter.eyes`` finds on the closed MakeHuman head (``full_neutral``: the skin with
    its mouth cavity and eye sockets, one part) given PARTS."""
    rig = np.load("../shared/rigs/makehuman_arkit.npz")
    mesh, idx = assemble(rig["full_neutral"], rig["full_faces"], head_parts(EYE, EYE * [-1, 1, 1], MOUTH))
    eyes = Retargeter.load(None).eyes(mesh)
    ok = eyes is not None and [list(v) for v in eyes.vertices] == [list(idx[p]) for p in PARTS[:2]]
    return (f"closed MakeHuman head ({len(rig['full_neutral']):,} vertices with its mouth cavity and eye "
            f"sockets): {'exactly the two eyeballs found' if ok else 'NOT the two eyeballs'}")


def cost(case, frames, repeats: int = 20) -> str:
    """The time to find a target's eyes (once per target, after ``prepare``), to turn them in one
    frame, and to measure a source frame's gaze, on the first target (seconds; median of ``repeats``)."""
    _, neutral, faces, parts = case
    mesh, _ = assemble(neutral, faces, parts)
    finds, poses, measures = [], [], []
    for _ in range(repeats):
        r = Retargeter.load(None)
        target = r.prepare(mesh)
        t0 = time.perf_counter()
        eyes = r.eyes(target)
        finds.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        eyes.pose(mesh.vertices, np.full((2, 2), 0.2))
        poses.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        eyes.measure(frames[0].vertices)
        measures.append(time.perf_counter() - t0)
    return (f"{mesh.n_vertices:,} vertices: finding the eyes {1e3 * np.median(finds):.0f} ms once per "
            f"target; turning them {1e3 * np.median(poses):.2f} ms a frame; measuring a source frame's "
            f"gaze {1e3 * np.median(measures):.2f} ms (median of {repeats})")


if __name__ == "__main__":
    run()
