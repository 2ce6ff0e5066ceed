#!/usr/bin/env python3
"""Stability map of the explicit solver (issue #6): which runs stay stable, which fail, and how
the engine reports it (SPEC §9).

usage: tools/stability_map.py [--out out/stability] [--sdem target/release/sdem] [--threads 2]
                              [--grains 300]

Two families of runs on a small sample with sample A's radius distribution (box scaled to keep
its initial packing fraction), isotropic compaction at a constant strain rate of 5e-3 from the
loose state:
  - time step x material: dt / dt_crit in {0.4, 0.8, 1.0, 1.2, 2.0} against nu in
    {0.3, 0.45, 0.49, 0.499} (compressible law, whose bulk modulus and hence critical step
    stiffen as nu -> 0.5) and nu = 0.5 (incompressible law), each to phi = 0.90;
  - deep compaction: nu = 0.5, dt = 0.4 dt_crit, towards phi = 0.98 where the secant law leaves
    its domain, with on_domain_exit: Stop (the default) and Cap.
Each run is classified from sdem's exit status and message: "completed", or the diagnostic that
stopped it (runaway, non-finite, inverted, swallowed, contact-domain). A completed run whose
macro.csv holds a NaN or inf would be a failure of the engine's checks: the tool reports it as
"NaN in output". Writes OUT/stability.csv and OUT/stability.svg. Runs that already have a
result.txt are reused.
"""
import argparse, csv, math, pathlib, re, subprocess, time

BASE = """Scenario(
    name: "{name}",
    seed: 3,
    sample: (count: {count}, box_width: {side}, box_height: {side},
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: {nu}, density: 1.0),
    model: Full,
    contact: (a: 0.58, b: 2.0, resolution_deg: 1.0, damping: 1.0, on_domain_exit: {policy}),
    time_step: FractionOfCritical({fraction}),
    loading: [ Isotropic(rate: Constant(5e-3), until: PackingFraction({phi_end})) ],
    output: (every: 200, jamming_pressure: 1e-5),
)
"""

DIAGNOSTICS = [
    ("faster than the elastic wave speed", "runaway"),
    ("non-finite", "non-finite"),
    ("inverted", "inverted"),
    ("no longer cross", "swallowed"),
    ("left the domain of the contact law", "contact-domain"),
]


def classify(code, text):
    if code == 0:
        return "completed"
    for needle, name in DIAGNOSTICS:
        if needle in text:
            return name
    return "error"


def nan_in_output(run_dir):
    path = run_dir / "macro.csv"
    if not path.exists():
        return False
    for row in csv.DictReader(open(path)):
        for column, value in row.items():
            value = (value or "").strip().lower()
            # The inertial number of an unloaded sample (p_c = 0) is infinite by definition.
            if value == "nan" or (value in ("inf", "-inf") and column != "inertial_number"):
                return True
    return False


def run(sdem, out, name, threads, **knobs):
    run_dir = out / name
    result = run_dir / "result.txt"
    if result.exists():
        return dict(line.split("=", 1) for line in result.read_text().splitlines())
    run_dir.mkdir(parents=True, exist_ok=True)
    scenario = run_dir / f"{name}.ron"
    scenario.write_text(BASE.format(name=name, **knobs))
    start = time.time()
    proc = subprocess.run(
        [sdem, "run", str(scenario), "--out", str(run_dir), "--threads", str(threads), "--quiet"],
        capture_output=True, text=True)
    seconds = time.time() - start
    text = proc.stdout + proc.stderr
    outcome = classify(proc.returncode, text)
    if nan_in_output(run_dir):
        outcome = "NaN in output"
    steps = re.search(r"done: (\d+) steps", text) or re.search(r"step (\d+):", text)
    phi = None
    macro = run_dir / "macro.csv"
    if macro.exists():
        rows = list(csv.DictReader(open(macro)))
        if rows:
            phi = rows[-1]["phi"]
    message = next((l.strip() for l in text.splitlines() if "step" in l and ":" in l and outcome != "completed"), "")
    record = {
        "outcome": outcome,
        "steps": steps.group(1) if steps else "",
        "last_phi": phi or "",
        "seconds": f"{seconds:.1f}",
        "message": message.replace("=", "~")[:200],
    }
    result.write_text("\n".join(f"{k}={v}" for k, v in record.items()) + "\n")
    return record


COLOURS = {"completed": "#7fc97f", "contact-domain": "#fdc086", "NaN in output": "#000000"}


