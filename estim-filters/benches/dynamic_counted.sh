#!/usr/bin/env bash
# CPU time per step of every (filter, n, way) of benches/dynamic.rs in counted mode, median of
# REPS runs, set-up (count = 0) subtracted; the numbers in BENCHMARKS.md ("After the update
# rework"). Needs perf (Debian's linux-perf).
#   BIN=$(ls -t target/release/deps/dynamic-* | grep -v '\.d$' | head -1)   # after --no-run
#   estim-filters/benches/dynamic_counted.sh "$BIN" 3
# Output lines: <filter> <n> <way> <median µs/step> spread <max/min - 1>
BIN=$1; REPS=${2:-3}
declare -A COUNT=(
 [kf/12]=100000 [kf/24]=35000 [kf/50]=7000 [kf/100]=1500 [kf/200]=250
 [ekf/12]=80000 [ekf/24]=30000 [ekf/50]=6000 [ekf/100]=1200 [ekf/200]=200
 [ukf/12]=40000 [ukf/24]=11000 [ukf/50]=2000 [ukf/100]=400 [ukf/200]=60 )
t() { DYNAMIC_BENCH_STEPS=$1 perf stat -x, -e task-clock "$BIN" --bench 2>&1 >/dev/null | awk -F, '/task-clock/ {print $1}'; }
for f in kf ekf ukf; do for n in 12 24 50 100 200; do
  c=${COUNT[$f/$n]}
  for way in estim dmatrix faer; do
    vals=""
    for r in $(seq $REPS); do
      v=$(t "$f/n=$n/$way=$c"); z=$(t "$f/n=$n/$way=0")
      vals="$vals $(python3 -c "print(($v-$z)*1000/$c)")"   # task-clock ms -> us/step
    done
    echo "$f $n $way $(python3 -c "import statistics,sys; v=[float(x) for x in '$vals'.split()]; print(f'{statistics.median(v):.3f} spread {max(v)/min(v)-1:.3f}')")"
  done
done; done
