#!/usr/bin/env bash
# CPU time per step of (filter, n) cases of benches/dynamic.rs in counted mode: the variants
# (estim, estim_static where it exists, dmatrix, dmatrix_prealloc, faer) run one after the other,
# REPS times (so they interleave), set-up (count = 0) subtracted; prints the median µs per step of
# each variant and the medians of the per-repetition ratios to estim (the machines are shared and
# drift between runs, so the ratio of neighbouring runs is the figure to quote), each with a 95%
# bootstrap interval for that median (10 000 resamples of the repetitions, fixed seed): the
# tables "Runtime-size steps" and "Static or dynamic" in BENCHMARKS.md. Needs perf (Debian's
# linux-perf).
#   BIN=$(ls -t target/release/deps/dynamic-* | grep -v '\.d$' | head -1)   # after --no-run
#   estim-filters/benches/dynamic_counted.sh "$BIN" 5
#   CASES="kf/2 ukf/6" VARIANTS="estim estim_static dmatrix_prealloc" dynamic_counted.sh "$BIN" 9
BIN=$1; REPS=${2:-5}
declare -A COUNT=(
 [kf/2]=2000000 [kf/4]=1000000 [kf/6]=600000 [kf/12]=100000 [kf/16]=60000 [kf/24]=35000
 [kf/50]=7000 [kf/100]=1500 [kf/200]=250
 [ekf/2]=2000000 [ekf/4]=1000000 [ekf/6]=500000 [ekf/12]=80000 [ekf/16]=50000 [ekf/24]=30000
 [ekf/50]=6000 [ekf/100]=1200 [ekf/200]=200
 [ukf/2]=1000000 [ukf/4]=400000 [ukf/6]=200000 [ukf/12]=40000 [ukf/16]=20000 [ukf/24]=11000
 [ukf/50]=2000 [ukf/100]=400 [ukf/200]=60 )
ALL_CASES=""
for f in kf ekf ukf; do for n in 2 4 6 12 16 24 50 100 200; do ALL_CASES="$ALL_CASES $f/$n"; done; done
CASES=${CASES:-$ALL_CASES}
VARIANTS=${VARIANTS:-estim estim_static dmatrix dmatrix_prealloc faer}
t() { DYNAMIC_BENCH_STEPS=$1 perf stat -x, -e task-clock "$BIN" --bench 2>&1 >/dev/null | awk -F, '/task-clock/ {print $1}'; }
for case in $CASES; do
  f=${case%/*}; n=${case#*/}; c=${COUNT[$case]}
  # estim_static exists at n = 2, 4, 6, 12, 16, 24, 50 only.
  vs=""; for v in $VARIANTS; do
    if [ "$v" = estim_static ] && ! [[ " 2 4 6 12 16 24 50 " == *" $n "* ]]; then continue; fi
    vs="$vs $v"
  done
  declare -A Z=() X=()
  for v in $vs; do Z[$v]=$(t "$f/n=$n/$v=0"); X[$v]=""; done
  for r in $(seq "$REPS"); do
    for v in $vs; do X[$v]="${X[$v]} $(t "$f/n=$n/$v=$c")"; done
  done
  args=(); for v in $vs; do args+=("$v" "${Z[$v]}" "${X[$v]}"); done
  python3 - "$f" "$n" "$c" "${args[@]}" <<'PY'
import random, statistics, sys
f, n, c, *rest = sys.argv[1:]
c = int(c)
runs = {}
for i in range(0, len(rest), 3):
    v, z, xs = rest[i:i + 3]
    runs[v] = [(float(x) - float(z)) * 1e3 / c for x in xs.split()]
med = statistics.median
def interval(r):
    rng = random.Random(1)
    b = sorted(med(rng.choices(r, k=len(r))) for _ in range(10000))
    return f"{b[250]:.2f}–{b[9749]:.2f}"
times = " ".join(f"{v} {med(x):.3f} µs" for v, x in runs.items())
ratios = []
e = runs.get("estim")
for v, x in runs.items():
    if v == "estim" or e is None:
        continue
    r = [a / b for a, b in zip(e, x)]
    ratios.append(f"estim/{v} {med(r):.2f} ({interval(r)})")
print(f"{f} n={n}: {times} | " + " ".join(ratios), flush=True)
PY
done
