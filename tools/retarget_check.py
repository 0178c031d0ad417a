"""How a retargeted dance keeps the dance's legs, and how far its joints turn in one frame.

    python3 tools/retarget_check.py MOTION.json RETARGET.bvh|RETARGET.smpl.npz [...]

For each file: the median over frames of |knee angle − motion.json's| and |hip angle −
motion.json's| per side (knee: between thigh and shin; hip: thigh against the torso, mid-hips to
mid-shoulders, as tests/api/retarget.rs measures them), and the largest one-frame turn of any
joint's local rotation (the angle of q_t⁻¹·q_{t+1}) with the share of frame steps on which some
joint turns past 60°, and which joints do. The rig is recognised by its joint names (Mixamo,
VRM, SMPL, the Unreal-named fixture); numpy only, no Blender.
"""
import json
import sys
import zipfile

import numpy as np

# Landmark → joint name, per rig.
RIGS = {
    "mixamo": lambda side, k: "mixamorig:" + side.capitalize() + {
        "shoulder": "Arm", "hip": "UpLeg", "knee": "Leg", "ankle": "Foot"}[k],
    "vrm": lambda side, k: side + {
        "shoulder": "UpperArm", "hip": "UpperLeg", "knee": "LowerLeg", "ankle": "Foot"}[k],
    "smpl": lambda side, k: side + "_" + k,
    "unreal": lambda side, k: {
        "shoulder": "upperarm", "hip": "thigh", "knee": "calf", "ankle": "foot"}[k] + "_" + side[0],
}


def rig_of(names):
    if any(n.startswith("mixamorig:") for n in names):
        return "mixamo"
    if "leftUpperLeg" in names:
        return "vrm"
    if "thigh_l" in names:
        return "unreal"
    return "smpl"


def rot_zyx(z, y, x):
    """Intrinsic ZYX Euler (degrees, [T]) → rotation matrices [T, 3, 3]: Rz · Ry · Rx."""
    z, y, x = np.radians(z), np.radians(y), np.radians(x)
    cz, sz, cy, sy, cx, sx = np.cos(z), np.sin(z), np.cos(y), np.sin(y), np.cos(x), np.sin(x)
    one, zero = np.ones_like(z), np.zeros_like(z)
    rz = np.stack([cz, -sz, zero, sz, cz, zero, zero, zero, one], -1).reshape(-1, 3, 3)
    ry = np.stack([cy, zero, sy, zero, one, zero, -sy, zero, cy], -1).reshape(-1, 3, 3)
    rx = np.stack([one, zero, zero, zero, cx, -sx, zero, sx, cx], -1).reshape(-1, 3, 3)
    return rz @ ry @ rx


def axis_angle(aa):
    """Axis-angle vectors [T, 3] → rotation matrices (Rodrigues)."""
    th = np.linalg.norm(aa, axis=-1, keepdims=True)
    k = np.where(th > 1e-12, aa / np.maximum(th, 1e-12), 0.0)
    kx = np.zeros(aa.shape[:-1] + (3, 3))
    kx[..., 0, 1], kx[..., 0, 2] = -k[..., 2], k[..., 1]
    kx[..., 1, 0], kx[..., 1, 2] = k[..., 2], -k[..., 0]
    kx[..., 2, 0], kx[..., 2, 1] = -k[..., 1], k[..., 0]
    th = th[..., None]
    return np.eye(3) + np.sin(th) * kx + (1 - np.cos(th)) * kx @ kx


def read_bvh(path):
    """Names, parents, offsets [J, 3], root positions [T, 3], local rotations [T, J, 3, 3]."""
    with open(path) as f:
        text = f.read()
    head, motion = text.split("MOTION", 1)
    names, parents, offsets, channels, stack, last = [], [], [], [], [], None
    tokens = head.split()
    i = 0
    while i < len(tokens):
        t = tokens[i]
        if t in ("ROOT", "JOINT"):
            names.append(tokens[i + 1])
            parents.append(stack[-1] if stack else -1)
            last = len(names) - 1
            i += 2
        elif t == "End":
            last = None
            i += 2
        elif t == "{":
            stack.append(last)
            i += 1
        elif t == "}":
            stack.pop()
            i += 1
        elif t == "OFFSET":
            if last is not None:
                offsets.append([float(v) for v in tokens[i + 1:i + 4]])
            i += 4
        elif t == "CHANNELS":
            n = int(tokens[i + 1])
            channels.append(tokens[i + 2:i + 2 + n])
            i += 2 + n
        else:
            i += 1
    lines = motion.strip().splitlines()
    data = np.array([[float(v) for v in line.split()] for line in lines[2:]])
    col, rots, root = 0, [], None
    for ch in channels:
        if len(ch) == 6:
            root = data[:, col:col + 3]
            col += 3
        z, y, x = data[:, col], data[:, col + 1], data[:, col + 2]
        assert ch[-3:] == ["Zrotation", "Yrotation", "Xrotation"], ch
        rots.append(rot_zyx(z, y, x))
        col += 3
    return names, parents, np.array(offsets), root, np.stack(rots, 1)


