"""Lower teeth and a tongue carried by the jaw (docs/RESULTS.md, "Heads with eyes and teeth").

The cases of ``parts.py`` (the artist's ARKit head onto itself and onto three realistic test
heads, 24 frames of the eval's mixed weights, seed 7), each target given four separate parts:
two eyeballs, an upper and a lower teeth arch (96 vertices each) behind the lips, and a tongue
(162 vertices) on the floor of the mouth, placed by the head's own eye and mouth landmarks.

Ground truth for the parts the jaw carries (lower teeth, tongue): their rest positions moved by the
jaw's rigid motion in each true frame (the target's own rig driven by the weights), fitted on the
true rig's chin (``retarget.jaw.chin_vertices`` of its jawOpen and mouth shapes); the other parts
stay at rest. Errors: mean distance of a part's vertices from their true place (mm), for the parts
left at rest (``--still-parts``, what the tool did before) and carried (the default), with the
neutral and refine (transfer), driven from the true weights (animate) and through the baked
53-shape rig (``export-rig``); "parts given to the jaw" says which parts ``jaw_parts`` gave it.
Then how often it gives the jaw exactly the lower teeth and the tongue on 20 validation heads in
each crop (face, head, head and neck, bust) for each candidate of ``retarget.jaw.LIFT`` (the one
kept was chosen there), on 20 test heads with the kept one, and what finding and carrying them
costs.

    OMP_NUM_THREADS=2 python docs/results/parts/jaw.py > docs/results/parts/jaw.md
"""
from __future__ import annotations

import sys

import numpy as np
import trimesh

from data_synth.facs import FACS_INDEX, FACS_NAMES
from data_synth.makehuman.expressions import base_arkit_ict
from data_synth.makehuman.segmentation import EYE, MOUTH
from data_synth.sampling import sample_weights
from retarget.api import Retargeter
from retarget.evaluate import RealRig, arkit_ict_matrix, ict_to_arkit_weights
from retarget.jaw import MOUTH as MOUTH_SHAPES, JawParts, chin_vertices
from retarget.mesh import Mesh

sys.path.insert(0, "docs/results/parts")
from parts import FRAMES, SEED, crop_heads, landmarks, test_heads  # noqa: E402

PARTS = ("eyes", "upper teeth", "lower teeth", "tongue")
CARRIED = ("lower teeth", "tongue")


def arch(mouth: np.ndarray, dy: float, radius: float = 2.6):
    """A teeth arch (96 vertices, 0.7 cm tall) 1 cm behind the mouth centre, dy cm above it."""
    ang = np.linspace(-1.1, 1.1, 24)
    rows = [np.c_[r * np.sin(ang), np.full_like(ang, mouth[1] + dy + h),
                  mouth[2] - 1.0 - radius + r * np.cos(ang)]
            for h in (-0.35, 0.35) for r in (radius, radius - 0.4)]
    k = len(ang)
    pairs = ((0, 1), (2, 3), (0, 2), (1, 3))
    f = [[a * k + i, b * k + i, a * k + i + 1] for a, b in pairs for i in range(k - 1)]
    f += [[b * k + i, b * k + i + 1, a * k + i + 1] for a, b in pairs for i in range(k - 1)]
    return np.concatenate(rows), np.asarray(f)


def head_parts(eye_l, eye_r, mouth):
    """[(vertices, faces)] of PARTS: eyeballs as parts.py places them, the arches 0.5 cm above and
    below the mouth centre, a flattened tongue 0.8 cm below it and 3.2 cm behind."""
    eyes = []
    for c in (eye_l, eye_r):
        s = trimesh.creation.icosphere(subdivisions=3, radius=1.2)
        eyes.append((s.vertices + c - [0.0, 0.0, 1.15], s.faces))
    ev = np.concatenate([e[0] for e in eyes])
    ef = np.concatenate([eyes[0][1], eyes[1][1] + len(eyes[0][0])])
    t = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    tongue = (t.vertices * [1.6, 0.45, 2.0] + [0.0, mouth[1] - 0.8, mouth[2] - 3.2], t.faces)
    return [(ev, ef), arch(mouth, 0.5), arch(mouth, -0.5), tongue]


