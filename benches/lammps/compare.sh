#!/usr/bin/env bash
# sdem against LAMMPS, back to back on this machine (issue #16): ROUNDS alternated rounds of
# LAMMPS gran/hooke (1 and 2 processes) and `sdem bench` (full and rigid, 1 and 2 threads).
#   usage: benches/lammps/compare.sh N LAMMPS_STEPS SDEM_STEPS [ROUNDS] [path/to/sdem]
#   e.g.   benches/lammps/compare.sh 100000 1000 100 3
# WARMUP=K (default 20) gives sdem bench K untimed steps first (see `sdem bench --help`).
# SAME_PACKING=1 also times sdem's rigid discs on LAMMPS's own packing, in its periodic box
# (to_sdem.py; "model=rigid-lammps-packing"): the same discs and contacts, where the lattice of
# `sdem bench` has 6 contacts a grain and LAMMPS's packing about 4.15; in the file's order, as
# LAMMPS's two processes wrote it (the left half of the box, then the right), and sorted into
# strips by `sdem sort-sample` ("model=rigid-lammps-packing-strips"), as LAMMPS sorts its own
# atoms in space: on two threads the file's order costs sdem's sweep its fused passes.
# Lines go to stdout and, with a summary (medians, ratios to LAMMPS on as many cores, two-core
# speed-ups, and the rounds whose two-core runs look starved), to work/compare_N.txt.
# Needs `lmp` and `mpirun` (apt-get install -y lammps openmpi-bin); builds LAMMPS's dense
# packing of N discs once (run.sh's compression: about 6 min for 10^5 on 2 cores) in work/,
# unless work/dense_N.data is there already: for 10^6, tile the 10^5 packing instead of
# compressing one (about an hour): python3 tile.py work/dense_100000.data 5 2 work/dense_1000000.data
set -eu
here=$(cd "$(dirname "$0")" && pwd)
n=$1; lsteps=$2; ssteps=$3; rounds=${4:-3}
sdem=$(realpath "${5:-$here/../../target/release/sdem}")
warmup=${WARMUP:-20}
command -v lmp >/dev/null || { echo "lmp not found: apt-get install -y lammps openmpi-bin"; exit 1; }
mkdir -p "$here/work" && cp "$here"/in.bench "$here"/in.common "$here"/in.compress "$here/work/" && cd "$here/work"
results=compare_$n.txt; : > "$results"
say() { echo "$@" | tee -a "$results"; }
# What a line keeps of `sdem bench`'s output: its rate and its contacts per grain.
bench_figures() { echo "$(echo "$1" | grep -o 'grain-steps/s: .*') | $(echo "$1" | head -1 | grep -o 'contacts per grain: [0-9.]*')"; }
. "$here/packing.sh"
lammps_packing "$n"
if [ "${SAME_PACKING:-0}" = 1 ]; then sdem_packing "$n" "$sdem"; fi
for r in $(seq 1 "$rounds"); do
  for np in 1 2; do
    pre=""; [ "$np" = 2 ] && pre="mpirun --allow-run-as-root -np 2"
    $pre lmp -log log.bench_${n}_np${np}_r$r -screen none -in in.bench -var tag "$n" -var nsteps "$lsteps" -var mode hold
    say "LAMMPS np=$np N=$n round=$r atom-steps/s: $(lammps_rate log.bench_${n}_np${np}_r$r "$n")"
  done
  for model in full rigid; do
    for t in 1 2; do
      out=$("$sdem" bench --grains "$n" --steps "$ssteps" --warmup "$warmup" --threads "$t" --model "$model")
      say "sdem model=$model threads=$t N=$n round=$r $(bench_figures "$out")"
    done
  done
  if [ "${SAME_PACKING:-0}" = 1 ]; then
    for t in 1 2; do
      for order in "" _strips; do
        out=$("$sdem" bench --from sdem_$n$order/checkpoint.bin --steps "$ssteps" --warmup "$warmup" --threads "$t")
        say "sdem model=rigid-lammps-packing${order/_/-} threads=$t N=$n round=$r $(bench_figures "$out")"
      done
    done
  fi
done
summary=$(python3 "$here/compare_summary.py" "$results")
say "$summary"
