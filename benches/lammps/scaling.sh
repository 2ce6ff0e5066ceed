#!/usr/bin/env bash
# sdem's thread scaling against LAMMPS's process scaling on one many-core machine (issue #16:
# "on a 16-core machine, report 1-16 threads"): ROUNDS alternated rounds of `sdem bench` (rigid
# and full, each thread count) and LAMMPS gran/hooke on its dense packing (each process count),
# then the medians, the speed-ups and the parallel efficiencies.
#   usage: benches/lammps/scaling.sh N "COUNTS" LAMMPS_STEPS SDEM_STEPS [ROUNDS] [path/to/sdem]
#   e.g.   benches/lammps/scaling.sh 100000 "1 2 4 8 16" 1000 120 3
# The rigid bench takes 3 x SDEM_STEPS steps (it is about 3 times faster a step). LAMMPS's
# rounds stop after LAMMPS_ROUNDS (default ROUNDS). `lmp` and `mpirun` come from PATH, or from
# LMP and MPIRUN (a carried build: bundle.sh); NO_LAMMPS=1 times sdem alone. mpirun runs with
# --bind-to none, as sdem's threads are not pinned either. Lines go to stdout and, with the
# summary, to work/scaling_N.txt; each sdem line keeps the run's seconds by pass, and the summary
# gives each pass's own speed-up, to show which pass holds the scaling back.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
n=$1; counts=$2; lsteps=$3; ssteps=$4; rounds=${5:-3}
sdem=$(realpath "${6:-$here/../../target/release/sdem}")
lrounds=${LAMMPS_ROUNDS:-$rounds}
lmp=${LMP:-lmp}; mpirun=${MPIRUN:-mpirun}
mkdir -p "$here/work" && cp "$here"/in.bench "$here"/in.common "$here"/in.compress "$here/work/" && cd "$here/work"
out=scaling_$n.txt; : > "$out"
say() { echo "$@" | tee -a "$out"; }
. "$here/packing.sh"
lammps=1
if [ "${NO_LAMMPS:-0}" = 1 ]; then lammps=0
elif ! command -v "$lmp" >/dev/null; then say "lmp not found (apt-get install -y lammps openmpi-bin, or LMP=...): sdem alone"; lammps=0
else lammps_packing "$n"; fi
say "machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) processors; sdem $("$sdem" --version 2>/dev/null | cut -d' ' -f2)"
for r in $(seq 1 "$rounds"); do
  for t in $counts; do
    for model in rigid full; do
      steps=$ssteps; [ "$model" = rigid ] && steps=$((3 * ssteps))
      res=$("$sdem" bench --grains "$n" --steps "$steps" --warmup 20 --threads "$t" --model "$model")
      say "sdem model=$model threads=$t N=$n round=$r $(echo "$res" | grep -o 'grain-steps/s: [0-9.e+]*') | $(echo "$res" | grep -o 'frames .*') | $(echo "$res" | grep -o 'sweep: .*')"
    done
  done
  if [ "$lammps" = 1 ] && [ "$r" -le "$lrounds" ]; then
    for np in $counts; do
      $mpirun --allow-run-as-root --oversubscribe --bind-to none -np "$np" "$lmp" -log log.scaling_${n}_np${np}_r$r \
        -screen none -in in.bench -var tag "$n" -var nsteps "$lsteps" -var mode hold
      say "LAMMPS processes=$np N=$n round=$r atom-steps/s: $(lammps_rate log.scaling_${n}_np${np}_r$r "$n")"
    done
  fi
done
python3 - "$out" <<'PY'
import re, statistics, sys
path = sys.argv[1]
rates = {}
for line in open(path):
    m = re.match(r"(sdem model=(\w+) threads|LAMMPS processes)=(\d+) .*steps/s: ([0-9.e+]+)", line)
    if m:
        code = "sdem " + m.group(2) if m.group(2) else "LAMMPS"
        rates.setdefault((code, int(m.group(3))), []).append(float(m.group(4)))
lines = ["", "medians (steps/s) | speed-up over 1 | parallel efficiency | ratio to LAMMPS"]
for code in ("sdem rigid", "sdem full", "LAMMPS"):
    base = rates.get((code, 1))
    for (c, p), v in sorted(rates.items()):
        if c != code:
            continue
        med = statistics.median(v)
        up = med / statistics.median(base) if base else float("nan")
        lam = rates.get(("LAMMPS", p))
        ratio = med / statistics.median(lam) if lam else float("nan")
        lines.append(f"{code:10s} {p:3d}: {med:.3e} | {up:6.2f} | {up / p:5.2f} | {ratio:5.2f}   (runs: {', '.join(f'{x:.3e}' for x in v)})")
# Each pass's median seconds and its own speed-up over one thread: which pass scales worse.
passes = {}
for line in open(path):
    m = re.match(r"sdem model=(\w+) threads=(\d+) .*\| frames (.*)", line)
    if m:
        for name, sec in re.findall(r"([a-z ]+?) ([0-9.]+) s \(", "frames " + m.group(3)):
            passes.setdefault((m.group(1), name.strip(), int(m.group(2))), []).append(float(sec))
if passes:
    lines += ["", "pass medians (s) | speed-up of the pass over 1 thread"]
    for (model, name, t), v in sorted(passes.items()):
        base = passes.get((model, name, 1))
        med = statistics.median(v)
        if med == 0:
            continue
        up = statistics.median(base) / med if base else float("nan")
        lines.append(f"sdem {model:5s} {name:14s} {t:3d}: {med:.3f} | {up:6.2f}")
print("\n".join(lines))
open(path, "a").write("\n".join(lines) + "\n")
PY
