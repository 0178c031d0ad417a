#!/usr/bin/env bash
# The λ × σ sweep of the key-pose transformer's weighted loss ω(t) = 1 + λ·Σ exp(−(t−t_i)²/2σ²)
# (like the paper's Tables 1–4): one short training run per setting, all with the same
# seed, data, steps and evaluation, then a table of key-pose consistency against smoothness.
#
# Usage: tools/keypose_sweep.sh [OUT_DIR] [EPOCHS] [PARALLEL]
#   OUT_DIR   where each run's folder goes (default: target/keypose-sweep)
#   EPOCHS    training epochs per setting (default 3; the served model trained 13)
#   PARALLEL  runs at once, one libtorch thread each (default 1)
# CHOREO_BIN names another binary (e.g. a copy, so that rebuilding meanwhile is safe).
# Each run writes OUT_DIR/lambda<L>_sigma<S>/{model.json,train_log.jsonl,eval.json,weights.safetensors};
# its result is one row of docs/experiments.md (OUT_DIR/sweep.md holds the table).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/keypose-sweep}
epochs=${2:-3}
parallel=${3:-1}
bin=${CHOREO_BIN:-target/release/choreo}
[[ -x $bin ]] || cargo build --release
mkdir -p "$out"

run() {
  local lambda=$1 sigma=$2 dir="$out/lambda${1}_sigma${2}"
  if [[ -f $dir/eval.json ]] && grep -q scv_at_joins "$dir/eval.json"; then
    echo "sweep: $dir done already" >&2; return 0
  fi
  echo "sweep: λ=$lambda σ=$sigma → $dir" >&2
  OMP_WAIT_POLICY=PASSIVE OMP_NUM_THREADS=1 "$bin" train keypose-transformer \
    --lambda "$lambda" --sigma "$sigma" --epochs "$epochs" --threads 1 --out "$dir" >"$dir.log" 2>&1
}

jobs=()
for sigma in 3 6; do
  for lambda in 0 1 3 5; do
    run "$lambda" "$sigma" &
    jobs+=($!)
    while (( $(jobs -rp | wc -l) >= parallel )); do wait -n || true; done
  done
done
wait

python3 - "$out" "$epochs" <<'PY'
import json, pathlib, sys
out, epochs = pathlib.Path(sys.argv[1]), sys.argv[2]
rows = []
for d in sorted(out.glob("lambda*_sigma*")):
    e = d / "eval.json"
    if not e.is_file():
        continue
    ev = json.loads(e.read_text())
    lam, sig = d.name[len("lambda"):].split("_sigma")
    rows.append((float(sig), float(lam), ev))
lines = [
    f"Key-pose transformer: λ × σ sweep ({epochs} epochs each, same seed and data; 6 test dances, 4 key poses each).",
    "Consistency = mean per-joint error at key frames of the network alone (before the exact pass), cm.",
    "S_cv (lower is smoother) of the network output and of the served output; Real S_cv = "
    + (f"{rows[0][2]['scv_real']:.3f}" if rows else "–") + ".",
    "",
    "| σ (frames) | λ | consistency cm ↓ | S_cv network | S_cv served | S_cv at joins | S_cv within windows | dance error cm |",
    "|---|---|---|---|---|---|---|---|",
]
for sig, lam, ev in sorted(rows, key=lambda r: (r[0], r[1])):
    lines.append(
        f"| {sig:g} | {lam:g} | {ev['network_error_cm']:.2f} | {ev['scv_network']:.3f} | {ev['scv_served']:.3f} | "
        f"{ev['scv_at_joins']:.3f} | {ev['scv_within_windows']:.3f} | {ev['dance_error_cm']:.1f} |"
    )
(out / "sweep.md").write_text("\n".join(lines) + "\n")
print("\n".join(lines))
PY
