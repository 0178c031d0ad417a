"""Imports a choreo BVH and glb into Blender and compares joint world positions with the JSON.

Run: blender -b --python-exit-code 1 --python tests/blender/check_import.py -- \
         MOTION.bvh MOTION.glb MOTION.json RESULT.json

Writes RESULT.json: for each of "bvh" and "glb", the import status, frame count (from the
action's keyframes), joint count, and the largest distance (metres) between Blender's world
position of every joint and our JSON `positions` at the first, middle and last frame.

Blender is z up; choreo (BVH, glTF, JSON) is y up. Both importers map (x, y, z) to (x, -z, y).
"""
import json
import os
import sys
import traceback

import bpy
import mathutils

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools"))
from blender_compat import builtin_open, keyframe_frames  # noqa: E402 (after the path)


def y_up_to_blender(p):
    return mathutils.Vector((p[0], -p[2], p[1]))


def joint_world_positions(names):
    """World position of each named joint: a pose bone head, or an object's origin."""
    out = {}
    for ob in bpy.context.scene.objects:
        if ob.type == "ARMATURE":
            for pb in ob.pose.bones:
                out.setdefault(pb.name, ob.matrix_world @ pb.head)
    for ob in bpy.context.scene.objects:
        if ob.name in names and ob.name not in out:
            out[ob.name] = ob.matrix_world.translation.copy()
    return out


def compare(kind, ref, importer):
    res = {"kind": kind}
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = int(round(ref["fps"]))
    scene.render.fps_base = scene.render.fps / ref["fps"]
    before = set(bpy.data.objects)
    status = importer()
    res["status"] = sorted(status)
    new = [ob for ob in bpy.data.objects if ob not in before]
    arms = [ob for ob in new if ob.type == "ARMATURE"]
    res["armatures"] = len(arms)
    names = ref["joint_names"]
    if arms:
        res["joints"] = sum(len(a.data.bones) for a in arms)
    else:
        res["joints"] = sum(1 for ob in new if ob.name in names)
    frames = keyframe_frames(new)
    res["frames"] = len(frames)
    t_len = ref["num_frames"]
    checks = {}
    for t in sorted({0, t_len // 2, t_len - 1}):
        if t >= len(frames):
            checks[str(t)] = None
            continue
        f = frames[t]
        scene.frame_set(int(f), subframe=f - int(f))
        bpy.context.view_layer.update()
        got = joint_world_positions(set(names))
        worst, worst_joint, missing = 0.0, None, []
        for j, name in enumerate(names):
            if name not in got:
                missing.append(name)
                continue
            d = (got[name] - y_up_to_blender(ref["positions"][t][j])).length
            if d > worst:
                worst, worst_joint = d, name
        checks[str(t)] = {"blender_frame": f, "max_error_m": worst, "worst_joint": worst_joint, "missing": missing}
    res["checks"] = checks
    return res


def main():
    argv = sys.argv[sys.argv.index("--") + 1:]
    bvh_path, glb_path, json_path, out_path = argv[:4]
    with builtin_open(json_path) as f:
        ref = json.load(f)
    results = {}
    for kind, importer in (
        ("bvh", lambda: bpy.ops.import_anim.bvh(
            filepath=bvh_path, global_scale=1.0, axis_forward="-Z", axis_up="Y",
            rotate_mode="NATIVE", update_scene_fps=False, update_scene_duration=True,
            use_fps_scale=False, frame_start=1)),
        ("glb", lambda: bpy.ops.import_scene.gltf(filepath=glb_path)),
    ):
        try:
            results[kind] = compare(kind, ref, importer)
        except Exception:
            results[kind] = {"kind": kind, "error": traceback.format_exc()}
    with builtin_open(out_path, "w") as f:
        json.dump(results, f, indent=1)
    print(json.dumps(results, indent=1))


main()
