#!/usr/bin/env bash
# Checks that two builds of choreo serve the same dances: for every model, two songs of
# ../shared/audio and seeds 0 and 1, `choreo generate` with each binary, and motion.json,
# motion.bvh and motion.glb compared byte for byte. report.json and preview.png are not compared
# (a change that adds to the report is the usual reason to run this); `diff` of the two
# report.json files shows what did change there. Prints one line a dance; exits 1 if any differs.
#   tools/served_identical.sh BEFORE_BIN AFTER_BIN [OUT]
# SONGS (paths, space-separated), MODELS and SEEDS override the defaults.
set -euo pipefail
cd "$(dirname "$0")/.."
before=${1:?usage: tools/served_identical.sh BEFORE_BIN AFTER_BIN [OUT]}
after=${2:?usage: tools/served_identical.sh BEFORE_BIN AFTER_BIN [OUT]}
out=${3:-/tmp/served-identical}
songs=${SONGS:-../shared/audio/trumpet_loop_90bpm.ogg ../shared/audio/hungarian_dance_5.ogg}
models=${MODELS:-dance-revolution keypose-transformer dancenet tsmt beat-graph}
seeds=${SEEDS:-0 1}
mkdir -p "$out"
differ=0
for song in $songs; do
  name=$(basename "${song%.*}")
  for model in $models; do
    for seed in $seeds; do
      case_dir="$out/$model-$name-s$seed"
      for side in before after; do
        bin=$before
        [[ $side == after ]] && bin=$after
        rm -rf "$case_dir/$side"
        OMP_WAIT_POLICY=PASSIVE "$bin" generate --model "$model" --seed "$seed" \
          --out "$case_dir/$side" "$song" >"$case_dir.$side.log" 2>&1
      done
      same=yes
      for file in motion.json motion.bvh motion.glb; do
        cmp -s "$case_dir/before/$file" "$case_dir/after/$file" || same="no ($file)"
      done
      echo "$model $name seed $seed: identical $same"
      [[ $same == yes ]] || differ=1
    done
  done
done
exit $differ
