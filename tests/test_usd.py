"""USD rig export: reopened with usd-core (names, offsets, points, animation, stage metadata, the UsdSkel
binding evaluated by UsdSkel itself), the commands that write it, the refusals, and Blender's importer
where Blender is available."""
import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from retarget import FACS_NAMES
from retarget.errors import RetargetError
from retarget.glb import read_glb_morph_names
from retarget.io import axis_rotation, load_mesh, save_mesh
from retarget.usd import write_rig_usd
from retarget.weights_io import read_weights, write_weights_csv

from .test_cli import api, files, glb_positions, run  # noqa: F401  (files: a fixture)
from .test_glb import rig  # noqa: F401  (a fixture)

needs_usd = pytest.mark.skipif(importlib.util.find_spec("pxr") is None, reason="usd-core is not installed")


def read_usd(path: Path) -> dict:
    """Independent reader of a UsdSkel rig with usd-core: stage metadata, mesh, shapes, animation."""
    from pxr import Usd, UsdGeom, UsdSkel

    stage = Usd.Stage.Open(str(path))
    root = stage.GetDefaultPrim()
    (mesh_prim,) = [p for p in Usd.PrimRange(root) if p.IsA(UsdGeom.Mesh)]
    mesh, binding = UsdGeom.Mesh(mesh_prim), UsdSkel.BindingAPI(mesh_prim)
    names = list(binding.GetBlendShapesAttr().Get())
    offsets = np.stack([np.asarray(UsdSkel.BlendShape(stage.GetPrimAtPath(t)).GetOffsetsAttr().Get())
                        for t in binding.GetBlendShapeTargetsRel().GetTargets()])
    (skel,) = binding.GetSkeletonRel().GetTargets()
    source = UsdSkel.BindingAPI(stage.GetPrimAtPath(skel)).GetAnimationSourceRel().GetTargets()
    weights, anim_names, times = None, None, []
    if source:
        anim = UsdSkel.Animation(stage.GetPrimAtPath(source[0]))
        anim_names = list(anim.GetBlendShapesAttr().Get())
        times = anim.GetBlendShapeWeightsAttr().GetTimeSamples()
        weights = np.stack([np.asarray(anim.GetBlendShapeWeightsAttr().Get(t)) for t in times])
    return {
        "stage": stage, "root": root, "up": UsdGeom.GetStageUpAxis(stage),
        "mpu": UsdGeom.GetStageMetersPerUnit(stage), "tcps": stage.GetTimeCodesPerSecond(),
        "fps": stage.GetFramesPerSecond(), "start": stage.GetStartTimeCode(), "end": stage.GetEndTimeCode(),
        "points": np.asarray(mesh.GetPointsAttr().Get()),
        "counts": np.asarray(mesh.GetFaceVertexCountsAttr().Get()),
        "indices": np.asarray(mesh.GetFaceVertexIndicesAttr().Get()),
        "normals": mesh.GetNormalsAttr().Get(), "subdivision": mesh.GetSubdivisionSchemeAttr().Get(),
        "names": names, "offsets": offsets, "anim_names": anim_names, "times": list(times),
        "weights": weights,
    }


def skel_evaluated_points(path: Path) -> list:
    """UsdSkel's own evaluation of the rig: the skinned + blend-shaped points (V,3) at every time
    code (or the rest pose), as ``UsdSkel.BakeSkinning`` writes them into an in-memory copy."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel

    stage = Usd.Stage.Open(Sdf.Layer.OpenAsAnonymous(str(path)))
    root = UsdSkel.Root(stage.GetDefaultPrim())
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.PrimDefaultPredicate)
    (binding,) = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
    (query,) = binding.GetSkinningTargets()
    assert query.HasBlendShapes() and query.HasJointInfluences()
    anim_query = cache.GetSkelQuery(binding.GetSkeleton()).GetAnimQuery()
    times = list(anim_query.GetBlendShapeWeightTimeSamples()) if anim_query else [0.0]
    assert UsdSkel.BakeSkinning(root, Gf.Interval(times[0], times[-1]))
    points = UsdGeom.Mesh(query.GetPrim()).GetPointsAttr()
    return [np.asarray(points.Get(Usd.TimeCode(t))) for t in times]


def validation_errors(stage) -> list:
    """usd-core's validators (UsdSkel binding, stage metadata, ...) on the stage: their messages."""
    from pxr import UsdValidation

    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    return [e.GetMessage() for e in UsdValidation.ValidationContext(validators).Validate(stage)]


