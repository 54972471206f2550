"""Run inside Blender: import a GLB and print its mesh's shape keys as one JSON line.

    blender -b --python tests/tools/blender_import.py -- FILE.glb
"""
import json
import sys

import bpy
import numpy

if not hasattr(numpy, "bool"):  # Debian's Blender 3.4 glTF importer still uses this removed alias
    numpy.bool = bool

path = sys.argv[sys.argv.index("--") + 1]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=path)
meshes = [ob for ob in bpy.context.scene.objects if ob.type == "MESH"]
keys = meshes[0].data.shape_keys if meshes else None
anim = keys.animation_data.action if keys and keys.animation_data else None
print("RESULT " + json.dumps({
    "meshes": len(meshes),
    "vertices": len(meshes[0].data.vertices) if meshes else 0,
    "shape_keys": [k.name for k in keys.key_blocks] if keys else [],
    "animated": anim is not None,
}))
