#!/usr/bin/env bash
# Two builds timed at the same moment, one on each core, the cores swapped every round: on a
# shared machine whose speed drifts by 20-30% within the hour, the ratio of two runs side by side
# moves far less than either run does (issue #16). Prints each round's grain-steps per second of
# both builds and their ratio (NEW / OLD), then the median ratio.
#   usage: tools/paired_bench.sh [--alternate] OLD_SDEM NEW_SDEM ROUNDS BENCH_ARGS...
#   e.g.   tools/paired_bench.sh /tmp/sdem_old target/release/sdem 8 \
#            bench --grains 100000 --steps 300 --warmup 20 --threads 1 --model rigid
# BENCH_ARGS are `sdem bench`'s (one thread each: the two runs share the machine's two cores).
# --alternate: the two builds one after the other instead, each on every core, the order
# swapped every round: for two-thread (or more) ratios, which side by side would put both
# threads of a build on one core. Take five rounds or more: drifts faster than a round's two
# runs do not cancel.
# Needs taskset (util-linux) and at least two cores.
set -eu
alternate=0
if [ "${1:-}" = "--alternate" ]; then
  alternate=1
  shift
fi
if [ $# -lt 4 ]; then
  sed -n '2,14p' "$0"
  exit 2
fi
old=$1 new=$2 rounds=$3
shift 3
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
rate() { awk '/^grain-steps\/s:/ {print $2}' "$1"; }
ratios=()
old_build=$old new_build=$new
for round in $(seq 1 "$rounds"); do
  if [ $((round % 2)) = 1 ]; then old_core=0 new_core=1; else old_core=1 new_core=0; fi
  # Each round runs fresh copies of the two builds: once, on a family-26 machine, one copy of
  # a build ran the full level 1.65 times slower than other copies of the same bytes, run after
  # run (the file's pages, not its code): a copy for every round confines such a copy to one
  # round instead of every round of a comparison.
  old=$work/old_build new=$work/new_build
  cp "$old_build" "$old"; cp "$new_build" "$new"
  if [ "$alternate" = 1 ]; then
    if [ "$old_core" = 0 ]; then
      "$old" "$@" >"$work/old.txt"; "$new" "$@" >"$work/new.txt"
    else
      "$new" "$@" >"$work/new.txt"; "$old" "$@" >"$work/old.txt"
    fi
  else
    taskset -c $old_core "$old" "$@" >"$work/old.txt" &
    taskset -c $new_core "$new" "$@" >"$work/new.txt" &
    wait
  fi
  a=$(rate "$work/old.txt") b=$(rate "$work/new.txt")
  ratio=$(python3 -c "print(f'{$b / $a:.4f}')")
  ratios+=("$ratio")
  echo "round $round: old $a, new $b grain-steps/s, new/old $ratio"
done
python3 -c "import statistics, sys; print(f'median new/old over $rounds rounds: {statistics.median(map(float, sys.argv[1:])):.4f}')" "${ratios[@]}"
