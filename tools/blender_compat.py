"""What every Blender script of choreo's shares (tools/blender_import.py, the checks in
tests/blender/): the patches Debian's Blender 3.4.1 importers need, and the frames read from an
action's keyframes. Importing this module applies the patches.

A script puts this folder on sys.path first (Blender runs a --python script without its own
folder there), then `from blender_compat import ...`.
"""
import builtins

# Debian's Blender 3.4.1 BVH importer opens files with mode 'rU', gone in Python 3.11.
builtin_open = builtins.open


def _open_without_u(file, mode="r", *args, **kwargs):
    if isinstance(mode, str) and "U" in mode:
        mode = mode.replace("U", "") or "r"
    return builtin_open(file, mode, *args, **kwargs)


builtins.open = _open_without_u

# Its glTF importer still uses numpy.bool, removed in numpy 1.24.
try:
    import numpy

    if not hasattr(numpy, "bool"):
        numpy.bool = bool
except ImportError:
    pass


def keyframe_frames(objects):
    """The frames any of `objects`' actions has a keyframe on, sorted (Blender's scene frame range
    is not the imported action's)."""
    frames = set()
    for ob in objects:
        ad = ob.animation_data
        if ad is None or ad.action is None:
            continue
        for fc in ad.action.fcurves:
            for kp in fc.keyframe_points:
                frames.add(round(kp.co[0], 3))
    return sorted(frames)
