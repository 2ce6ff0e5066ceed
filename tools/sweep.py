#!/usr/bin/env python3
"""Speed against accuracy: run one scenario over a grid of cost knobs and seeds, chart error against cost.

usage: tools/sweep.py [--scenario scenarios/isotropic_A.ron] [--out out/sweep] [--phi-end 0.92]
                      [--seeds 1,2,3] [--jobs 2] [--sdem target/release/sdem] [--threads 1]
                      [--eq69 PHI0,Z0] [--grid full|quick] [--adaptive off|on]
                      [--only LABEL,...]

Each grid point changes the contour resolution dbeta, the time step (fraction of the critical
estimate) or the model level (Full, Volumetric, Rigid, or Adaptive(): the per-grain adaptive
level with its default thresholds) of the base scenario, and stops its isotropic compaction at
--phi-end. Each point runs once per sample seed (the `seed` of the scenario: another random
sample with the same size distribution, hence another jamming realisation), `--jobs` runs at a
time, each on `--threads` threads.

For each point the tool records its cost: the median over seeds of the run's CPU seconds (user +
system of the sdem process: less sensitive than wall time to other jobs on a shared machine) and
wall seconds, the mean number of steps and grain-steps/s. The accuracy is measured on the
seed-averaged curve p_c(phi) (linear interpolation on phi = 0.86, 0.865, ..., phi_end):
  - error_vs_finest: RMS relative difference between the point's seed-averaged curve and that of
    the finest point (smallest dbeta, then smallest dt, full model);
  - bias_vs_finest: the mean over phi of the same signed relative difference (negative: the
    point's p_c lies below the finest's);
  - error_vs_finest_per_seed: median over seeds of the RMS relative difference to the finest
    point's run of the same seed;
  - noise_floor: what error_vs_finest would read for a point that changes nothing but the
    realisation: sqrt(2) x the standard error of the finest point's seed-averaged curve, RMS over
    phi (sample standard deviation over seeds / sqrt(number of seeds));
  - error_vs_eq69: RMS relative difference of the seed-averaged curve to eq. 69 (Cantor et al.
    2020) with the paper's jamming point of the sample (--eq69, defaults by scenario name:
    A 0.833,4.20; B 0.858,4.22).
It writes OUT/sweep.csv (one row per point), OUT/runs.csv (one row per run) and OUT/sweep.svg
(error against CPU time, log-log, Pareto front marked, noise floor dashed, the finest
point's cost as a vertical line). Runs that already
have a summary.txt are reused.
"""
import argparse, csv, math, os, pathlib, re, statistics, subprocess, sys, time
from concurrent.futures import ThreadPoolExecutor

EQ69 = {"A": (0.833, 4.20), "B": (0.858, 4.22)}

GRIDS = {
    # (dbeta in degrees, dt / critical, model)
    "full": [(0.5, 0.4, "Full"), (1.0, 0.4, "Full"), (4.0, 0.4, "Full"), (12.0, 0.4, "Full"),
             (1.0, 0.8, "Full"), (1.0, 0.4, "Volumetric"), (1.0, 0.4, "Rigid"),
             (1.0, 0.4, "Adaptive()"), (1.0, 0.6, "Adaptive()"), (1.0, 0.8, "Adaptive()")],
    "quick": [(1.0, 0.4, "Full"), (4.0, 0.4, "Full")],
}


def eq69(phi, phi0, z0):
    if phi <= phi0:
        return 0.0
    return -(0.12 * phi / (2 * math.pi)) * (z0 + 5.1 * (phi - phi0) ** 0.5) * math.log((1 - phi) / (1 - phi0))


def variant_text(base, resolution, fraction, model, phi_end, name, seed):
    t = re.sub(r'name: "[^"]*"', f'name: "{name}"', base)
    t = re.sub(r"\bseed: \d+", f"seed: {seed}", t)
    t = re.sub(r"resolution_deg: [0-9.eE+-]+", f"resolution_deg: {resolution}", t)
    t = re.sub(r"FractionOfCritical\([0-9.eE+-]+\)", f"FractionOfCritical({fraction})", t)
    t = re.sub(r"model: \w+(\([^)]*\))?", f"model: {model}", t)
    t = re.sub(r"until: PackingFraction\([0-9.]+\)", f"until: PackingFraction({phi_end})", t)
    return t


def curve(run_dir):
    rows = [r for r in csv.DictReader(open(run_dir / "macro.csv")) if r["phase"] == "isotropic"]
    return sorted((float(r["phi"]), float(r["p_c"])) for r in rows)


def interpolate(pts, phi):
    for (a, pa), (b, pb) in zip(pts, pts[1:]):
        if a <= phi <= b and b > a:
            return pa + (pb - pa) * (phi - a) / (b - a)
    return None


