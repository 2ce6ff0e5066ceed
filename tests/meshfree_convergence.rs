//! Convergence of the multibody meshfree solver in nodal density (issue #12): the top wall force
//! of two stacked discs compressed between two walls, and the wall stresses of a small isotropic
//! compaction, each at three numbers of boundary nodes per grain. The tables are in
//! `docs/meshfree.md`, section "Convergence in nodal density".
//!
//! ```sh
//! RAYON_NUM_THREADS=1 cargo test --release --test meshfree_convergence -- --ignored --nocapture
//! ```
//!
//! With `SDEM_CONVERGENCE_CSV=<folder>` set, each test also writes its table there as CSV.

mod common;

use common::meshfree::{column, settings};
use sdem::run::{RunOptions, run_scenario};
use sdem::scenario::Scenario;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// Force on the top wall after each of `steps` load steps of a quasi-static compression of two
/// touching discs (centred on x = 0, E = 1) between a bottom and a top wall, which each move in
/// by `approach / 2` in all: [`common::meshfree::column`] of two discs.
fn two_disc_forces(boundary_nodes: usize, nu: f64, approach: f64, steps: usize) -> Vec<f64> {
    let two = column(2, boundary_nodes, nu, approach, steps);
    assert!(
        two.penetration <= settings().gap_tolerance,
        "penetration {:e}",
        two.penetration
    );
    two.force
}

/// One row of a convergence table: a quantity at successive densities N (each the last times a
/// common ratio r). `label` holds the row's label columns, separated by commas.
struct Row {
    label: String,
    values: Vec<f64>,
}

impl Row {
    /// |value(N_k+1) - value(N_k)|.
    fn diffs(&self) -> Vec<f64> {
        self.values
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .collect()
    }
    /// Relative changes |value(N_k+1) - value(N_k)| / |value(N_k+1)|.
    fn changes(&self) -> Vec<f64> {
        self.values
            .windows(2)
            .map(|w| (w[1] - w[0]).abs() / w[1].abs())
            .collect()
    }
    /// Observed orders ln(d_k / d_k+1) / ln(r), one per three successive densities.
    fn orders(&self, ratio: f64) -> Vec<f64> {
        self.diffs()
            .windows(2)
            .map(|d| (d[0] / d[1]).ln() / ratio.ln())
            .collect()
    }
}

/// Prints the table (markdown) and returns it as CSV (with a header line when `header`).
fn table(title: &str, labels: &str, densities: &[usize], rows: &[Row], header: bool) -> String {
    let ratio = densities[1] as f64 / densities[0] as f64;
    for w in densities.windows(2) {
        assert!((w[1] as f64 / w[0] as f64 - ratio).abs() < 1e-12);
    }
    let n = densities;
    let mut md_head: Vec<String> = labels.split(',').map(str::to_string).collect();
    let mut csv_head = md_head.clone();
    for k in n {
        md_head.push(format!("N = {k}"));
        csv_head.push(format!("n{k}"));
    }
    for w in n.windows(2) {
        md_head.push(format!("change {}→{}", w[0], w[1]));
        csv_head.push(format!("rel_change_{}_{}", w[0], w[1]));
    }
    for w in n.windows(3) {
        md_head.push(format!("order {}–{}", w[0], w[2]));
        csv_head.push(format!("order_{}_{}", w[0], w[2]));
    }
    println!("\n{title}");
    println!("| {} |", md_head.join(" | "));
    println!("|{}", "---|".repeat(md_head.len()));
    let mut csv = String::new();
    if header {
        csv = csv_head.join(",") + "\n";
    }
    for r in rows {
        let mut md: Vec<String> = r.label.split(',').map(str::to_string).collect();
        let mut c = md.clone();
        for v in &r.values {
            md.push(format!("{v:.6}"));
            c.push(format!("{v:.9e}"));
        }
        for v in r.changes() {
            md.push(format!("{v:.2e}"));
            c.push(format!("{v:.4e}"));
        }
        for p in r.orders(ratio) {
            md.push(format!("{p:.2}"));
            c.push(format!("{p:.4}"));
        }
        println!("| {} |", md.join(" | "));
        writeln!(csv, "{}", c.join(",")).unwrap();
    }
    csv
}

