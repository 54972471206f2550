"""The face frame of 64 reference meshes before and after the bust fix (docs/RESULTS.md, "A bust's
face frame"): the MakeHuman base's four crops, 12 test heads as head with neck, head and bust, and
24 procedural heads and faces; prints each mesh whose frame changed and the count.

    git show e34e66d~1:retarget/canonical.py | sed 's/from .errors/from retarget.errors/' > /tmp/canonical_old.py
    python docs/results/face_frame/compare_frames.py /tmp/canonical_old.py
"""
import importlib.util
import sys

import numpy as np

from data_synth.identity import sample_identity
from data_synth.makehuman import base_head_rig, build_head_rig, head_tessellation, sample_head_identity
from data_synth.rig import build_rig
from data_synth.tessellate import tessellate
from retarget.canonical import fit_face_frame
from retarget.evaluate import makehuman_crops

spec = importlib.util.spec_from_file_location("canonical_old", sys.argv[1])
old = importlib.util.module_from_spec(spec)
sys.modules["canonical_old"] = old
spec.loader.exec_module(old)
meshes = {f"mh base {k}": (v, f) for k, (v, f) in makehuman_crops().items()}
for s in range(12):
    base = base_head_rig(sample_head_identity(s, "test"), "arkit")
    for crop in ("head_neck", "head", "bust"):
        rig = build_head_rig(base, head_tessellation(seed=s, n_vertices=2500, kind="jittered", crop=crop), 20)
        meshes[f"mh test {s} {crop}"] = (rig.neutral, rig.faces)
    for spec in ({"n_vertices": 2500, "kind": "adaptive", "region": "full"}, {"n_vertices": 800, "kind": "regular", "region": "face"}):
        rig = build_rig(sample_identity(s, "test"), tessellate(seed=s, **spec), 20)
        meshes[f"proc {s} {spec['region']} {spec['n_vertices']}"] = (rig.neutral, rig.faces)
changed = 0
for k, (v, f) in meshes.items():
    v = np.asarray(v, np.float64)
    a, b = old.fit_face_frame(v, f), fit_face_frame(v, f)
    if not (np.allclose(a[0], b[0]) and np.isclose(a[1], b[1])):
        changed += 1; print("changed", k, a[1], "->", b[1], a[0].round(2), b[0].round(2))
print(len(meshes), "meshes,", changed, "changed")
