#!/usr/bin/env python3
"""Does a dance change its posture over the song, or hold one figure throughout?

The served lines (arm speed, tempo lock, song and seed distances) all pass for a dance whose
arms swing fast around one fixed shape for three minutes: dance-revolution's previews hold one
arm out and one raised from the first second to the last. This measures what they miss: the
posture's own change over the song.

Posture variety: the elbows and wrists relative to the spine (or, for `all`, those and the knees
and ankles), turned into the hips' facing frame, averaged over each 4-s window; then the median,
over every pair of windows at least 8 s apart, of the mean joint distance between the two
averages (metres). A dance that repeats one figure has near-equal window averages (≈ 0); one
that moves through figures has distant ones. Songs shorter than 30 s are left out.

    python3 tools/posture_variety.py real [DATA]     # the 43 real dances (default ../shared/...)
    python3 tools/posture_variety.py DIR...          # every motion.json below each DIR

choreo computes the same measure in Rust (`metrics::posture::posture_variety_m`: every
report.json's musicality, `posture_variety_m`); this script is the independent numpy check, and
measures folders of downloaded dances.

Needs numpy (Debian's python3-numpy: /usr/bin/python3).
"""
import glob
import json
import os
import sys

import numpy as np

# The dataset's joint order (src/motion/skeleton.rs JOINT_NAMES).
NAMES = ["head_right", "head_left", "spine", "right_shoulder", "right_elbow", "right_forearm",
         "right_wrist", "right_hip", "right_knee", "right_ankle", "right_heel", "right_toe",
         "left_shoulder", "left_elbow", "left_forearm", "left_wrist", "left_hip", "left_knee",
         "left_ankle", "left_heel", "left_toe", "left_hand_dir", "right_hand_dir"]
ARMS = ["right_elbow", "right_wrist", "left_elbow", "left_wrist"]
LIMBS = ARMS + ["right_knee", "right_ankle", "left_knee", "left_ankle"]
WINDOW_S = 4.0
GAP_S = 8.0
MIN_SONG_S = 30.0


def variety(positions, names, fps):
    """{'arms': m, 'all': m} for positions [frames, joints, 3] in metres, y up."""
    ix = {n: i for i, n in enumerate(names)}
    spine = positions[:, ix["spine"]]
    hips = positions[:, ix["left_hip"]] - positions[:, ix["right_hip"]]
    yaw = np.arctan2(hips[:, 2], hips[:, 0])
    c, s = np.cos(-yaw)[:, None], np.sin(-yaw)[:, None]
    out = {}
    for label, joints in (("arms", ARMS), ("all", LIMBS)):
        r = positions[:, [ix[j] for j in joints]] - spine[:, None]
        x = r[..., 0] * c - r[..., 2] * s
        z = r[..., 0] * s + r[..., 2] * c
        r = np.stack([x, r[..., 1], z], -1)
        w = int(WINDOW_S * fps)
        n = len(r) // w
        means = r[: n * w].reshape(n, w, len(joints), 3).mean(1)
        gap = int(GAP_S / WINDOW_S)
        d = [np.linalg.norm(means[i] - means[j], axis=-1).mean()
             for i in range(n) for j in range(i + gap, n)]
        out[label] = float(np.median(d)) if d else float("nan")
    return out


def summary(label, values):
    a = np.array([v["arms"] for _, v in values])
    b = np.array([v["all"] for _, v in values])
    print(f"{label}: {len(values)} dances; arms min {a.min():.3f} p10 {np.percentile(a, 10):.3f} "
          f"median {np.median(a):.3f} max {a.max():.3f}; arms and legs median {np.median(b):.3f}")
    return a


def main(args):
    if args[0] == "real":
        data = args[1] if len(args) > 1 else "../shared/data/dance-with-melody"
        rows = []
        for d in sorted(glob.glob(os.path.join(data, "DANCE_*"))):
            p = np.load(os.path.join(d, "skeletons.npy")) / 100.0  # centimetres
            rows.append((os.path.basename(d), variety(p, NAMES, 25.0)))
        summary("real dances", rows)
        return
    real_min = 0.059  # the real dances' lowest arms figure (`real` above)
    for top in args:
        rows = []
        for f in sorted(glob.glob(os.path.join(top, "**", "motion.json"), recursive=True)):
            m = json.load(open(f))
            if m["num_frames"] < MIN_SONG_S * m["fps"]:
                continue
            rows.append((f, variety(np.array(m["positions"]), m["joint_names"], m["fps"])))
        if not rows:
            print(f"{top}: no motion.json of {MIN_SONG_S:.0f} s or more")
            continue
        a = summary(top, rows)
        print(f"  under the slowest-changing real dance ({real_min} m): {(a < real_min).sum()} of {len(a)}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["real"])
