#!/usr/bin/env python3
"""Charts of a meshfree_biaxial_100 run: wall stresses against the vertical strain, and the
Newton iterations and augmentations of every step.

usage: tools/meshfree_biaxial_plot.py RUN_DIR [--out CHART.svg] [--compare OTHER_RUN_DIR --label TEXT]

Reads RUN_DIR/macro.csv (written by `sdem run scenarios/meshfree_biaxial_100.ron --out RUN_DIR`).
The vertical strain is 1 - H/H0 with H0 the box height at the start; stresses are compression
positive, as in macro.csv. Writes an SVG with two panels and prints, per phase, the steps, the
Newton iterations, factorizations and augmentations per step (mean and max) and the stresses at
the phase end.

With --compare, the other run's wall stresses (e.g. the explicit scheme's) are drawn dashed on
the first panel, and a table gives both runs' stresses at vertical strains 0.45, 0.47, ... (the
loaded part), interpolated in strain, with the relative difference of the mean wall stress
(sxx_c + syy_c) / 2 against RUN_DIR's.
"""
import argparse, csv, pathlib, statistics


def read(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def panel(x0, y0, w, h, xs_list, ys_list, colours, labels, xlabel, ylabel, title, dashes=None,
          from_zero=True):
    """A line chart; the y axis starts at 0 (or below) unless `from_zero` is false."""
    lo_x = min(min(xs) for xs in xs_list)
    hi_x = max(max(xs) for xs in xs_list)
    lo_y = min(min(ys) for ys in ys_list)
    lo_y = min(0.0, lo_y) if from_zero else lo_y
    hi_y = max(max(ys) for ys in ys_list) * 1.05 or 1.0
    sx = lambda x: x0 + (x - lo_x) / ((hi_x - lo_x) or 1.0) * w
    sy = lambda y: y0 + h - (y - lo_y) / ((hi_y - lo_y) or 1.0) * h
    out = [f'<rect x="{x0}" y="{y0}" width="{w}" height="{h}" fill="none" stroke="#444"/>',
           f'<text x="{x0 + w / 2}" y="{y0 - 8}" text-anchor="middle">{title}</text>',
           f'<text x="{x0 + w / 2}" y="{y0 + h + 32}" text-anchor="middle">{xlabel}</text>',
           f'<text x="{x0 - 48}" y="{y0 + h / 2}" transform="rotate(-90 {x0 - 48} {y0 + h / 2})" '
           f'text-anchor="middle">{ylabel}</text>']
    for k in range(5):
        xv = lo_x + (hi_x - lo_x) * k / 4
        yv = lo_y + (hi_y - lo_y) * k / 4
        out.append(f'<text x="{sx(xv)}" y="{y0 + h + 16}" text-anchor="middle">{xv:.3g}</text>')
        out.append(f'<text x="{x0 - 6}" y="{sy(yv) + 4}" text-anchor="end">{yv:.3g}</text>')
    for k, (xs, ys, c, label) in enumerate(zip(xs_list, ys_list, colours, labels)):
        pts = " ".join(f"{sx(x):.1f},{sy(y):.1f}" for x, y in zip(xs, ys))
        dash = f' stroke-dasharray="{dashes[k]}"' if dashes and dashes[k] else ""
        out.append(f'<polyline points="{pts}" fill="none" stroke="{c}" stroke-width="1.5"{dash}/>')
    for k, (c, label) in enumerate(zip(colours, labels)):
        out.append(f'<text x="{x0 + 10}" y="{y0 + 18 + 16 * k}" fill="{c}">{label}</text>')
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run_dir")
    ap.add_argument("--out")
    ap.add_argument("--compare", help="another run of the scenario, drawn dashed")
    ap.add_argument("--label", default="other run")
    a = ap.parse_args()
    run = pathlib.Path(a.run_dir)
    rows = read(run / "macro.csv")
    h0 = float(rows[0]["box_height"])
    strain = [1 - float(r["box_height"]) / h0 for r in rows]
    steps = [int(r["step"]) for r in rows]
    sxx = [float(r["sxx_c"]) for r in rows]
    syy = [float(r["syy_c"]) for r in rows]
    newton = [int(r["newton_iterations"]) for r in rows]
    factorizations = [int(r.get("factorizations", 0)) for r in rows]
    aug = [int(r["augmentations"]) for r in rows]
    w, h = 900, 380
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{2 * h}" '
           'font-family="sans-serif" font-size="12">',
           f'<rect width="{w}" height="{2 * h}" fill="white"/>']
    xs, ys = [strain, strain], [sxx, syy]
    colours = ["#1f77b4", "#d62728"]
    labels = ["sxx_c (side walls)", "syy_c (top and bottom walls)"]
    dashes = [None, None]
    other = None
    if a.compare:
        other = read(pathlib.Path(a.compare) / "macro.csv")
        o_strain = [1 - float(r["box_height"]) / float(other[0]["box_height"]) for r in other]
        xs += [o_strain, o_strain]
        ys += [[float(r["sxx_c"]) for r in other], [float(r["syy_c"]) for r in other]]
        colours += colours
        labels += [f"sxx_c, {a.label} (dashed)", f"syy_c, {a.label} (dashed)"]
        dashes += ["6,4", "6,4"]
    svg += panel(80, 40, w - 120, h - 100, xs, ys, colours, labels,
                 "vertical strain 1 - H/H0", "wall stress (compression +)",
                 "meshfree_biaxial_100: wall stresses", dashes)
    svg += panel(80, h + 40, w - 120, h - 100, [steps, steps, steps], [newton, factorizations, aug],
                 ["#2ca02c", "#8c564b", "#9467bd"],
                 ["Newton iterations per step", "factorizations per step", "augmentations per step"],
                 "step", "count", "implicit solver effort (Bathe: two solves per step)")
    svg.append("</svg>")
    out = pathlib.Path(a.out) if a.out else run / "biaxial_100.svg"
    out.write_text("\n".join(svg))
    print(f"wrote {out}")
    phases = []
    for r, e in zip(rows, strain):
        if not phases or phases[-1][0] != r["phase"]:
            phases.append((r["phase"], []))
        phases[-1][1].append((r, e))
    print("phase       steps  newton/step (mean, max)  factorizations/step  augmentations/step  "
          "end: strain  sxx_c  syy_c  max_penetration")
    for name, pr in phases:
        n = [int(r["newton_iterations"]) for r, _ in pr]
        f = [int(r.get("factorizations", 0)) for r, _ in pr]
        g = [int(r["augmentations"]) for r, _ in pr]
        last, e = pr[-1]
        pen = max(float(r["max_penetration"]) for r, _ in pr)
        print(f"{name:<10} {int(last['step']):>6}  {statistics.mean(n):6.1f} {max(n):4d}"
              f"                 {statistics.mean(f):6.1f} {max(f):4d}"
              f"       {statistics.mean(g):6.1f} {max(g):4d}"
              f"     {e:.3f}  {float(last['sxx_c']):.4g}  "
              f"{float(last['syy_c']):.4g}  {pen:.3e}")
    if other is not None:
        compare(rows, strain, other, a.label)


