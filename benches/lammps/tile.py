#!/usr/bin/env python3
"""Tile a periodic LAMMPS packing (write_data of atom_style sphere) NX x NY times.

usage: tile.py IN.data NX NY OUT.data

The copies are the same packing shifted by whole box lengths, so the tiled box is as dense and
as well relaxed as the original and each disc keeps its contacts. It gives `compare.sh` a
packing of N = NX * NY * N0 discs without compressing one from a gas (about an hour at
N = 10^6 on 2 cores): `python3 tile.py work/dense_100000.data 5 2 work/dense_1000000.data`.
"""
import sys


def main():
    src, nx, ny, dst = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    lines = open(src).read().split("\n")
    n = None
    box = {}
    atoms_at = velocities_at = None
    for k, line in enumerate(lines):
        words = line.split()
        if len(words) == 2 and words[1] == "atoms":
            n = int(words[0])
        elif len(words) == 4 and words[2] in ("xlo", "ylo", "zlo"):
            box[words[2][0]] = (float(words[0]), float(words[1]))
        elif line.startswith("Atoms"):
            atoms_at = k
        elif line.startswith("Velocities"):
            velocities_at = k
    if n is None or atoms_at is None or "x" not in box or "y" not in box:
        sys.exit(f"{src}: not a LAMMPS data file with atoms, a box and an Atoms section")
    atoms = [l.split() for l in lines[atoms_at + 2 : atoms_at + 2 + n]]
    velocities = (
        [l.split() for l in lines[velocities_at + 2 : velocities_at + 2 + n]]
        if velocities_at is not None
        else []
    )
    (xlo, xhi), (ylo, yhi) = box["x"], box["y"]
    lx, ly = xhi - xlo, yhi - ylo
    copies = [(a, b) for a in range(nx) for b in range(ny)]
    out = [
        f"LAMMPS data file: {src} tiled {nx} x {ny} (tile.py)",
        "",
        f"{n * len(copies)} atoms",
        "1 atom types",
        "",
        f"{xlo!r} {xlo + nx * lx!r} xlo xhi",
        f"{ylo!r} {ylo + ny * ly!r} ylo yhi",
        f"{box['z'][0]!r} {box['z'][1]!r} zlo zhi",
        "",
        lines[atoms_at],
        "",
    ]
    for c, (a, b) in enumerate(copies):
        for w in atoms:
            # id type diameter density x y z ix iy iz
            ident = int(w[0]) + c * n
            x, y = float(w[4]) + a * lx, float(w[5]) + b * ly
            out.append(" ".join([str(ident), w[1], w[2], w[3], repr(x), repr(y), w[6], "0 0 0"]))
    if velocities:
        out += ["", "Velocities", ""]
        for c in range(len(copies)):
            for w in velocities:
                out.append(" ".join([str(int(w[0]) + c * n)] + w[1:]))
    open(dst, "w").write("\n".join(out) + "\n")


if __name__ == "__main__":
    main()
