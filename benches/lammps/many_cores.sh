#!/usr/bin/env bash
# Issue #16's figures on a many-core machine, in one call of about 6 minutes on 16 cores (220 s
# on the lent machine of the thirty-fourth session, before the probes 0. and 4.):
#  0. the topology lscpu reports, and whether two processors share a core or a cache: `sdem
#     bench` (rigid, 10^5) on processor 0, then two threads pinned to 0 and 1, and to 0 and
#     half the count;
#  1. scaling.sh at 10^5 grains (sdem rigid and full, LAMMPS), 1, 2, 4, ... up to every
#     processor, with each sdem run's seconds by pass;
#  2. scenarios/isotropic_100k.ron on every processor: wall time, peak memory, and whether its
#     macro.csv is the shipped one byte for byte (it was run on 2 threads of another machine);
#  3. `sdem bench` at 10^6 grains on 1 and on every processor: speed and peak memory a grain;
#  4. LAMMPS's packing in its file's order and sorted into strips (`sdem sort-sample`), 1, 2,
#     4, ... threads: what a sample's order costs the threaded sweep (about 40 s more).
#   usage: benches/lammps/many_cores.sh [BUNDLE]      (from the repository's root)
# BUNDLE: a folder made by bundle.sh (sdem, LAMMPS and Open MPI for a machine without them);
# without it, target/release/sdem and the `lmp` and `mpirun` on PATH. Lines go to stdout and
# to RESULTS (default benches/lammps/work/many_cores.txt). SCENARIO_SECONDS (default 300) bounds
# the scenario's run: it takes about 6 minutes on 2 cores.
set -u
root=$(cd "$(dirname "$0")/../.." && pwd); cd "$root"
work=benches/lammps/work; mkdir -p $work
results=$(realpath -m "${RESULTS:-$work/many_cores.txt}"); : > "$results"
say() { echo "$@" | tee -a "$results"; }
sdem=$root/target/release/sdem
if [ -n "${1:-}" ]; then
  bundle=$(realpath "$1"); sdem=$bundle/sdem
  tar -xJf "$bundle/ompi.tar.xz" -C "$bundle"
  export LMP=$bundle/ompi/bin/lmp
  export MPIRUN="env LD_LIBRARY_PATH=$bundle/ompi/deps OPAL_PREFIX=$bundle/ompi PATH=$bundle/ompi/bin:$PATH OMPI_MCA_btl=self,vader OMPI_MCA_pml=ob1 OMPI_MCA_btl_vader_single_copy_mechanism=none $bundle/ompi/bin/mpirun"
  [ -f "$bundle/dense_100000.data.xz" ] && xz -dc "$bundle/dense_100000.data.xz" >$work/dense_100000.data
  timeout 60 $MPIRUN --allow-run-as-root -np 2 "$LMP" -h >/dev/null ||
    { say "the bundle's LAMMPS does not start here: sdem alone"; export NO_LAMMPS=1; }
fi
# Peak resident memory of a command's process tree, and its wall time.
peak() { python3 -c '
import resource, subprocess, sys, time
t = time.time(); rc = subprocess.call(sys.argv[1:]); wall = time.time() - t
print(f"rc={rc} wall={wall:.1f} s peak={resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024:.0f} MB")' "$@"; }
p=$(nproc); counts=""; c=1
while [ $c -lt "$p" ]; do counts="$counts $c"; c=$((2 * c)); done; counts="$counts $p"
say "$(date -u +%FT%TZ) $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $p processors ($(lscpu | awk -F: '/per core/ {gsub(/ /, "", $2); print $2}') a core), $(free -g | awk '/Mem/ {print $2}') GB"
# The topology as the machine reports it: a VM may hide that two of its processors share a core.
lscpu | grep -E '^(Thread|Core|Socket|NUMA node|L[123]|Model name)' | sed 's/  */ /g' | tee -a "$results"
# Two threads on processors 0 and 1 against 0 and p/2, alternated with one thread on 0: where
# the two pinnings differ, two of the machine's processors share a core or a cache.
for r in 1 2 3; do
  for cpus in 0 0,1 "0,$((p / 2))"; do
    t=$(echo "$cpus" | tr ',' '\n' | wc -l)
    res=$(taskset -c "$cpus" "$sdem" bench --grains 100000 --steps 300 --warmup 20 --threads "$t" --model rigid 2>&1)
    say "pinned to $cpus: sdem rigid threads=$t round=$r $(echo "$res" | grep -o 'grain-steps/s: [0-9.e+]*') | $(echo "$res" | grep -o 'frames .*') | $(echo "$res" | grep -o 'sweep: .*')"
  done
done
LAMMPS_ROUNDS=2 timeout 300 benches/lammps/scaling.sh 100000 "$counts" 1000 120 3 "$sdem" | tee -a "$results"
out=$(mktemp -d)
r=$(peak timeout "${SCENARIO_SECONDS:-300}" "$sdem" run scenarios/isotropic_100k.ron --out "$out" --quiet 2>&1 | tail -1)
say "isotropic_100k on $p threads: $r"
if [[ $r != rc=0* ]]; then say "  did not finish within ${SCENARIO_SECONDS:-300} s (SCENARIO_SECONDS)"
elif cmp -s "$out/macro.csv" docs/runs/isotropic_100k_issue16_s48/macro.csv; then say "  macro.csv: the shipped one byte for byte"
else say "  macro.csv: NOT the shipped one"; fi
rm -rf "$out"
for model in rigid full; do
  for t in "$p" 1; do
    steps=40; [ $model = full ] && steps=12
    r=$(peak timeout 120 "$sdem" bench --grains 1000000 --steps $steps --warmup 5 --threads "$t" --model $model 2>&1)
    say "sdem bench N=10^6 model=$model threads=$t: $(echo "$r" | grep -o 'grain-steps/s: [0-9.e+]*') | $(echo "$r" | grep -o 'frames .*') | $(echo "$r" | grep -o 'vector lanes: .*') | $(echo "$r" | tail -1)"
  done
done
# 4. The order of a sample file: LAMMPS's packing (work/dense_100000.data) as rigid sdem discs
#    in its file's order (two halves: its two MPI processes' atoms) and sorted into strips by
#    `sdem sort-sample` (packing.sh's sdem_packing), `bench --from` each, on 1, 2, 4, ...
#    threads: how much the sweep's fallback to two passes costs where many threads share a step.
if [ -f $work/dense_100000.data ]; then
  (cd $work && . ../packing.sh && sdem_packing 100000 "$sdem" 2>/dev/null)
  for r in 1 2; do
    for t in $counts; do
      for order in file strips; do
        dir=sdem_100000; [ $order = strips ] && dir=sdem_100000_strips
        res=$("$sdem" bench --from $work/$dir/checkpoint.bin --steps 300 --warmup 20 --threads "$t" 2>&1)
        say "LAMMPS's packing in order=$order threads=$t round=$r $(echo "$res" | grep -o 'grain-steps/s: [0-9.e+]*') | $(echo "$res" | grep -o 'frames .*') | $(echo "$res" | grep -o 'sweep: .*')"
      done
    done
  done
fi
