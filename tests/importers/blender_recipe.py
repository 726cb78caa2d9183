"""blender -b --factory-startup --python blender_recipe.py -- FORMATS.md FILE OUT.json

Run docs/FORMATS.md's Blender import script (the block between its blender-import markers)
on FILE as a user would paste it, then write what the scene holds, as JSON: its frame rate,
frame range and custom properties, and the frames of the shape-key action's keys.
"""

import json
import re
import sys

import bpy
import numpy as np

# Debian's Blender 3.4 importer still says np.bool, an alias NumPy 1.24 (Debian's) removed.
if "bool" not in np.__dict__:
    np.bool = bool

doc, src, out = sys.argv[sys.argv.index("--") + 1 :][:3]
with open(doc, encoding="utf-8") as f:
    text = f.read()
block = re.search(r"<!-- blender-import:begin -->\n```python\n(.*?)```", text, re.S).group(1)
assert 'PATH = "/path/to/take.glb"' in block
bpy.ops.wm.read_factory_settings(use_empty=True)
exec(block.replace('"/path/to/take.glb"', repr(src)), {"__name__": "__main__"})
scene = bpy.context.scene
frames = []
for obj in bpy.data.objects:
    keys = obj.data.shape_keys if obj.type == "MESH" else None
    if keys is not None and keys.animation_data and keys.animation_data.action:
        frames = [p.co[0] for p in keys.animation_data.action.fcurves[0].keyframe_points]
result = {
    "fps": scene.render.fps / scene.render.fps_base,
    "frame_start": scene.frame_start,
    "frame_end": scene.frame_end,
    # a Blender ID's custom properties: keys(), it is not iterable as a dict is
    "custom": {k: scene[k] for k in scene.keys() if isinstance(scene[k], int | float | str)},  # noqa: SIM118
    "key_frames": frames,
}
with open(out, "w") as f:
    json.dump(result, f)
