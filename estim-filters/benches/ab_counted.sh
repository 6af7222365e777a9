#!/usr/bin/env bash
# Two builds of the same bench, side by side: CPU time per step of each case in counted mode,
# the two binaries alternating REPS times, set-up (count = 0) subtracted; prints the median
# time of each and the median of the per-pair ratios new/old with its min and max (the
# machines are shared and drift, so neighbouring runs are compared). Needs perf.
#   estim-filters/benches/ab_counted.sh dynamic OLD_BIN NEW_BIN 7
#   estim-filters/benches/ab_counted.sh filters OLD_BIN NEW_BIN 7
KIND=$1; OLD=$2; NEW=$3; REPS=${4:-5}
case $KIND in
  dynamic) VAR=DYNAMIC_BENCH_STEPS
    CASES="kf/n=12/estim=100000 kf/n=50/estim=7000 kf/n=200/estim=250
           ekf/n=12/estim=80000 ekf/n=50/estim=6000 ekf/n=200/estim=200
           ukf/n=12/estim=40000 ukf/n=50/estim=2000 ukf/n=200/estim=60" ;;
  filters) VAR=FILTERS_BENCH_STEPS
    CASES="step_3x2_linear/KalmanFilter=2000000 step_3x2_linear/Ukf=2000000
           step_6x4_nonlinear/Ekf=1000000 step_6x4_nonlinear/SecondOrderEkf=1000000
           step_6x4_nonlinear/Ukf=1000000" ;;
  *) echo "usage: $0 dynamic|filters OLD_BIN NEW_BIN [REPS]" >&2; exit 2 ;;
esac
t() { env "$VAR=$2" perf stat -x, -e task-clock "$1" --bench 2>&1 >/dev/null | awk -F, '/task-clock/ {print $1}'; }
echo "| case | old µs/step | new µs/step | new/old (median) | min | max |"
echo "|---|---:|---:|---:|---:|---:|"
for c in $CASES; do
  name=${c%=*}; count=${c##*=}
  zo=$(t "$OLD" "$name=0"); zn=$(t "$NEW" "$name=0")
  o=""; n=""
  for r in $(seq "$REPS"); do
    o="$o $(t "$OLD" "$c")"; n="$n $(t "$NEW" "$c")"
  done
  python3 - "$name" "$count" "$zo" "$zn" "$o" "$n" <<'PY'
import statistics, sys
name, count, zo, zn, o, n = sys.argv[1:]
count = int(count)
per = lambda xs, z: [(float(x) - float(z)) * 1e3 / count for x in xs.split()]
o, n = per(o, zo), per(n, zn)
r = [b / a for a, b in zip(o, n)]
med = statistics.median
print(f"| {name} | {med(o):.3f} | {med(n):.3f} | {med(r):.3f} | {min(r):.3f} | {max(r):.3f} |")
PY
done
