#!/usr/bin/env python3
"""Does librosa hear one song's slow and fast copies at one metrical level?

The tempo section of `choreo eval` reads a follower's step-rate ratio (1.41 for 1.2x over 0.85x)
only where the song's analysis hears both copies at one level. choreo's analysis is librosa's
(`src/audio/rhythm.rs`); this asks librosa 0.11 itself, at its default prior (120 BPM, one
octave) and wider ones, which songs it splits.

    python3 tools/tempo_levels.py DIR...   # each DIR holds <song>_<factor>.wav copies, e.g.
                                           # sox -D song.ogg song_0.85.wav tempo 0.85

A song counts as heard at one level where its tempo ratio lies within 8 % of the factors'.
Needs `pip install librosa` (0.11).
"""
import glob
import os
import sys

import librosa
from librosa.feature.rhythm import tempo

PRIOR_OCTAVES = [1.0, 1.5, 2.0, 3.0, 100.0]


def main(dirs):
    copies = {}
    for d in dirs:
        for path in sorted(glob.glob(os.path.join(d, "*.wav"))):
            song, factor = os.path.basename(path)[:-4].rsplit("_", 1)
            copies.setdefault(song, {})[float(factor)] = path
    one_level = {w: 0 for w in PRIOR_OCTAVES}
    for song, paths in copies.items():
        slow, fast = min(paths), max(paths)
        envelopes = {}
        for f in (slow, fast):
            y, sr = librosa.load(paths[f], sr=22050, mono=True)
            envelopes[f] = (librosa.onset.onset_strength(y=y, sr=sr), sr)
        cells = []
        for w in PRIOR_OCTAVES:
            bpm = {
                f: float(tempo(onset_envelope=o, sr=sr, start_bpm=120, std_bpm=w)[0])
                for f, (o, sr) in envelopes.items()
            }
            ok = abs(bpm[fast] / bpm[slow] / (fast / slow) - 1) < 0.08
            one_level[w] += ok
            cells.append(f"{w:g} oct: {bpm[slow]:5.1f} -> {bpm[fast]:5.1f} {'one' if ok else 'SPLIT'}")
        print(f"{song:22s} " + " | ".join(cells), flush=True)
    print(f"{len(copies)} songs heard at one level, by prior width (octaves): {one_level}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["."])
