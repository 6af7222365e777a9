#!/usr/bin/env bash
# CPU time per step of every (filter, n) of benches/dynamic.rs in counted mode: the three ways
# (estim, dmatrix, faer) run back to back, REPS times, set-up (count = 0) subtracted; prints
# the median µs per step of each way and the medians of the per-repetition ratios
# dmatrix/estim and estim/faer (the machines are shared and drift between runs, so the ratio
# of neighbouring runs is the figure to quote), each with a 95% bootstrap interval for that
# median (10 000 resamples of the repetitions, fixed seed): the table "Runtime-size steps" in
# BENCHMARKS.md. Needs perf (Debian's linux-perf).
#   BIN=$(ls -t target/release/deps/dynamic-* | grep -v '\.d$' | head -1)   # after --no-run
#   estim-filters/benches/dynamic_counted.sh "$BIN" 5
BIN=$1; REPS=${2:-5}
declare -A COUNT=(
 [kf/12]=100000 [kf/24]=35000 [kf/50]=7000 [kf/100]=1500 [kf/200]=250
 [ekf/12]=80000 [ekf/24]=30000 [ekf/50]=6000 [ekf/100]=1200 [ekf/200]=200
 [ukf/12]=40000 [ukf/24]=11000 [ukf/50]=2000 [ukf/100]=400 [ukf/200]=60 )
t() { DYNAMIC_BENCH_STEPS=$1 perf stat -x, -e task-clock "$BIN" --bench 2>&1 >/dev/null | awk -F, '/task-clock/ {print $1}'; }
echo "| filter | n | estim µs | dmatrix µs | faer µs | dmatrix/estim | 95% interval | estim/faer | 95% interval |"
echo "|---|---|---:|---:|---:|---:|---|---:|---|"
for f in kf ekf ukf; do for n in 12 24 50 100 200; do
  c=${COUNT[$f/$n]}
  ze=$(t "$f/n=$n/estim=0"); zd=$(t "$f/n=$n/dmatrix=0"); zf=$(t "$f/n=$n/faer=0")
  e=""; d=""; g=""
  for r in $(seq "$REPS"); do
    e="$e $(t "$f/n=$n/estim=$c")"; d="$d $(t "$f/n=$n/dmatrix=$c")"; g="$g $(t "$f/n=$n/faer=$c")"
  done
  python3 - "$f" "$n" "$c" "$ze" "$zd" "$zf" "$e" "$d" "$g" <<'PY'
import random, statistics, sys
f, n, c, ze, zd, zf, e, d, g = sys.argv[1:]
c = int(c)
per = lambda xs, z: [(float(x) - float(z)) * 1e3 / c for x in xs.split()]
e, d, g = per(e, ze), per(d, zd), per(g, zf)
med = statistics.median
ef = [x / y for x, y in zip(e, g)]
de = [y / x for x, y in zip(e, d)]
def interval(r):
    rng = random.Random(1)
    b = sorted(med(rng.choices(r, k=len(r))) for _ in range(10000))
    return f"{b[250]:.2f}–{b[9749]:.2f}"
print(f"| {f} | {n} | {med(e):.2f} | {med(d):.2f} | {med(g):.2f} | {med(de):.2f} | {interval(de)} | {med(ef):.2f} | {interval(ef)} |")
PY
done; done
