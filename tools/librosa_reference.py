#!/usr/bin/env python3
"""librosa 0.11.0 reference for choreo's audio module (src/audio/).

    python3 tools/librosa_reference.py fixtures   # writes tests/fixtures/audio/<song>/
    python3 tools/librosa_reference.py bench --fps 25 SONG...   # JSON timings, one thread

Run with any python3: it creates .venv-librosa with librosa==0.11.0 (PyPI) on first use and
re-executes itself there. Songs: every .ogg in ../shared/audio and three test-split songs of
../shared/data/dance-with-melody (one cha-cha, one rumba, one waltz). Only small summaries are
written: full 1-D envelopes, beat frames, and every `step`-th frame of 2-D features, so the
fixtures stay near 2 MB. The songs themselves are never copied.
"""
import os
import sys

# One thread for numpy/scipy/numba, set before they are imported (the bench compares with
# choreo on one thread).
for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(var, "1")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VENV = os.path.join(ROOT, ".venv-librosa")
LIBROSA = "0.11.0"


def ensure_librosa():
    """Re-exec inside .venv-librosa (created on demand) unless librosa 0.11.0 is importable."""
    try:
        import librosa  # noqa: F401

        if librosa.__version__ == LIBROSA:
            return
    except ImportError:
        pass
    py = os.path.join(VENV, "bin", "python")
    if os.path.abspath(sys.executable) == os.path.abspath(py):
        sys.exit(f"librosa=={LIBROSA} is not importable in {VENV}")
    if not os.path.exists(py):
        import subprocess

        subprocess.check_call([sys.executable, "-m", "venv", VENV])
        subprocess.check_call([py, "-m", "pip", "install", "-q", f"librosa=={LIBROSA}", "soundfile"])
    os.execv(py, [py] + sys.argv)


ensure_librosa()

import json  # noqa: E402
import time  # noqa: E402

import librosa  # noqa: E402
import numpy as np  # noqa: E402

SHARED = os.path.join(ROOT, "..", "shared")
OUT = os.path.join(ROOT, "tests", "fixtures", "audio")
DANCE_SONGS = ["DANCE_C_8", "DANCE_R_9", "DANCE_W_3"]
HOP = 512
N_FFT = 2048


def songs():
    audio_dir = os.path.join(SHARED, "audio")
    out = [(os.path.splitext(f)[0], os.path.join(audio_dir, f)) for f in sorted(os.listdir(audio_dir)) if f.endswith(".ogg")]
    data = os.path.join(SHARED, "data", "dance-with-melody")
    out += [(d, os.path.join(data, d, "audio.mp3")) for d in DANCE_SONGS]
    return out


def grid(fps):
    """choreo's feature grid: hop 512 doubled until fps * hop >= 12 kHz; sr = fps * hop."""
    hop = HOP
    while fps * hop < 12000:
        hop *= 2
    return int(round(fps * hop)), hop


def dance_revolution(y, sr, hop):
    """The DanceRevolution set as the paper's prepro.py/extractor.py compute it, in choreo's
    column order: MFCC 20 | dMFCC 20 | chroma_cqt 12 | tempogram 384 | onset 1 | beat 1."""
    mel = librosa.feature.melspectrogram(y=y, sr=sr, n_fft=N_FFT, hop_length=hop)
    mel_db = librosa.power_to_db(mel, ref=np.max)
    mfcc = librosa.feature.mfcc(S=mel_db, n_mfcc=20)
    dmfcc = librosa.feature.delta(mfcc, width=3)
    harmonic, percussive = librosa.effects.hpss(y, n_fft=N_FFT, hop_length=hop)
    chroma = librosa.feature.chroma_cqt(y=harmonic, sr=sr, hop_length=hop)
    onset = librosa.onset.onset_strength(y=percussive, sr=sr, hop_length=hop, aggregate=np.median)
    tg = librosa.feature.tempogram(onset_envelope=onset, sr=sr, hop_length=hop)
    _, beats = librosa.beat.beat_track(onset_envelope=onset, sr=sr, hop_length=hop)
    one_hot = np.zeros(len(onset), dtype=np.float32)
    one_hot[beats] = 1.0
    t = min(mfcc.shape[1], chroma.shape[1], tg.shape[1], len(onset))
    return np.concatenate([mfcc[:, :t], dmfcc[:, :t], chroma[:, :t], tg[:, :t], onset[None, :t], one_hot[None, :t]]).T


def rows(x, step):
    """Every `step`-th frame of a [bins, frames] array, as [rows, bins] float32."""
    return np.ascontiguousarray(x[:, ::step].T.astype(np.float32))


