#!/usr/bin/env bash
# Instructions per atom-step of LAMMPS gran/hooke and of sdem's rigid discs on the same packing
# (LAMMPS's, in its periodic box), from callgrind: the difference of a long and a short timed run,
# so that setup cancels. Machine-independent, unlike the times of compare.sh.
#   usage: benches/lammps/callgrind_compare.sh [N (default 2000)] [path/to/sdem]
# Needs `lmp`, `mpirun` (apt-get install -y lammps openmpi-bin) and valgrind. Builds the dense
# packing of N discs in work/ unless work/dense_N.data is there (a few seconds for 2000).
# sdem's figure includes its neighbour-list rebuilds over the 300 steps (it prints how many);
# LAMMPS's list, with a thicker skin, is not rebuilt on this packing.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
n=${1:-2000}
sdem=$(realpath "${2:-$here/../../target/release/sdem}")
command -v lmp >/dev/null || { echo "lmp not found: apt-get install -y lammps openmpi-bin"; exit 1; }
command -v valgrind >/dev/null || { echo "valgrind not found"; exit 1; }
mkdir -p "$here/work" && cp "$here"/in.bench "$here"/in.common "$here"/in.compress "$here/work/" && cd "$here/work"
. "$here/packing.sh"
lammps_packing "$n"
sdem_packing "$n" "$sdem"
total() {
  callgrind_annotate "$1" 2>/dev/null | grep -m1 "PROGRAM TOTALS" | awk '{gsub(",","",$1); print $1}'
}
count_lammps() {
  local out=cg_lammps_$1.out
  valgrind --tool=callgrind --callgrind-out-file=$out lmp -log log.callgrind_$1 -screen none \
    -in in.bench -var tag "$n" -var nsteps "$1" -var mode hold >/dev/null 2>&1
  total $out
}
count_sdem() {
  local out=cg_sdem_$1.out
  valgrind --tool=callgrind --callgrind-out-file=$out "$sdem" bench --from sdem_$n/checkpoint.bin \
    --steps "$1" --warmup 20 --threads 1 >log.callgrind_sdem_$1 2>&1
  total $out
}
la=$(count_lammps 100); lb=$(count_lammps 400)
sa=$(count_sdem 100); sb=$(count_sdem 400)
builds() { grep -o 'neighbour-list builds: [0-9]*' log.callgrind_sdem_$1 | grep -o '[0-9]*$'; }
python3 -c "
l = ($lb - $la) / (300 * $n); s = ($sb - $sa) / (300 * $n)
print(f'N = $n, 300 steps: LAMMPS gran/hooke {l:.0f}, sdem rigid {s:.0f} instructions per atom-step; LAMMPS / sdem = {l / s:.2f}')
print('sdem neighbour-list builds in those steps: ' + str($(builds 400) - $(builds 100)))"
