#!/usr/bin/env bash
# CPU time per step of the static filters bench (benches/filters.rs) in counted mode: each
# framework step and its hand-written baseline run back to back, REPS times, set-up (count = 0)
# subtracted; prints the median ns per step and the median of the per-repetition ratios (the
# machines are shared and drift between runs, so the ratio of neighbouring runs is the figure
# to quote). Needs perf (Debian's linux-perf).
#   BIN=$(ls -t target/release/deps/filters-* | grep -v '\.d$' | head -1)   # after --no-run
#   estim-filters/benches/filters_counted.sh "$BIN" 5
BIN=$1; REPS=${2:-5}
t() { FILTERS_BENCH_STEPS=$1 perf stat -x, -e task-clock "$BIN" --bench 2>&1 >/dev/null | awk -F, '/task-clock/ {print $1}'; }
pairs="step_3x2_linear/KalmanFilter:step_3x2_linear/hand_kf:2000000
step_3x2_linear/Ukf:step_3x2_linear/hand_ukf:2000000
step_6x4_nonlinear/Ekf:step_6x4_nonlinear/hand_ekf:1000000
step_6x4_nonlinear/SecondOrderEkf:step_6x4_nonlinear/hand_ekf:1000000
step_6x4_nonlinear/Ukf:step_6x4_nonlinear/hand_ukf:1000000"
for p in $pairs; do
  IFS=: read -r fw hand count <<< "$p"
  zf=$(t "$fw=0"); zh=$(t "$hand=0")
  a=""; b=""
  for r in $(seq "$REPS"); do
    a="$a $(t "$fw=$count")"; b="$b $(t "$hand=$count")"
  done
  python3 - "$fw" "$hand" "$count" "$zf" "$zh" "$a" "$b" <<'PY'
import statistics, sys
fw, hand, count, zf, zh, a, b = sys.argv[1:]
count, zf, zh = int(count), float(zf), float(zh)
a = [(float(x) - zf) * 1e6 / count for x in a.split()]
b = [(float(x) - zh) * 1e6 / count for x in b.split()]
ratios = [x / y for x, y in zip(a, b)]
print(f"{fw} {statistics.median(a):.1f} ns | {hand} {statistics.median(b):.1f} ns | ratio {statistics.median(ratios):.2f} (min {min(ratios):.2f}, max {max(ratios):.2f})")
PY
done