@needs_usd
@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usd"])
def test_rig_reopens_with_names_offsets_points_and_animation(tmp_path, rig, ext):  # noqa: F811
    v, f, deltas, names, anim = rig
    path = tmp_path / "out" / f"head rig{ext}"
    write_rig_usd(path, v, f, deltas, names, animation=anim, fps=24)
    assert path.read_bytes()[:8] == (b"#usda 1." if ext == ".usda" else b"PXR-USDC")
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporary file left
    u = read_usd(path)
    assert u["root"].GetTypeName() == "SkelRoot" and u["root"].GetName() == "head_rig"
    assert u["up"] == "Y" and u["mpu"] == pytest.approx(0.01)
    assert np.allclose(u["points"], v, atol=1e-5)
    assert (u["counts"] == 3).all() and np.array_equal(u["indices"].reshape(-1, 3), f)
    normals = np.asarray(u["normals"])
    assert np.allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-5)
    assert (np.einsum("ij,ij->i", normals, v) > 0).all()  # outward on a sphere
    assert u["subdivision"] == "none"
    assert u["names"] == names == u["anim_names"]
    assert np.allclose(u["offsets"], deltas, atol=1e-6)
    # frame t at time code t, 24 time codes per second, the stage spanning the take
    assert u["times"] == list(range(len(anim))) and np.allclose(u["weights"], anim, atol=1e-6)
    assert u["tcps"] == u["fps"] == 24 and (u["start"], u["end"]) == (0, len(anim) - 1)
    # UsdSkel itself applies the shapes: neutral + w(t)·deltas at every time code
    for t, pts in enumerate(skel_evaluated_points(path)):
        assert np.allclose(pts, v + np.tensordot(anim[t], deltas, axes=1), atol=1e-4), t


@needs_usd
def test_rig_without_animation_and_z_up_metres(tmp_path, rig):  # noqa: F811
    v, f, deltas, names, _ = rig
    path = tmp_path / "rig.usda"
    write_rig_usd(path, v, f, deltas, names, up_axis="Z", meters_per_unit=1.0, normals=False)
    u = read_usd(path)
    assert u["up"] == "Z" and u["mpu"] == 1.0 and u["normals"] is None
    assert u["weights"] is None and u["times"] == [] and not u["stage"].HasAuthoredTimeCodeRange()
    assert np.allclose(skel_evaluated_points(path)[0], v, atol=1e-5)  # the rest pose: weights 0


@needs_usd
def test_usd_validators_pass_and_see_a_broken_binding(tmp_path, rig):  # noqa: F811
    """usd-core's validators (UsdValidation, where usd-core has it) accept both rigs; the checks can
    fail: a mesh without SkelBindingAPI is reported, and UsdSkel then finds no skinning target, so no shape would play."""
    pytest.importorskip("pxr.UsdValidation")
    from pxr import Usd, UsdSkel

    v, f, deltas, names, anim = rig
    write_rig_usd(tmp_path / "rig.usda", v, f, deltas, names, animation=anim)
    write_rig_usd(tmp_path / "still.usdc", v, f, deltas, names, up_axis="Z", normals=False)
    for name in ("rig.usda", "still.usdc"):
        assert validation_errors(Usd.Stage.Open(str(tmp_path / name))) == [], name
    stage = Usd.Stage.Open(str(tmp_path / "rig.usda"))
    stage.GetPrimAtPath("/rig/Mesh").RemoveAPI(UsdSkel.BindingAPI)
    assert any("SkelBindingAPI" in m for m in validation_errors(stage))
    root = UsdSkel.Root(stage.GetDefaultPrim())
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.PrimDefaultPredicate)
    assert all(not b.GetSkinningTargets() for b in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate))


