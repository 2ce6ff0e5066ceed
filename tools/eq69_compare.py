#!/usr/bin/env python3
"""Compare a run's p_c(phi) (macro.csv) with eq. 69 (Cantor et al. 2020, SPEC §8).

usage: tools/eq69_compare.py OUT_DIR [--phi0 X --z0 Z]
Without --phi0/--z0, uses the run's own jamming point from OUT_DIR/summary.txt (z_nr_0).
Prints the RMS relative error over phi in [phi0 + 0.01, max phi] and a short table.
"""
import csv, math, sys, pathlib

def reference(phi, phi0, z0, k=5.1, a=0.5, b=0.12, phimax=1.0):
    if phi <= phi0:
        return 0.0
    return -(b * phi / (2 * math.pi)) * (z0 + k * (phi - phi0) ** a) * math.log((phimax - phi) / (phimax - phi0))

def main():
    out = pathlib.Path(sys.argv[1])
    args = sys.argv[2:]
    summary = dict(l.split(" = ", 1) for l in (out / "summary.txt").read_text().splitlines() if " = " in l)
    phi0 = float(args[args.index("--phi0") + 1]) if "--phi0" in args else float(summary["phi_0"])
    z0 = float(args[args.index("--z0") + 1]) if "--z0" in args else float(summary["z_nr_0"])
    rows = [r for r in csv.DictReader(open(out / "macro.csv")) if r["phase"] == "isotropic"]
    pts = [(float(r["phi"]), float(r["p_c"])) for r in rows]
    top = max(p[0] for p in pts)
    sel = [(phi, p) for phi, p in pts if phi0 + 0.01 <= phi <= top]
    errs = [(p - reference(phi, phi0, z0)) / reference(phi, phi0, z0) for phi, p in sel]
    rms = math.sqrt(sum(e * e for e in errs) / len(errs))
    print(f"phi0 = {phi0:.4f}  Z0 = {z0:.3f}  rows = {len(sel)}  RMS relative error = {100 * rms:.1f}%")
    for target in (0.84, 0.86, 0.88, 0.90, 0.92, 0.94, 0.95):
        near = min(pts, key=lambda t: abs(t[0] - target))
        if abs(near[0] - target) < 0.004:
            ref = reference(near[0], phi0, z0)
            print(f"  phi {near[0]:.4f}  p_c {near[1]:.4e}  eq69 {ref:.4e}  ratio {near[1] / ref if ref else float('nan'):.3f}")

main()