fn save(name: &str, csv: &str) {
    if let Some(dir) = std::env::var_os("SDEM_CONVERGENCE_CSV") {
        let dir = PathBuf::from(dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join(name), csv).unwrap();
    }
}

/// Boundary nodes per disc of the two-disc case (each twice the last).
const TWO_DISC_DENSITIES: [usize; 3] = [32, 64, 128];

#[test]
#[ignore = "release, ~40 s on 1 thread: three densities, 10 load steps each"]
fn two_disc_force_converges_in_nodal_density() {
    // Two discs (R = 0.5, E = 1, nu = 0.3, neo-Hookean) compressed by 0.4 in all, i.e. each
    // disc by 0.2 of its diameter (20% strain), in 10 load steps.
    let densities = TWO_DISC_DENSITIES;
    let steps = 10;
    let approach = 0.4;
    let forces: Vec<Vec<f64>> = densities
        .iter()
        .map(|&nb| {
            let t = Instant::now();
            let f = two_disc_forces(nb, 0.3, approach, steps);
            println!("N = {nb}: {:.1} s, forces {f:?}", t.elapsed().as_secs_f64());
            f
        })
        .collect();
    let rows: Vec<Row> = (1..=steps)
        .map(|s| Row {
            label: format!("{:.2}", approach / 2.0 * s as f64 / steps as f64),
            values: forces.iter().map(|f| f[s - 1]).collect(),
        })
        .collect();
    let csv = table(
        "Top wall force of two stacked discs against the approach per disc (fraction of a \
         diameter)",
        "approach_per_disc",
        &densities,
        &rows,
        true,
    );
    save("two_discs.csv", &csv);
    // Over the whole loading: the largest and the RMS relative change between successive
    // densities.
    let n = densities.len() - 1;
    let max: Vec<f64> = (0..n)
        .map(|k| rows.iter().map(|r| r.changes()[k]).fold(0.0, f64::max))
        .collect();
    let rms: Vec<f64> = (0..n)
        .map(|k| {
            (rows.iter().map(|r| r.changes()[k].powi(2)).sum::<f64>() / rows.len() as f64).sqrt()
        })
        .collect();
    let pointwise = rows
        .iter()
        .filter(|r| r.diffs().windows(2).all(|d| d[1] < d[0]))
        .count();
    let e = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.2e}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!(
        "\nover the loading, per refinement: max relative change [{}], RMS [{}]",
        e(&max),
        e(&rms)
    );
    println!(
        "load steps whose differences shrink at every refinement: {pointwise} of {}",
        rows.len()
    );
    assert!(rows.iter().all(|r| r.values.iter().all(|f| *f > 0.0)));
    for k in 1..n {
        assert!(max[k] < max[k - 1], "max relative change {max:?}");
        assert!(rms[k] < rms[k - 1], "RMS relative change {rms:?}");
    }
}

/// A small isotropic compaction of 7 soft discs (E = 1, nu = 0.3, R ~ 0.5) in a box, with
/// `boundary_nodes` nodes on each disc's contour; the sample is the same for every density
/// (same seed).
fn compaction(boundary_nodes: usize) -> String {
    format!(
        r#"
Scenario(
    name: "mf_conv_{boundary_nodes}",
    seed: 11,
    sample: (count: 7, box_width: 3.2, box_height: 3.2,
             radii: Uniform(min: 0.4, max: 0.6)),
    material: (young: 1.0, poisson: 0.3, density: 1.0),
    model: Meshfree((boundary_nodes: {boundary_nodes}, rayleigh_alpha: 2.0)),
    time_step: Fixed(0.05),
    loading: [ Isotropic(rate: Constant(0.02), until: PackingFraction(0.90)) ],
    output: (every: 1),
)
"#
    )
}