@needs_usd
def test_names_become_valid_prim_names_and_bad_arguments_are_refused(tmp_path, rig):  # noqa: F811
    v, f, deltas, _, anim = rig
    odd = ["mouth.Smile L", "3jaw", "ok_name"]
    write_rig_usd(tmp_path / "odd.usda", v, f, deltas, odd)
    u = read_usd(tmp_path / "odd.usda")
    assert u["names"] == odd  # the tokens keep the names; the prims are valid identifiers
    assert [p.GetName() for p in u["stage"].GetPrimAtPath("/odd/Mesh").GetChildren()] == \
        ["mouth_Smile_L", "_3jaw", "ok_name"]
    with pytest.raises(ValueError, match="distinct"):
        write_rig_usd(tmp_path / "x.usda", v, f, deltas, ["a-b", "a_b", "c"])
    with pytest.raises(ValueError, match="deltas"):
        write_rig_usd(tmp_path / "x.usda", v, f, deltas[:, :-1], odd)
    with pytest.raises(ValueError, match="names"):
        write_rig_usd(tmp_path / "x.usda", v, f, deltas, odd[:2])
    with pytest.raises(ValueError, match="animation"):
        write_rig_usd(tmp_path / "x.usda", v, f, deltas, odd, animation=anim[:, :2])
    with pytest.raises(ValueError, match="up_axis"):
        write_rig_usd(tmp_path / "x.usda", v, f, deltas, odd, up_axis="X")
    with pytest.raises(ValueError, match="face index"):
        write_rig_usd(tmp_path / "x.usda", v, f + len(v), deltas, odd)
    with pytest.raises(RetargetError, match="is a folder"):
        write_rig_usd(tmp_path, v, f, deltas, odd)
    assert not (tmp_path / "x.usda").exists()


def test_without_usd_core_a_usd_output_is_one_line_error(files, tmp_path, rig, monkeypatch, capsys):  # noqa: F811
    monkeypatch.setitem(sys.modules, "pxr", None)  # import pxr -> ImportError, as when not installed
    v, f, deltas, names, _ = rig
    with pytest.raises(RetargetError, match=r"rig\.usda: writing USD needs usd-core: pip install 'retarget\[usd\]'"):
        write_rig_usd(tmp_path / "rig.usda", v, f, deltas, names)
    capsys.readouterr()
    for argv in (["export-rig", files / "target.obj", "-o", tmp_path / "rig.usdc"],
                 ["animate", files / "target.obj", "--weights", files / "w.csv", "-o", tmp_path / "take.usd"]):
        assert run(*argv, files=files) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "pip install 'retarget[usd]'" in err and err.startswith("error: ")
    assert list(tmp_path.iterdir()) == []


@needs_usd
def test_export_rig_usd_holds_the_baked_rig_with_the_glb_names(files, tmp_path, capsys):  # noqa: F811
    target = load_mesh(files / "target.obj")
    baked = api(files).bake(target)
    assert run("export-rig", files / "target.obj", "-o", tmp_path / "rig.usda", files=files) == 0
    u = read_usd(tmp_path / "rig.usda")
    assert u["names"] == list(FACS_NAMES) and u["weights"] is None
    assert np.allclose(u["points"], baked.neutral, atol=1e-4) and np.allclose(u["offsets"], baked.deltas, atol=1e-4)
    assert u["up"] == "Y" and u["mpu"] == pytest.approx(0.01)
    # ARKit names and the animation: the same shapes, names and weights as the GLB of the same command
    for ext in (".glb", ".usdc"):
        assert run("export-rig", files / "target.obj", "-o", tmp_path / f"arkit{ext}", "--names", "arkit",
                   "--weights", files / "w.csv", "--meters-per-unit", "0.001", files=files) == 0
    _, glb_deltas, glb_names, glb_anim = glb_positions(tmp_path / "arkit.glb")
    u = read_usd(tmp_path / "arkit.usdc")
    assert u["names"] == glb_names == read_glb_morph_names(tmp_path / "arkit.glb") and len(glb_names) == 51
    assert np.allclose(u["offsets"], glb_deltas, atol=1e-6) and np.allclose(u["weights"], glb_anim, atol=1e-6)
    assert u["weights"][0, u["names"].index("jawOpen")] == pytest.approx(0.5)
    assert u["tcps"] == 30 and u["mpu"] == pytest.approx(0.001)  # w.csv has no time column: 30 fps
    # a z-up copy of the target: the rig is written in the file's axes and the stage says Z up
    to_file = axis_rotation("+z", "-y")  # project frame -> the z-up file axes: v @ R
    save_mesh(tmp_path / "tgt_z.obj", target.vertices @ to_file, target.faces)
    assert run("export-rig", tmp_path / "tgt_z.obj", "-o", tmp_path / "z.usda", "--up", "+z", "--forward", "-y",
               files=files) == 0
    u = read_usd(tmp_path / "z.usda")
    assert u["up"] == "Z" and np.allclose(u["points"], baked.neutral @ to_file, atol=1e-4)
    assert np.allclose(u["offsets"], baked.deltas @ to_file, atol=1e-4)
    # an x-up copy: USD cannot declare +x up, so the rig is written in the project frame, +y up
    save_mesh(tmp_path / "tgt_x.obj", target.vertices @ axis_rotation("+x", "+z"), target.faces)
    capsys.readouterr()
    assert run("export-rig", tmp_path / "tgt_x.obj", "-o", tmp_path / "x.usda", "--up", "+x", files=files) == 0
    assert "the rig is written +y up" in capsys.readouterr().err
    u = read_usd(tmp_path / "x.usda")
    assert u["up"] == "Y" and np.allclose(u["points"], baked.neutral, atol=1e-4)


