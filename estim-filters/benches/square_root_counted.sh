#!/usr/bin/env bash
# Instructions per step (valgrind callgrind, Ir) of the square-root filters against the Joseph
# form, from benches/square_root.rs in counted mode: each variant runs COUNT steps (a multiple
# of the 64-step trajectory, so the resets are averaged in) with collection on inside the
# counted loop only; prints Ir per step and the square-root / Joseph ratio per filter and size.
# Instruction counts do not drift with the load of a shared machine, which wall time does.
# Give a second binary to print old / new ratios of the same variants (e.g. main's build).
#   BIN=$(ls -t target/release/deps/square_root-* | grep -v '\.d$' | head -1)   # after --no-run
#   estim-filters/benches/square_root_counted.sh "$BIN" [OLD_BIN]
BIN=$1; OLD=${2:-}
declare -A COUNT=([static_6x4]=1280 [dyn_20x10]=256 [dyn_50x20]=64)
GROUPS_=${GROUPS_:-"static_6x4 dyn_20x10 dyn_50x20"}
ir() {  # binary, group/variant, count -> Ir per step
  local out; out=$(mktemp)
  SQUARE_ROOT_BENCH_STEPS="$2=$3" valgrind --tool=callgrind --callgrind-out-file="$out" \
    --toggle-collect='*run_counted*' "$1" --bench >/dev/null 2>&1
  local total; total=$(callgrind_annotate "$out" 2>/dev/null | awk '/PROGRAM TOTALS/ {gsub(",", "", $1); print $1}')
  rm -f "$out"
  echo $(( total / $3 ))
}
for g in $GROUPS_; do
  c=${COUNT[$g]}
  for f in kf ekf ukf; do
    j=$(ir "$BIN" "$g/${f}_joseph" "$c"); s=$(ir "$BIN" "$g/${f}_sqrt" "$c")
    line="$g $f: joseph $j Ir, sqrt $s Ir, sqrt/joseph $(python3 -c "print(f'{$s/$j:.2f}')")"
    if [ -n "$OLD" ]; then
      oj=$(ir "$OLD" "$g/${f}_joseph" "$c"); os=$(ir "$OLD" "$g/${f}_sqrt" "$c")
      line="$line | old: joseph $oj, sqrt $os, sqrt/joseph $(python3 -c "print(f'{$os/$oj:.2f}')"), new/old sqrt $(python3 -c "print(f'{$s/$os:.2f}')")"
    fi
    echo "$line"
  done
done
