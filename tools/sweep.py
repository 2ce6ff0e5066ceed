#!/usr/bin/env python3
"""Speed against accuracy: run one scenario over a grid of cost knobs and chart error against cost.

usage: tools/sweep.py [--scenario scenarios/isotropic_A.ron] [--out out/sweep] [--phi-end 0.92]
                      [--sdem target/release/sdem] [--threads 1] [--quick]
                      [--adaptive off|on] [--only LABEL,...]

Each variant changes the contour resolution dbeta, the time step (fraction of the critical
estimate) or the model level of the base scenario (Full, Volumetric, or Adaptive(): the
per-grain adaptive level with its default thresholds; --adaptive on adds the adaptive variant of
every full-model point of the grid; --only runs a few named points), stops the isotropic compaction at
--phi-end, and runs `sdem run` on it. For each run the tool records its cost (wall seconds,
grain-steps/s) and two errors of its p_c(phi) curve, over phi in [0.86, phi_end]:
  - against the finest run of the grid (smallest dbeta, smallest dt, full model): RMS relative
    difference at common phi (linear interpolation);
  - against eq. 69 (Cantor et al. 2020) with the paper's jamming point of sample A
    (phi0 = 0.833, Z0 = 4.20).
It writes OUT/sweep.csv and OUT/sweep.svg (error against wall time, log-log, Pareto front of the
error against the finest run marked). Runs that already have a summary.txt are reused.
"""
import argparse, csv, math, pathlib, re, subprocess, sys

def reference(phi, phi0=0.833, z0=4.20):
    if phi <= phi0:
        return 0.0
    return -(0.12 * phi / (2 * math.pi)) * (z0 + 5.1 * (phi - phi0) ** 0.5) * math.log((1 - phi) / (1 - phi0))

def variant_text(base, resolution, fraction, model, phi_end, name):
    t = re.sub(r'name: "[^"]*"', f'name: "{name}"', base)
    t = re.sub(r"resolution_deg: [0-9.eE+-]+", f"resolution_deg: {resolution}", t)
    t = re.sub(r"FractionOfCritical\([0-9.eE+-]+\)", f"FractionOfCritical({fraction})", t)
    t = re.sub(r"model: \w+(\([^)]*\))?", f"model: {model}", t)
    t = re.sub(r"until: PackingFraction\([0-9.]+\)", f"until: PackingFraction({phi_end})", t)
    return t

def curve(run_dir):
    rows = [r for r in csv.DictReader(open(run_dir / "macro.csv")) if r["phase"] == "isotropic"]
    pts = sorted((float(r["phi"]), float(r["p_c"])) for r in rows)
    return pts

def interpolate(pts, phi):
    for (a, pa), (b, pb) in zip(pts, pts[1:]):
        if a <= phi <= b and b > a:
            return pa + (pb - pa) * (phi - a) / (b - a)
    return None

def rms(values):
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else float("nan")

def svg_chart(rows, path):
    w, h, m = 720, 480, 70
    xs = [r["wall_seconds"] for r in rows]
    ys = [max(r["error_vs_finest"], 1e-4) for r in rows]
    lx0, lx1 = math.log10(min(xs)) - 0.1, math.log10(max(xs)) + 0.1
    ly0, ly1 = math.log10(min(ys)) - 0.2, math.log10(max(ys)) + 0.2
    X = lambda x: m + (math.log10(x) - lx0) / (lx1 - lx0) * (w - 2 * m)
    Y = lambda y: h - m - (math.log10(y) - ly0) / (ly1 - ly0) * (h - 2 * m)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<line x1="{m}" y1="{h-m}" x2="{w-m}" y2="{h-m}" stroke="black"/>',
           f'<line x1="{m}" y1="{m}" x2="{m}" y2="{h-m}" stroke="black"/>',
           f'<text x="{w/2}" y="{h-20}" text-anchor="middle">wall time of the run (s, log)</text>',
           f'<text x="18" y="{h/2}" transform="rotate(-90 18 {h/2})" text-anchor="middle">RMS relative error of p_c(phi) vs finest run (log)</text>',
           f'<text x="{w/2}" y="24" text-anchor="middle" font-size="15">speed against accuracy (sample A, isotropic, to phi = {rows[0]["phi_end"]})</text>']
    for e in range(math.floor(ly0), math.ceil(ly1) + 1):
        if ly0 <= e <= ly1:
            out.append(f'<text x="{m-8}" y="{Y(10**e)+4}" text-anchor="end">1e{e}</text><line x1="{m}" x2="{w-m}" y1="{Y(10**e)}" y2="{Y(10**e)}" stroke="#ddd"/>')
    for e in range(math.floor(lx0), math.ceil(lx1) + 1):
        for k in (1, 2, 5):
            v = k * 10**e
            if lx0 <= math.log10(v) <= lx1:
                out.append(f'<text x="{X(v)}" y="{h-m+16}" text-anchor="middle">{v:g}</text>')
    # Pareto front: no other run both cheaper and more accurate.
    front = [r for r in rows if not any(o["wall_seconds"] < r["wall_seconds"] and o["error_vs_finest"] < r["error_vs_finest"] for o in rows)]
    front.sort(key=lambda r: r["wall_seconds"])
    out.append('<polyline fill="none" stroke="#c33" stroke-width="2" points="' + " ".join(f'{X(r["wall_seconds"])},{Y(max(r["error_vs_finest"],1e-4))}' for r in front) + '"/>')
    for r in rows:
        x, y = X(r["wall_seconds"]), Y(max(r["error_vs_finest"], 1e-4))
        color = "#c33" if r in front else "#36c"
        out.append(f'<circle cx="{x}" cy="{y}" r="5" fill="{color}"/><text x="{x+8}" y="{y-6}">{r["label"]}</text>')
    out.append(f'<text x="{w-m}" y="{m}" text-anchor="end" fill="#c33">red: Pareto front</text></svg>')
    pathlib.Path(path).write_text("\n".join(out))