def read_smpl_npz(path):
    d = np.load(path)
    poses, trans = d["poses"], d["trans"]
    # The rest layout choreo writes (src/motion/retarget/smpl.rs REST), read from the source.
    rest, names, parents = smpl_rest()
    rots = axis_angle(poses.reshape(len(poses), 24, 3))
    offsets = np.array([rest[j] - rest[p] if p >= 0 else np.zeros(3) for j, p in enumerate(parents)])
    return names, parents, offsets, trans + rest[0], rots


def smpl_rest():
    import os
    import re
    src = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "src", "motion", "retarget", "smpl.rs")
    text = open(src).read()
    block = text[text.index("pub const REST"):]
    block = block[block.index("= [") + 3:]
    block = block[:block.index("];")]
    rest = np.array([[float(v) for v in m] for m in re.findall(r"\[(-?[\d.]+), (-?[\d.]+), (-?[\d.]+)\]", block)])
    names = re.findall(r'"(\w+)"', text[text.index("pub const JOINT_NAMES"):text.index("pub const PARENTS")])
    pblock = text[text.index("pub const PARENTS"):text.index("pub const REST")]
    parents = [-1 if p == "None" else int(p[5:-1]) for p in re.findall(r"None|Some\(\d+\)", pblock)]
    return rest, names, parents


def fk(parents, offsets, root, rots):
    t_len, n = rots.shape[:2]
    world = np.zeros((t_len, n, 3, 3))
    pos = np.zeros((t_len, n, 3))
    for j, p in enumerate(parents):
        if p < 0:
            world[:, j] = rots[:, j]
            pos[:, j] = root + offsets[j]
        else:
            world[:, j] = world[:, p] @ rots[:, j]
            pos[:, j] = pos[:, p] + np.einsum("tij,j->ti", world[:, p], offsets[j])
    return pos


def angle(a, b):
    c = np.sum(a * b, -1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(c, -1, 1)))


def leg_angles(pos, at):
    """{"left knee": [T], "left hip": [T], ...} from positions and a landmark → index map."""
    torso = (pos[:, at("left", "shoulder")] + pos[:, at("right", "shoulder")]) / 2 - (
        pos[:, at("left", "hip")] + pos[:, at("right", "hip")]) / 2
    out = {}
    for side in ("left", "right"):
        hip, knee, ankle = (pos[:, at(side, k)] for k in ("hip", "knee", "ankle"))
        out[f"{side} knee"] = angle(hip - knee, ankle - knee)
        out[f"{side} hip"] = angle(torso, knee - hip)
    return out


def turns(rots):
    """Per step and joint, the angle (degrees) of the local rotation's change."""
    rel = np.einsum("tjki,tjkl->tjil", rots[:-1], rots[1:])
    tr = np.trace(rel, axis1=-2, axis2=-1)
    return np.degrees(np.arccos(np.clip((tr - 1) / 2, -1, 1)))


def main():
    motion_path, files = sys.argv[1], sys.argv[2:]
    m = json.load(open(motion_path))
    cpos = np.array(m["positions"], dtype=float)
    cnames = m["joint_names"]
    want = leg_angles(cpos, lambda side, k: cnames.index(f"{side}_{k}"))
    report = {}
    for path in files:
        if path.endswith(".npz"):
            names, parents, offsets, root, rots = read_smpl_npz(path)
        else:
            names, parents, offsets, root, rots = read_bvh(path)
        rig = rig_of(names)
        pos = fk(parents, offsets, root, rots)
        got = leg_angles(pos, lambda side, k: names.index(RIGS[rig](side, k)))
        medians = {k: float(np.median(np.abs(got[k] - want[k]))) for k in want}
        turn = turns(rots)
        step_max = turn.max(1)
        over = {names[j]: int((turn[:, j] > 60).sum()) for j in range(len(names)) if (turn[:, j] > 60).any()}
        worst = np.unravel_index(np.argmax(turn), turn.shape)
        report[path] = {
            "rig": rig,
            "frames": int(len(rots)),
            "median_deg": {k: round(v, 2) for k, v in medians.items()},
            "max_turn_deg": round(float(step_max.max()), 1),
            "max_turn_at": [int(worst[0]), names[worst[1]]],
            "steps_over_60": int((step_max > 60).sum()),
            "share_over_60": round(float((step_max > 60).mean()), 5),
            "joints_over_60": over,
        }
        print(path, json.dumps(report[path]))
    return report


if __name__ == "__main__":
    main()
