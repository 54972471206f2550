"""Run inside Blender: import a GLB or a USD file and print its mesh's shape keys as one JSON line.

    blender -b --python tests/tools/blender_import.py -- FILE.glb|FILE.usda
    python tests/tools/blender_import.py -- FILE.usda     # a Python with the bpy module

For USD also: "usd_importer" (false where this Blender was built without USD, e.g. Debian's 3.4), the
neutral's local coordinates "basis" (V,3), the first shape's "first_offsets" (V,3), the mesh object's
"world" matrix (4,4) and the shape keys' "keyframes" {name: [[frame, value], ...]}.
"""
import json
import sys

import bpy
import numpy

if not hasattr(numpy, "bool"):  # Debian's Blender 3.4 glTF importer still uses this removed alias
    numpy.bool = bool

path = sys.argv[sys.argv.index("--") + 1]
usd = path.lower().endswith((".usd", ".usda", ".usdc"))
bpy.ops.wm.read_factory_settings(use_empty=True)
result = {}
if usd:
    result["usd_importer"] = "usd_import" in dir(bpy.ops.wm)
    if not result["usd_importer"]:
        print("RESULT " + json.dumps(result))
        sys.exit(0)
    bpy.ops.wm.usd_import(filepath=path)
else:
    bpy.ops.import_scene.gltf(filepath=path)
meshes = [ob for ob in bpy.context.scene.objects if ob.type == "MESH"]
keys = meshes[0].data.shape_keys if meshes else None
anim = keys.animation_data.action if keys and keys.animation_data else None
result.update({
    "meshes": len(meshes),
    "vertices": len(meshes[0].data.vertices) if meshes else 0,
    "shape_keys": [k.name for k in keys.key_blocks] if keys else [],
    "animated": anim is not None,
})
if usd and keys:
    blocks = keys.key_blocks
    basis = [list(v.co) for v in blocks[0].data]
    result["basis"] = basis
    if len(blocks) > 1:
        result["first_offsets"] = [[a - b for a, b in zip(v.co, base)] for v, base in zip(blocks[1].data, basis)]
    result["world"] = [list(row) for row in meshes[0].matrix_world]
    result["keyframes"] = {
        fc.data_path.split('"')[1]: [list(p.co) for p in fc.keyframe_points]
        for fc in (anim.fcurves if anim else []) if fc.data_path.startswith("key_blocks[")}
print("RESULT " + json.dumps(result))
