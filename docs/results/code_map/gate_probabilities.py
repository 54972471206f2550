"""The gate of a checkpoint's code map (``retarget.code_map``) on held-out heads: its probability
that each head is MakeHuman-like, for the validation eval's inversion heads (procedural and
realistic), the ARKit rig, and two test identities' MakeHuman crops and tessellations beside their
procedural heads (docs/RESULTS.md, "The code map", part 5).

    OMP_NUM_THREADS=1 python docs/results/code_map/gate_probabilities.py > docs/results/code_map/gate_probabilities.txt
"""
from __future__ import annotations

import argparse

from data_synth.identity import sample_identity
from data_synth.makehuman import base_head_rig, build_head_rig, head_tessellation, sample_head_identity
from data_synth.rig import build_rig
from data_synth.tessellate import tessellate
from retarget.api import Retargeter
from retarget.code_map import gate_probability
from retarget.evaluate import EvalData, load_eval_config
from retarget.mesh import Mesh

HEAD_SPECS = ({"n_vertices": 2500, "kind": "decimated", "crop": "face"},
              {"n_vertices": 3000, "kind": "decimated", "crop": "head"},
              {"n_vertices": 4000, "kind": "subdivided", "crop": "bust"},
              {"n_vertices": 1200, "kind": "jittered", "crop": "head_neck"},
              {"n_vertices": 8000, "kind": "decimated", "crop": "head_neck"})
UV_SPECS = ({"n_vertices": 2500, "kind": "regular", "region": "face"},
            {"n_vertices": 8000, "kind": "adaptive", "region": "full"})


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default="retarget/checkpoints/default.pt")
    args = ap.parse_args()
    r = Retargeter.load(args.checkpoint)
    if r.code_map_gate is None:
        raise SystemExit(f"{args.checkpoint} has no code map gate")

    def p(rig) -> float:
        return gate_probability(r.code_map_gate, r.prepare(Mesh(rig.neutral, rig.faces)).codes.z_id.numpy())

    data = EvalData(load_eval_config("configs/eval/validation.yaml"))
    for suite in ("inverse", "head_inverse"):
        print(f"validation {suite}: " + " ".join(f"{p(c.source):.4f}" for c in data.cases(suite)))
    print(f"ARKit rig: {p(data.real_rig()):.4f}")
    for i in range(2):
        base = base_head_rig(sample_head_identity(i, "test"), "arkit")
        for spec in HEAD_SPECS:
            print(f"test makehuman {i} {spec['crop']} {spec['kind']} {spec['n_vertices']}: "
                  f"{p(build_head_rig(base, head_tessellation(seed=0, **spec), 20)):.4f}")
        for spec in UV_SPECS:
            print(f"test procedural {i} {spec['region']} {spec['kind']} {spec['n_vertices']}: "
                  f"{p(build_rig(sample_identity(i, 'test'), tessellate(seed=0, **spec), 20)):.4f}")


if __name__ == "__main__":
    main()
