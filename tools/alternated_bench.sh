#!/usr/bin/env bash
# Two builds timed one after the other, each on every core, the order swapped every round: for
# two-thread (or more) figures, which tools/paired_bench.sh cannot give (it pins each build to
# one core). Prints each round's grain-steps per second of both builds and their ratio
# (NEW / OLD), then the median ratio. Slower drifts of the machine than a round's two runs
# cancel in the ratio; faster ones do not: take five rounds or more.
#   usage: tools/alternated_bench.sh OLD_SDEM NEW_SDEM ROUNDS BENCH_ARGS...
#   e.g.   tools/alternated_bench.sh /tmp/sdem_old target/release/sdem 5 \
#            bench --grains 100000 --steps 400 --warmup 20 --threads 2 --model rigid
set -eu
if [ $# -lt 4 ]; then
  sed -n '2,9p' "$0"
  exit 2
fi
old=$1 new=$2 rounds=$3
shift 3
rate() { "$1" "${@:2}" | awk '/^grain-steps\/s:/ {print $2}'; }
ratios=()
for round in $(seq 1 "$rounds"); do
  if [ $((round % 2)) = 1 ]; then
    a=$(rate "$old" "$@"); b=$(rate "$new" "$@")
  else
    b=$(rate "$new" "$@"); a=$(rate "$old" "$@")
  fi
  ratio=$(python3 -c "print(f'{$b / $a:.4f}')")
  ratios+=("$ratio")
  echo "round $round: old $a, new $b grain-steps/s, new/old $ratio"
done
python3 -c "import statistics, sys; print(f'median new/old over {len(sys.argv) - 1} rounds: {statistics.median(map(float, sys.argv[1:])):.4f}')" "${ratios[@]}"
