#!/usr/bin/env bash
# CPU time (perf stat task-clock, all threads) and wall time of Lu's Monte Carlo validation
# (estim-filters/benches/lu_monte_carlo.rs: 5000 runs x 6000 steps) on estim's runner against the
# hand-written Monte Carlo (and the hand-written filter on the runner), sequential and on 2
# threads. Each repetition runs the six variants
# back to back (interleaved); set-up (a 1-run process) is subtracted from the CPU time. Prints
# the medians and the medians of the per-repetition ratios to hand. Needs perf.
#   cargo build --release -p estim-filters-benches --features parallel --bench lu_monte_carlo
#   BIN=$(ls -t target/release/deps/lu_monte_carlo-* | grep -v '\.d$' | head -1)
#   estim-filters/benches/lu_monte_carlo_counted.sh "$BIN" 5
BIN=$1; REPS=${2:-5}; RUNS=${RUNS:-5000}
"$BIN" check --runs 200 || exit 1
m() { perf stat -x, -e task-clock "$BIN" "$1" --threads "$2" --runs "$3" 2>&1 | awk -F, '/task-clock/ {c=$1} /wall_s/ {w=$NF; sub(/.*wall_s /, "", w)} END {print c, w}'; }
out=""
for v in "library 1" "runner 1" "hand 1" "library 2" "runner 2" "hand 2"; do
  set -- $v; out="$out|$1-$2 setup $(m "$1" "$2" 1)"
done
for r in $(seq "$REPS"); do
  for v in "library 1" "runner 1" "hand 1" "library 2" "runner 2" "hand 2"; do
    set -- $v; out="$out|$1-$2 run $(m "$1" "$2" "$RUNS")"
  done
done
python3 - "$RUNS" "$out" <<'PY'
import statistics, sys
runs = int(sys.argv[1])
setup, cpu, wall = {}, {}, {}
for line in sys.argv[2].split("|")[1:]:
    name, kind, c, w = line.split()
    if kind == "setup":
        setup[name] = float(c)
    else:
        cpu.setdefault(name, []).append(float(c) - setup[name])
        wall.setdefault(name, []).append(float(w))
med = statistics.median
for t in ("1", "2"):
    lib, run, hand = f"library-{t}", f"runner-{t}", f"hand-{t}"
    parts = [f"{t} thread(s):"]
    for name in (lib, run, hand):
        parts.append(f"{name.split('-')[0]} CPU {med(cpu[name])/1e3:.3f} s, wall {med(wall[name]):.3f} s |")
    for name in (lib, run):
        rc = [a / b for a, b in zip(cpu[name], cpu[hand])]
        rw = [a / b for a, b in zip(wall[name], wall[hand])]
        parts.append(f"{name.split('-')[0]}/hand CPU {med(rc):.2f} (min {min(rc):.2f}, max {max(rc):.2f}), wall {med(rw):.2f} |")
    print(" ".join(parts))
PY
