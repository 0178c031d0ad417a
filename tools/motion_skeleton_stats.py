#!/usr/bin/env python3
"""Figures behind src/motion/skeleton.rs: how the 23 dance-with-melody joints were identified.

Reads ../shared/data/dance-with-melody (never copied into the repo) and prints, over all dances:
mean height of each joint relative to the body centre, distance mean ± std (over frames) between
joints of each chain, which foot point lies in front of the ankle, which side each chain is on,
and the least-squares weights that give the body centre as a weighted centroid of the joints.

Usage: .venv-motion/bin/python tools/motion_skeleton_stats.py [DATASET_ROOT]
(needs numpy: python3 -m venv .venv-motion && .venv-motion/bin/pip install numpy)
"""
import glob
import sys

import numpy as np

root = sys.argv[1] if len(sys.argv) > 1 else "../shared/data/dance-with-melody"
dirs = sorted(glob.glob(root + "/DANCE_*"))
if not dirs:
    sys.exit(f"no dances under {root}")
S = np.concatenate([np.load(d + "/skeletons.npy") for d in dirs]).astype(np.float64)
print(f"{len(dirs)} dances, {len(S)} frames")
np.set_printoptions(precision=1, suppress=True, linewidth=150)
print("mean height above the body centre (cm):", S[:, :, 1].mean(0))


def dist(a, b):
    d = np.linalg.norm(S[:, a] - S[:, b], axis=-1)
    return d.mean(), d.std()


for chain in ([3, 4, 5, 6, 22], [12, 13, 14, 15, 21], [7, 8, 9, 10, 11], [16, 17, 18, 19, 20], [0, 1, 2, 3, 12, 7, 16]):
    print("distances (cm, mean±std over frames) within", chain)
    for a in chain:
        print(f"  {a:2d}", " ".join("%5.1f±%3.1f" % dist(a, b) for b in chain))

# Body frame: right = (7 - 16) horizontal, up = y; the toes tell forward.
lat = S[:, 7] - S[:, 16]
lat[:, 1] = 0
lat /= np.linalg.norm(lat, axis=-1, keepdims=True)
up = np.array([0.0, 1.0, 0.0])
fwd = np.cross(up, lat)  # forward if 7 is the right hip (right-handed, y up)
for ankle, heel, toe in ((9, 10, 11), (18, 19, 20)):
    a = ((S[:, toe] - S[:, ankle]) * fwd).sum(-1)
    b = ((S[:, heel] - S[:, ankle]) * fwd).sum(-1)
    print(f"ankle {ankle}: point {toe} in front {100 * (a > 0).mean():.1f}% of frames; point {heel} behind {100 * (b < 0).mean():.1f}%")
side = (S * lat[:, None, :]).sum(-1).mean(0)
print("mean offset along the 16→7 axis (cm; + = right side if up×(16→7) is forward):", side)

# Body centre as a weighted centroid: minimise |sum_j w_j s_j|^2 subject to sum w = 1.
A = S.transpose(0, 2, 1).reshape(-1, S.shape[1])
w = np.linalg.solve(A.T @ A, np.ones(S.shape[1]))
w /= w.sum()
r = np.linalg.norm((S * w[None, :, None]).sum(1), axis=-1)
print("centre weights:", np.round(w, 4).tolist())
print("centre residual (cm) p50 %.2f p95 %.2f max %.2f" % (np.percentile(r, 50), np.percentile(r, 95), r.max()))