def fixtures():
    os.makedirs(OUT, exist_ok=True)
    for name, path in songs():
        if not os.path.exists(path):
            sys.exit(f"missing {path}")
        d = os.path.join(OUT, name)
        os.makedirs(d, exist_ok=True)
        meta = {"source": os.path.relpath(path, ROOT), "librosa": librosa.__version__}

        # Native rate: the DSP itself (no resampler in between).
        y, sr = librosa.load(path, sr=None)
        meta.update(sr_native=int(sr), n_native=int(len(y)))
        mel = librosa.feature.melspectrogram(y=y, sr=sr)
        t_n = mel.shape[1]
        step = max(1, t_n // 150)
        meta["step_native"] = step
        np.save(os.path.join(d, "mel_native.npy"), rows(mel, step))
        np.save(os.path.join(d, "mfcc_native.npy"), rows(librosa.feature.mfcc(S=librosa.power_to_db(mel), n_mfcc=20), step))
        np.save(os.path.join(d, "onset_native.npy"), librosa.onset.onset_strength(y=y, sr=sr).astype(np.float32))
        S = np.abs(librosa.stft(y)) ** 2
        meta["tuning_stft_native"] = float(librosa.estimate_tuning(S=S, sr=sr, bins_per_octave=12))
        meta["tuning_cqt_native"] = float(librosa.estimate_tuning(y=y, sr=sr, bins_per_octave=36))
        np.save(os.path.join(d, "chroma_stft_native.npy"), rows(librosa.feature.chroma_stft(S=S, sr=sr), step))
        np.save(os.path.join(d, "chroma_cqt_native.npy"), rows(librosa.feature.chroma_cqt(y=y, sr=sr), step))
        del S

        # librosa's default analysis rate: beats and tempo as `choreo analyze` reports them.
        y22, sr22 = librosa.load(path)
        meta.update(sr22=int(sr22), n22=int(len(y22)))
        onset22 = librosa.onset.onset_strength(y=y22, sr=sr22, aggregate=np.median)
        np.save(os.path.join(d, "onset22_median.npy"), onset22.astype(np.float32))
        tempo, beats = librosa.beat.beat_track(y=y22, sr=sr22)
        meta["tempo22"] = float(np.atleast_1d(tempo)[0])
        meta["beats22"] = [int(b) for b in beats]
        # The same beat tracker on our own onset envelope isolates the DP from the front end.
        meta["tempo22_from_onset"] = float(np.atleast_1d(librosa.feature.tempo(onset_envelope=onset22, sr=sr22))[0])
        np.save(os.path.join(d, "tempogram22.npy"), rows(librosa.feature.tempogram(onset_envelope=onset22, sr=sr22), step))

        # The DanceRevolution set at 25 fps, end to end (librosa resamples with soxr_hq).
        fsr, fhop = grid(25)
        y25, _ = librosa.load(path, sr=fsr)
        dr = dance_revolution(y25, fsr, fhop).T
        step25 = max(1, dr.shape[1] // 40)
        meta.update(sr25=fsr, n25=int(len(y25)), frames25=int(dr.shape[1]), step25=step25)
        np.save(os.path.join(d, "dance_revolution25.npy"), rows(dr, step25))
        np.save(os.path.join(d, "onset25_percussive.npy"), dr[436].astype(np.float32))
        meta["beats25"] = [int(i) for i in np.flatnonzero(dr[437])]

        with open(os.path.join(d, "ref.json"), "w") as f:
            json.dump(meta, f, indent=1)
        print(name, {k: v for k, v in meta.items() if not isinstance(v, list)}, flush=True)


def bench(argv):
    import argparse

    ap = argparse.ArgumentParser()
    ap.add_argument("--fps", type=float, default=25.0)
    ap.add_argument("songs", nargs="+")
    a = ap.parse_args(argv)
    sr, hop = grid(a.fps)
    # Warm numba's JIT (beat tracker) on noise so compile time is not counted.
    dance_revolution(np.random.default_rng(0).standard_normal(sr * 5).astype(np.float32) * 0.1, sr, hop)
    for song in a.songs:
        t0 = time.perf_counter()
        y, _ = librosa.load(song, sr=sr)
        t1 = time.perf_counter()
        feats = dance_revolution(y, sr, hop)
        t2 = time.perf_counter()
        # Beats as `choreo analyze` gives them: librosa's default rate, its own decode.
        y22, sr22 = librosa.load(song)
        librosa.beat.beat_track(y=y22, sr=sr22)
        t3 = time.perf_counter()
        print(json.dumps({"song": song, "decode_s": t1 - t0, "features_s": t2 - t1, "total_s": t2 - t0, "beats_s": t3 - t2, "frames": int(feats.shape[0])}), flush=True)


if __name__ == "__main__":
    cmd = sys.argv[1] if len(sys.argv) > 1 else "fixtures"
    if cmd == "fixtures":
        fixtures()
    elif cmd == "bench":
        bench(sys.argv[2:])
    else:
        sys.exit(__doc__)
