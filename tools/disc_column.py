#!/usr/bin/env python3
"""Grain against wall, and grain against grain: SDEM's contact law on one and two discs (issue #13).

usage: tools/disc_column.py [--out out/disc_column] [--sdem target/release/sdem] [--nodes 64] [--nu 0.3]

The secant law is calibrated on one disc pressed by walls (`sdem calibrate`); in an assembly
most contacts are between two curved grains. This tool presses a row of one disc, and a row of
two discs, in a box one diameter high (the right wall moves left at the strain rate 4e-3 to a
strain of the box width of 0.1; the other walls stay, and hold the row straight: a free row of
frictionless discs buckles), with the meshfree
solver (explicit, neo-Hookean, `--nodes` boundary nodes, k0 = 300 E/R) and with SDEM full (the
paper's law, the single-grain calibration, and the assembly pair a = 1.0, b = 2.0), nu = `--nu`,
E = rho = 1, R = 0.012. It prints the stress on the right wall of each SDEM law over the
meshfree one, at a few strains (of the box width) of each case. A third case is the
calibration's own loading: one disc, the four walls in. If the law transfers from wall contacts
to grain contacts, the two rows show the same ratios; if SDEM's grain model maps the box strain to
the contact geometry as the meshfree disc does, the calibration's case shows ratios near 1.

Outputs in --out: the runs (scenario, macro.csv, cost.txt; a finished run of the same scenario
is not run again) and `disc_column.csv` (case, law, strain,
sxx_ref, sxx, ratio).
"""

import argparse
import csv
import pathlib
import sys

from sdem_vs_meshfree import run_cached

R = 0.012
SHRINK = 0.999
RATE = 4e-3
STRAIN_END = 0.1
ROW_STRAIN = 5e-4
LAWS = {"paper": (0.58, 2.0), "calibrated": (0.615, 2.53), "assembly": (1.0, 2.0)}
STRAINS = [0.02, 0.04, 0.06, 0.08, 0.10]


# (label, discs in the row, loading phase): the calibration's own path (the four walls in), and
# the right wall alone with one and with two discs.
CASES = [("1 disc, four walls in", 1, "Isotropic"), ("1 disc, right wall in", 1, "Oedometric"),
         ("2 discs, right wall in", 2, "Oedometric")]


def scenario(name, discs, phase, model, extra, time_step, every, nu):
    width, height = 2 * R * discs, 2 * R
    return f"""// Written by tools/disc_column.py.
Scenario(
    name: "{name}",
    sample: (file: "packing_{discs}.csv", box_width: {width!r}, box_height: {height!r}),
    material: (young: 1.0, poisson: {nu}, density: 1.0),
    model: {model},{extra}
    time_step: {time_step},
    loading: [
        {phase}(rate: Constant({RATE}), until: Strain({STRAIN_END})),
    ],
    output: (every: {every}),
)
"""


def curve(run_dir, width0):
    rows = list(csv.DictReader(open(run_dir / "macro.csv")))
    return [(1 - float(r["box_width"]) / width0, float(r["sxx_c"])) for r in rows]


def at(points, strain):
    for (x0, y0), (x1, y1) in zip(points, points[1:]):
        if x0 <= strain <= x1 and x1 > x0:
            return y0 + (strain - x0) / (x1 - x0) * (y1 - y0)
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="out/disc_column")
    ap.add_argument("--sdem", default="target/release/sdem")
    ap.add_argument("--nodes", type=int, default=64, help="boundary nodes per meshfree disc")
    ap.add_argument("--nu", type=float, default=0.3, help="Poisson's ratio of both solvers' grains")
    a = ap.parse_args()
    if not pathlib.Path(a.sdem).exists():
        sys.exit(f"disc_column: {a.sdem} not found: build it with `cargo build --release`")
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for case, (label, discs, phase) in enumerate(CASES):
        lines = ["x,y,radius"] + [f"{(2 * k + 1) * R!r},{R!r},{R * SHRINK!r}" for k in range(discs)]
        (out / f"packing_{discs}.csv").write_text("\n".join(lines) + "\n")
        mf = f"case{case}_meshfree{a.nodes}"
        run_cached(a.sdem, 1, out / mf, scenario(
            mf, discs, phase, f"Meshfree((boundary_nodes: {a.nodes}, grading: 3.0, law: NeoHookean, "
            "scheme: CentralDifference, k0: 300.0, rayleigh_alpha: 2.0))", "",
            f"Fixed({ROW_STRAIN / RATE})", 1, a.nu))
        ref = curve(out / mf, 2 * R * discs)
        for law, (la, lb) in LAWS.items():
            name = f"case{case}_sdem_{law}"
            run_cached(a.sdem, 1, out / name, scenario(
                name, discs, phase, "Full",
                f"\n    contact: (a: {la}, b: {lb}, resolution_deg: 1.0, damping: 1.0),",
                "FractionOfCritical(0.4)", 20, a.nu))
            sd = curve(out / name, 2 * R * discs)
            for e in STRAINS:
                r, s = at(ref, e), at(sd, e)
                if r and s:
                    rows.append(dict(case=label, law=law, strain=e, sxx_ref=r, sxx=s, ratio=s / r))
    with open(out / "disc_column.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("\n| case | SDEM law | " + " | ".join(f"strain {e}" for e in STRAINS) + " |")
    print("|---|---|" + "---|" * len(STRAINS))
    for label, _, _ in CASES:
        for law, (la, lb) in LAWS.items():
            cells = {r["strain"]: r for r in rows if r["case"] == label and r["law"] == law}
            print(f"| {label} | {law} (a {la}, b {lb}) | "
                  + " | ".join(f"{cells[e]['ratio']:.2f} ({cells[e]['sxx_ref']:.1e})" if e in cells else "–"
                               for e in STRAINS) + " |")


if __name__ == "__main__":
    main()