def assemble(neutral, faces, parts):
    """The head with its parts: (Mesh, {part name: vertex indices})."""
    vs, fs, idx, n = [neutral], [faces], {}, len(neutral)
    for name, (pv, pf) in zip(PARTS, parts):
        vs.append(pv)
        fs.append(pf + n)
        idx[name] = np.arange(n, n + len(pv))
        n += len(pv)
    return Mesh(np.concatenate(vs), np.concatenate(fs)), idx


def true_parts(frames, neutral, chin, mesh, idx):
    """The parts' true places in each frame (T, P, 3) for P = every part vertex, in mesh order:
    CARRIED moved by the true chin's motion (``JawParts.carry`` with the true rig's chin)."""
    v = len(neutral)
    truth = JawParts(np.asarray(mesh.vertices, np.float64), np.arange(v), chin,
                     np.sort(np.concatenate([idx[n] for n in CARRIED])), len(CARRIED))
    return np.stack([truth.carry(np.concatenate([f, mesh.vertices[v:]]))[v:] for f in frames])


def run():
    real = RealRig.load("../shared/rigs/makehuman_arkit.npz")
    m = arkit_ict_matrix(real.names)
    w53 = sample_weights(np.random.default_rng(SEED), FRAMES, mode="mixed").astype(np.float32)
    a = ict_to_arkit_weights(w53, m).astype(np.float32)
    src = real.evaluate(a)
    mouth_idx = [FACS_INDEX[n] for n in MOUTH_SHAPES]
    ict, _ = base_arkit_ict()
    skin = len(real.neutral)
    cases = [("ARKit head onto itself", real.neutral, real.faces, src, w53,
              chin_vertices(ict[FACS_INDEX["jawOpen"], :skin], ict[mouth_idx, :skin]),
              head_parts(EYE, EYE * [-1, 1, 1], MOUTH))]
    for s, base, rig, w in test_heads(w53):
        cases.append((f"ARKit head onto test head {s}", rig.neutral, rig.faces, rig.evaluate(w), w,
                      chin_vertices(rig.deltas[FACS_INDEX["jawOpen"]], rig.deltas[mouth_idx]),
                      head_parts(*landmarks(base.neutral))))
    src_neutral = Mesh(real.neutral, real.faces)
    src_frames = [Mesh(f, real.faces) for f in src]
    # eyeballs kept at rest (turn_eyes=False): the ground truth here leaves them so (eyes.py studies them)
    carry, still = Retargeter.load(None, turn_eyes=False), Retargeter.load(None, carry_jaw=False, turn_eyes=False)
    head = ("| case | parts given to the jaw | path | " + " | ".join(
        f"{p}: at rest / carried (mm)" for p in PARTS) + " | skin MSE (mm²), at rest / carried |")
    lines = [head, "| --- | --- | --- |" + " ---: |" * (len(PARTS) + 1)]
    for name, neutral, faces, gt, w, chin, parts in cases:
        mesh, idx = assemble(neutral, faces, parts)
        v = len(neutral)
        truth = true_parts(gt, neutral, chin, mesh, idx)
        jaw = carry.jaw_parts(carry.prepare(mesh))
        given = [p for p in PARTS if jaw is not None and np.isin(idx[p], jaw.carried).all()]
        paths = {
            "transfer, neutral + refine": lambda r: r.transfer(src_frames, mesh, source_neutral=src_neutral,
                                                               refine=True),
            "animate (true weights)": lambda r: r.animate(mesh, w),
            "baked rig (export-rig)": lambda r: r.bake(mesh).evaluate(w),
        }
        for label, run_path in paths.items():
            outs = [run_path(r) for r in (still, carry)]
            cells = []
            for p in PARTS:
                sel = idx[p] - v
                errs = [10 * np.linalg.norm(o[:, v:][:, sel] - truth[:, sel], axis=-1).mean() for o in outs]
                cells.append(f"{errs[0]:.2f} / {errs[1]:.2f}")
            mse = [float((((o[:, :v] - gt) * 10) ** 2).sum(-1).mean()) for o in outs]
            lines.append(f"| {name} | {', '.join(given) or 'none'} | {label} | " + " | ".join(cells)
                         + f" | {mse[0]:.3f} / {mse[1]:.3f} |")
        print(name, file=sys.stderr, flush=True)
    print("\n".join(lines))
    print()
    print(classified("val", list(range(CLASSIFY_HEADS)), LIFTS))
    print(classified("test", list(range(CLASSIFY_HEADS))))
    print(closed_head())
    print()
    print(cost(cases[0]))


