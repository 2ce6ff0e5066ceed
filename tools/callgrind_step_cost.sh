#!/usr/bin/env bash
# Instructions per grain-step of the SDEM step under callgrind: the difference of two runs of
# different lengths, so that setup and warm-up cancel. Repeatable whatever the machine's load.
#
# usage: tools/callgrind_step_cost.sh [path/to/sdem] [dbeta in degrees, default 1] [model: full (default), volumetric, rigid]
#   The dense bench packing (2,000 grains): 40 against 10 timed steps.
# usage: tools/callgrind_step_cost.sh path/to/sdem --from CHECKPOINT
#   A run's own state (`sdem bench --from`): 400 against 100 timed steps after 20 untimed. The
#   jammed end state of isotropic_A (1,000 grains, adaptive levels), which tracks the
#   scenarios better than the lattice bench (it rebuilds its list seldom and few of its grains
#   line a wall), is written by
#     sdem run scenarios/isotropic_A.ron --out OUT --checkpoint-every 1000000
#   as OUT/checkpoint.bin.
set -euo pipefail
bin=${1:-target/release/sdem}
if [[ "${2:-}" == "--from" ]]; then
  checkpoint=${3:?usage: tools/callgrind_step_cost.sh path/to/sdem --from CHECKPOINT}
  [[ -f "$checkpoint" ]] || { echo "no checkpoint at $checkpoint" >&2; exit 2; }
  run=(bench --from "$checkpoint" --warmup 20 --threads 1)
  short=100
  long=400
else
  run=(bench --grains 2000 --threads 1 --resolution "${2:-1}" --model "${3:-full}")
  short=10
  long=40
fi
count() {
  local out; out=$(mktemp)
  valgrind --tool=callgrind --callgrind-out-file="$out" "$bin" "${run[@]}" --steps "$1" >/dev/null 2>&1
  callgrind_annotate "$out" 2>/dev/null | grep -m1 "PROGRAM TOTALS" | awk '{gsub(",","",$1); print $1}'
  rm -f "$out"
}
a=$(count "$short"); b=$(count "$long")
grains=$("$bin" "${run[@]}" --steps 1 | sed -n 's/.* grains: \([0-9]*\) .*/\1/p')
python3 -c "print(f'instructions per grain-step: {($b - $a) / (($long - $short) * $grains):.0f}')"
