#!/usr/bin/env bash
# Static or dynamic, two builds side by side: per case (filter/n/count), `estim` (Dyn) and
# `estim_static` of OLD and of NEW run one after the other, REPS times, in counted mode (CPU
# time, set-up subtracted); prints the median µs per step and the medians of the per-repetition
# ratios static/dynamic in each build and new static/old static (the table "Static or dynamic"
# in BENCHMARKS.md). estim_static exists at n = 2, 4, 6, 12, 16, 24, 50.
#   estim-filters/benches/crossover_counted.sh OLD_BIN NEW_BIN 3 kf/12/60000 ukf/50/500
OLD=$1; NEW=$2; REPS=$3; shift 3
t() { DYNAMIC_BENCH_STEPS=$2 perf stat -x, -e task-clock "$1" --bench 2>&1 >/dev/null | awk -F, '/task-clock/ {print $1}'; }
for cs in "$@"; do
  IFS=/ read -r f n c <<< "$cs"
  vars="old:estim old:estim_static new:estim new:estim_static"
  declare -A Z=() X=()
  for v in $vars; do b=${v%%:*}; w=${v#*:}; [ $b = old ] && B=$OLD || B=$NEW; Z[$v]=$(t $B "$f/n=$n/$w=0"); X[$v]=""; done
  for r in $(seq $REPS); do for v in $vars; do b=${v%%:*}; w=${v#*:}; [ $b = old ] && B=$OLD || B=$NEW; X[$v]="${X[$v]} $(t $B "$f/n=$n/$w=$c")"; done; done
  args=(); for v in $vars; do args+=("$v" "${Z[$v]}" "${X[$v]}"); done
  python3 - "$f" "$n" "$c" "${args[@]}" <<'PY'
import statistics, sys
f, n, c, *rest = sys.argv[1:]
c = int(c); runs = {}
for i in range(0, len(rest), 3):
    v, z, xs = rest[i:i+3]; runs[v] = [(float(x) - float(z)) * 1e3 / c for x in xs.split()]
m = statistics.median
r = lambda a, b: m([x/y for x, y in zip(runs[a], runs[b])])
print(f"{f} n={n}: old dyn {m(runs['old:estim']):.2f} static {m(runs['old:estim_static']):.2f} µs; new dyn {m(runs['new:estim']):.2f} static {m(runs['new:estim_static']):.2f} µs | static/dyn old {r('old:estim_static','old:estim'):.2f} new {r('new:estim_static','new:estim'):.2f} | new static/old static {r('new:estim_static','old:estim_static'):.2f}", flush=True)
PY
done
