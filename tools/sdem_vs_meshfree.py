#!/usr/bin/env python3
"""SDEM against the multibody meshfree reference on one packing (issue #13).

usage: tools/sdem_vs_meshfree.py [--out out/sdem_vs_meshfree] [--sdem target/release/sdem]
                                 [--sample A|B] [--count 100] [--seed 1] [--rate 4e-3]
                                 [--phi-end 0.90] [--jobs 2] [--only PATTERN] [--report-only]
                                 [--fit] [--calibrate] [--pictures] [--meshfree CASE:NU:NODES:K0 ...]

One packing, two solvers, the same walls, loading and material:

1. The packing: `--count` discs of sample A's (or B's) radius distribution, placed in a box of
   side sqrt(N / 1000) (SPEC §8) and compacted as rigid discs (SDEM, quasi-static) to a loose
   state just below jamming, phi_start = 0.77. The radii are then shrunk by 0.1% so that no two
   contours touch (the meshfree solver refuses a start with penetrating contours); this file,
   `packing.csv`, is the initial state of every run. A second rigid compaction of the same sample
   to its jamming point gives phi_J.
2. The cases (SPEC §7), every wall at a constant strain rate `--rate`, every phase ended by a
   strain (so that the walls follow the same path in every run):
   - isotropic: the four walls in, from phi_start to phi = `--phi-end` (nominal: the strain that
     takes the box area there);
   - oedometric: isotropic to phi_J, then the right wall alone, to phi = `--phi-end`.
   For nu = 0.3 and for (nearly) incompressible grains: SDEM at nu = 0.5 (with its
   incompressibility correction), the meshfree solver at nu = 0.45 (`NU_MESHFREE_HIGH`).
3. The meshfree reference: the explicit scheme (lumped mass, central differences, penalty
   contacts), neo-Hookean grains, at two nodal densities and two penalties (`MESHFREE_RUNS`) for
   the convergence checks; the stiffest penalty's finest run of a case is its reference.
4. The SDEM settings (`SDEM_VARIANTS`): model level, contour resolution, time step and contact
   law (the paper's a = 0.58, b = 2; the single-grain calibration `sdem calibrate`; and the pair
   fitted to the reference itself, `--fit`).

Outputs, in --out: `packing.csv`, `runs/<case>_nu<nu>_<setting>/` (scenario, macro.csv,
grains.csv, summary.txt, cost.txt with the CPU seconds of the run), and the report:
`sdem_vs_meshfree.csv` (one row per case, nu, SDEM setting and strain point:
case,nu,model,strain,sxx_ref,syy_ref,sxx,syy,rel_err,cpu_s_sdem,cpu_s_ref), `summary.csv` (one
row per case, nu and setting: error measures and costs), `convergence.csv` (the meshfree
densities against each other) and SVG charts. A run whose directory holds a finished run of the
same scenario text is not run again: delete its directory to redo it.
"""

import argparse
import csv
import itertools
import math
import os
import pathlib
import re
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

from meshfree_biaxial_plot import panel
from sweep import eq69

RADII = {
    "A": "Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)",
    "B": "Fractal(dimension: 2.0, min: 0.004, max: 0.038)",
}
PHI_START = 0.77
SHRINK = 0.999
NU_MESHFREE_HIGH = 0.45
# The meshfree runs (`--meshfree` replaces them): (case, meshfree nu, boundary nodes per grain,
# penalty k0 in E / R). The reference of a case is its run with the stiffest penalty, then the
# most nodes; the others measure the convergence in nodal density (same k0) and in penalty (same
# nodes). The penalty sets the explicit step (k0 = 300: half the step of k0 = 30), so the
# oedometric cases, the longest, are run at k0 = 30 only (their penalty error is the one
# measured on the isotropic case, docs/sdem_vs_meshfree.md).
MESHFREE_RUNS = [
    ("isotropic", NU_MESHFREE_HIGH, 32, 300),
    ("isotropic", 0.3, 32, 300),
    ("isotropic", NU_MESHFREE_HIGH, 24, 300),
    ("isotropic", 0.3, 24, 300),
    ("isotropic", 0.3, 32, 30),
    ("isotropic", 0.3, 48, 30),
    ("isotropic", NU_MESHFREE_HIGH, 48, 30),
    ("oedometric", NU_MESHFREE_HIGH, 32, 30),
    ("oedometric", 0.3, 32, 30),
]
MESHFREE_GRADING = 3.0
# Mass-proportional damping of the meshfree grains (1/time): slow enough that the drag of the
# affine motion is below 1e-5 E on the walls, fast enough to damp the grains' vibrations.
MESHFREE_ALPHA = 2.0
# Strain between two rows of macro.csv.
ROW_STRAIN = 5e-4
# (a, b) of the single-grain calibration (docs/calibration.md, neo-Hookean).
CALIBRATED = (0.615, 2.53)
PAPER = (0.58, 2.0)

# label -> (model, dbeta in degrees, dt / critical, (a, b)); the first is the baseline.
SDEM_VARIANTS = {
    "full": ("Full", 1.0, 0.4, PAPER),
    "adaptive": ("Adaptive()", 1.0, 0.4, PAPER),
    "volumetric": ("Volumetric", 1.0, 0.4, PAPER),
    "rigid": ("Rigid", 1.0, 0.4, PAPER),
    "full_dbeta4": ("Full", 4.0, 0.4, PAPER),
    "full_dbeta0.5": ("Full", 0.5, 0.4, PAPER),
    "full_dt0.8": ("Full", 1.0, 0.8, PAPER),
    "full_dt0.2": ("Full", 1.0, 0.2, PAPER),
    "full_calibrated": ("Full", 1.0, 0.4, CALIBRATED),
}


def read_summary(run_dir):
    text = (run_dir / "summary.txt").read_text()
    return dict(l.split(" = ", 1) for l in text.splitlines() if " = " in l)


