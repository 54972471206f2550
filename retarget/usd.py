"""USD export: a UsdSkel blendshape rig (one mesh, K named blend shapes, optional weight animation).

The stage (``.usda`` text, ``.usdc`` or ``.usd`` binary crate) holds, under its default prim::

    /<name>            SkelRoot
      Skel             Skeleton, one joint "root" (identity bind and rest transforms)
        Anim           SkelAnimation (with weights): blendShapeWeights at time codes 0..T-1
      Mesh             Mesh (triangles, subdivisionScheme none, optional vertex normals),
                       SkelBindingAPI: skel:skeleton -> Skel, rigidly bound to "root",
                       skel:blendShapes = the K names, skel:blendShapeTargets -> its children
        <shape>        BlendShape: offsets (V,3), one per name, dense (every point)

UsdSkel applies blend shapes only to a mesh bound to a skeleton, hence the one-joint skeleton. Frame
t of the animation is at time code t, with timeCodesPerSecond = framesPerSecond = fps. Units are
those of the arrays given (the pipeline passes the target mesh's own units, by the project's
convention centimetres: metersPerUnit 0.01) and the stage declares ``meters_per_unit`` and
``up_axis``. usd-core (``pip install 'retarget[usd]'``) is imported only when a USD file is written.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .errors import RetargetError
from .glb import rig_arrays
from .io import atomic_output
from .mesh import vertex_normals

USD_FORMATS = (".usd", ".usda", ".usdc")


def is_usd_path(path) -> bool:
    """True for a ``.usd`` / ``.usda`` / ``.usdc`` path (any case)."""
    return Path(path).suffix.lower() in USD_FORMATS


def require_usd(path) -> None:
    """RetargetError naming ``path`` when usd-core (the ``pxr`` package) is not installed."""
    try:
        from pxr import Usd, UsdSkel  # noqa: F401
    except ImportError:
        raise RetargetError(f"{path}: writing USD needs usd-core: pip install 'retarget[usd]'") from None


def _prim_name(name: str) -> str:
    """A valid USD prim name (identifier) for ``name``: other characters -> "_", no leading digit."""
    ident = re.sub(r"\W", "_", name, flags=re.ASCII) or "_"
    return "_" + ident if ident[0].isdigit() else ident


def write_rig_usd(path, neutral, faces, deltas, names, animation=None, fps: float = 30.0,
                  up_axis: str = "Y", meters_per_unit: float = 0.01, normals: bool = True) -> None:
    """Write a blendshape rig as a UsdSkel stage, atomically (format from the extension).

    neutral (V,3), faces (F,3) triangles, deltas (K,V,3) offsets of each shape (units of neutral),
    names (K,) distinct shape names (the blend-shape tokens; the prim names are the same made valid
    identifiers). animation: optional (T,K) weights, frame t at time code t, fps time codes per
    second. up_axis "Y" or "Z" and meters_per_unit: the stage metadata for the arrays' frame and
    units. normals: store the neutral's vertex normals.
    """
    require_usd(path)
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

    neutral, faces, deltas, names = rig_arrays(neutral, faces, deltas, names, "blend shapes")
    prims = [_prim_name(n) for n in names]
    if len(set(prims)) != len(prims):
        raise ValueError("blend shape names must be distinct as USD identifiers")
    if up_axis not in ("Y", "Z"):
        raise ValueError(f"up_axis must be 'Y' or 'Z', got {up_axis!r}")
    if not fps > 0 or not meters_per_unit > 0:
        raise ValueError("fps and meters_per_unit must be positive")
    w = None
    if animation is not None:
        w = np.asarray(animation, dtype=np.float32)
        if w.ndim != 2 or w.shape[1] != len(names) or not len(w):
            raise ValueError(f"animation must be (T,{len(names)}) weights with T >= 1, got {w.shape}")

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up_axis == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))
    root = UsdSkel.Root.Define(stage, Sdf.Path("/" + _prim_name(Path(path).stem)))
    stage.SetDefaultPrim(root.GetPrim())

    skel = UsdSkel.Skeleton.Define(stage, root.GetPath().AppendChild("Skel"))
    skel.CreateJointsAttr(["root"])
    skel.CreateJointNamesAttr(["root"])
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1.0)]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1.0)]))

    mesh = UsdGeom.Mesh.Define(stage, root.GetPath().AppendChild("Mesh"))
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(neutral))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.astype(np.int32).ravel()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([neutral.min(0), neutral.max(0)])))
    if normals:
        mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(vertex_normals(neutral, faces).astype(np.float32)))
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)

    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(constant=True, elementSize=1).Set(Vt.IntArray([0]))
    binding.CreateJointWeightsPrimvar(constant=True, elementSize=1).Set(Vt.FloatArray([1.0]))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    binding.CreateBlendShapesAttr(names)
    targets = []
    for prim, d in zip(prims, deltas):
        shape = UsdSkel.BlendShape.Define(stage, mesh.GetPath().AppendChild(prim))
        shape.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(d))
        targets.append(shape.GetPath())
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)

    if w is not None:
        anim = UsdSkel.Animation.Define(stage, skel.GetPath().AppendChild("Anim"))
        anim.CreateJointsAttr(["root"])
        anim.CreateTranslationsAttr(Vt.Vec3fArray([Gf.Vec3f(0.0)]))
        anim.CreateRotationsAttr(Vt.QuatfArray([Gf.Quatf(1.0)]))
        anim.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1.0)]))
        anim.CreateBlendShapesAttr(names)
        weights = anim.CreateBlendShapeWeightsAttr()
        for t, row in enumerate(w):
            weights.Set(Vt.FloatArray.FromNumpy(row), Usd.TimeCode(t))
        UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(len(w) - 1)
        stage.SetTimeCodesPerSecond(float(fps))
        stage.SetFramesPerSecond(float(fps))

    with atomic_output(path) as tmp:
        try:
            ok = stage.GetRootLayer().Export(str(tmp), comment="written by retarget")
        except Exception as e:  # usd-core reports write failures as Tf errors
            raise RetargetError(f"{path}: usd-core could not write the stage ({e})".splitlines()[0]) from None
        if not ok:
            raise RetargetError(f"{path}: usd-core could not write the stage")
