#!/usr/bin/env python3
"""Periodic cell against walls (issue #14): the size effect, the jamming point and simple shear.

usage: tools/periodic_study.py [--out out/periodic] [--sdem target/release/sdem] [--jobs 1]
                               [--sizes 1000,10000,100000] [--seeds-small 3] [--only PATTERN]
                               [--report-only] [--no-shear]

1. Size effect. Sample A's distribution (SPEC §8) with N grains in a box of side sqrt(N / 1000),
   compacted isotropically to phi = 0.90 with the protocol of `scenarios/isotropic_100k.ron`
   (affine compression, 1e-2 in the loose gas up to phi = 0.78, then inertial number 9.5e-4;
   adaptive model level at 0.6 x critical; dbeta = 0.5 deg), once between four walls and once in
   a periodic cell (`boundary: Periodic`), for each N of --sizes; the smaller sizes with
   --seeds-small seeds (1000 grains) and 2 seeds (10 000 grains) to show the realisation noise;
   at 10^5 grains the shipped `isotropic_100k.ron` and `isotropic_100k_periodic.ron` are run.
   Reported: p_c at phi = 0.84, 0.86, 0.88, 0.90 (interpolated in the macro.csv rows), the
   jamming point by both rattler rules (SPEC §7) and eq. 69's RMS error with the paper's
   (phi0, Z0) = (0.833, 4.20) and with the run's own 3-rule point.
2. The jamming point of samples A and B with the shipped protocols (`isotropic_A.ron`,
   `isotropic_B.ron`: compaction to phi = 0.95 at inertial number 1e-3), walls against a
   periodic cell (`isotropic_A_periodic.ron`, and isotropic_B.ron with `boundary: Periodic`):
   phi0 and Z0 by the 3-contact rattler rule, eq. 69's RMS error with the paper's and the run's
   own jamming point, in `jamming_protocol.csv`.
3. Simple shear (`scenarios/shear_A_periodic.ron`): sample A sheared at constant normal stress
   syy = 1e-3, 1e-2 and 5e-2 E, each at the rate that puts the inertial number at 9.6e-4, and at
   syy = 1e-2 also at half that rate (the quasi-static limit). Reported: the steady-state stress
   ratio mu = -sxy_c / p_c (mean and standard deviation of the rows over gamma in [1, 2], and
   the standard error of the mean from 10 blocks of 0.1 in gamma), the packing fraction and
   coordination there.

Outputs in --out: `runs/<name>/` (the scenario beside it as `<name>.ron`, macro.csv,
summary.txt, cost.txt with the run's CPU seconds), `size_effect.csv`, `jamming.csv`,
`shear.csv`, and the charts `size_effect.svg` (p_c against phi, walls and periodic, every N)
and `shear.svg` (mu and phi against gamma). A run whose directory holds a finished run of the
same scenario text is not run again.
"""
import argparse
import csv
import math
import os
import pathlib
import re
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from meshfree_biaxial_plot import panel  # noqa: E402
from sdem_vs_meshfree import eq69_error, jamming_row  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
PHI_POINTS = (0.84, 0.86, 0.88, 0.90)
PAPER_A = (0.833, 4.20)
PAPER_B = (0.858, 4.22)


def size_text(n, seed, periodic):
    """isotropic_100k.ron's protocol at n grains, walls or periodic; at 10^5 grains (seed 1) the
    shipped scenarios themselves, `isotropic_100k.ron` and `isotropic_100k_periodic.ron`. Both
    take plain steps: the walls scenario's multi-rate cycles are taken out, as a periodic cell
    has none (the study compares boundaries, not integrators)."""
    plain = lambda text: text.replace("Adaptive(multi_rate: true)", "Adaptive()")
    if n == 100000 and seed == 1:
        name = "isotropic_100k_periodic.ron" if periodic else "isotropic_100k.ron"
        return plain((ROOT / "scenarios" / name).read_text())
    base = plain((ROOT / "scenarios" / "isotropic_100k.ron").read_text())
    base = "\n".join(l for l in base.splitlines() if not l.lstrip().startswith("//")) + "\n"
    side = math.sqrt(n / 1000)
    kind = "periodic" if periodic else "walls"
    t = re.sub(r'name: "[^"]*"', f'name: "size_{kind}_{n}_s{seed}"', base)
    t = re.sub(r"\bseed: \d+", f"seed: {seed}", t)
    t = re.sub(r"count: \d+", f"count: {n}", t)
    t = re.sub(r"box_width: [0-9.]+", f"box_width: {side!r}", t)
    t = re.sub(r"box_height: [0-9.]+", f"box_height: {side!r}", t)
    if periodic:
        t = t.replace("            affine: true,\n", "")
        t = t.replace("    output:", "    boundary: Periodic,\n    output:")
    # A row every 1000 steps at 10^5 grains; denser rows for the small samples.
    t = re.sub(r"every: \d+", f"every: {100 if n <= 1000 else 500 if n <= 10000 else 1000}", t)
    return t