@needs_usd
def test_animate_usd_take_plays_the_weights_at_the_takes_fps(files, tmp_path):  # noqa: F811
    rng = np.random.default_rng(3)
    weights = rng.uniform(0, 1, (5, 53)).astype(np.float32)
    write_weights_csv(tmp_path / "take.csv", weights, fps=24)
    track = read_weights(tmp_path / "take.csv")
    assert run("animate", files / "target.obj", "--weights", tmp_path / "take.csv", "-o", tmp_path / "take.usdc",
               files=files) == 0
    u = read_usd(tmp_path / "take.usdc")
    assert u["names"] == u["anim_names"] == list(FACS_NAMES)
    assert u["times"] == [0, 1, 2, 3, 4] and np.allclose(u["weights"], track.weights, atol=1e-6)
    assert u["tcps"] == u["fps"] == pytest.approx(24, rel=1e-4) and (u["start"], u["end"]) == (0, 4)
    # the take UsdSkel plays is the baked rig of `animate --baked`
    assert run("animate", files / "target.obj", "--weights", tmp_path / "take.csv", "-o", tmp_path / "baked",
               "--baked", files=files) == 0
    for t, pts in enumerate(skel_evaluated_points(tmp_path / "take.usdc")):
        assert np.allclose(pts, load_mesh(tmp_path / "baked" / f"frame_{t:04d}.obj").vertices, atol=1e-4), t


def test_usd_outputs_are_refused_where_they_are_not_written(files, tmp_path, capsys):  # noqa: F811
    cases = [(["transfer", files / "target.obj", files / "target.obj", "-o", tmp_path / "t.usd"], "cannot write .usd"),
             (["invert", files / "target.obj", "-o", tmp_path / "w.usda"], "written as .csv"),
             (["export-rig", files / "target.obj", "-o", tmp_path / "rig.fbx"], "written as .glb, or as USD"),
             (["export-rig", files / "target.obj", "-o", tmp_path / "rig.usda", "--meters-per-unit", "nan"],
              "--meters-per-unit nan: must be a positive number")]
    capsys.readouterr()
    for argv, message in cases:
        assert run(*argv, files=files) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, err
    assert list(tmp_path.iterdir()) == []


def blender_command(script: Path, path: Path):
    """How to run ``script -- path`` in Blender: the ``blender`` on PATH, else None."""
    exe = shutil.which("blender")
    return None if exe is None else [exe, "-b", "--python", str(script), "--", str(path)]


@needs_usd
def test_usd_rig_imports_into_blender_as_named_shape_keys(tmp_path, rig):  # noqa: F811
    v, f, deltas, names, anim = rig
    path = tmp_path / "rig.usdc"
    write_rig_usd(path, v, f, deltas, names, animation=anim, fps=24)
    cmd = blender_command(Path(__file__).parent / "tools" / "blender_import.py", path)
    if cmd is None:
        pytest.skip("Blender is not installed")
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env={**os.environ, "PYTHONPATH": ""})
    line = [ln for ln in res.stdout.splitlines() if ln.startswith("RESULT ")]
    assert line, res.stdout[-2000:] + res.stderr[-2000:]
    out = json.loads(line[0][len("RESULT "):])
    if not out["usd_importer"]:
        pytest.skip("this Blender is built without USD")
    assert out["meshes"] == 1 and out["vertices"] == len(v)
    assert out["shape_keys"] == ["Basis", *names] and out["animated"]
    # the mesh's own coordinates are the file's; metersPerUnit 0.01 and Y up go into its object matrix
    assert np.allclose(out["basis"], v, atol=1e-4) and np.allclose(out["first_offsets"], deltas[0], atol=1e-4)
    world = np.asarray(out["world"])
    assert np.allclose(world[:3, :3], 0.01 * np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]), atol=1e-6)
    for k, name in enumerate(names):
        keys = np.asarray(out["keyframes"][name])
        assert np.allclose(keys[:, 1], anim[:, k], atol=1e-5), name
        assert np.allclose(keys[:, 0] - keys[0, 0], np.arange(len(anim)))
