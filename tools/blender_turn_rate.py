"""How fast a dance turns, read back by Blender: the mean |change of heading| per second of the
hip line (right hip → left hip) in the floor plane, over every keyframe of each BVH's action.

    blender -b --python tools/blender_turn_rate.py -- A.bvh [B.bvh …] OUT.json

The keypose-transformer card's turning figures (25°/s with the network's own facing, 71°/s with
the scaffold's clips', real waltzes 56–70°/s) were read this way from `choreo generate` BVHs.
"""
import sys, json, math
import os
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import blender_compat  # noqa: F401  (patches Debian's importers)
from blender_compat import keyframe_frames
import bpy
argv = sys.argv[sys.argv.index("--") + 1:]
out = {}
for path in argv[:-1]:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=path, global_scale=1.0, axis_forward="-Z", axis_up="Y", update_scene_fps=True, update_scene_duration=True)
    arm = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"][0]
    frames = keyframe_frames([arm])
    names = [b.name for b in arm.pose.bones]
    hips = [n for n in names if "hip" in n.lower()]
    r = [n for n in hips if "right" in n.lower()][0]; l = [n for n in hips if "left" in n.lower()][0]
    yaws = []
    for f in frames:
        bpy.context.scene.frame_set(int(f))
        pr = arm.matrix_world @ arm.pose.bones[r].head
        pl = arm.matrix_world @ arm.pose.bones[l].head
        # Blender is Z up after the import's axis conversion: the hip line's heading in the floor plane.
        yaws.append(math.atan2(pl.y - pr.y, pl.x - pr.x))
    un = [yaws[0]]
    for y in yaws[1:]:
        d = y - un[-1]
        d = (d + math.pi) % (2 * math.pi) - math.pi
        un.append(un[-1] + d)
    fps = bpy.context.scene.render.fps / bpy.context.scene.render.fps_base
    rate = sum(abs(b - a) for a, b in zip(un, un[1:])) / (len(un) - 1) * fps
    out[path] = {"frames": len(frames), "fps": fps, "mean_turn_deg_s": math.degrees(rate), "hips": [r, l]}
json.dump(out, open(argv[-1], "w"), indent=1)
