"""blender -b --factory-startup --python blender_gltf.py -- FILE OUT.json

Import FILE with Blender's own glTF importer and write what it made, as JSON: per mesh
object its shape key names and the action on its shape keys (name, frame rate, and per
F-curve the data path and its keyframes as [frame, value] pairs); per object with an
action of its own (a turning head node), that action's F-curves the same way.
"""

import json
import sys

import bpy
import numpy as np

# Debian's Blender 3.4 importer still says np.bool, an alias NumPy 1.24 (Debian's) removed.
if "bool" not in np.__dict__:
    np.bool = bool

src, out = sys.argv[sys.argv.index("--") + 1 :][:2]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)
scene = bpy.context.scene
found = []
for obj in bpy.data.objects:
    keys = obj.data.shape_keys if obj.type == "MESH" else None
    if keys is None:
        continue
    action = keys.animation_data.action if keys.animation_data else None
    curves = []
    for fc in action.fcurves if action else []:
        points = [[p.co[0], p.co[1]] for p in fc.keyframe_points]
        curves.append({"path": fc.data_path, "keys": points})
    found.append(
        {
            "object": obj.name,
            "vertices": len(obj.data.vertices),
            "shape_keys": [k.name for k in keys.key_blocks],
            "action": action.name if action else None,
            "fcurves": curves,
        }
    )
objects = []
for obj in bpy.data.objects:
    action = obj.animation_data.action if obj.animation_data else None
    if action is None:
        continue
    curves = [
        {"path": fc.data_path, "index": fc.array_index,
         "keys": [[p.co[0], p.co[1]] for p in fc.keyframe_points]}
        for fc in action.fcurves
    ]  # fmt: skip
    objects.append({"object": obj.name, "action": action.name, "fcurves": curves})
result = {"fps": scene.render.fps / scene.render.fps_base, "meshes": found, "objects": objects}
with open(out, "w") as f:
    json.dump(result, f)
