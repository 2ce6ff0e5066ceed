#!/usr/bin/env bash
# Instructions per grain-step of the SDEM step on the dense bench packing (2000 grains), from
# callgrind: the difference of 40 and 10 timed steps, so setup and warm-up cancel. Repeatable
# whatever the machine's load.
# usage: tools/callgrind_step_cost.sh [path/to/sdem] [dbeta in degrees, default 1] [model: full (default), volumetric, rigid]
set -euo pipefail
bin=${1:-target/release/sdem}
resolution=${2:-1}
model=${3:-full}
count() {
  local out; out=$(mktemp)
  valgrind --tool=callgrind --callgrind-out-file="$out" "$bin" bench --grains 2000 --steps "$1" --threads 1 --resolution "$resolution" --model "$model" >/dev/null 2>&1
  callgrind_annotate "$out" 2>/dev/null | grep -m1 "PROGRAM TOTALS" | awk '{gsub(",","",$1); print $1}'
  rm -f "$out"
}
a=$(count 10); b=$(count 40)
grains=$("$bin" bench --grains 2000 --steps 1 --threads 1 | sed -n 's/.* grains: \([0-9]*\) .*/\1/p')
python3 -c "print(f'instructions per grain-step: {($b - $a) / (30 * $grains):.0f}')"
