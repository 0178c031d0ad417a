"""Independent numpy check of generated dances (motion.json), for the model cards' whole-song tables.

It recomputes, from the exported world positions only, the plausibility figures that
`src/metrics/physical.rs` reports, so the Rust measures are checked against a second
implementation: lowest foot height (p5, median; foot points = heels and toes), mean joint
acceleration p99.9 and max (|p[t+1] - 2p[t] + p[t-1]| * fps^2, mean over the 23 dataset joints),
the largest within +-0.5 s of each key pose, mean joint speed, the last/first-30-s energy ratio, and
the root-relative pose distance between two seeds.

usage: wholesong_check.py measure DIR [KEYS.json]   one dance folder (motion.json inside)
       wholesong_check.py seeds DIR_A DIR_B          root-relative distance of two dances (m)
       wholesong_check.py keys DURATION_S OUT.json   5 poses of test dance DANCE_W_3, spread over a song
"""
import json
import sys

import numpy as np

FEET = [10, 11, 19, 20]  # dataset joints: right heel, right toe, left heel, left toe
DATA = "../shared/data/dance-with-melody"


def load(d):
    m = json.load(open(f"{d}/motion.json"))
    p = np.asarray(m["positions"], dtype=np.float64)
    # motion.json joint j+1 is the dataset's joint j; joint 0 is the body centre.
    return m["fps"], p[:, 1:24], p[:, 0]


def measure(d, keys_path=None):
    fps, p, _ = load(d)
    low = p[:, FEET, 1].min(1)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=2).mean(1) * fps
    acc = np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=2).mean(1) * fps * fps
    energy = (np.linalg.norm(np.diff(p, axis=0), axis=2) ** 2).mean(1) * fps * fps
    span = min(int(30 * fps), len(energy) // 2)
    out = {
        "frames": len(p),
        "low_p5": np.percentile(low, 5),
        "low_median": np.median(low),
        "acc_p999": np.percentile(acc, 99.9),
        "acc_max": acc.max(),
        "speed": speed.mean(),
        "freeze": energy[-span:].mean() / max(energy[:span].mean(), 1e-9),
    }
    if keys_path:
        near, errs = [], []
        for k in json.load(open(keys_path)):
            # The key's frame as choreo places it: Rust's round(), half away from zero (Python's
            # round() takes a half to the even side: 59.94 s at 25 fps would be 1498, not 1499).
            f = int(np.floor(k["time_s"] * fps + 0.5))
            # Key error: mean per-joint distance (cm) at the key's frame, both poses centroid-aligned.
            q = np.asarray(k["joints"], dtype=np.float64)
            errs.append(np.linalg.norm((p[f] - p[f].mean(0)) - (q - q.mean(0)), axis=1).mean() * 100)
            # acc[i] is frame i + 1's acceleration.
            lo, hi = max(0, f - int(0.5 * fps) - 1), min(len(acc), f + int(0.5 * fps))
            near.append(acc[lo:hi].max())
        out["acc_near_keys_max"] = max(near)
        out["key_err_max_cm"] = max(errs)
    return out


def seeds(a, b):
    _, pa, ra = load(a)
    _, pb, rb = load(b)
    n = min(len(pa), len(pb))
    return np.linalg.norm((pa[:n] - ra[:n, None]) - (pb[:n] - rb[:n, None]), axis=2).mean()


def keys(duration, out):
    sk = np.load(f"{DATA}/DANCE_W_3/skeletons.npy") / 100.0
    frames = np.linspace(100, len(sk) - 100, 5).astype(int)
    times = np.linspace(0.15 * duration, 0.85 * duration, 5)
    poses = [{"time_s": round(float(t), 2), "joint_set": "dataset", "joints": sk[f].astype(float).tolist()} for t, f in zip(times, frames)]
    json.dump(poses, open(out, "w"))


if __name__ == "__main__":
    cmd, args = sys.argv[1], sys.argv[2:]
    if cmd == "measure":
        print(json.dumps({k: round(float(v), 4) for k, v in measure(*args).items()}))
    elif cmd == "seeds":
        print(round(float(seeds(*args)), 4))
    elif cmd == "keys":
        keys(float(args[0]), args[1])
    else:
        sys.exit(__doc__)
