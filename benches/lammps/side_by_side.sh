#!/usr/bin/env bash
# sdem against LAMMPS at the same moment, one core each (issue #16): LAMMPS gran/hooke on one
# process and `sdem bench` on one thread run together, each pinned to its own core, the cores
# swapped every round. On a shared machine whose speed drifts by 20-30% within minutes (both
# codes' rates in `compare.sh`'s alternated runs moved by that much from one sitting to the
# next, the rigid discs' ratio from 0.84 to 1.10 with the same build), two runs side by side
# see the same machine and their ratio moves far less than either rate: the one-core goals'
# figure that a drifting hour still resolves. Each pays for sharing the L3 cache and the
# memory with the other (sdem's larger state more: the ratio is, if anything, low).
#   usage: benches/lammps/side_by_side.sh N LAMMPS_STEPS SDEM_STEPS ROUNDS [path/to/sdem] [model]
#   e.g.   benches/lammps/side_by_side.sh 100000 1000 400 8 target/release/sdem full
# Choose the steps so that both runs take about as long (at 10^5 grains on the project's
# machine: LAMMPS 1000 steps, sdem 400 at the full level, 1000 for rigid discs): the longer
# run's tail runs alone. Prints each round's rates and ratio (sdem / LAMMPS) and the median
# ratio; lines also go to work/side_by_side_N_MODEL.txt. WARMUP=K as in compare.sh (20).
# Needs `lmp` (apt-get install -y lammps openmpi-bin), taskset (util-linux), two cores.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
if [ $# -lt 4 ]; then
  sed -n '2,16p' "$0"
  exit 2
fi
n=$1; lsteps=$2; ssteps=$3; rounds=$4
sdem=$(realpath "${5:-$here/../../target/release/sdem}")
model=${6:-full}
warmup=${WARMUP:-20}
command -v lmp >/dev/null || { echo "lmp not found: apt-get install -y lammps openmpi-bin"; exit 1; }
mkdir -p "$here/work" && cp "$here"/in.bench "$here"/in.common "$here"/in.compress "$here/work/" && cd "$here/work"
results=side_by_side_${n}_$model.txt; : > "$results"
say() { echo "$@" | tee -a "$results"; }
. "$here/packing.sh"
lammps_packing "$n"
ratios=()
for r in $(seq 1 "$rounds"); do
  if [ $((r % 2)) = 1 ]; then lcore=0 score=1; else lcore=1 score=0; fi
  log=log.side_${n}_r$r
  taskset -c $lcore lmp -log "$log" -screen none -in in.bench -var tag "$n" -var nsteps "$lsteps" -var mode hold &
  lpid=$!
  taskset -c $score "$sdem" bench --grains "$n" --steps "$ssteps" --warmup "$warmup" --threads 1 \
    --model "$model" > sdem_side.out &
  spid=$!
  wait $lpid $spid
  lrate=$(lammps_rate "$log" "$n")
  srate=$(awk '/^grain-steps\/s:/ {print $2}' sdem_side.out)
  ratio=$(python3 -c "print(f'{$srate / $lrate:.4f}')")
  ratios+=("$ratio")
  say "round $r: LAMMPS (core $lcore) $lrate atom-steps/s, sdem $model (core $score) $srate grain-steps/s, sdem / LAMMPS $ratio"
done
say "median sdem $model / LAMMPS, one core each, side by side, over $rounds rounds: $(printf '%s\n' "${ratios[@]}" | sort -g | awk '{v[NR]=$1} END {print (NR%2 ? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2)}')"