def rms(values):
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else float("nan")


def label(resolution, fraction, model):
    return f"d{resolution:g}_t{fraction:g}_{model.rstrip('()')}"


def run_one(sdem, threads, scenario, run_dir):
    """Runs sdem; returns (returncode, last stderr line, CPU seconds of the child)."""
    err_path = run_dir.parent / f"{run_dir.name}.stderr"
    err = open(err_path, "w")
    proc = subprocess.Popen([sdem, "run", str(scenario), "--out", str(run_dir), "--quiet", "--threads", threads],
                            stdout=subprocess.DEVNULL, stderr=err)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    err.close()
    lines = err_path.read_text().strip().splitlines()
    return proc.returncode, (lines[-1] if lines else ""), usage.ru_utime + usage.ru_stime


def svg_chart(points, noise, reference, title, path):
    w, h, m = 760, 500, 72
    xs = [p["cpu_seconds"] for p in points] + [reference["cpu_seconds"]]
    ys = [max(p["error_vs_finest"], 1e-4) for p in points] + [noise]
    lx0, lx1 = math.log10(min(xs)) - 0.12, math.log10(max(xs)) + 0.25
    ly0, ly1 = math.log10(min(ys)) - 0.2, math.log10(max(ys)) + 0.2
    X = lambda x: m + (math.log10(x) - lx0) / (lx1 - lx0) * (w - 2 * m)
    Y = lambda y: h - m - (math.log10(y) - ly0) / (ly1 - ly0) * (h - 2 * m)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<line x1="{m}" y1="{h-m}" x2="{w-m}" y2="{h-m}" stroke="black"/>',
           f'<line x1="{m}" y1="{m}" x2="{m}" y2="{h-m}" stroke="black"/>',
           f'<text x="{w/2}" y="{h-22}" text-anchor="middle">CPU time of one run (s, 1 thread, median over seeds, log)</text>',
           f'<text x="16" y="{h/2}" transform="rotate(-90 16 {h/2})" text-anchor="middle">RMS relative error of seed-averaged p_c(phi) vs finest (log)</text>',
           f'<text x="{w/2}" y="26" text-anchor="middle" font-size="15">{title}</text>']
    for e in range(math.floor(ly0), math.ceil(ly1) + 1):
        for k in (1, 2, 5):
            v = k * 10.0**e
            if ly0 <= math.log10(v) <= ly1:
                out.append(f'<text x="{m-8}" y="{Y(v)+4}" text-anchor="end">{v:g}</text>'
                           f'<line x1="{m}" x2="{w-m}" y1="{Y(v)}" y2="{Y(v)}" stroke="#ddd"/>')
    for e in range(math.floor(lx0), math.ceil(lx1) + 1):
        for k in (1, 2, 5):
            v = k * 10.0**e
            if lx0 <= math.log10(v) <= lx1:
                out.append(f'<text x="{X(v)}" y="{h-m+16}" text-anchor="middle">{v:g}</text>'
                           f'<line y1="{m}" y2="{h-m}" x1="{X(v)}" x2="{X(v)}" stroke="#eee"/>')
    out.append(f'<line x1="{m}" x2="{w-m}" y1="{Y(noise)}" y2="{Y(noise)}" stroke="#777" stroke-dasharray="6 4"/>'
               f'<text x="{w-m-4}" y="{Y(noise)-5}" text-anchor="end" fill="#555">noise floor (realisations): {100*noise:.1f}%</text>')
    # The reference has no error of its own: a vertical line at its cost.
    xr = X(reference["cpu_seconds"])
    out.append(f'<line x1="{xr}" x2="{xr}" y1="{m}" y2="{h-m}" stroke="#2a2" stroke-dasharray="3 3"/>'
               f'<text x="{xr+4}" y="{h-m-6}" fill="#282">reference: {reference["label"]}</text>')
    # Pareto front: no other point both cheaper and more accurate.
    front = [p for p in points if not any(o["cpu_seconds"] < p["cpu_seconds"] and o["error_vs_finest"] < p["error_vs_finest"] for o in points)]
    front.sort(key=lambda p: p["cpu_seconds"])
    out.append('<polyline fill="none" stroke="#c33" stroke-width="2" points="'
               + " ".join(f'{X(p["cpu_seconds"])},{Y(max(p["error_vs_finest"], 1e-4))}' for p in front) + '"/>')
    for p in points:
        x, y = X(p["cpu_seconds"]), Y(max(p["error_vs_finest"], 1e-4))
        color = "#c33" if p in front else "#36c"
        out.append(f'<circle cx="{x}" cy="{y}" r="5" fill="{color}"/><text x="{x+8}" y="{y-6}">{p["label"]}</text>')
    out.append(f'<text x="{w-m}" y="{m-8}" text-anchor="end" fill="#c33">red: Pareto front</text></svg>')
    pathlib.Path(path).write_text("\n".join(out))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default="scenarios/isotropic_A.ron")
    ap.add_argument("--out", default="out/sweep")
    ap.add_argument("--phi-end", type=float, default=0.92)
    ap.add_argument("--seeds", default="1,2,3", help="comma-separated sample seeds")
    ap.add_argument("--jobs", type=int, default=max(1, os.cpu_count() or 1), help="runs at a time")
    ap.add_argument("--sdem", default="target/release/sdem")
    ap.add_argument("--threads", default="1", help="threads of each run")
    ap.add_argument("--eq69", default="", help="PHI0,Z0 of eq. 69 (default: by scenario name, sample A or B)")
    ap.add_argument("--grid", choices=sorted(GRIDS), default="full")
    ap.add_argument("--adaptive", choices=["off", "on"], default="off",
                    help="on: also run each full-model point with model Adaptive()")
    ap.add_argument("--only", default="", help="comma-separated labels: run only these grid points")
    a = ap.parse_args()

    scenario_path = pathlib.Path(a.scenario)
    if not scenario_path.exists():
        sys.exit(f"sweep: scenario {scenario_path} not found")
    if not pathlib.Path(a.sdem).exists():
        sys.exit(f"sweep: {a.sdem} not found: build it with `cargo build --release`")
    base = scenario_path.read_text()
    if a.eq69:
        phi0, z0 = (float(v) for v in a.eq69.split(","))
    else:
        sample = "B" if "_B" in scenario_path.stem else "A"
        phi0, z0 = EQ69[sample]
    seeds = [int(s) for s in a.seeds.split(",")]
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)

    grid = list(GRIDS[a.grid])
    if a.adaptive == "on":
        grid += [(r, f, "Adaptive()") for r, f, m in grid if m == "Full" and (r, f, "Adaptive()") not in grid]
    if a.only:
        wanted = set(a.only.split(","))
        grid = [g for g in grid if label(*g) in wanted]

    runs = {}  # (label, seed) -> dict

    def job(point, seed):
        resolution, fraction, model = point
        name = f"{label(*point)}_s{seed}"
        run_dir = out / name
        meta = out / f"{name}.cost"
        if not (run_dir / "summary.txt").exists():
            scenario = out / f"{name}.ron"
            scenario.write_text(variant_text(base, resolution, fraction, model, a.phi_end, name, seed))
            print(f"running {name} ...", flush=True)
            code, last, cpu = run_one(a.sdem, a.threads, scenario, run_dir)
            if code != 0:
                print(f"  {name} failed: {last}", flush=True)
                return dict(failed=last)
            meta.write_text(f"{cpu}\n")
        summary = dict(l.split(" = ", 1) for l in (run_dir / "summary.txt").read_text().splitlines() if " = " in l)
        wall = float(summary["wall_seconds"])
        cpu = float(meta.read_text()) if meta.exists() else wall
        return dict(wall_seconds=wall, cpu_seconds=cpu, steps=int(summary["steps"]),
                    grain_steps_per_second=float(summary["grain_steps_per_second"]),
                    phi_0=float(summary.get("phi_0", "nan")), curve=curve(run_dir))

    # Longest runs first, so that the pool ends together: the finest point, then by expected steps.
    order = sorted(((p, s) for s in seeds for p in grid), key=lambda ps: (ps[0][2] != "Full", ps[0][1], ps[0][0], ps[1]))
    with ThreadPoolExecutor(max_workers=a.jobs) as pool:
        futures = {ps: pool.submit(job, *ps) for ps in order}
        for (point, seed), fut in futures.items():
            runs[(label(*point), seed)] = fut.result()

    grid_phi = [0.86 + 0.005 * k for k in range(int(round((a.phi_end - 0.86) / 0.005)) + 1)]
    ok = lambda lab: [runs[(lab, s)] for s in seeds if "curve" in runs[(lab, s)]]
    finest_point = min((g for g in grid if ok(label(*g))), key=lambda g: (g[2] != "Full", g[0], g[1]))
    finest = label(*finest_point)

    def sampled(run):
        return [interpolate(run["curve"], phi) for phi in grid_phi]

    def mean_curve(lab):
        curves = [sampled(r) for r in ok(lab)]
        return [statistics.fmean(c[k] for c in curves) if all(c[k] is not None for c in curves) else None
                for k in range(len(grid_phi))]

    ref = mean_curve(finest)
    ref_curves = [sampled(r) for r in ok(finest)]
    noise = float("nan")
    if len(ref_curves) > 1:
        rel_se = [statistics.stdev(c[k] for c in ref_curves) / math.sqrt(len(ref_curves)) / ref[k]
                  for k in range(len(grid_phi)) if ref[k] and all(c[k] is not None for c in ref_curves)]
        noise = math.sqrt(2) * rms(rel_se)

    points = []
    for g in grid:
        lab = label(*g)
        done = ok(lab)
        failed = [f"s{s}: {runs[(lab, s)]['failed']}" for s in seeds if "failed" in runs[(lab, s)]]
        p = dict(label=lab, resolution=g[0], fraction=g[1], model=g[2], seeds=len(done), failed="; ".join(failed))
        if done:
            mc = mean_curve(lab)
            diffs = [(x - r) / r for x, r in zip(mc, ref) if x is not None and r]
            per_seed = []
            for s in seeds:
                run, base_run = runs[(lab, s)], runs[(finest, s)]
                if "curve" in run and "curve" in base_run and lab != finest:
                    d = [(x - r) / r for x, r in zip(sampled(run), sampled(base_run)) if x is not None and r]
                    run["error_vs_finest_same_seed"] = rms(d)
                    per_seed.append(rms(d))
            p.update(
                cpu_seconds=statistics.median(r["cpu_seconds"] for r in done),
                wall_seconds=statistics.median(r["wall_seconds"] for r in done),
                steps=round(statistics.fmean(r["steps"] for r in done)),
                grain_steps_per_second=statistics.median(r["grain_steps_per_second"] for r in done),
                phi_0=statistics.fmean(r["phi_0"] for r in done),
                phi_0_spread=statistics.stdev(r["phi_0"] for r in done) if len(done) > 1 else float("nan"),
                error_vs_finest=0.0 if lab == finest else rms(diffs),
                bias_vs_finest=statistics.fmean(diffs) if diffs else float("nan"),
                error_vs_finest_per_seed=statistics.median(per_seed) if per_seed else float("nan"),
                noise_floor=noise,
                error_vs_eq69=rms([(x - eq69(phi, phi0, z0)) / eq69(phi, phi0, z0)
                                   for x, phi in zip(mc, grid_phi) if x is not None and eq69(phi, phi0, z0) > 0]),
            )
        points.append(p)

    cols = ["label", "resolution", "fraction", "model", "seeds", "cpu_seconds", "wall_seconds", "steps",
            "grain_steps_per_second", "phi_0", "phi_0_spread", "error_vs_finest", "bias_vs_finest", "error_vs_finest_per_seed",
            "noise_floor", "error_vs_eq69", "failed"]
    fmt = lambda v: f"{v:.6g}" if isinstance(v, float) else v
    with open(out / "sweep.csv", "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore")
        wr.writeheader()
        for p in points:
            wr.writerow({k: fmt(v) for k, v in p.items()})
    with open(out / "runs.csv", "w", newline="") as f:
        wr = csv.writer(f)
        keys = ("cpu_seconds", "wall_seconds", "steps", "grain_steps_per_second", "phi_0", "error_vs_finest_same_seed", "failed")
        wr.writerow(["label", "seed", *keys])
        for g in grid:
            for s in seeds:
                r = runs[(label(*g), s)]
                wr.writerow([label(*g), s] + [fmt(r.get(k, "")) for k in keys])

    print(f"reference: {finest} (seeds {','.join(map(str, seeds))}); eq. 69 with phi0 = {phi0}, Z0 = {z0}; "
          f"noise floor {100*noise:.2f}%")
    for p in points:
        if p["seeds"]:
            print(f"{p['label']:20s} cpu {p['cpu_seconds']:8.1f} s  steps {p['steps']:8d}  phi0 {p['phi_0']:.4f}  "
                  f"vs finest {100*p['error_vs_finest']:5.2f}% (bias {100*p['bias_vs_finest']:+5.2f}%, per seed {100*p['error_vs_finest_per_seed']:5.2f}%)  "
                  f"vs eq.69 {100*p['error_vs_eq69']:5.1f}%  {p['failed']}")
        else:
            print(f"{p['label']:20s} FAILED: {p['failed']}")
    charted = [p for p in points if p["seeds"] and p["label"] != finest]
    if charted:
        title = f"speed against accuracy: {scenario_path.stem}, to phi = {a.phi_end}, seeds {','.join(map(str, seeds))}"
        reference = next(p for p in points if p["label"] == finest)
        svg_chart(charted, noise if noise == noise else 1e-3, reference, title, out / "sweep.svg")
        print(f"wrote {out / 'sweep.csv'}, {out / 'runs.csv'} and {out / 'sweep.svg'}")


if __name__ == "__main__":
    main()