CLASSIFY_HEADS = 20
LIFTS = (0.0, 0.05, 0.1, 0.15)     # retarget.jaw.LIFT's candidates, judged on the validation heads


def classified(split: str, seeds, lifts=None) -> str:
    """How often ``jaw_parts`` gives the jaw exactly the lower teeth and the tongue: the ``split``
    heads ``seeds`` in every crop (decimated to 4,000 vertices), each given PARTS by its landmarks;
    with ``lifts``, for each value of ``retarget.jaw.LIFT`` in turn (the others as they are)."""
    import retarget.jaw as jaw_module

    r = Retargeter.load(None)
    heads = [(name, r.prepare(mesh), idx) for name, mesh, idx in crop_heads(split, seeds, head_parts, assemble)]
    lines, kept = [], jaw_module.LIFT
    for lift in lifts or (kept,):
        jaw_module.LIFT = lift
        wrong = []
        for name, target, idx in heads:
            target.jaw_found = False
            jaw = r.jaw_parts(target)
            given = set() if jaw is None else {p for p in PARTS if np.isin(idx[p], jaw.carried).any()}
            if given != set(CARRIED):
                wrong.append(f"{name}: {', '.join(sorted(given)) or 'none'}")
        lines.append(f"{split} heads {seeds[0]}-{seeds[-1]}, LIFT {lift}: the jaw given exactly the lower "
                     f"teeth and the tongue on {len(heads) - len(wrong)} of {len(heads)} head crops"
                     + (f" (wrong: {'; '.join(wrong)})" if wrong else ""))
    jaw_module.LIFT = kept
    return "\n".join(lines)


def closed_head() -> str:
    """The parts ``jaw_parts`` gives the jaw on the closed MakeHuman head (``full_neutral``: the
    skin with its mouth cavity and eye sockets, one part) given PARTS."""
    rig = np.load("../shared/rigs/makehuman_arkit.npz")
    mesh, idx = assemble(rig["full_neutral"], rig["full_faces"], head_parts(EYE, EYE * [-1, 1, 1], MOUTH))
    r = Retargeter.load(None)
    jaw = r.jaw_parts(r.prepare(mesh))
    given = [p for p in PARTS if jaw is not None and np.isin(idx[p], jaw.carried).all()]
    return (f"closed MakeHuman head ({len(rig['full_neutral']):,} vertices with its mouth cavity and eye "
            f"sockets): the jaw given {', '.join(given) or 'nothing'}")


def cost(case, repeats: int = 20) -> str:
    """The time to find a target's jaw parts (once per target, after ``prepare``) and to carry
    them in one frame, on the first case's target (seconds; median of ``repeats``)."""
    import time

    _, neutral, faces, gt, *_rest, parts = case
    mesh, _ = assemble(neutral, faces, parts)
    finds, carries = [], []
    for _ in range(repeats):
        r = Retargeter.load(None)
        target = r.prepare(mesh)
        t0 = time.perf_counter()
        jaw = r.jaw_parts(target)
        finds.append(time.perf_counter() - t0)
        frame = np.concatenate([gt[0], mesh.vertices[len(neutral):]])
        t0 = time.perf_counter()
        jaw.carry(frame)
        carries.append(time.perf_counter() - t0)
    return (f"{mesh.n_vertices:,} vertices: finding the jaw's parts {1e3 * np.median(finds):.0f} ms once "
            f"per target; carrying them {1e3 * np.median(carries):.2f} ms a frame (median of {repeats})")


if __name__ == "__main__":
    assert len(FACS_NAMES) == 53
    run()