def shear_text(syy, rate_factor):
    """shear_A_periodic.ron at normal stress syy, its rate set for I = 9.6e-4 times rate_factor."""
    base = (ROOT / "scenarios" / "shear_A_periodic.ron").read_text()
    base = "\n".join(l for l in base.splitlines() if not l.lstrip().startswith("//")) + "\n"
    rate = 9.6e-4 * rate_factor * math.sqrt(syy) / 0.024
    name = f"shear_syy{syy:g}" + ("" if rate_factor == 1 else f"_rate{rate_factor:g}")
    t = re.sub(r'name: "[^"]*"', f'name: "{name}"', base)
    t = t.replace("until: MeanStress(1e-2)", f"until: MeanStress({syy!r})")
    t = re.sub(r"Shear\(rate: [^,]+, syy: [^,]+,",
               f"Shear(rate: {rate:.4e}, syy: {syy!r},", t)
    # A row every 0.005 of shear strain.
    every = max(200, int(0.005 / rate / 1.366e-3))
    t = re.sub(r"every: \d+", f"every: {every}", t)
    return name, t


def jamming_text(sample, periodic):
    """The shipped isotropic compaction of sample A or B, walls or periodic."""
    if sample == "A" and periodic:
        return (ROOT / "scenarios" / "isotropic_A_periodic.ron").read_text()
    t = (ROOT / "scenarios" / f"isotropic_{sample}.ron").read_text()
    if periodic:
        t = t.replace(f'name: "isotropic_{sample}"', f'name: "isotropic_{sample}_periodic"')
        t = t.replace("    output:", "    boundary: Periodic,\n    output:")
    return t


def jamming_report(a, runs):
    table = []
    for sample, kind, run_dir in runs:
        if not (run_dir / "summary.txt").exists():
            continue
        rows = rows_of(run_dir)
        j = jamming_row(run_dir.name, rows)
        paper = PAPER_A if sample == "A" else PAPER_B
        row = dict(sample=sample, boundary=kind, paper_phi0=paper[0], paper_z0=paper[1],
                   eq69_rms_paper=f"{eq69_error(rows, *paper):.4f}",
                   p_c_0_90=f"{p_at(rows, 0.90):.4e}", p_c_0_95=f"{float(rows[-1]['p_c']):.4e}",
                   cpu_s=round(float((run_dir / 'cost.txt').read_text()), 1))
        if j:
            row.update(phi0_2rule=f"{j['phi0']:.4f}", z0_2rule=f"{j['z_nr0']:.3f}",
                       phi0_3rule=f"{j['phi0_3rule']:.4f}", z0_3rule=f"{j['z_nr3_0']:.3f}",
                       p_c_at_3rule=f"{j['p_c_3rule']:.3e}",
                       eq69_rms_own_3rule=f"{j['eq69_rms_err_3rule']:.4f}")
        table.append(row)
    write_csv(a.out / "jamming_protocol.csv", table)
    print("\njamming point, shipped protocols (3-contact rule), eq. 69 RMS with the paper's and the own point")
    for r in table:
        print(f"  {r['sample']} {r['boundary']:9} phi0 {r.get('phi0_3rule', '')} Z0 {r.get('z0_3rule', '')}"
              f" (paper {r['paper_phi0']}, {r['paper_z0']})  eq69 paper {r['eq69_rms_paper']}"
              f"  own {r.get('eq69_rms_own_3rule', '')}  p(0.90) {r['p_c_0_90']}  {r['cpu_s']} CPU s")


