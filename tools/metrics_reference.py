#!/usr/bin/env python3
"""Reference values for choreo's metrics, computed with the peers' own code.

Writes tests/fixtures/metrics/{beats,fid}.json; tests/metrics.rs checks the Rust numbers against
them (beats to 1e-6, FID to 1e-4 relative).

- Kinematic beats: FACT's `motion_peak_onehot` (scipy.signal.argrelextrema, order 10 at 60 fps
  scaled to 25 fps) and Bailando's `calc_db` (scipy.ndimage.gaussian_filter, sigma 5 at 60 fps
  scaled), on seeded synthetic motions.
- Beat lists: mir_eval.beat.f_measure, cemgil (plain value), p_score; BAS in both conventions.
- FID: pytorch-fid's `calculate_frechet_distance` with scipy.linalg.sqrtm on seeded feature
  matrices, plus Bailando's mean pairwise distance.

Set-up (once):  python3 -m venv .venv-metrics && .venv-metrics/bin/pip install numpy scipy mir_eval
Run:            .venv-metrics/bin/python tools/metrics_reference.py
"""
import json
import os

import mir_eval
import numpy as np
import scipy
from scipy import linalg
from scipy.ndimage import gaussian_filter
from scipy.signal import argrelextrema

FPS = 25.0
OUT = os.path.join(os.path.dirname(__file__), "..", "tests", "fixtures", "metrics")


def fact_beats(joints, fps):
    """FACT mint/tools/calculate_beat_scores.py motion_peak_onehot, order scaled from 60 fps."""
    velocity = np.zeros_like(joints, dtype=np.float64)
    velocity[1:] = joints[1:] - joints[:-1]
    envelope = np.sum(np.linalg.norm(velocity, axis=2), axis=1)
    order = max(1, int(round(10 * fps / 60)))
    idx = argrelextrema(envelope, np.less, axis=0, order=order)[0]
    return idx / fps


def bailando_beats(joints, fps):
    """Bailando utils/metrics_new.py calc_db, sigma scaled from 60 fps."""
    vel = np.mean(np.sqrt(np.sum((joints[1:] - joints[:-1]) ** 2, axis=2)), axis=1)
    vel = gaussian_filter(vel, 5 * fps / 60)
    idx = argrelextrema(vel, np.less)[0]
    return idx / fps


def bas(reference, other, sigma=0.05):
    """Mean over `reference` of exp(-d^2 / 2 sigma^2), d the distance to the nearest of `other`."""
    if len(reference) == 0 or len(other) == 0:
        return 0.0
    d = np.abs(np.asarray(reference)[:, None] - np.asarray(other)[None, :]).min(axis=1)
    return float(np.mean(np.exp(-(d**2) / 2 / sigma**2)))


def synthetic_motion(rng, frames, joints):
    """A smooth random dance with a beat-like speed envelope (cm-scale steps, in metres)."""
    t = np.arange(frames) / FPS
    base = rng.normal(size=(joints, 3)) * 0.3
    phase = rng.uniform(0, 2 * np.pi, size=(joints, 3))
    freq = rng.uniform(0.5, 2.5, size=(joints, 3))
    pos = base[None] + 0.1 * np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase[None])
    pos += np.cumsum(rng.normal(scale=0.002, size=pos.shape), axis=0)
    # Round through float32's shortest decimal so the JSON holds exactly the values used here.
    return np.array([float(str(x)) for x in pos.astype(np.float32).ravel()]).reshape(pos.shape)


def beat_list(rng, duration, period, jitter, drop):
    beats = np.arange(rng.uniform(0, period), duration, period)
    beats = beats + rng.normal(scale=jitter, size=beats.shape)
    beats = beats[rng.uniform(size=beats.shape) >= drop]
    return np.sort(beats[(beats >= 0) & (beats <= duration)])


