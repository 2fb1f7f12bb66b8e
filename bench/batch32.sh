#!/usr/bin/env bash
# The production-batch benchmark (docs/benchmarks.md, "trainer batch"): 32 simulated
# units of mixed gyro designs, each a 17-h planned run at 10 Hz (trainer plan) to train on
# and a 4-h cycle to hold out, one `trainer batch`; prints wall time, units per minute and
# the peak memory of the batch and its fits (GNU time's maximum resident set size).
# Usage: bench/batch32.sh [TRAINER] [WORKDIR]
set -euo pipefail
T=${1:-target/release/trainer}
W=${2:-$(mktemp -d)}
mkdir -p "$W/runs"
"$T" plan --min-c -40 --max-c 60 --max-rate-c-per-min 1 --hours 17 -o "$W/plan.csv" --force >/dev/null
{
  echo 'batch = "BENCH-32"'
  for i in $(seq 1 32); do
    d=$(( (i % 4) + 1 ))
    "$T" simulate --chamber-profile "$W/plan.csv" --sample-rate-hz 10 --design "$d" --seed "$i" -o "$W/runs/u$i.csv" --force >/dev/null
    "$T" simulate --profile cycle --hours 4 --sample-rate-hz 10 --design "$d" --seed "$((1000 + i))" -o "$W/runs/h$i.csv" --force >/dev/null
    printf '[[unit]]\nserial = "FOG-%04d"\ntrain = ["runs/u%d.csv"]\nholdout = ["runs/h%d.csv"]\n' "$i" "$i" "$i"
  done
} > "$W/batch.toml"
start=$(date +%s.%N)
/usr/bin/time -v "$T" batch "$W/batch.toml" -o "$W/out" --force 2> "$W/time.txt" >/dev/null || true
end=$(date +%s.%N)
grep -E "^\[|units, " "$W/time.txt" | tail -3
awk -v s="$start" -v e="$end" 'BEGIN { printf "wall %.1f s, %.2f units/min\n", e - s, 32 * 60 / (e - s) }'
grep -E "Maximum resident" "$W/time.txt"