def final_box(summary):
    m = re.search(r"origin: \(([^,]+), ([^)]+)\), box_width: ([^,]+), box_height: ([^)]+)\)",
                  summary["final_box"])
    return tuple(float(v) for v in m.groups())


def run_sdem(sdem, threads, scenario, run_dir):
    """Runs `sdem run`; returns (exit code, last stderr line, CPU seconds of the child)."""
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    err_path = run_dir.parent / f"{run_dir.name}.stderr"
    with open(err_path, "w") as err:
        proc = subprocess.Popen([sdem, "run", str(scenario), "--out", str(run_dir), "--quiet",
                                 "--threads", str(threads), "--mcap", str(run_dir / "trajectory.mcap")],
                                stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
    lines = err_path.read_text().strip().splitlines()
    return os.waitstatus_to_exitcode(status), (lines[-1] if lines else ""), usage.ru_utime + usage.ru_stime


def run_cached(sdem, threads, run_dir, text):
    """Runs the scenario `text` in `run_dir` unless a finished run of the same text is there.
    Returns the CPU seconds of the run, or raises with sdem's message."""
    scenario = run_dir.parent / f"{run_dir.name}.ron"
    cost = run_dir / "cost.txt"
    if scenario.exists() and scenario.read_text() == text and cost.exists() and (run_dir / "summary.txt").exists():
        return float(cost.read_text())
    scenario.parent.mkdir(parents=True, exist_ok=True)
    scenario.write_text(text)
    print(f"running {run_dir.name} ...", flush=True)
    code, last, cpu = run_sdem(sdem, threads, scenario, run_dir)
    if code != 0:
        raise RuntimeError(f"{run_dir.name}: sdem exited with {code}: {last}")
    cost.write_text(f"{cpu}\n")
    print(f"  {run_dir.name}: {cpu:.1f} CPU s", flush=True)
    return cpu


def scenario_text(name, seed, sample, material, model, extra, time_step, loading, every):
    return f"""// Written by tools/sdem_vs_meshfree.py.
Scenario(
    name: "{name}",
    seed: {seed},
    sample: {sample},
    material: {material},
    model: {model},{extra}
    time_step: {time_step},
    loading: [
{loading}
    ],
    output: (every: {every}, jamming_pressure: 1e-5),
)
"""


def prepare(a, out):
    """The loose packing every run starts from; returns (box, phi_start, phi_J)."""
    side = math.sqrt(a.count / 1000.0)
    sample = f"(count: {a.count}, box_width: {side:.6f}, box_height: {side:.6f}, radii: {RADII[a.sample]})"
    common = dict(seed=a.seed, sample=sample, material="(young: 1.0, poisson: 0.3, density: 1.0)",
                  model="Rigid", extra="\n    contact: (a: 0.58, b: 2.0, resolution_deg: 1.0, damping: 1.0),",
                  time_step="FractionOfCritical(0.4)", every=500)
    rate = "QuasiStatic(inertial_number: 1e-3, max: 1e-2, fast: 1e-3, fast_until_phi: 0.74)"
    loose = out / "prepare" / "loose"
    run_cached(a.sdem, 1, loose, scenario_text(
        name="loose", loading=f"        Isotropic(rate: {rate}, until: PackingFraction({PHI_START})),", **common))
    jammed = out / "prepare" / "jammed"
    run_cached(a.sdem, 1, jammed, scenario_text(
        name="jammed", loading=f"        Isotropic(rate: {rate}, until: Jammed),", **common))
    phi_j = float(read_summary(jammed)["phi_0"])
    # The jamming point by both rattler rules, and eq. 69: the same sample, deformable
    # incompressible grains, quasi-static from the loose state to phi = 0.95.
    common.update(model="Full", material="(young: 1.0, poisson: 0.5, density: 1.0)", every=100)
    run_cached(a.sdem, 1, out / "prepare" / "quasistatic_nu0.5", scenario_text(
        name="quasistatic_nu0.5", loading=f"        Isotropic(rate: {rate}, until: PackingFraction(0.95)),",
        **common))
    rows = list(csv.DictReader(open(loose / "grains.csv")))
    lines = ["x,y,radius"] + [f"{r['x']},{r['y']},{float(r['radius']) * SHRINK:.12e}" for r in rows]
    (out / "packing.csv").write_text("\n".join(lines) + "\n")
    box = final_box(read_summary(loose))
    phi_start = sum(math.pi * (float(r["radius"]) * SHRINK) ** 2 for r in rows) / (box[2] * box[3])
    return box, phi_start, phi_j


def loading_program(case, rate, phi_start, phi_j, phi_end):
    """The phases of a case and the strain measure of each row: isotropic strain 1 - L/L0 of the
    box side, or, for oedometric, the width strain of the oedometric phase."""
    iso = lambda phi: 1.0 - math.sqrt(phi_start / phi)
    if case == "isotropic":
        return f"        Isotropic(rate: Constant({rate}), until: Strain({iso(phi_end):.6f})),"
    return (f"        Isotropic(rate: Constant({rate}), until: Strain({iso(phi_j):.6f})),\n"
            f"        Oedometric(rate: Constant({rate}), until: Strain({1.0 - phi_j / phi_end:.6f})),")


def meshfree_name(case, nu, nodes, k0):
    return f"{case}_nu{nu}_meshfree{nodes}" + ("" if k0 == 30 else f"_k{k0}")


def meshfree_runs(a, box, phi_start, phi_j):
    """(run directory name, scenario text) of every meshfree run, the longest first."""
    runs = []
    for case, nu, nodes, k0 in a.meshfree:
        name = meshfree_name(case, nu, nodes, k0)
        runs.append((name, common_text(a, box, phi_start, phi_j, case, nu, name,
                                       model=f"Meshfree((boundary_nodes: {nodes}, grading: {MESHFREE_GRADING}, "
                                       f"law: NeoHookean, scheme: CentralDifference, k0: {float(k0)}, "
                                       f"rayleigh_alpha: {MESHFREE_ALPHA}))",
                                       extra="", time_step=f"Fixed({ROW_STRAIN / a.rate:.6g})", every=1)))
    return runs


def common_text(a, box, phi_start, phi_j, case, nu, name, model, extra, time_step, every):
    x0, y0, w, h = box
    sample = f'(file: "../packing.csv", origin: ({x0!r}, {y0!r}), box_width: {w!r}, box_height: {h!r})'
    return scenario_text(name=name, seed=a.seed, sample=sample,
                         material=f"(young: 1.0, poisson: {nu}, density: 1.0)", model=model, extra=extra,
                         time_step=time_step, loading=loading_program(case, a.rate, phi_start, phi_j, a.phi_end),
                         every=every)



# The SDEM nu paired with each meshfree nu: the same nu, and SDEM's incompressible grains
# against the meshfree solver's most nearly incompressible ones.
NU_PAIRS = [(0.3, 0.3), (NU_MESHFREE_HIGH, NU_MESHFREE_HIGH), (0.5, NU_MESHFREE_HIGH)]
CASES = ("isotropic", "oedometric")
# Rows of a run at most every this many steps (SDEM; its time step is ~1e-3).
SDEM_EVERY = 20
# Points of comparison: every STRAIN_STEP of the volumetric strain 1 - A/A0 of the box.
STRAIN_STEP = 0.0025
# The loaded part, where the paper's "within 10%" is tested: the reference's mean wall stress
# above this (in E). Below it the wall stress of either solver holds a dynamic part of
# rho c v ~ 5e-4 E (the walls' speed at the default rate) and is not a quasi-static measure.
P_LOADED = 5e-3
# The (a, b) grid of --fit.
FIT_A = [0.45, 0.5, 0.58, 0.65, 0.75, 0.85, 1.0, 1.2]
# (sdem requires b > 0.)
FIT_B = [0.5, 1.0, 1.5, 2.0, 3.0, 4.0]


def sdem_text(a, box, phi_start, phi_j, case, nu, name, variant, law=None, rate=None):
    model, dbeta, dt, (ca, cb) = variant
    if law is not None:
        ca, cb = law
    b = dict(vars(a))
    if rate is not None:
        b["rate"] = rate
    return common_text(argparse.Namespace(**b), box, phi_start, phi_j, case, nu, name, model=model,
                       extra=f"\n    contact: (a: {ca}, b: {cb}, resolution_deg: {dbeta}, damping: 1.0),"
                             "\n    deformation: (damping: 1.0, k_alpha: 1e-3, alpha_mass_scale: 1.0),",
                       time_step=f"FractionOfCritical({dt})", every=SDEM_EVERY)


def sdem_runs(a, box, phi_start, phi_j):
    runs = []
    for case in CASES:
        for nu, _ in NU_PAIRS:
            for label, variant in SDEM_VARIANTS.items():
                name = f"{case}_nu{nu}_{label}"
                runs.append((name, sdem_text(a, box, phi_start, phi_j, case, nu, name, variant)))
            # The rate check: the baseline at a quarter of the rate.
            name = f"{case}_nu{nu}_full_slow"
            runs.append((name, sdem_text(a, box, phi_start, phi_j, case, nu, name,
                                         SDEM_VARIANTS["full"], rate=a.rate / 4)))
    return runs


def fit_runs(a, box, phi_start, phi_j):
    runs = []
    for case in CASES:
        for nu, _ in NU_PAIRS:
            for ca, cb in itertools.product(FIT_A, FIT_B):
                name = f"{case}_nu{nu}_fit_a{ca}_b{cb}"
                runs.append((name, sdem_text(a, box, phi_start, phi_j, case, nu, name,
                                             SDEM_VARIANTS["full"], law=(ca, cb))))
    return runs


# --- reading runs ---------------------------------------------------------------------------

class Run:
    """A finished run: its macro.csv rows against the volumetric strain of the box, its final
    grains and its CPU seconds."""

    def __init__(self, run_dir):
        self.dir = run_dir
        rows = list(csv.DictReader(open(run_dir / "macro.csv")))
        # The first row is one output interval in: the start's box is the scenario's (the same
        # for every run of a packing).
        text = (run_dir.parent / f"{run_dir.name}.ron").read_text()
        w0 = float(re.search(r"box_width: ([0-9.e-]+)", text).group(1))
        h0 = float(re.search(r"box_height: ([0-9.e-]+)", text).group(1))
        area0 = w0 * h0
        self.rows = rows
        self.strain = [1.0 - float(r["box_width"]) * float(r["box_height"]) / area0 for r in rows]
        # A run still going (or stopped) has no cost, summary or grains yet.
        finished = (run_dir / "cost.txt").exists()
        self.cpu = float((run_dir / "cost.txt").read_text()) if finished else float("nan")
        self.summary = read_summary(run_dir) if finished else {}
        self.grains = list(csv.DictReader(open(run_dir / "grains.csv"))) if finished else []

    def at(self, column, strain):
        """`column` linearly interpolated at this volumetric strain (None outside the run)."""
        xs = self.strain
        for k in range(1, len(xs)):
            if xs[k - 1] <= strain <= xs[k] and xs[k] > xs[k - 1]:
                t = (strain - xs[k - 1]) / (xs[k] - xs[k - 1])
                lo, hi = float(self.rows[k - 1][column]), float(self.rows[k][column])
                return lo + t * (hi - lo)
        return None

    def final_strain(self):
        return self.strain[-1]


def first_row_from_which(rows, holds):
    """The first isotropic row from which `holds(row)` stays true to the end (None if it ends
    false)."""
    rows = [r for r in rows if r["phase"] == "isotropic"]
    failing = [k for k, r in enumerate(rows) if not holds(r)]
    first = failing[-1] + 1 if failing else 0
    return rows[first] if first < len(rows) else None


def jamming_row(label, rows, p_jam=1e-5):
    """The jamming point by each rattler rule, and eq. 69's RMS error with each (phi_0, Z_0):
    - 2-rule (SPEC §7): from where p_c stays above p_jam; Z_0 = z_nr there;
    - 3-rule: from where a network of grains with 3 contacts or more exists (z_nr3 > 0: its
      "3-core" appears at once, as a percolation); Z_0 = z_nr3 there."""
    two = first_row_from_which(rows, lambda r: float(r["p_c"]) > p_jam)
    three = first_row_from_which(rows, lambda r: float(r.get("z_nr3") or "nan") > 0)
    if not two or not three:
        return None
    phi0, z2 = float(two["phi"]), float(two["z_nr"])
    phi3, z3, p3 = float(three["phi"]), float(three["z_nr3"]), float(three["p_c"])
    return dict(run=label, phi0=phi0, z_nr0=z2, eq69_rms_err_2rule=eq69_error(rows, phi0, z2),
                phi0_3rule=phi3, z_nr3_0=z3, p_c_3rule=p3, eq69_rms_err_3rule=eq69_error(rows, phi3, z3))


def strain_points(ref, other):
    end = min(ref.final_strain(), other.final_strain())
    return [STRAIN_STEP * k for k in range(1, int(end / STRAIN_STEP) + 1)]


def relative_errors(ref, run, column="p_c"):
    """(strain, relative error of `column` against the reference) over the common strains of
    the loaded part."""
    out = []
    for e in strain_points(ref, run):
        r, v = ref.at("p_c", e), run.at(column, e)
        rc = ref.at(column, e)
        if r is None or v is None or rc is None or r < P_LOADED or rc == 0:
            continue
        out.append((e, (v - rc) / abs(rc)))
    return out


def error_measures(ref, run):
    """RMS and largest |relative error| of p_c over the loaded part, and the relative errors of
    sxx_c, syy_c and p_c at the last common strain."""
    errs = [x for _, x in relative_errors(ref, run)]
    end = strain_points(ref, run)[-1]
    at_end = {c: (run.at(c, end) - ref.at(c, end)) / ref.at(c, end) for c in ("sxx_c", "syy_c", "p_c")}
    rms = math.sqrt(sum(x * x for x in errs) / len(errs)) if errs else float("nan")
    worst = max((abs(x) for x in errs), default=float("nan"))
    return rms, worst, at_end, len(errs)


# The strain window at the end of a case over which the tangent stiffness dp_c/d(strain) is
# compared: it does not depend on where each run jammed, which scatters between runs of one
# packing by ~0.01-0.02 of strain on sample B's 100 grains and dominates the error at equal strain.
SLOPE_WINDOW = 0.04


def tangent_stiffness(run, end):
    """Least-squares slope of p_c against the volumetric strain over [end - SLOPE_WINDOW, end]."""
    pts = [(x, float(r["p_c"])) for x, r in zip(run.strain, run.rows) if end - SLOPE_WINDOW <= x <= end]
    if len(pts) < 3:
        return float("nan")
    mx = statistics.fmean(x for x, _ in pts)
    my = statistics.fmean(y for _, y in pts)
    return sum((x - mx) * (y - my) for x, y in pts) / sum((x - mx) ** 2 for x, _ in pts)


def slope_ratio(ref, run):
    """The run's tangent stiffness at the end over the reference's (1: the same stiffness)."""
    end = min(ref.final_strain(), run.final_strain())
    return tangent_stiffness(run, end) / tangent_stiffness(ref, end)


def mean_stress_distribution(run):
    """Per-grain mean stress (compression positive) over its mean: quantiles 10, 50, 90 and the
    coefficient of variation, over the grains that carry load."""
    s = sorted(float(g["mean_stress_c"]) for g in run.grains)
    s = [x for x in s if x > 0]
    mean = statistics.fmean(s)
    q = lambda f: s[min(len(s) - 1, int(f * len(s)))] / mean
    return q(0.1), q(0.5), q(0.9), statistics.pstdev(s) / mean, len(s)


def eq69_error(rows, phi0, z0):
    """RMS relative error of p_c(phi) against eq. 69 (E = 1) over phi in [phi0 + 0.01, end]
    (isotropic rows)."""
    errs = []
    for r in rows:
        if r["phase"] != "isotropic":
            continue
        phi, p = float(r["phi"]), float(r["p_c"])
        if phi >= phi0 + 0.01:
            ref = eq69(phi, phi0, z0)
            errs.append(p / ref - 1)
    return math.sqrt(sum(x * x for x in errs) / len(errs)) if errs else float("nan")


# --- charts ---------------------------------------------------------------------------------

NU_COLOURS = {0.3: "#c33", NU_MESHFREE_HIGH: "#393", 0.5: "#36c"}


def chart_case(path, title, curves):
    """Four panels against the volumetric strain: sxx_c and syy_c; p_c and q_c; phi; z and
    z_nr3. `curves`: [(label, Run, colour, dash)]."""
    w, h = 1000, 330
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{2 * h + 40}" '
           f'font-family="sans-serif" font-size="12">',
           f'<text x="{w / 2}" y="18" text-anchor="middle" font-size="15">{title}</text>']
    pw, ph = w / 2 - 110, h - 100

    def series(column, transform=float):
        xs, ys, cs, ls, ds = [], [], [], [], []
        for label, run, colour, dash in curves:
            # A run of an sdem before a column (z_nr3) has no curve of it.
            points = [(e, transform(r.get(column) or "nan")) for e, r in zip(run.strain, run.rows)]
            # z_nr3 is 0 while no 3-contact network exists: drawn where there is one.
            points = [(e, v) for e, v in points if v == v and not (column == "z_nr3" and v == 0)]
            if not points:
                continue
            # At most ~300 points a curve: the charts stay light, the CSVs keep every row.
            points = points[::max(1, len(points) // 300)]
            xs.append([e for e, _ in points])
            ys.append([v for _, v in points])
            cs.append(colour), ls.append(f"{label} {column}"), ds.append(dash)
        return xs, ys, cs, ls, ds

    def two(c1, c2):
        a1, b1, col1, l1, d1 = series(c1)
        a2, b2, col2, l2, d2 = series(c2)
        return a1 + a2, b1 + b2, col1 + col2, l1 + l2, d1 + ["2,3" if not d else "1,3" for d in d2]

    for k, (cols, ylabel) in enumerate([(("sxx_c", "syy_c"), "wall stress / E"),
                                        (("p_c", "q_c"), "p_c, q_c / E"),
                                        (("phi",), "phi"), (("z", "z_nr3"), "coordination")]):
        x0 = 80 + (k % 2) * (w / 2)
        y0 = 60 + (k // 2) * h
        xs, ys, cs, ls, ds = two(*cols) if len(cols) == 2 else series(cols[0])
        svg += panel(x0, y0, pw, ph, xs, ys, cs, ls, "volumetric strain 1 - A/A0", ylabel,
                     " and ".join(cols), dashes=ds, from_zero=cols != ("phi",))
    svg.append("</svg>")
    path.write_text("\n".join(svg))


def log_panel(points, path, title):
    """Error against CPU seconds, log-log, a labelled dot per point: [(label, cpu, err, colour)];
    an error of None (the reference) sits on the floor of the chart, 0.01."""
    w, h, m = 1000, 700, 80
    floor = 0.01
    xs = [math.log10(p[1]) for p in points]
    ys = [math.log10(max(p[2] if p[2] is not None else floor, floor)) for p in points]
    lx, hx = min(xs) - 0.2, max(xs) + 0.2
    ly, hy = min(ys) - 0.2, max(ys) + 0.2
    sx = lambda x: m + (x - lx) / (hx - lx) * (w - 2 * m)
    sy = lambda y: h - m - (y - ly) / (hy - ly) * (h - 2 * m)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="11">',
           f'<text x="{w / 2}" y="24" text-anchor="middle" font-size="14">{title}</text>',
           f'<rect x="{m}" y="{m}" width="{w - 2 * m}" height="{h - 2 * m}" fill="none" stroke="#444"/>',
           f'<text x="{w / 2}" y="{h - 30}" text-anchor="middle">CPU seconds (log)</text>',
           f'<text x="22" y="{h / 2}" transform="rotate(-90 22 {h / 2})" text-anchor="middle">'
           f'RMS relative error of p_c against the meshfree reference (log)</text>']
    for e in range(math.floor(lx), math.ceil(hx) + 1):
        if lx <= e <= hx:
            out.append(f'<text x="{sx(e)}" y="{h - m + 16}" text-anchor="middle">1e{e}</text>')
    for e in range(math.floor(ly), math.ceil(hy) + 1):
        if ly <= e <= hy:
            out.append(f'<text x="{m - 6}" y="{sy(e) + 4}" text-anchor="end">{10.0 ** e:g}</text>')
    if ly <= -1 <= hy:
        out.append(f'<line x1="{m}" x2="{w - m}" y1="{sy(-1)}" y2="{sy(-1)}" stroke="#999" stroke-dasharray="4,4"/>'
                   f'<text x="{w - m - 4}" y="{sy(-1) - 4}" text-anchor="end" fill="#999">10% (the paper\'s claim)</text>')
    for k, ((label, _, _, colour), x, y) in enumerate(zip(points, xs, ys)):
        # Labels of the right half to the left of their dot, so that they stay in the chart;
        # the meshfree ones stacked (their dots sit together).
        right = sx(x) > w / 2
        dy = -5 - 14 * sum(1 for p in points[:k] if p[3] == colour == "#000") if colour == "#000" else -5
        out.append(f'<circle cx="{sx(x):.1f}" cy="{sy(y):.1f}" r="4" fill="{colour}"/>'
                   f'<text x="{sx(x) + (-6 if right else 6):.1f}" y="{sy(y) + dy:.1f}" fill="{colour}" '
                   f'text-anchor="{"end" if right else "start"}">{label}</text>')
    out.append("</svg>")
    path.write_text("\n".join(out))


# --- the report -----------------------------------------------------------------------------

def report(a, out):
    runs_dir = out / "runs"
    load = lambda name: Run(runs_dir / name) if (runs_dir / name / "cost.txt").exists() else None
    rows, summary, convergence, jamming, distributions, chart_points = [], [], [], [], [], []
    fits = []
    for case in CASES:
        for nu, nu_mf in NU_PAIRS:
            mf = {(k0, n): load(meshfree_name(c, v, n, k0)) for c, v, n, k0 in a.meshfree
                  if (c, v) == (case, nu_mf)}
            mf = {key: run for key, run in mf.items() if run}
            if not mf:
                print(f"{case} nu {nu}: no meshfree run yet", flush=True)
                continue
            ref_key = max(mf)
            ref = mf[ref_key]
            ref_n = f"{ref_key[1]} nodes, k0 = {ref_key[0]}"
            for (k0, n), run in sorted(mf.items()):
                if (k0, n) != ref_key and nu == nu_mf:
                    rms, worst, at_end, count = error_measures(ref, run)
                    convergence.append(dict(case=case, nu=nu_mf, boundary_nodes=n, k0=k0,
                                            reference=ref_n, rms_rel_err_p=rms, max_rel_err_p=worst,
                                            rel_err_p_end=at_end["p_c"], cpu_s=run.cpu, cpu_s_ref=ref.cpu,
                                            points=count))
                    finer = ", finer: its difference" if n > ref_key[1] else ""
                    chart_points.append((case, f"meshfree {n} nodes k0 {k0} (nu {nu_mf}{finer})", run.cpu, rms,
                                         "#000"))
            # Nodal density alone: each density against the next finer one at the same penalty,
            # where the reference is not that finer run (its row is above).
            for (k0, n), run in sorted(mf.items()):
                finer = sorted(m for (k, m) in mf if k == k0 and m > n)
                if finer and nu == nu_mf and (k0, finer[0]) != ref_key:
                    other = mf[(k0, finer[0])]
                    rms, worst, at_end, count = error_measures(other, run)
                    convergence.append(dict(case=case, nu=nu_mf, boundary_nodes=n, k0=k0,
                                            reference=f"{finer[0]} nodes, k0 = {k0}", rms_rel_err_p=rms,
                                            max_rel_err_p=worst, rel_err_p_end=at_end["p_c"], cpu_s=run.cpu,
                                            cpu_s_ref=other.cpu, points=count))
            if nu == nu_mf:
                # The reference has no error by definition: drawn on the chart's floor.
                chart_points.append((case, f"meshfree reference (nu {nu_mf}): {ref_n}", ref.cpu, None, "#000"))

            if nu == nu_mf:
                distributions.append((case, nu_mf, f"meshfree {ref_n}") + mean_stress_distribution(ref))
            curves = [(f"meshfree {ref_n}", ref, "#000", "")]
            for label in list(SDEM_VARIANTS) + ["full_slow"]:
                run = load(f"{case}_nu{nu}_{label}")
                if not run:
                    continue
                for e in strain_points(ref, run):
                    sr, yr, s, y = ref.at("sxx_c", e), ref.at("syy_c", e), run.at("sxx_c", e), run.at("syy_c", e)
                    if None in (sr, yr, s, y):
                        continue
                    rows.append(dict(case=case, nu=nu, model=label, strain=f"{e:.4f}", sxx_ref=sr, syy_ref=yr,
                                     sxx=s, syy=y, rel_err=(s + y - sr - yr) / (sr + yr) if sr + yr else float("nan"),
                                     cpu_s_sdem=run.cpu, cpu_s_ref=ref.cpu))
                rms, worst, at_end, count = error_measures(ref, run)
                summary.append(dict(case=case, nu=nu, nu_ref=nu_mf, model=label, rms_rel_err_p=rms,
                                    max_rel_err_p=worst, rel_err_sxx_end=at_end["sxx_c"],
                                    rel_err_syy_end=at_end["syy_c"], rel_err_p_end=at_end["p_c"],
                                    within_10pct=worst <= 0.10, points=count, cpu_s=run.cpu, cpu_s_ref=ref.cpu,
                                    cost_ratio=ref.cpu / run.cpu, slope_ratio_end=slope_ratio(ref, run)))
                chart_points.append((case, f"{label} (nu {nu})", run.cpu, rms, NU_COLOURS[nu]))
                if label == "full":
                    distributions.append((case, nu, label) + mean_stress_distribution(run))
                    curves.append(("SDEM full", run, "#c33", "6,3"))
                if label == "full_calibrated":
                    curves.append(("SDEM calibrated", run, "#36c", "2,2"))
            # The (a, b) pair of the grid that fits this case best.
            best = None
            for ca, cb in itertools.product(FIT_A, FIT_B):
                run = load(f"{case}_nu{nu}_fit_a{ca}_b{cb}")
                if run:
                    rms = error_measures(ref, run)[0]
                    fits.append(dict(case=case, nu=nu, a=ca, b=cb, rms_rel_err_p=rms,
                                     slope_ratio_end=slope_ratio(ref, run)))
                    if best is None or rms < best[0]:
                        best = (rms, ca, cb, run)
            if best:
                curves.append((f"SDEM fitted a={best[1]} b={best[2]}", best[3], "#393", "1,2"))
                chart_points.append((case, f"full, a={best[1]} b={best[2]} fitted (nu {nu})", best[3].cpu,
                                     best[0], NU_COLOURS[nu]))
            # The last frame of the reference and of the full model, on one colour scale.
            full = load(f"{case}_nu{nu}_full")
            if full and a.pictures:
                top = 2.0 * float(ref.rows[-1]["p_c"])
                for run, tag in ((ref, "meshfree"), (full, "sdem")):
                    picture = out / f"{case}_nu{nu}_{tag}.png"
                    if tag == "meshfree" and nu != nu_mf and picture.with_name(f"{case}_nu{nu_mf}_meshfree.png").exists():
                        continue
                    subprocess.run([a.sdem, "render", str(run.dir / "trajectory.mcap"), "--out", str(picture),
                                    "--size", "500", "--stress-max", f"{top:.3e}"], check=True,
                                   stdout=subprocess.DEVNULL)
            chart_case(out / f"{case}_nu{nu}.svg",
                       f"{case} compaction, {ref.summary.get('grains', '?')} grains: meshfree (nu = {nu_mf}, "
                       f"{ref_n}) against SDEM (nu = {nu})", curves)
    write_csv(out / "sdem_vs_meshfree.csv", rows)
    write_csv(out / "summary.csv", summary)
    write_csv(out / "convergence.csv", convergence)
    # The jamming point needs a quasi-static approach to it: the rigid compaction of the packing
    # (the comparison runs start with wall stresses of ~1e-4 E from the walls' start).
    jamming.append(jamming_row("the packing's sample, SDEM full, nu = 0.5 (prepare/quasistatic_nu0.5)",
                               list(csv.DictReader(open(out / "prepare" / "quasistatic_nu0.5" / "macro.csv")))))
    for extra in a.jamming_runs:
        jamming.append(jamming_row(extra, list(csv.DictReader(open(pathlib.Path(extra) / "macro.csv")))))
    jamming = [j for j in jamming if j]
    write_csv(out / "jamming.csv", jamming)
    write_csv(out / "fit.csv", fits)
    write_csv(out / "mean_stress_distribution.csv",
              [dict(zip(("case", "nu", "model", "q10_over_mean", "q50_over_mean", "q90_over_mean",
                         "cv", "grains"), d)) for d in distributions])
    for case in CASES:
        points = [p[1:] for p in chart_points if p[0] == case]
        if points:
            log_panel(points, out / f"speed_accuracy_{case}.svg",
                      f"{case}: SDEM settings against the meshfree reference "
                      f"(red: nu 0.3, green: 0.45, blue: 0.5; black: meshfree)")
    print_tables(summary, convergence, jamming, fits, distributions)


def write_csv(path, rows):
    if not rows:
        return
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def print_tables(summary, convergence, jamming, fits, distributions):
    pct = lambda x: f"{100 * x:+.1f}%"
    print("\n| case | nu | SDEM setting | RMS err p_c | max err p_c | sxx_c at end | syy_c at end | "
          "stiffness at end / ref | CPU s | meshfree CPU s | ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for s in summary:
        print(f"| {s['case']} | {s['nu']} | {s['model']} | {100 * s['rms_rel_err_p']:.1f}% | "
              f"{100 * s['max_rel_err_p']:.1f}% | {pct(s['rel_err_sxx_end'])} | {pct(s['rel_err_syy_end'])} | "
              f"{s['slope_ratio_end']:.2f} | {s['cpu_s']:.1f} | {s['cpu_s_ref']:.0f} | {s['cost_ratio']:.0f} |")
    print("\n| case | nu | nodes | k0 | against | RMS diff p_c | max diff p_c | p_c at end | CPU s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for c in convergence:
        print(f"| {c['case']} | {c['nu']} | {c['boundary_nodes']} | {c['k0']} | {c['reference']} | "
              f"{100 * c['rms_rel_err_p']:.1f}% | {100 * c['max_rel_err_p']:.1f}% | {pct(c['rel_err_p_end'])} | {c['cpu_s']:.0f} |")
    print("\n| run | 2-rule: phi_0 | Z_0 | eq. 69 RMS err | 3-rule: phi_0 | Z_0 | p_c there | eq. 69 RMS err |")
    print("|---|---|---|---|---|---|---|---|")
    for j in jamming:
        print(f"| {j['run']} | {j['phi0']:.4f} | {j['z_nr0']:.2f} | {100 * j['eq69_rms_err_2rule']:.1f}% | "
              f"{j['phi0_3rule']:.4f} | {j['z_nr3_0']:.2f} | {j['p_c_3rule']:.1e} | {100 * j['eq69_rms_err_3rule']:.1f}% |")
    print("\n| case | nu | model | q10/mean | q50/mean | q90/mean | CV | loaded grains |")
    print("|---|---|---|---|---|---|---|---|")
    for d in distributions:
        print(f"| {d[0]} | {d[1]} | {d[2]} | {d[3]:.2f} | {d[4]:.2f} | {d[5]:.2f} | {d[6]:.2f} | {d[7]} |")
    if fits:
        print("\n| case | nu | best a | best b | RMS err p_c |")
        print("|---|---|---|---|---|")
        for key, group in itertools.groupby(fits, key=lambda f: (f["case"], f["nu"])):
            b = min(group, key=lambda f: f["rms_rel_err_p"])
            print(f"| {key[0]} | {key[1]} | {b['a']} | {b['b']} | {100 * b['rms_rel_err_p']:.1f}% |")
        for nu in sorted({f["nu"] for f in fits}):
            both = {}
            for f in fits:
                if f["nu"] == nu:
                    both.setdefault((f["a"], f["b"]), []).append(f["rms_rel_err_p"])
            pairs = [(math.sqrt(sum(x * x for x in v) / len(v)), k) for k, v in both.items() if len(v) == len(CASES)]
            if pairs:
                err, (ca, cb) = min(pairs)
                print(f"one pair for both cases at nu {nu}: a = {ca}, b = {cb}, RMS err p_c {100 * err:.1f}%")


def calibrate_assembly(a, out):
    """`sdem calibrate --assembly` on both cases of each nu (SDEM full's scenario against the
    case's reference): the one (a, b) pair for both loadings, refined off the grid, in
    calibrate_nu<nu>/. An existing assembly_fit.txt is kept (delete it to redo)."""
    runs_dir = out / "runs"
    for nu, nu_mf in NU_PAIRS:
        args = []
        for case in CASES:
            refs = [(k0, n, meshfree_name(c, v, n, k0)) for c, v, n, k0 in a.meshfree if (c, v) == (case, nu_mf)]
            refs = [r for r in refs if (runs_dir / r[2] / "cost.txt").exists()]
            scenario = runs_dir / f"{case}_nu{nu}_full.ron"
            if refs and scenario.exists():
                args += ["--assembly", str(scenario), "--reference", str(runs_dir / max(refs)[2])]
        fit_dir = out / f"calibrate_nu{nu}"
        if not args:
            continue
        if not (fit_dir / "assembly_fit.txt").exists():
            print(f"sdem calibrate --assembly, nu {nu} ...", flush=True)
            subprocess.run([a.sdem, "calibrate", *args, "--out", str(fit_dir), "--threads", str(a.jobs)],
                           check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        print(f"\nnu {nu}: {' '.join(['sdem', 'calibrate', *args])}\n" + (fit_dir / "assembly_fit.txt").read_text())


DISC_NODES = [24, 32, 48, 64, 96]
DISC_NUS = [0.3, 0.45, 0.49]
DISC_SIDES = [0.99, 0.985, 0.98, 0.97, 0.96, 0.94, 0.90]


def disc_convergence(a, out):
    """The nodal-density convergence of one meshfree disc pressed by four walls (`sdem calibrate`,
    implicit, exact contact), at the densities of the assembly runs and above: the force on a
    wall at each box side over the 96-node force, per nu. The mean wall stress of a disc in its
    box is F / side (diameter 1, E = 1): side 0.985 carries ~5e-3 E, the start of the loaded part
    of the assembly comparison. Writes disc_convergence.csv."""
    forces = {}
    for n in DISC_NODES:
        run_dir = out / "disc" / f"nodes{n}"
        if not (run_dir / "calibration.csv").exists():
            subprocess.run([a.sdem, "calibrate", "--nu", ",".join(map(str, DISC_NUS)), "--boundary-nodes", str(n),
                            "--out", str(run_dir), "--threads", str(a.jobs)], check=True,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for r in csv.DictReader(open(run_dir / "calibration.csv")):
            forces[(n, float(r["nu"]), round(2 * float(r["h"]), 4))] = float(r["F"])
    rows = []
    for nu in DISC_NUS:
        for side in DISC_SIDES:
            finest = forces[(DISC_NODES[-1], nu, side)]
            row = dict(nu=nu, box_side=side, wall_stress_finest=finest / side)
            row.update({f"rel_diff_{n}": forces[(n, nu, side)] / finest - 1 for n in DISC_NODES[:-1]})
            rows.append(row)
    write_csv(out / "disc_convergence.csv", rows)
    print("\n| nu | box side | wall stress (96 nodes) | " + " | ".join(f"{n} nodes" for n in DISC_NODES[:-1]) + " |")
    print("|---|---|---|" + "---|" * (len(DISC_NODES) - 1))
    for r in rows:
        print(f"| {r['nu']} | {r['box_side']} | {r['wall_stress_finest']:.2e} | "
              + " | ".join(f"{100 * r[f'rel_diff_{n}']:+.1f}%" for n in DISC_NODES[:-1]) + " |")


def meshfree_run(text):
    """`CASE:NU:NODES:K0` of `--meshfree`."""
    try:
        case, nu, nodes, k0 = text.split(":")
        if case not in CASES:
            raise ValueError(f"case {case!r} is not one of {', '.join(CASES)}")
        return case, float(nu), int(nodes), int(k0)
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"{text!r}: expected CASE:NU:NODES:K0 (e.g. isotropic:0.3:32:30): {e}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="out/sdem_vs_meshfree")
    ap.add_argument("--sdem", default="target/release/sdem")
    ap.add_argument("--sample", choices=sorted(RADII), default="A")
    ap.add_argument("--count", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--rate", type=float, default=4e-3, help="strain rate of every loading phase")
    ap.add_argument("--phi-end", type=float, default=0.90)
    ap.add_argument("--jobs", type=int, default=2, help="runs at a time (each on one thread)")
    ap.add_argument("--only", default="", help="regular expression: run only the matching runs")
    ap.add_argument("--skip-meshfree", action="store_true", help="run the SDEM side only")
    ap.add_argument("--meshfree", nargs="+", type=meshfree_run, metavar="CASE:NU:NODES:K0",
                    default=MESHFREE_RUNS,
                    help="the meshfree runs (default: MESHFREE_RUNS), e.g. isotropic:0.3:32:30; the stiffest "
                         "penalty's finest run of a case and nu is its reference")
    ap.add_argument("--fit", action="store_true",
                    help=f"also run SDEM over the (a, b) grid {FIT_A} x {FIT_B} to fit the law to the reference")
    ap.add_argument("--calibrate", action="store_true",
                    help="also run `sdem calibrate --assembly` on both cases of each nu (calibrate_nu<nu>/)")
    ap.add_argument("--disc-convergence", action="store_true",
                    help="also compress one meshfree disc at 24 to 96 boundary nodes (`sdem calibrate`): the "
                         "nodal-density convergence of a contact at the assembly's deformations")
    ap.add_argument("--report-only", action="store_true", help="run nothing: report on the runs there are")
    ap.add_argument("--pictures", action="store_true",
                    help="draw the last state of the reference and of SDEM full (`sdem render`, PNG)")
    ap.add_argument("--jamming-runs", nargs="*", default=[], metavar="RUN_DIR",
                    help="other runs (e.g. of scenarios/isotropic_A.ron) whose jamming point and eq. 69 error "
                         "to report with both rattler rules")
    a = ap.parse_args()
    if not pathlib.Path(a.sdem).exists():
        sys.exit(f"sdem_vs_meshfree: {a.sdem} not found: build it with `cargo build --release`")
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    box, phi_start, phi_j = prepare(a, out)
    print(f"packing: {a.count} grains, phi_start = {phi_start:.4f}, phi_J = {phi_j:.4f}", flush=True)
    if not a.report_only:
        # The longest first (oedometric, nearly incompressible, finest), so that the pool ends
        # together; then SDEM.
        jobs = [] if a.skip_meshfree else meshfree_runs(a, box, phi_start, phi_j)
        jobs += sdem_runs(a, box, phi_start, phi_j)
        if a.fit:
            jobs += fit_runs(a, box, phi_start, phi_j)
        if a.only:
            jobs = [j for j in jobs if re.search(a.only, j[0])]
        failed = []
        with ThreadPoolExecutor(max_workers=a.jobs) as pool:
            futures = [(name, pool.submit(run_cached, a.sdem, 1, out / "runs" / name, text)) for name, text in jobs]
            for name, f in futures:
                try:
                    f.result()
                except RuntimeError as e:
                    print(f"FAILED {e}", flush=True)
                    failed.append(name)
        if failed:
            print(f"{len(failed)} runs failed: {', '.join(failed)} (see runs/<name>.stderr)")
    report(a, out)
    if a.calibrate:
        calibrate_assembly(a, out)
    if a.disc_convergence:
        disc_convergence(a, out)


if __name__ == "__main__":
    main()
