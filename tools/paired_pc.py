#!/usr/bin/env python3
"""Paired comparison of p_c(phi) between two builds or settings, seed by seed (issue #16's
accuracy check for changes that alter results).

    tools/paired_pc.py BASE_DIR NEW_DIR [phi ...]

BASE_DIR and NEW_DIR each hold one run folder per seed, named alike (e.g. s1 ... s5), each with
the macro.csv of `sdem run`. For each phi (default 0.84 0.86 0.88 0.90) it prints the base's
mean p_c and seed spread, and the relative change of NEW against BASE on the same seed, as the
mean +- the standard error of the mean over the seeds; then the steps and jamming points.
p_c at phi is interpolated log-linearly between the rows that bracket it (p_c > 0 on both).
"""
import csv
import math
import os
import sys


def rows(run):
    with open(os.path.join(run, "macro.csv")) as f:
        return [r for r in csv.DictReader(f) if r["phase"] != "end"]


def pc_at(run_rows, phi):
    pts = [(float(r["phi"]), float(r["p_c"])) for r in run_rows]
    for (p0, c0), (p1, c1) in zip(pts, pts[1:]):
        if p0 <= phi <= p1 and p1 > p0 and c0 > 0 and c1 > 0:
            w = (phi - p0) / (p1 - p0)
            return math.exp((1 - w) * math.log(c0) + w * math.log(c1))
    return None


def mean_sem(xs):
    m = sum(xs) / len(xs)
    if len(xs) < 2:
        return m, float("nan")
    var = sum((x - m) ** 2 for x in xs) / (len(xs) - 1)
    return m, math.sqrt(var / len(xs))


def summary_value(run, key):
    path = os.path.join(run, "summary.txt")
    if not os.path.exists(path):
        return None
    for line in open(path):
        k, _, v = line.partition("=")
        if k.strip() == key:
            return v.strip()
    return None


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    base, new = sys.argv[1], sys.argv[2]
    phis = [float(x) for x in sys.argv[3:]] or [0.84, 0.86, 0.88, 0.90]
    seeds = sorted(d for d in os.listdir(base) if os.path.isdir(os.path.join(new, d)))
    if not seeds:
        sys.exit(f"no run folder of {base} has a namesake in {new}")
    print(f"seeds: {' '.join(seeds)}")
    print("phi    base p_c (spread)      new vs base (mean +- s.e.)")
    for phi in phis:
        b = [pc_at(rows(os.path.join(base, s)), phi) for s in seeds]
        n = [pc_at(rows(os.path.join(new, s)), phi) for s in seeds]
        pairs = [(x, y) for x, y in zip(b, n) if x and y]
        if not pairs:
            print(f"{phi:.3f}  (not reached)")
            continue
        bm, bs = mean_sem([x for x, _ in pairs])
        spread = bs * math.sqrt(len(pairs)) / bm if len(pairs) > 1 else float("nan")
        dm, ds = mean_sem([100.0 * (y / x - 1.0) for x, y in pairs])
        print(f"{phi:.3f}  {bm:.3e} ({100 * spread:.1f}%)   {dm:+.1f} +- {ds:.1f}%  ({len(pairs)} seeds)")
    for key in ("steps", "phi_0", "wall_seconds"):
        vb = [summary_value(os.path.join(base, s), key) for s in seeds]
        vn = [summary_value(os.path.join(new, s), key) for s in seeds]
        print(f"{key}: base {' '.join(str(v) for v in vb)} | new {' '.join(str(v) for v in vn)}")


if __name__ == "__main__":
    main()
