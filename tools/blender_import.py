"""Imports a choreo dance into Blender at the dance's own frame rate and saves it as a .blend.

    blender --background --python tools/blender_import.py -- DANCE.bvh|DANCE.glb [OUT.blend] [--armature NAME]

Any of choreo's BVH and glb files (motion.bvh, motion.glb, and either on another rig:
`motion.bvh?rig=mixamo`, `motion.glb?rig=<uploaded id>`). OUT.blend defaults to the dance's
path with `.blend`. What it does:

- applies the patches Debian's Blender 3.4.1 needs with Python 3.11 and numpy 1.24
  (blender_compat.py: the BVH importer's `rU` open mode, the glTF importer's `numpy.bool`);
- sets the scene to the dance's frame rate before importing: a BVH's `Frame Time`, a glb's
  `extras.fps` (glTF itself has none, and Blender's glTF importer puts each key on frame
  `seconds × the scene's fps`, 24 in a new scene, so without this the keys fall between frames);
- imports (BVH: metres, y up, as choreo writes it; glb: as is), names the armature for the rig
  (a glb names it itself, e.g. `Armature` for Mixamo; a BVH names none and Blender would call it
  after the file, so it gets the name the same dance's glb has: `Armature` for Mixamo, VRM and an
  uploaded rig, `SMPL`, `choreo_skeleton`; `--armature NAME` to choose), sets the scene's frame
  range to the action's keys, and saves.

It prints one line `choreo-import: {...}` (JSON: the armature, its bone count, fps, keyframes,
seconds, the saved file) for scripts to read.
"""
import json
import os
import struct
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_compat import builtin_open, keyframe_frames  # noqa: E402 (after the path)


def glb_fps(path):
    """The frame rate a choreo glb names in its scene's (or animation's) `extras.fps`, or None."""
    with builtin_open(path, "rb") as f:
        head = f.read(20)
        if len(head) < 20 or head[:4] != b"glTF":
            return None
        length, kind = struct.unpack("<II", head[12:20])
        if kind != 0x4E4F534A:  # "JSON"
            return None
        doc = json.loads(f.read(length))
    scenes = doc.get("scenes") or [{}]
    scene = scenes[doc.get("scene", 0)] if doc.get("scene", 0) < len(scenes) else {}
    for extras in ((scene.get("extras") or {}), *((a.get("extras") or {}) for a in doc.get("animations") or [])):
        fps = extras.get("fps")
        if isinstance(fps, (int, float)) and fps > 0:
            return float(fps)
    return None


def bvh_armature_name(armature):
    """What choreo's glb of the same dance calls this BVH's armature, told by its bones (a BVH
    has no name for it): SMPL's joints, choreo's own, else `Armature` (Mixamo, VRM and uploaded
    rigs, as Mixamo's own downloads import)."""
    bones = {b.name for b in armature.data.bones}
    if {"pelvis", "spine3", "left_collar"} <= bones:
        return "SMPL"
    if {"head_right", "head_left", "right_forearm"} <= bones:
        return "choreo_skeleton"
    return "Armature"


def set_scene_fps(scene, fps):
    """The scene's rate as Blender's BVH importer sets it: a whole fps and a base for the rest."""
    scene.render.fps = max(1, int(round(fps)))
    scene.render.fps_base = scene.render.fps / fps


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    name = None
    if "--armature" in argv:
        i = argv.index("--armature")
        if i + 1 >= len(argv):
            sys.exit("--armature needs a name")
        name = argv[i + 1]
        del argv[i:i + 2]
    if not argv or not argv[0].lower().endswith((".bvh", ".glb")):
        sys.exit("usage: blender --background --python tools/blender_import.py -- DANCE.bvh|DANCE.glb [OUT.blend] [--armature NAME]")
    path = os.path.abspath(argv[0])
    out = os.path.abspath(argv[1]) if len(argv) > 1 else os.path.splitext(path)[0] + ".blend"

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    before = set(bpy.data.objects)
    if path.lower().endswith(".glb"):
        fps = glb_fps(path)
        if fps is None:
            print("choreo-import: warning: the glb names no fps; keeping the scene's", scene.render.fps)
        else:
            set_scene_fps(scene, fps)
        bpy.ops.import_scene.gltf(filepath=path)
    else:
        # The importer sets the scene's rate from the file's Frame Time (update_scene_fps).
        bpy.ops.import_anim.bvh(
            filepath=path, global_scale=1.0, axis_forward="-Z", axis_up="Y",
            rotate_mode="NATIVE", update_scene_fps=True, update_scene_duration=True,
            use_fps_scale=False, frame_start=1)
    new = [ob for ob in bpy.data.objects if ob not in before]
    armatures = [ob for ob in new if ob.type == "ARMATURE"]
    for ob in armatures[:1]:
        if name is None and path.lower().endswith(".bvh"):
            name = bvh_armature_name(ob)
        if name is not None:
            ob.name = name
            ob.data.name = name
    keys = keyframe_frames(new)
    if keys:
        # The action's own range (a glb's keys start at frame 0; the scene's did not follow).
        scene.frame_start = int(round(keys[0]))
        scene.frame_end = int(round(keys[-1]))
    bpy.ops.wm.save_as_mainfile(filepath=out)
    fps = scene.render.fps / scene.render.fps_base
    summary = {
        "file": path,
        "saved": out,
        "armature": armatures[0].name if armatures else None,
        "bones": len(armatures[0].data.bones) if armatures else 0,
        "fps": fps,
        "keyframes": len(keys),
        "seconds": (keys[-1] - keys[0]) / fps if keys else 0.0,
    }
    print("choreo-import: " + json.dumps(summary))


main()