def beats_fixture(rng):
    motions = []
    for k in range(4):
        frames, joints = [250, 300, 180, 400][k], [2, 3, 2, 1][k]
        pos = synthetic_motion(rng, frames, joints)
        music = beat_list(rng, frames / FPS, rng.uniform(0.4, 0.8), 0.02, 0.1)
        fb = fact_beats(pos.astype(np.float32).astype(np.float64), FPS)
        bb = bailando_beats(pos.astype(np.float32).astype(np.float64), FPS)
        motions.append({
            "fps": FPS,
            "shape": list(pos.shape),
            "positions": pos.ravel().tolist(),
            "music_beats": music.tolist(),
            "fact_beats": fb.tolist(),
            "bailando_beats": bb.tolist(),
            "bas_fact": bas(fb, music),
            "bas_bailando": bas(music, bb),
            "f_measure": float(mir_eval.beat.f_measure(music, fb)),
            "cemgil": float(mir_eval.beat.cemgil(music, fb)[0]),
            "p_score": float(mir_eval.beat.p_score(music, fb)),
        })
    lists = []
    for k in range(40):
        dur = rng.uniform(5, 60)
        ref = beat_list(rng, dur, rng.uniform(0.3, 1.0), 0.0, 0.0)
        if k % 3 == 0:
            # Estimated beats on a 25-fps frame grid, as kinematic beats are.
            est = np.round(beat_list(rng, dur, rng.uniform(0.3, 1.0), 0.05, 0.2) * FPS) / FPS
            est = np.unique(est)
        else:
            est = beat_list(rng, dur, rng.uniform(0.3, 1.0), 0.03, 0.3)
        lists.append({
            "reference": ref.tolist(),
            "estimated": est.tolist(),
            "f_measure": float(mir_eval.beat.f_measure(ref, est)),
            "cemgil": float(mir_eval.beat.cemgil(ref, est)[0]),
            "p_score": float(mir_eval.beat.p_score(ref, est)),
            "bas_fact": bas(est, ref),
            "bas_bailando": bas(ref, est),
        })
    return {"motions": motions, "beat_lists": lists}


def frechet_distance(mu1, sigma1, mu2, sigma2, eps=1e-6):
    """pytorch-fid's calculate_frechet_distance (as FACT and Bailando use it)."""
    diff = mu1 - mu2
    covmean = linalg.sqrtm(sigma1.dot(sigma2))
    if not np.isfinite(covmean).all():
        offset = np.eye(sigma1.shape[0]) * eps
        covmean = linalg.sqrtm((sigma1 + offset).dot(sigma2 + offset))
    if np.iscomplexobj(covmean):
        covmean = covmean.real
    return float(diff.dot(diff) + np.trace(sigma1) + np.trace(sigma2) - 2 * np.trace(covmean))


def avg_distance(x):
    n = x.shape[0]
    total = 0.0
    for i in range(n):
        for j in range(i + 1, n):
            total += np.linalg.norm(x[i] - x[j])
    return float(total / (n * (n - 1) / 2))


def fid_fixture(rng):
    cases = []
    # The last case has fewer samples than dimensions: singular covariances, as a short dance gives.
    for n1, n2, d in [(80, 60, 8), (150, 120, 16), (40, 30, 12), (15, 12, 20)]:
        a = rng.normal(size=(n1, d)) @ rng.normal(size=(d, d))
        b = rng.normal(loc=0.3, size=(n2, d)) @ rng.normal(size=(d, d)) * 0.8
        a, b = np.round(a, 5), np.round(b, 5)
        # Z-normalise both by the first set's statistics, as choreo does with the train set.
        mean, std = a.mean(axis=0), a.std(axis=0)
        a_n, b_n = (a - mean) / (std + 1e-10), (b - mean) / (std + 1e-10)
        fid = frechet_distance(a_n.mean(0), np.cov(a_n, rowvar=False), b_n.mean(0), np.cov(b_n, rowvar=False))
        cases.append({
            "a": a.tolist(),
            "b": b.tolist(),
            "fid_normalised": fid,
            "div_a": avg_distance(a_n),
            "div_b": avg_distance(b_n),
        })
    return {"cases": cases}


def main():
    os.makedirs(OUT, exist_ok=True)
    rng = np.random.default_rng(20241122)
    versions = {"numpy": np.__version__, "scipy": scipy.__version__, "mir_eval": mir_eval.__version__}
    for name, fx in [("beats", beats_fixture(rng)), ("fid", fid_fixture(rng))]:
        fx["generated_by"] = "tools/metrics_reference.py"
        fx["versions"] = versions
        with open(os.path.join(OUT, f"{name}.json"), "w") as f:
            json.dump(fx, f)
        print(f"wrote {name}.json")


if __name__ == "__main__":
    main()