def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenario", default="scenarios/isotropic_A.ron")
    ap.add_argument("--out", default="out/sweep")
    ap.add_argument("--phi-end", type=float, default=0.92)
    ap.add_argument("--sdem", default="target/release/sdem")
    ap.add_argument("--threads", default="1")
    ap.add_argument("--quick", action="store_true", help="only dbeta 1, 4 and dt 0.4")
    ap.add_argument("--adaptive", choices=["off", "on"], default="off",
                    help="on: also run each full-model point with model Adaptive()")
    ap.add_argument("--only", default="", help="comma-separated labels: run only these grid points")
    a = ap.parse_args()
    base = pathlib.Path(a.scenario).read_text()
    out = pathlib.Path(a.out); out.mkdir(parents=True, exist_ok=True)
    grid = [(0.5, 0.4, "Full"), (1.0, 0.4, "Full"), (2.0, 0.4, "Full"), (4.0, 0.4, "Full"), (8.0, 0.4, "Full"),
            (1.0, 0.2, "Full"), (1.0, 0.8, "Full"), (1.0, 0.4, "Volumetric")]
    if a.quick:
        grid = [(1.0, 0.4, "Full"), (4.0, 0.4, "Full")]
    if a.adaptive == "on":
        grid += [(r, f, "Adaptive()") for r, f, m in grid if m == "Full"]
    label = lambda r, f, m: f"d{r:g}_t{f:g}_{m.rstrip('()')}"
    if a.only:
        wanted = set(a.only.split(","))
        grid = [g for g in grid if label(*g) in wanted]
    rows = []
    for resolution, fraction, model in grid:
        name = label(resolution, fraction, model)
        run_dir = out / name
        if not (run_dir / "summary.txt").exists():
            scenario = out / f"{name}.ron"
            scenario.write_text(variant_text(base, resolution, fraction, model, a.phi_end, name))
            print(f"running {name} ...", flush=True)
            result = subprocess.run([a.sdem, "run", str(scenario), "--out", str(run_dir), "--quiet", "--threads", a.threads],
                                    capture_output=True, text=True)
            if result.returncode != 0:
                print(f"  {name} failed: {result.stderr.strip().splitlines()[-1]}", flush=True)
                rows.append(dict(label=name, resolution=resolution, fraction=fraction, model=model, failed=result.stderr.strip().splitlines()[-1]))
                continue
        summary = dict(l.split(" = ", 1) for l in (run_dir / "summary.txt").read_text().splitlines() if " = " in l)
        rows.append(dict(label=name, resolution=resolution, fraction=fraction, model=model, phi_end=a.phi_end,
                         wall_seconds=float(summary["wall_seconds"]), steps=int(summary["steps"]),
                         grain_steps_per_second=float(summary["grain_steps_per_second"]),
                         phi_0=float(summary.get("phi_0", "nan")), curve=curve(run_dir)))
    done = [r for r in rows if "curve" in r]
    finest = min(done, key=lambda r: (r["model"] != "Full", r["resolution"], r["fraction"]))
    grid_phi = [0.86 + 0.005 * k for k in range(int((a.phi_end - 0.86) / 0.005) + 1)]
    for r in done:
        diffs, eq69 = [], []
        for phi in grid_phi:
            p, q = interpolate(r["curve"], phi), interpolate(finest["curve"], phi)
            if p is not None and q:
                diffs.append((p - q) / q)
            if p is not None:
                eq69.append((p - reference(phi)) / reference(phi))
        r["error_vs_finest"] = rms(diffs) if r is not finest else 0.0
        r["error_vs_eq69"] = rms(eq69)
    with open(out / "sweep.csv", "w", newline="") as f:
        cols = ["label", "resolution", "fraction", "model", "wall_seconds", "steps", "grain_steps_per_second", "phi_0", "error_vs_finest", "error_vs_eq69", "failed"]
        wr = csv.DictWriter(f, fieldnames=cols, extrasaction="ignore"); wr.writeheader()
        for r in rows:
            wr.writerow(r)
    print(f"reference: {finest['label']}")
    for r in rows:
        if "curve" in r:
            print(f"{r['label']:22s} {r['wall_seconds']:8.1f} s  {r['grain_steps_per_second']:.2e} grain-steps/s  phi0 {r['phi_0']:.4f}  "
                  f"error vs finest {100*r['error_vs_finest']:5.2f}%  vs eq.69 {100*r['error_vs_eq69']:5.1f}%")
        else:
            print(f"{r['label']:22s} FAILED: {r['failed']}")
    charted = [r for r in done if r is not finest]
    if charted:
        svg_chart(charted, out / "sweep.svg")
        print(f"wrote {out / 'sweep.csv'} and {out / 'sweep.svg'}")

main()