def interpolate(xs, ys, x):
    """ys at x by linear interpolation on increasing xs (None outside)."""
    for k in range(1, len(xs)):
        if xs[k - 1] <= x <= xs[k] and xs[k] > xs[k - 1]:
            t = (x - xs[k - 1]) / (xs[k] - xs[k - 1])
            return ys[k - 1] + t * (ys[k] - ys[k - 1])
    return None


def compare(rows, strain, other, label):
    o_strain = [1 - float(r["box_height"]) / float(other[0]["box_height"]) for r in other]
    print(f"\nvertical strain: sxx_c, syy_c of {label} against this run's; rel. diff. of (sxx_c + syy_c)/2")
    print("strain   phase      sxx_c    syy_c    sxx_c'   syy_c'   rel_diff")
    worst = 0.0
    e = 0.45
    while e <= max(strain) + 1e-9:
        ref = [interpolate(strain, [float(r[c]) for r in rows], e) for c in ("sxx_c", "syy_c")]
        oth = [interpolate(o_strain, [float(r[c]) for r in other], e) for c in ("sxx_c", "syy_c")]
        if None not in ref and None not in oth:
            phase = next(r["phase"] for r, x in zip(rows, strain) if x >= e - 1e-12)
            mean_ref, mean_oth = sum(ref) / 2, sum(oth) / 2
            rel = (mean_oth - mean_ref) / mean_ref if mean_ref else float("nan")
            worst = max(worst, abs(rel))
            print(f"{e:.3f}    {phase:<9} {ref[0]:8.4g} {ref[1]:8.4g} {oth[0]:8.4g} {oth[1]:8.4g} {rel:+9.3%}")
        e += 0.02
    print(f"largest |rel_diff| = {worst:.2%}")


if __name__ == "__main__":
    main()
