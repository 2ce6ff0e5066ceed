#!/usr/bin/env bash
# A port model of one function of a release build (issue #16): its instructions without the
# jumps, calls, pushes and pops, through llvm-mca for a processor model, which prints the
# cycles a pass over them takes and each port's busy cycles. A model, not a measurement: the
# forty-fifth session lowered the polygon kernel's modelled cycles by 10% and measured it 9%
# slower (docs/performance.md). Needs objdump, nm and llvm-mca (apt-get install -y llvm).
#   usage: tools/kernel_port_model.sh [SDEM] [SYMBOL_PART] [MCPU]
#   e.g.   tools/kernel_port_model.sh target/release/sdem avx51218grain_grain_blocks icelake-server
set -eu
sdem=${1:-target/release/sdem}
symbol=${2:-avx51218grain_grain_blocks}
mcpu=${3:-icelake-server}
read -r start size <<<"$(nm -S "$sdem" | awk -v s="$symbol" '$0 ~ s {print $1, $2; exit}')"
[ -n "${start:-}" ] || { echo "no symbol matching $symbol in $sdem" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
objdump -d --no-show-raw-insn -M att "$sdem" --start-address=0x"$start" \
  --stop-address=$((0x$start + 0x$size)) |
  awk -F'\t' '/^  /{print $2}' |
  grep -v -E '^(j|call|ret|push|pop|nop|int3|ud2|cs nop|data16)' |
  sed -e 's/#.*//' -e 's/ *$//' >"$work/function.s"
echo "$(wc -l <"$work/function.s") instructions of $symbol"
llvm-mca -mcpu="$mcpu" -resource-pressure -timeline=false -instruction-info=false "$work/function.s" |
  awk '/^Iterations/,/^Block RThroughput/; /^Resources:/,/^$/; /Resource pressure per iteration/{getline; print; getline; print; exit}'
