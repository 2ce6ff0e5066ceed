#!/usr/bin/env python3
"""The meshfree bouncing disc (Mollon 2016, §5, fig. 7-8) with the Bathe composite scheme, the trapezoidal rule
and the explicit scheme (central differences, lumped mass, penalty contacts).

usage: tools/bouncing_disc.py [--sdem target/release/sdem] [--out out/bouncing_disc] [--t-end 4]
                              [--scenario scenarios/meshfree_bouncing_disc.ron] [--threads 1]
                              [--docs DIR]

Writes two variants of the scenario into OUT and runs them one after the other
(`sdem run VARIANT --out OUT/<scheme> --quiet --threads 1`):
  - bathe:       scheme Bathe, dt = 0.02 (two sub-steps of dt/2 per step);
  - trapezoidal: scheme Trapezoidal, dt = 0.01: the same number of implicit solves as Bathe's
                 two sub-steps, the paper's fair comparison;
  - explicit:    scheme CentralDifference, output every 0.02 (sdem sub-steps below the critical
                 step), k0 = 100 E/R: penalty contacts penetrate by p / k0.
Both relax until --t-end. Runs that already have a summary.txt are reused (delete OUT to rerun).

From each macro.csv it takes the kinetic, elastic and gravitational potential energies, the
deepest penetration, the Newton iterations and augmentations of each step. The centroid
height is y_c = potential_energy / (m |g|): sdem's potential energy is -f_ext . x over the
nodes, which for the consistent body force is m |g| times the height of the mass centroid. The mass is
m = density x the area of the disc's reference boundary polygon (N boundary nodes on the circle
of radius R: N R^2 sin(2 pi / N) / 2, slightly less than pi R^2); the tool checks it against the
first step of free fall. (The area column of grains.csv is the current, deformed area: not the
mass.)

It writes OUT/<scheme>.csv (time, height, energies, penetration, solver counts per step),
OUT/meshfree_bouncing_disc.svg (panels against time: centroid height; total energy; kinetic
and elastic energy, log; max penetration, log; both schemes) and prints per scheme: wall time,
steps, Newton iterations and augmentations in total, the max penetration over the last 40% of
the run, the steps without an active contact (solved with one augmentation per implicit solve:
the disc is in the air; macro.csv has no gap of the lowest node, so this is how loss of contact
shows), the energy at the end, and the steps where the total energy rose by more than 1e-6
relative (with mass-proportional Rayleigh damping it can only decrease in the exact solution).
With --docs DIR it also copies the chart and the CSVs there (DIR/meshfree_bouncing_disc.svg is
not used: the chart goes to docs/images/, the CSVs to DIR).
"""
import argparse, csv, math, pathlib, re, shutil, subprocess, sys, time

SCHEMES = [  # (label, scheme, dt, colour, implicit solves per step, k0 in E/R or None: the scenario's)
    ("bathe", "Bathe", 0.02, "#1f5fb4", 2, None),
    ("trapezoidal", "Trapezoidal", 0.01, "#d2461e", 1, None),
    # Explicit: penalty contacts (no augmentation), so k0 sets the penetration, p / k0: ten
    # times the implicit runs' k0. dt is the output step; sdem sub-steps it below the
    # critical step by itself.
    ("explicit", "CentralDifference", 0.02, "#2a9d3a", 0, 100.0),
]
RISE = 1e-6  # relative rise of the total energy between two steps that counts as a rise


def variant_text(base, base_dir, name, scheme, dt, t_end, k0=None):
    t = re.sub(r'name: "[^"]*"', f'name: "{name}"', base)
    t = re.sub(r"scheme: \w+", f"scheme: {scheme}", t)
    if k0 is not None:
        t = re.sub(r"k0: [0-9.eE+-]+", f"k0: {k0}", t)
    t = re.sub(r"time_step: Fixed\([0-9.eE+-]+\)", f"time_step: Fixed({dt})", t)
    t = re.sub(r"until: Time\([0-9.eE+-]+\)", f"until: Time({t_end})", t)
    # The sample file is relative to the scenario: make it absolute.
    t = re.sub(r'file: "([^"/][^"]*)"', lambda m: f'file: "{(base_dir / m.group(1)).resolve()}"', t)
    return t