def svg(rows, fractions, nus, deep, path):
    cell_w, cell_h, left, top = 120, 44, 150, 60
    w = left + cell_w * len(fractions) + 20
    h = top + cell_h * (len(nus) + len(deep) + 1) + 60
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<text x="{left}" y="20" font-size="14">Stability of the explicit solver (sample A radii, 5e-3 compaction)</text>',
           f'<text x="{left}" y="42">dt / dt_crit (critical estimate of SPEC §9)</text>']
    for c, f in enumerate(fractions):
        out.append(f'<text x="{left + c * cell_w + cell_w / 2}" y="{top - 4}" text-anchor="middle">{f}</text>')
    for r, nu in enumerate(nus):
        y = top + r * cell_h
        label = f"nu = {nu}" + (" (incompr.)" if nu == 0.5 else "")
        out.append(f'<text x="{left - 8}" y="{y + cell_h / 2 + 4}" text-anchor="end">{label}</text>')
        for c, f in enumerate(fractions):
            row = rows[(nu, f)]
            colour = COLOURS.get(row["outcome"], "#f0027f")
            x = left + c * cell_w
            out.append(f'<rect x="{x}" y="{y}" width="{cell_w - 2}" height="{cell_h - 2}" fill="{colour}"/>')
            out.append(f'<text x="{x + cell_w / 2}" y="{y + 18}" text-anchor="middle">{row["outcome"]}</text>')
            out.append(f'<text x="{x + cell_w / 2}" y="{y + 34}" text-anchor="middle" font-size="10">phi {float(row["last_phi"] or "nan"):.3f}</text>')
    y0 = top + (len(nus) + 1) * cell_h
    out.append(f'<text x="{left}" y="{y0 - 8}">deep compaction towards phi = 0.98 (nu = 0.5, dt = 0.4 dt_crit)</text>')
    for r, (policy, row) in enumerate(deep):
        y = y0 + r * cell_h
        colour = COLOURS.get(row["outcome"], "#f0027f")
        out.append(f'<text x="{left - 8}" y="{y + cell_h / 2 + 4}" text-anchor="end">on_domain_exit: {policy}</text>')
        out.append(f'<rect x="{left}" y="{y}" width="{2 * cell_w - 2}" height="{cell_h - 2}" fill="{colour}"/>')
        out.append(f'<text x="{left + cell_w}" y="{y + 18}" text-anchor="middle">{row["outcome"]}</text>')
        out.append(f'<text x="{left + cell_w}" y="{y + 34}" text-anchor="middle" font-size="10">phi {float(row["last_phi"] or "nan"):.3f}</text>')
    out.append(f'<text x="{left}" y="{h - 16}" font-size="11">green: completed; orange: stopped by the contact-law domain check; magenta: stopped by an instability diagnostic; black: NaN in output (none expected)</text>')
    out.append("</svg>")
    path.write_text("\n".join(out))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="out/stability")
    ap.add_argument("--sdem", default="target/release/sdem")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--grains", type=int, default=300)
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    side = math.sqrt(args.grains / 1000.0)
    fractions = [0.4, 0.8, 1.0, 1.2, 2.0]
    nus = [0.3, 0.45, 0.49, 0.499, 0.5]
    rows, table = {}, []
    for nu in nus:
        for f in fractions:
            name = f"nu{nu}_dt{f}"
            r = run(args.sdem, out, name, args.threads, count=args.grains, side=side, nu=nu,
                    fraction=f, phi_end=0.90, policy="Stop")
            rows[(nu, f)] = r
            table.append({"family": "dt_nu", "nu": nu, "dt_fraction": f, "policy": "Stop", **r})
            print(f"{name:16s} {r['outcome']:15s} steps {r['steps']:>8s} phi {r['last_phi']} {r['seconds']} s", flush=True)
    deep = []
    for policy in ["Stop", "Cap"]:
        name = f"deep_{policy}"
        r = run(args.sdem, out, name, args.threads, count=args.grains, side=side, nu=0.5,
                fraction=0.4, phi_end=0.98, policy=policy)
        deep.append((policy, r))
        table.append({"family": "deep", "nu": 0.5, "dt_fraction": 0.4, "policy": policy, **r})
        print(f"{name:16s} {r['outcome']:15s} steps {r['steps']:>8s} phi {r['last_phi']} {r['seconds']} s", flush=True)
    with open(out / "stability.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table[0].keys()))
        w.writeheader()
        w.writerows(table)
    svg(rows, fractions, nus, deep, out / "stability.svg")
    print(f"wrote {out / 'stability.csv'} and {out / 'stability.svg'}")


if __name__ == "__main__":
    main()