/// The columns of macro.csv we need, one entry per row.
struct Macro {
    time: Vec<f64>,
    phi: Vec<f64>,
    sxx: Vec<f64>,
    syy: Vec<f64>,
    p: Vec<f64>,
    area: Vec<f64>,
}

/// Runs the compaction at `boundary_nodes` and reads its macro.csv. With
/// `SDEM_CONVERGENCE_MACRO=<folder>` set, the macro.csv is kept there as
/// `macro_n<boundary_nodes>.csv`, and read from there instead of running when it exists (the
/// runs are deterministic: same seed, any thread count).
fn run_compaction(boundary_nodes: usize) -> Macro {
    let cache = std::env::var_os("SDEM_CONVERGENCE_MACRO")
        .map(|d| PathBuf::from(d).join(format!("macro_n{boundary_nodes}.csv")));
    let text = match &cache {
        Some(path) if path.exists() => {
            println!("N = {boundary_nodes}: macro.csv from {}", path.display());
            std::fs::read_to_string(path).unwrap()
        }
        _ => {
            let text = compaction_macro(boundary_nodes);
            if let Some(path) = &cache {
                std::fs::create_dir_all(path.parent().unwrap()).unwrap();
                std::fs::write(path, &text).unwrap();
            }
            text
        }
    };
    parse_macro(&text)
}

fn compaction_macro(boundary_nodes: usize) -> String {
    let scenario = Scenario::parse(&compaction(boundary_nodes), "mf_conv.ron").unwrap();
    scenario.validate().unwrap();
    let out = std::env::temp_dir().join(format!(
        "sdem-mfconv-{}-{boundary_nodes}",
        std::process::id()
    ));
    std::fs::remove_dir_all(&out).ok();
    let t = Instant::now();
    let summary = run_scenario(
        &scenario,
        &RunOptions {
            out_dir: out.clone(),
            ..Default::default()
        },
    )
    .unwrap();
    println!(
        "N = {boundary_nodes}: {} steps, {:.1} s",
        summary.steps,
        t.elapsed().as_secs_f64()
    );
    let text = std::fs::read_to_string(out.join("macro.csv")).unwrap();
    std::fs::remove_dir_all(&out).ok();
    text
}

fn parse_macro(text: &str) -> Macro {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let (ct, cphi, cx, cy, cp, cw, ch) = (
        col("time"),
        col("phi"),
        col("sxx_c"),
        col("syy_c"),
        col("p_c"),
        col("box_width"),
        col("box_height"),
    );
    let mut m = Macro {
        time: vec![],
        phi: vec![],
        sxx: vec![],
        syy: vec![],
        p: vec![],
        area: vec![],
    };
    for line in lines {
        let f: Vec<f64> = line
            .split(',')
            .map(|s| s.parse().unwrap_or(f64::NAN))
            .collect();
        m.time.push(f[ct]);
        m.phi.push(f[cphi]);
        m.sxx.push(f[cx]);
        m.syy.push(f[cy]);
        m.p.push(f[cp]);
        m.area.push(f[cw] * f[ch]);
    }
    m
}

/// Linear interpolation of `y` at the first crossing of `x = at` (x increasing there).
fn at_first_crossing(x: &[f64], y: &[f64], at: f64) -> f64 {
    for k in 1..x.len() {
        if x[k - 1] <= at && x[k] >= at {
            let s = (at - x[k - 1]) / (x[k] - x[k - 1]);
            return y[k - 1] + s * (y[k] - y[k - 1]);
        }
    }
    panic!("{at} not reached (range {:?} .. {:?})", x.first(), x.last());
}

/// Boundary nodes per disc of the compaction (each 1.5 times the last).
const COMPACTION_DENSITIES: [usize; 3] = [16, 24, 36];

