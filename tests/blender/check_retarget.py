"""Imports a retargeted BVH and glb (e.g. a job's motion.bvh?rig=mixamo) into Blender and dumps
the evaluated pose: the world position of every bone's head at chosen frames.

Run: blender -b --python-exit-code 1 --python tests/blender/check_retarget.py -- \
         MOTION.bvh MOTION.glb FRAMES RESULT.json

FRAMES is a comma-separated list of frame indices (0-based, the dance's frames). RESULT.json
holds, for each of "bvh" and "glb": the armatures' bone names, the frame count (from the
action's keyframes), and per asked frame the head of every pose bone in choreo's axes (y up:
Blender's (x, y, z) is choreo's (x, -z, y)). The caller compares angles between bones with
motion.json's. Importer quirks of Debian's Blender 3.4.1 are patched by tools/blender_compat.py.
"""
import json
import os
import sys
import traceback

import bpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools"))
from blender_compat import builtin_open, keyframe_frames  # noqa: E402 (after the path)


def dump(importer, frames_wanted):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    before = set(bpy.data.objects)
    status = importer()
    new = [ob for ob in bpy.data.objects if ob not in before]
    arms = [ob for ob in new if ob.type == "ARMATURE"]
    res = {"status": sorted(status), "armatures": len(arms)}
    if not arms:
        return res
    res["armature_names"] = [a.name for a in arms]
    res["bones"] = [b.name for a in arms for b in a.data.bones]
    keys = keyframe_frames(new)
    res["frames"] = len(keys)
    scene = bpy.context.scene
    poses = {}
    for t in frames_wanted:
        if t >= len(keys):
            continue
        f = keys[t]
        scene.frame_set(int(f), subframe=f - int(f))
        bpy.context.view_layer.update()
        heads = {}
        for a in arms:
            for pb in a.pose.bones:
                p = a.matrix_world @ pb.head
                heads[pb.name] = [p[0], p[2], -p[1]]
        poses[str(t)] = heads
    res["poses"] = poses
    return res


def main():
    argv = sys.argv[sys.argv.index("--") + 1:]
    bvh_path, glb_path, frames_arg, out_path = argv[:4]
    frames = [int(f) for f in frames_arg.split(",") if f]
    results = {}
    for kind, importer in (
        ("bvh", lambda: bpy.ops.import_anim.bvh(
            filepath=bvh_path, global_scale=1.0, axis_forward="-Z", axis_up="Y",
            rotate_mode="NATIVE", update_scene_fps=False, update_scene_duration=True,
            use_fps_scale=False, frame_start=1)),
        ("glb", lambda: bpy.ops.import_scene.gltf(filepath=glb_path)),
    ):
        try:
            results[kind] = dump(importer, frames)
        except Exception:
            results[kind] = {"error": traceback.format_exc()}
    with builtin_open(out_path, "w") as f:
        json.dump(results, f)


main()