def without_comments(text):
    return "\n".join(l for l in text.splitlines() if not l.lstrip().startswith("//"))


def run(sdem, run_dir, text, threads):
    """Runs the scenario `text` in `run_dir` unless a finished run of it (comments aside) is
    there; returns the CPU seconds."""
    scenario = run_dir.parent / f"{run_dir.name}.ron"
    cost = run_dir / "cost.txt"
    if (scenario.exists() and without_comments(scenario.read_text()) == without_comments(text)
            and cost.exists() and (run_dir / "summary.txt").exists()):
        return float(cost.read_text())
    scenario.parent.mkdir(parents=True, exist_ok=True)
    scenario.write_text(text)
    print(f"running {run_dir.name} ...", flush=True)
    with open(run_dir.parent / f"{run_dir.name}.stderr", "w") as err:
        proc = subprocess.Popen(["nice", "-n", "5", sdem, "run", str(scenario), "--out", str(run_dir),
                                 "--quiet", "--threads", str(threads)],
                                stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise RuntimeError(f"{run_dir.name}: sdem exited with {code}; see its .stderr")
    cpu = usage.ru_utime + usage.ru_stime
    cost.write_text(f"{cpu}\n")
    print(f"  {run_dir.name}: {cpu:.0f} CPU s", flush=True)
    return cpu


def rows_of(run_dir):
    with open(run_dir / "macro.csv") as f:
        return list(csv.DictReader(f))


def p_at(rows, phi):
    """p_c at packing fraction phi, linear between the rows around it (None if not reached)."""
    pts = [(float(r["phi"]), float(r["p_c"])) for r in rows if r["phase"] == "isotropic"]
    for (f0, p0), (f1, p1) in zip(pts, pts[1:]):
        if f0 <= phi <= f1 and f1 > f0:
            return p0 + (p1 - p0) * (phi - f0) / (f1 - f0)
    return None


def size_effect(a, runs):
    table, jam = [], []
    for kind, n, seed, run_dir in runs:
        if not (run_dir / "summary.txt").exists():
            continue
        rows = rows_of(run_dir)
        cpu = float((run_dir / "cost.txt").read_text())
        row = dict(boundary=kind, grains=n, seed=seed, cpu_s=round(cpu, 1))
        for phi in PHI_POINTS:
            p = p_at(rows, phi)
            row[f"p_c_{phi:.2f}"] = f"{p:.4e}" if p is not None else ""
        row["eq69_rms_paper"] = f"{eq69_error(rows, *PAPER_A):.4f}"
        j = jamming_row(run_dir.name, rows)
        if j:
            row.update(phi0_3rule=f"{j['phi0_3rule']:.4f}", z0_3rule=f"{j['z_nr3_0']:.3f}",
                       eq69_rms_own_3rule=f"{j['eq69_rms_err_3rule']:.4f}",
                       phi0_2rule=f"{j['phi0']:.4f}", z0_2rule=f"{j['z_nr0']:.3f}")
            jam.append(dict(boundary=kind, grains=n, seed=seed, **{k: v for k, v in j.items() if k != "run"}))
        table.append(row)
    write_csv(a.out / "size_effect.csv", table)
    write_csv(a.out / "jamming.csv", jam)
    print("\nsize effect: p_c at phi (E = 1), jamming point by the 3-contact rule, eq. 69 RMS")
    print(f"{'boundary':9} {'N':>7} {'seed':>4} " + " ".join(f"{'p@' + format(p, '.2f'):>10}" for p in PHI_POINTS)
          + f" {'phi0_3':>7} {'Z0_3':>6} {'eq69(paper)':>11} {'eq69(own)':>9} {'CPU s':>7}")
    for r in table:
        print(f"{r['boundary']:9} {r['grains']:>7} {r['seed']:>4} "
              + " ".join(f"{r[f'p_c_{p:.2f}']:>10}" for p in PHI_POINTS)
              + f" {r.get('phi0_3rule', ''):>7} {r.get('z0_3rule', ''):>6} {r['eq69_rms_paper']:>11}"
              f" {r.get('eq69_rms_own_3rule', ''):>9} {r['cpu_s']:>7}")
    chart_size_effect(a.out / "size_effect.svg", runs)


def chart_size_effect(path, runs):
    colours = {1000: "#c33", 10000: "#393", 100000: "#36c"}
    xs, ys, cs, ls, ds = [], [], [], [], []
    for kind, n, seed, run_dir in runs:
        if not (run_dir / "summary.txt").exists():
            continue
        pts = [(float(r["phi"]), float(r["p_c"])) for r in rows_of(run_dir)
               if r["phase"] == "isotropic" and float(r["phi"]) >= 0.82 and float(r["p_c"]) > 0]
        if not pts:
            continue
        xs.append([p[0] for p in pts])
        ys.append([math.log10(p[1]) for p in pts])
        cs.append(colours.get(n, "#000"))
        ls.append(f"{kind} N = {n} seed {seed}")
        ds.append("" if kind == "periodic" else "5,3")
    ref = [0.835 + 0.001 * k for k in range(66)]
    xs.append(ref)
    ys.append([math.log10(max(1e-9, -eq69_value(f))) for f in ref])
    cs.append("#000"), ls.append("eq. 69, paper's (phi0, Z0)"), ds.append("1,3")
    svg = ['<svg xmlns="http://www.w3.org/2000/svg" width="900" height="640" font-family="sans-serif" font-size="12">',
           '<text x="450" y="20" text-anchor="middle" font-size="15">Size effect: sample A, walls (dashed) '
           'against a periodic cell (solid)</text>']
    svg += panel(90, 50, 760, 520, xs, ys, cs, ls, "packing fraction phi", "log10 p_c / E",
                 "mean stress against packing fraction", dashes=ds, from_zero=False)
    svg.append("</svg>")
    path.write_text("\n".join(svg))


def eq69_value(phi):
    from sweep import eq69
    return -eq69(phi, *PAPER_A)


def shear_report(a, runs):
    table = []
    curves = []
    for syy, factor, name, run_dir in runs:
        if not (run_dir / "summary.txt").exists():
            continue
        rows = [r for r in rows_of(run_dir) if r["phase"] == "shear"]
        steady = [r for r in rows if 1.0 <= float(r["shear_strain"]) <= 2.0]
        mu_full = [-float(r["sxy_c"]) / float(r["p_c"]) for r in steady]
        q_full = [math.hypot(float(r["q_c"]), float(r["sxy_c"])) / float(r["p_c"]) for r in steady]
        mean = lambda key: statistics.fmean(float(r[key]) for r in steady)
        # Standard error of the mean from 10 blocks of 0.1 in gamma (the rows are correlated).
        blocks = [[m for m, r in zip(mu_full, steady) if k <= 10 * (float(r["shear_strain"]) - 1.0) < k + 1]
                  for k in range(10)]
        block_means = [statistics.fmean(b) for b in blocks if b]
        mu_se = statistics.stdev(block_means) / math.sqrt(len(block_means))
        table.append(dict(
            syy=syy, rate_factor=factor, name=name, rows=len(steady),
            mu_mean=f"{statistics.fmean(mu_full):.4f}", mu_sd=f"{statistics.pstdev(mu_full):.4f}",
            mu_se=f"{mu_se:.4f}",
            deviator_ratio=f"{statistics.fmean(q_full):.4f}",
            p_c=f"{mean('p_c'):.4e}", syy_c=f"{mean('syy_c'):.4e}", phi=f"{mean('phi'):.4f}",
            z=f"{mean('z'):.3f}", z_nr3=f"{mean('z_nr3'):.3f}",
            inertial_number=f"{statistics.fmean(float(r['inertial_number']) for r in steady):.3e}",
            p_kin_over_p=f"{mean('p_kin') / mean('p_c'):.2e}",
            cpu_s=round(float((run_dir / 'cost.txt').read_text()), 1)))
        curves.append((name, rows))
    write_csv(a.out / "shear.csv", table)
    print("\nsimple shear, steady state over gamma in [1, 2]: mu = -sxy_c / p_c")
    for r in table:
        print(f"  {r['name']:24} mu = {r['mu_mean']} ± {r['mu_sd']} (s.e. {r['mu_se']})  (s1-s2)/(s1+s2) = {r['deviator_ratio']}"
              f"  p_c = {r['p_c']}  phi = {r['phi']}  z = {r['z']}  I = {r['inertial_number']}"
              f"  p_kin/p = {r['p_kin_over_p']}  {r['cpu_s']} CPU s")
    if curves:
        colours = ["#c33", "#393", "#36c", "#a6c", "#000"]
        svg = ['<svg xmlns="http://www.w3.org/2000/svg" width="1000" height="420" font-family="sans-serif" font-size="12">',
               '<text x="500" y="20" text-anchor="middle" font-size="15">Simple shear of sample A '
               '(periodic cell, frictionless, nu = 0.5) at constant normal stress</text>']
        for k, (column, label) in enumerate([("mu", "-sxy_c / p_c"), ("phi", "phi")]):
            xs, ys = [], []
            for name, rows in curves:
                xs.append([float(r["shear_strain"]) for r in rows])
                ys.append([-float(r["sxy_c"]) / float(r["p_c"]) if column == "mu" else float(r["phi"])
                           for r in rows])
            svg += panel(80 + 500 * k, 50, 390, 300, xs, ys, colours[:len(curves)],
                         [c[0] for c in curves], "shear strain gamma", label, label,
                         from_zero=column == "mu")
        svg.append("</svg>")
        (a.out / "shear.svg").write_text("\n".join(svg))


def write_csv(path, rows):
    if not rows:
        return
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="out/periodic", type=pathlib.Path)
    ap.add_argument("--sdem", default=str(ROOT / "target" / "release" / "sdem"))
    ap.add_argument("--jobs", type=int, default=1, help="runs at once (each with 2 / jobs threads)")
    ap.add_argument("--sizes", default="1000,10000,100000")
    ap.add_argument("--seeds-small", type=int, default=3)
    ap.add_argument("--only", default="", help="run only the runs whose name contains this")
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--no-shear", action="store_true")
    a = ap.parse_args()
    sizes = [int(s) for s in a.sizes.split(",")]
    size_runs = []
    for n in sizes:
        seeds = a.seeds_small if n <= 1000 else 2 if n <= 10000 else 1
        for seed in range(1, seeds + 1):
            for kind in ("walls", "periodic"):
                size_runs.append((kind, n, seed, a.out / "runs" / f"size_{kind}_{n}_s{seed}"))
    jam_runs = [(sample, kind, a.out / "runs" / f"jam_{sample}_{kind}")
                for sample in ("A", "B") for kind in ("walls", "periodic")]
    shear_runs = []
    if not a.no_shear:
        for syy, factor in [(1e-2, 1), (5e-2, 1), (1e-3, 1), (1e-2, 0.5)]:
            name, _ = shear_text(syy, factor)
            shear_runs.append((syy, factor, name, a.out / "runs" / name))
    if not a.report_only:
        jobs = []
        for kind, n, seed, run_dir in size_runs:
            jobs.append((run_dir, size_text(n, seed, kind == "periodic")))
        for sample, kind, run_dir in jam_runs:
            jobs.append((run_dir, jamming_text(sample, kind == "periodic")))
        for syy, factor, name, run_dir in shear_runs:
            jobs.append((run_dir, shear_text(syy, factor)[1]))
        jobs = [j for j in jobs if a.only in j[0].name]
        threads = max(1, 2 // a.jobs)
        with ThreadPoolExecutor(a.jobs) as pool:
            for f in [pool.submit(run, a.sdem, d, t, threads) for d, t in jobs]:
                try:
                    f.result()
                except RuntimeError as e:
                    print(f"failed: {e}", flush=True)
    a.out.mkdir(parents=True, exist_ok=True)
    size_effect(a, size_runs)
    jamming_report(a, jam_runs)
    shear_report(a, shear_runs)


if __name__ == "__main__":
    main()
