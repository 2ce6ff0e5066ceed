#!/usr/bin/env python3
"""LAMMPS's bench packing as an sdem scenario: the same discs in the same periodic box.

usage: to_sdem.py dense_N.data OUT_PREFIX [STEPS]
Writes OUT_PREFIX_grains.csv (x, y, radius, the box's corner moved to the origin) and
OUT_PREFIX.ron: rigid discs in a periodic cell of LAMMPS's box, held (a Relax phase of STEPS
steps, default 10, checkpointed at its end), so that `sdem bench --from` times sdem's step on the
packing LAMMPS's deck times (benches/lammps/compare.sh, SAME_PACKING=1).
"""
import os
import sys

data, prefix = sys.argv[1], sys.argv[2]
steps = int(sys.argv[3]) if len(sys.argv) > 3 else 10
lines = open(data).read().splitlines()
box = {}
for line in lines:
    words = line.split()
    if len(words) == 4 and words[2] in ("xlo", "ylo"):
        box[words[2][0]] = (float(words[0]), float(words[1]))
start = next(k for k, l in enumerate(lines) if l.startswith("Atoms")) + 2
grains = []
for line in lines[start:]:
    words = line.split()
    if len(words) < 7:
        break
    # id type diameter density x y z [ix iy iz]
    diameter, x, y = float(words[2]), float(words[4]), float(words[5])
    grains.append((x - box["x"][0], y - box["y"][0], 0.5 * diameter))
width = box["x"][1] - box["x"][0]
height = box["y"][1] - box["y"][0]
with open(prefix + "_grains.csv", "w") as f:
    f.write("x,y,radius\n")
    for x, y, r in grains:
        f.write(f"{x:.15e},{y:.15e},{r:.15e}\n")
name = os.path.basename(prefix)
with open(prefix + ".ron", "w") as f:
    f.write(f"""// LAMMPS's bench packing ({os.path.basename(data)}, {len(grains)} discs) as rigid SDEM discs in
// the same periodic box, held for {steps} steps: written by benches/lammps/to_sdem.py.
Scenario(
    name: "{name}",
    sample: (box_width: {width!r}, box_height: {height!r}, file: "{name}_grains.csv"),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    model: Rigid,
    contact: (a: 0.58, b: 2.0, resolution_deg: 1.0, damping: 1.0),
    time_step: FractionOfCritical(0.4),
    loading: [Relax(until: Steps({steps}))],
    boundary: Periodic,
    output: (every: {steps}, checkpoint: Some(EverySteps({steps}))),
)
""")
print(f"{len(grains)} discs, box {width:.6f} x {height:.6f}")
