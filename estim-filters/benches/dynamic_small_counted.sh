#!/usr/bin/env bash
# Two builds of benches/dynamic.rs side by side at given cases, in counted mode (CPU time,
# `perf stat -e task-clock`, set-up at count 0 subtracted): per case, OLD's `estim`, NEW's
# `estim`, `estim_static` (where it exists) and `dmatrix_prealloc` run one after the other,
# REPS times; prints the median ns per step of each and the medians of the per-repetition
# ratios of NEW's `estim` to each (the table "Runtime-size steps at small n" in BENCHMARKS.md).
#   estim-filters/benches/dynamic_small_counted.sh OLD_BIN NEW_BIN 5 kf/2/1000000 ukf/6/100000
OLD=$1; NEW=$2; REPS=$3; shift 3
t() { DYNAMIC_BENCH_STEPS=$2 perf stat -x, -e task-clock "$1" --bench 2>&1 >/dev/null | awk -F, '/task-clock/ {print $1}'; }
for cs in "$@"; do
  IFS=/ read -r f n c <<< "$cs"
  vars="old:estim new:estim new:estim_static new:dmatrix_prealloc"
  [[ " 2 4 6 12 16 24 50 " == *" $n "* ]] || vars="old:estim new:estim new:dmatrix_prealloc"
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
med = statistics.median
e = runs["new:estim"]
out = " ".join(f"{v} {med(x)*1000:.0f}ns" for v, x in runs.items())
rat = " ".join(f"new/{v} {med([a/b for a,b in zip(e,x)]):.2f}" for v, x in runs.items() if v != "new:estim")
print(f"{f} n={n}: {out} | {rat}", flush=True)
PY
done
