"""Imports a choreo motion.glb into Blender and checks its mannequin follows the skeleton.

Run: blender -b --factory-startup --python-exit-code 1 --python tests/blender/check_mannequin.py -- \
         MOTION.glb JOINT[,JOINT...] RESULT.json

Writes RESULT.json: the armatures and skinned meshes found (a mesh with an Armature modifier
bound to the imported armature, and how many vertex groups it has), and for each named joint the
mesh vertex nearest to it in the rest pose, with its distance from the joint at rest and the
largest distance from the joint's posed position over every tenth keyframe of the dance, where
both come from Blender's own evaluation (pose bones and the evaluated, deformed mesh). A vertex
that stays near its joint says the skin follows the bones; a forearm twist flip, or weights on a
wrong bone, would carry it away (candy-wrap).
"""
import json
import os
import sys
import traceback

import bpy

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools"))
from blender_compat import keyframe_frames  # noqa: E402 (after the path)


def evaluated_vertices(ob, indices):
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = ob.evaluated_get(depsgraph)
    me = ev.to_mesh()
    out = [ev.matrix_world @ me.vertices[i].co for i in indices]
    ev.to_mesh_clear()
    return out


def check(glb_path, joints):
    res = {}
    bpy.ops.wm.read_factory_settings(use_empty=True)
    res["status"] = sorted(bpy.ops.import_scene.gltf(filepath=glb_path))
    objects = list(bpy.context.scene.objects)
    arms = [ob for ob in objects if ob.type == "ARMATURE"]
    res["armatures"] = len(arms)
    skinned = []
    for ob in objects:
        if ob.type != "MESH":
            continue
        for mod in ob.modifiers:
            if mod.type == "ARMATURE" and mod.object in arms:
                skinned.append((ob, mod.object))
    res["skinned_meshes"] = [
        {"name": ob.name, "armature": arm.name, "vertices": len(ob.data.vertices), "vertex_groups": len(ob.vertex_groups)}
        for ob, arm in skinned
    ]
    if not skinned:
        return res
    mesh_ob, arm = skinned[0]
    # Rest pose: the mesh's own vertices (its bind pose) and the bones' rest heads.
    rest_vertices = [mesh_ob.matrix_world @ v.co for v in mesh_ob.data.vertices]
    picks = {}
    for name in joints:
        bone = arm.data.bones.get(name)
        if bone is None:
            picks[name] = None
            continue
        head = arm.matrix_world @ bone.head_local
        i = min(range(len(rest_vertices)), key=lambda k: (rest_vertices[k] - head).length)
        picks[name] = (i, (rest_vertices[i] - head).length)
    frames = keyframe_frames(objects)
    res["frames"] = len(frames)
    scene = bpy.context.scene
    worst = {name: 0.0 for name in joints if picks[name] is not None}
    moved = {name: 0.0 for name in worst}
    first = {}
    indices = [picks[name][0] for name in worst]
    for f in frames[::10]:
        scene.frame_set(int(f), subframe=f - int(f))
        bpy.context.view_layer.update()
        verts = evaluated_vertices(mesh_ob, indices)
        for name, v in zip(worst, verts):
            joint = arm.matrix_world @ arm.pose.bones[name].head
            worst[name] = max(worst[name], (v - joint).length)
            first.setdefault(name, joint.copy())
            moved[name] = max(moved[name], (joint - first[name]).length)
    res["sampled_frames"] = len(frames[::10])
    res["joints"] = {
        name: None if picks[name] is None else {
            "vertex": picks[name][0],
            "rest_distance_m": picks[name][1],
            "max_distance_m": worst[name],
            "joint_travel_m": moved[name],
        }
        for name in joints
    }
    return res


def main():
    argv = sys.argv[sys.argv.index("--") + 1:]
    glb_path, joints, out_path = argv[0], argv[1].split(","), argv[2]
    try:
        res = check(glb_path, joints)
    except Exception:
        res = {"error": traceback.format_exc()}
    with open(out_path, "w") as f:
        json.dump(res, f, indent=1)
    print(json.dumps(res, indent=1))


main()
