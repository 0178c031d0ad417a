#!/usr/bin/env bash
# Whole-song check of a served model on every song of ../shared/audio: seeds 1 and 2, without key
# poses and with 5 poses of test dance DANCE_W_3 spread over the song, each measured by
# tools/wholesong_check.py (numpy, independent of the Rust metrics). Prints a Markdown table.
# Needs ffprobe (ffmpeg) and a Python with numpy. Models without key poses: KEYS=0.
#   PYTHON=/path/to/python [KEYS=0] tools/wholesong_check.sh MODEL [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
model=${1:?usage: tools/wholesong_check.sh MODEL [OUT]}
out=${2:-/tmp/wholesong-$model}
py=${PYTHON:-python3}
mkdir -p "$out"
echo "| song | seed | keys | frames | lowest foot p5 / median (m) | accel p99.9 / max (m/s²) | max within ±0.5 s of a key | worst key error (cm) | speed (m/s) | freeze L/F |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for song in ../shared/audio/*.{mp3,wav,flac,ogg,m4a}; do
  [[ -e $song ]] || continue
  name=$(basename "${song%.*}")
  duration=$(ffprobe -v error -show_entries format=duration -of csv=p=0 "$song")
  "$py" tools/wholesong_check.py keys "$duration" "$out/$name.keys.json"
  for seed in 1 2; do
    for keys in ${KEYS:-0 5}; do
      dir="$out/$name-s$seed-k$keys"
      extra=()
      [[ $keys == 5 ]] && extra=(--key-poses "$out/$name.keys.json")
      OMP_WAIT_POLICY=PASSIVE ./target/release/choreo generate "$song" --model "$model" --out "$dir" --seed "$seed" "${extra[@]}" >/dev/null 2>&1
      if [[ $keys == 5 ]]; then m=$("$py" tools/wholesong_check.py measure "$dir" "$out/$name.keys.json"); else m=$("$py" tools/wholesong_check.py measure "$dir"); fi
      "$py" -c "import json,sys; m=json.loads(sys.argv[1]); print('| $name | $seed | $keys | %d | %.3f / %.3f | %.1f / %.1f | %s | %s | %.3f | %.2f |' % (m['frames'], m['low_p5'], m['low_median'], m['acc_p999'], m['acc_max'], ('%.1f' % m['acc_near_keys_max']) if 'acc_near_keys_max' in m else '–', ('%.2f' % m['key_err_max_cm']) if 'key_err_max_cm' in m else '–', m['speed'], m['freeze']))" "$m"
    done
  done
  echo "| $name | 1 vs 2 | 0 | root-relative pose distance $("$py" tools/wholesong_check.py seeds "$out/$name-s1-k0" "$out/$name-s2-k0") m | | | | | | |"
done
