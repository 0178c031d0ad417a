"""Opens a .blend saved by tools/blender_import.py and says what a user would find in it.

Run: blender -b --factory-startup FILE.blend --python-exit-code 1 --python tests/blender/check_blend.py -- RESULT.json

RESULT.json: the armatures' names, the scene's frame rate (fps / fps_base) and frame range, and of
the armatures' actions the keyframe count, how far the keys lie from whole frames at most, and
how many seconds they span at the scene's rate.
"""
import json
import os
import sys

import bpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools"))
from blender_compat import builtin_open, keyframe_frames  # noqa: E402 (after the path)

out_path = sys.argv[sys.argv.index("--") + 1]
scene = bpy.context.scene
arms = [ob for ob in scene.objects if ob.type == "ARMATURE"]
keys = keyframe_frames(arms)
fps = scene.render.fps / scene.render.fps_base
result = {
    "armatures": [a.name for a in arms],
    "fps": fps,
    "frame_start": scene.frame_start,
    "frame_end": scene.frame_end,
    "keyframes": len(keys),
    "off_whole_frames": max((abs(k - round(k)) for k in keys), default=0.0),
    "seconds": (keys[-1] - keys[0]) / fps if keys else 0.0,
}
with builtin_open(out_path, "w") as f:
    json.dump(result, f)