def number(text, key):
    m = re.search(rf"\b{key}: ([0-9.eE+-]+)", text)
    if not m:
        sys.exit(f"scenario has no {key}")
    return float(m.group(1))


def read_run(run_dir, mass, g):
    rows = []
    for r in csv.DictReader(open(run_dir / "macro.csv")):
        ke, ee, pe = float(r["kinetic_energy"]), float(r["elastic_energy"]), float(r["potential_energy"])
        rows.append({
            "time": float(r["time"]), "height": pe / (mass * g), "total_energy": ke + ee + pe,
            "kinetic_energy": ke, "elastic_energy": ee, "potential_energy": pe,
            "max_penetration": float(r["max_penetration"]),
            "newton_iterations": int(r["newton_iterations"]), "augmentations": int(r["augmentations"]),
            "sub_steps": int(r["sub_steps"]),
        })
    return rows


def airborne(row, solves_per_step):
    """No active contact in the step: one augmentation per implicit solve, no penetration."""
    return row["augmentations"] <= solves_per_step * row["sub_steps"] and row["max_penetration"] == 0.0


def summarise(label, rows, summary, t_end, solves):
    late = [r for r in rows if r["time"] > 0.6 * t_end + 1e-12]
    rises = [(b["time"], (b["total_energy"] - a["total_energy"]) / abs(a["total_energy"]))
             for a, b in zip(rows, rows[1:]) if b["total_energy"] - a["total_energy"] > RISE * abs(a["total_energy"])]
    heights = [r["height"] for r in late]
    return {
        "scheme": label,
        "wall_seconds": float(summary.get("wall_seconds", "nan")),
        "steps": len(rows),
        "t_last": rows[-1]["time"] if rows else float("nan"),
        "newton_iterations": sum(r["newton_iterations"] for r in rows),
        "augmentations": sum(r["augmentations"] for r in rows),
        "extra_sub_steps": sum(r["sub_steps"] - 1 for r in rows),
        "late_max_penetration": max((r["max_penetration"] for r in late), default=float("nan")),
        "late_zero_penetration_steps": sum(1 for r in late if r["max_penetration"] == 0.0),
        "late_steps": len(late),
        "airborne_steps": sum(1 for r in rows if airborne(r, solves)),
        "late_airborne_steps": sum(1 for r in late if airborne(r, solves)),
        "last_airborne_time": max((r["time"] for r in rows if airborne(r, solves)), default=float("nan")),
        "late_height_min": min(heights, default=float("nan")),
        "late_height_max": max(heights, default=float("nan")),
        "late_max_kinetic_energy": max((r["kinetic_energy"] for r in late), default=float("nan")),
        "energy_end": rows[-1]["total_energy"] if rows else float("nan"),
        "energy_rises": len(rises),
        "largest_rise": max((d for _, d in rises), default=0.0),
        "first_rise_time": rises[0][0] if rises else float("nan"),
    }