/// Which column of [`Macro`].
type Pick = fn(&Macro) -> &Vec<f64>;
const STRESSES: [(&str, Pick); 3] = [
    ("sxx_c", |m| &m.sxx),
    ("syy_c", |m| &m.syy),
    ("p_c", |m| &m.p),
];

#[test]
#[ignore = "release, ~10 min on 1 thread: three compactions"]
fn compaction_wall_stress_in_nodal_density() {
    let densities = COMPACTION_DENSITIES;
    let runs: Vec<Macro> = densities.iter().map(|&n| run_compaction(n)).collect();
    let levels = [0.80, 0.84, 0.88];
    // Fixed packing fraction as macro.csv reports it (grain areas: their deformed contour
    // polygons, so a coarser grain is smaller and the box at a given phi too).
    let mut rows = Vec::new();
    for (name, pick) in STRESSES {
        for phi in levels {
            rows.push(Row {
                label: format!("phi,{phi:.2},{name}"),
                values: runs
                    .iter()
                    .map(|m| at_first_crossing(&m.phi, pick(m), phi))
                    .collect(),
            });
        }
    }
    // Fixed box size, the same for every density at the same time: labelled by the packing
    // fraction of the exact discs, phi_disc = sum(pi r^2) / box area.
    let c = |n: usize| {
        let n = n as f64;
        n * (2.0 * std::f64::consts::PI / n).sin() / (2.0 * std::f64::consts::PI)
    };
    // The first row's grains are undeformed regular N-gons: polygon area = c(N) disc area.
    let disc_areas: Vec<f64> = runs
        .iter()
        .zip(densities)
        .map(|(m, n)| m.phi[0] * m.area[0] / c(n))
        .collect();
    println!("sum of disc areas from each run's first row: {disc_areas:?}");
    let disc_area = disc_areas[0];
    assert!(
        disc_areas
            .iter()
            .all(|a| (a / disc_area - 1.0).abs() < 1e-6)
    );
    for (name, pick) in STRESSES {
        for phi in levels {
            rows.push(Row {
                label: format!("phi_disc,{phi:.2},{name}"),
                values: runs
                    .iter()
                    .map(|m| {
                        let phid: Vec<f64> = m.area.iter().map(|a| disc_area / a).collect();
                        at_first_crossing(&phid, pick(m), phi)
                    })
                    .collect(),
            });
        }
    }
    let csv = table(
        "Wall stresses of the compaction at a fixed packing fraction: phi (contour polygons) \
         and phi_disc (exact discs, i.e. a fixed box size)",
        "at,level,stress",
        &densities,
        &rows,
        true,
    );
    save("compaction.csv", &csv);
    // The stress paths, step by step, up to the shortest run.
    let len = runs.iter().map(|m| m.time.len()).min().unwrap();
    let mut series = String::from("time,phi_disc");
    for n in densities {
        write!(series, ",phi_n{n},sxx_c_n{n},syy_c_n{n},p_c_n{n}").unwrap();
    }
    series.push('\n');
    for k in 0..len {
        write!(
            series,
            "{:.4},{:.6}",
            runs[0].time[k],
            disc_area / runs[0].area[k]
        )
        .unwrap();
        for m in &runs {
            write!(
                series,
                ",{:.6},{:.6e},{:.6e},{:.6e}",
                m.phi[k], m.sxx[k], m.syy[k], m.p[k]
            )
            .unwrap();
        }
        series.push('\n');
    }
    save("compaction_series.csv", &series);
    let shrinking = rows
        .iter()
        .filter(|r| r.diffs().windows(2).all(|d| d[1] < d[0]))
        .count();
    println!(
        "rows whose differences shrink with refinement: {shrinking} of {}",
        rows.len()
    );
    // The runs must carry load at the levels compared; convergence is reported, not asserted
    // (the dynamics of a loose packing may differ between discretizations).
    assert!(rows.iter().all(|r| r.values.iter().all(|v| *v > 0.0)));
}