def svg_chart(runs, t_end, path, title, gap_tolerance):
    """Four stacked panels against time, one polyline per scheme."""
    w, ph, gap, ml, mr, mt = 820, 190, 46, 86, 24, 58
    panels = [
        ("centroid height y_c (bars at the top: steps without an active contact)", "height", False, None),
        ("total energy (kinetic + elastic + potential)", "total_energy", False, None),
        ("kinetic (solid) and elastic (dashed) energy, log (below 1e-6 drawn at the floor)",
         ("kinetic_energy", "elastic_energy"), True, -6),
        ("max penetration, log (0 drawn at the floor; dotted: gap tolerance)", "max_penetration", True, None),
    ]
    h = mt + len(panels) * (ph + gap) + 20
    X = lambda t: ml + t / t_end * (w - ml - mr)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<text x="{w/2}" y="22" text-anchor="middle" font-size="15">{title}</text>']
    lx = ml
    for label, _, dt, colour in runs:
        out.append(f'<line x1="{lx}" x2="{lx+24}" y1="40" y2="40" stroke="{colour}" stroke-width="2"/>'
                   f'<text x="{lx+30}" y="44">{label}, dt = {dt:g}</text>')
        lx += 235
    for k, (name, key, log, floor_exp) in enumerate(panels):
        top = mt + k * (ph + gap)
        bottom = top + ph
        keys = key if isinstance(key, tuple) else (key,)
        vals = [r[kk] for _, rows, _, _ in runs for r in rows for kk in keys]
        if log:
            pos = [v for v in vals if v > 0]
            lo = math.floor(math.log10(min(pos))) if pos else -12
            hi = math.ceil(math.log10(max(pos))) if pos else 0
            if key == "max_penetration":
                hi = max(hi, math.ceil(math.log10(gap_tolerance)))
            if floor_exp is not None:
                lo = max(lo, floor_exp)
            if hi <= lo:
                hi = lo + 1
            Y = lambda v, lo=lo, hi=hi, top=top, bottom=bottom: bottom - (math.log10(max(v, 10.0**lo)) - lo) / (hi - lo) * (bottom - top)
            step = max(1, math.ceil((hi - lo) / 6))
            ticks = [10.0 ** e for e in range(lo, hi + 1, step)]
            fmt = lambda v: f"1e{round(math.log10(v))}"
        else:
            lo, hi = min(vals), max(vals)
            pad = 0.05 * (hi - lo or abs(hi) or 1.0)
            lo, hi = lo - pad, hi + pad
            Y = lambda v, lo=lo, hi=hi, top=top, bottom=bottom: bottom - (v - lo) / (hi - lo) * (bottom - top)
            raw = (hi - lo) / 5
            mag = 10.0 ** math.floor(math.log10(raw))
            st = min((m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw))
            ticks = [st * i for i in range(math.ceil(lo / st), math.floor(hi / st) + 1)]
            fmt = lambda v: f"{v:.4g}"
        out.append(f'<rect x="{ml}" y="{top}" width="{w-ml-mr}" height="{ph}" fill="none" stroke="black"/>'
                   f'<text x="{ml}" y="{top-6}" font-weight="bold">{name}</text>')
        for v in ticks:
            y = Y(v)
            out.append(f'<line x1="{ml}" x2="{w-mr}" y1="{y:.1f}" y2="{y:.1f}" stroke="#e4e4e4"/>'
                       f'<text x="{ml-6}" y="{y+4:.1f}" text-anchor="end">{fmt(v)}</text>')
        for i in range(0, int(round(t_end / 0.5)) + 1):
            t = 0.5 * i
            out.append(f'<line y1="{top}" y2="{bottom}" x1="{X(t):.1f}" x2="{X(t):.1f}" stroke="#eee"/>'
                       f'<text x="{X(t):.1f}" y="{bottom+15}" text-anchor="middle">{t:g}</text>')
        # The last 40% of the run, over which the summary measures the late behaviour.
        out.append(f'<line y1="{top}" y2="{bottom}" x1="{X(0.6*t_end):.1f}" x2="{X(0.6*t_end):.1f}" stroke="#999" stroke-dasharray="4 3"/>')
        if key == "max_penetration":
            out.append(f'<line x1="{ml}" x2="{w-mr}" y1="{Y(gap_tolerance):.1f}" y2="{Y(gap_tolerance):.1f}" stroke="black" stroke-dasharray="1 3"/>')
        if key == "height":
            for j, (label, rows, dt, colour) in enumerate(runs):
                for r in rows:
                    if r["airborne"]:
                        out.append(f'<rect x="{X(r["time"] - dt):.1f}" y="{top + 3 + 7*j}" width="{X(dt) - X(0):.1f}" height="5" fill="{colour}"/>')
        for label, rows, _, colour in runs:
            for j, kk in enumerate(keys):
                dash = ' stroke-dasharray="5 3"' if j == 1 else ""
                pts = " ".join(f"{X(r['time']):.1f},{Y(r[kk]):.1f}" for r in rows)
                out.append(f'<polyline fill="none" stroke="{colour}" stroke-width="1.3"{dash} stroke-opacity="0.85" points="{pts}"/>')
    out.append(f'<text x="{(ml + w - mr)/2}" y="{h-8}" text-anchor="middle">time (dashed vertical: start of the last 40% of the run)</text></svg>')
    pathlib.Path(path).write_text("\n".join(out))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sdem", default="target/release/sdem")
    ap.add_argument("--out", default="out/bouncing_disc")
    ap.add_argument("--t-end", type=float, default=4.0)
    ap.add_argument("--scenario", default="scenarios/meshfree_bouncing_disc.ron")
    ap.add_argument("--threads", default="1")
    ap.add_argument("--docs", help="also copy the CSVs to DOCS/ and the chart to docs/images/")
    a = ap.parse_args()

    base_path = pathlib.Path(a.scenario)
    base = base_path.read_text()
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)

    # Mass of the disc: density x area of the reference boundary polygon.
    nb = int(number(base, "boundary_nodes"))
    density = number(base, "density")
    g = -float(re.search(r"gravity: \(\s*[0-9.eE+-]+,\s*([0-9.eE+-]+)\)", base).group(1))
    sample = re.search(r'file: "([^"]*)"', base).group(1)
    disc = next(csv.DictReader(open(base_path.parent / sample)))
    radius, y0 = float(disc["radius"]), float(disc["y"])
    mass = density * 0.5 * nb * radius**2 * math.sin(2 * math.pi / nb)
    print(f"disc: R = {radius:g}, {nb} boundary nodes, m = density x polygon area = {mass:.9f} "
          f"(pi R^2 = {math.pi*radius**2:.9f}), g = {g:g}, initial height {y0:g}")

    runs, summaries = [], []
    for label, scheme, dt, colour, solves, k0 in SCHEMES:
        scenario = out / f"{label}.ron"
        scenario.write_text(variant_text(base, base_path.parent, f"meshfree_bouncing_disc_{label}", scheme, dt, a.t_end, k0))
        run_dir = out / label
        if not (run_dir / "summary.txt").exists():
            t0 = time.time()
            err = open(out / f"{label}.stderr", "w")
            rc = subprocess.call([a.sdem, "run", str(scenario), "--out", str(run_dir), "--quiet", "--threads", a.threads],
                                 stdout=subprocess.DEVNULL, stderr=err)
            err.close()
            print(f"{label}: sdem exited {rc} after {time.time()-t0:.1f} s")
            if rc != 0:
                print((out / f"{label}.stderr").read_text().strip()[-2000:])
        summary = {}
        if (run_dir / "summary.txt").exists():
            for line in open(run_dir / "summary.txt"):
                if " = " in line:
                    k, v = line.strip().split(" = ", 1)
                    summary[k] = v
        if not (run_dir / "macro.csv").exists():
            sys.exit(f"{label}: no macro.csv in {run_dir}")
        rows = read_run(run_dir, mass, g)
        # The stop test compares the accumulated time with t_end: 400 x 0.01 adds up to
        # 3.99999999999996 and sdem runs one step more. Keep the rows up to t_end.
        extra = [r for r in rows if r["time"] > a.t_end * (1 + 1e-9)]
        if extra:
            print(f"{label}: sdem ran {len(extra)} step(s) past t_end = {a.t_end:g} (to t = {extra[-1]['time']:g}); dropped")
            rows = [r for r in rows if r["time"] <= a.t_end * (1 + 1e-9)]
        for r in rows:
            r["airborne"] = int(airborne(r, solves))
        with open(out / f"{label}.csv", "w", newline="") as f:
            cols = ["time", "height", "total_energy", "kinetic_energy", "elastic_energy", "potential_energy",
                    "max_penetration", "newton_iterations", "augmentations", "sub_steps", "airborne"]
            wr = csv.writer(f)
            wr.writerow(cols)
            for r in rows:
                wr.writerow([f"{r[c]:.9e}" if isinstance(r[c], float) else r[c] for c in cols])
        runs.append((label, rows, dt, colour))
        summaries.append(summarise(label, rows, summary, a.t_end, solves))
        # Check of the mass: the first step is free fall with mass-proportional damping alpha,
        # y(t) = y0 - g (t - (1 - exp(-alpha t)) / alpha).
        alpha = number(base, "rayleigh_alpha")
        t1 = rows[0]["time"]
        fall = g * (t1 - (1 - math.exp(-alpha * t1)) / alpha) if alpha > 0 else 0.5 * g * t1 * t1
        print(f"{label}: first step t = {t1:g}: y_c = {rows[0]['height']:.9f}, free fall gives {y0 - fall:.9f}")

    svg = out / "meshfree_bouncing_disc.svg"
    svg_chart(runs, a.t_end, svg,
              f"Meshfree bouncing disc (E = 50, alpha = 1): Bathe composite, trapezoidal rule (same cost), explicit",
              number(base, "gap_tolerance"))

    print()
    print(f"{'scheme':12} {'wall s':>7} {'steps':>6} {'Newton':>7} {'augm.':>6} {'halved':>6} "
          f"{'late max pen':>12} {'pen=0':>7} {'air':>7} {'late y_c range':>19} {'late max KE':>11} {'E end':>12} {'rises':>5} {'largest rise':>12}")
    for s in summaries:
        print(f"{s['scheme']:12} {s['wall_seconds']:7.2f} {s['steps']:6d} {s['newton_iterations']:7d} {s['augmentations']:6d} "
              f"{s['extra_sub_steps']:6d} {s['late_max_penetration']:12.3e} {s['late_zero_penetration_steps']:3d}/{s['late_steps']:<3d} {s['late_airborne_steps']:3d}/{s['late_steps']:<3d} "
              f"{s['late_height_min']:9.6f}-{s['late_height_max']:.6f} {s['late_max_kinetic_energy']:11.3e} {s['energy_end']:12.9f} "
              f"{s['energy_rises']:5d} {s['largest_rise']:12.3e}")
    air = ", ".join(f"{s['scheme']} {s['airborne_steps']} (last at t = {s['last_airborne_time']:g})" for s in summaries)
    print(f"late: t > {0.6*a.t_end:g}; pen=0: late steps with no penetration (out of contact, or in contact with gap >= 0); "
          f"air: late steps without an active contact (whole run: {air}); "
          f"rises: steps where the total energy rose by more than {RISE:g} relative; halved: extra sub-steps")
    with open(out / "summary.csv", "w", newline="") as f:
        wr = csv.DictWriter(f, fieldnames=list(summaries[0]))
        wr.writeheader()
        wr.writerows(summaries)
    print(f"wrote {', '.join(f'{out}/{s[0]}.csv' for s in SCHEMES)}, {out}/summary.csv and {svg}")

    if a.docs:
        d = pathlib.Path(a.docs)
        d.mkdir(parents=True, exist_ok=True)
        for name in [f"{s[0]}.csv" for s in SCHEMES] + ["summary.csv"]:
            shutil.copy(out / name, d / name)
        images = pathlib.Path("docs/images")
        images.mkdir(parents=True, exist_ok=True)
        shutil.copy(svg, images / "meshfree_bouncing_disc.svg")
        print(f"copied the CSVs to {d} and the chart to {images / 'meshfree_bouncing_disc.svg'}")


if __name__ == "__main__":
    main()
