//! Validation runs of the SDEM paper's cases (SPEC §8): the shipped scenarios, run to the end.
//! Heavy (minutes each, release build):
//!
//! ```sh
//! cargo test --release --test validation -- --ignored --nocapture --test-threads 1
//! ```
//!
//! Outputs land in `target/validation/<scenario>/`. The numbers are discussed in
//! `docs/validation.md`.

use sdem::output::reference::CantorReference;
use sdem::run::{RunOptions, RunSummary, run_scenario};
use sdem::scenario::Scenario;
use std::path::{Path, PathBuf};

struct Row {
    phase: String,
    phi: f64,
    sxx_c: f64,
    syy_c: f64,
    p_c: f64,
    q_c: f64,
}

fn run_shipped(name: &str) -> (RunSummary, Vec<Row>) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let (scenario, _) =
        Scenario::load(&root.join("scenarios").join(format!("{name}.ron"))).unwrap();
    let out: PathBuf = root.join("target/validation").join(name);
    let summary = run_scenario(
        &scenario,
        &RunOptions {
            out_dir: out.clone(),
            progress_seconds: Some(60.0),
            ..Default::default()
        },
    )
    .unwrap();
    let text = std::fs::read_to_string(out.join("macro.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let (phase, phi, sxx, syy, p, q) = (
        col("phase"),
        col("phi"),
        col("sxx_c"),
        col("syy_c"),
        col("p_c"),
        col("q_c"),
    );
    let rows = lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            Row {
                phase: f[phase].to_string(),
                phi: f[phi].parse().unwrap(),
                sxx_c: f[sxx].parse().unwrap(),
                syy_c: f[syy].parse().unwrap(),
                p_c: f[p].parse().unwrap(),
                q_c: f[q].parse().unwrap(),
            }
        })
        .collect();
    (summary, rows)
}

/// Isotropic compaction of a sample against eq. 69 with the paper's jamming point.
fn check_isotropic(name: &str, paper_phi0: f64, paper_z0: f64, max_rms: f64) {
    let (summary, rows) = run_shipped(name);
    let jam = summary.jamming.expect("the sample jams");
    let curve: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.phase == "isotropic")
        .map(|r| (r.phi, r.p_c))
        .collect();
    let paper = CantorReference::new(paper_phi0, paper_z0);
    let (rms_paper, n_paper) = paper
        .rms_relative_error(&curve, 1.0, paper_phi0 + 0.01, 0.95)
        .unwrap();
    let (rms_own, n_own) = summary.eq69_rms_error.unwrap();
    println!(
        "{name}: phi_0 = {:.4}, z_0 = {:.3}, z_nr_0 = {:.3}; final phi = {:.4}, p_c = {:.4e}; \
         eq. 69 RMS: {:.1}% with the paper's (phi0, Z0) over {n_paper} rows, {:.1}% with the run's own over {n_own}; \
         max I once loaded = {:.2e}; {} steps in {:.0} s",
        jam.phi,
        jam.z,
        jam.z_nr,
        summary.last.phi,
        summary.last.p_c,
        100.0 * rms_paper,
        100.0 * rms_own,
        summary.max_loaded_inertial_number,
        summary.steps,
        summary.wall_seconds
    );
    // Frictionless discs jam near random close packing (paper: 0.833 for A, 0.858 for B).
    assert!((jam.phi - paper_phi0).abs() < 0.03, "phi_0 = {}", jam.phi);
    // Quasi-static once loaded (SPEC §7): the rate controller holds I at 1e-3.
    assert!(summary.max_loaded_inertial_number < 1.1e-3);
    // The pressure curve follows eq. 69 within the stated bound. The paper calls its agreement
    // "very satisfactory" without a number; 30% is a regression guard set after our first
    // measurements (A: 17%, B: 25%), see docs/validation.md for why they are not lower.
    assert!(rms_paper < max_rms, "RMS {rms_paper}");
    // Past jamming the pressure only grows with phi (checked on rows 0.005 apart in phi).
    let loaded: Vec<&(f64, f64)> = curve
        .iter()
        .filter(|(phi, _)| *phi > jam.phi + 0.01)
        .collect();
    for w in loaded.windows(2) {
        if w[1].0 > w[0].0 + 0.005 {
            assert!(w[1].1 > w[0].1, "p_c fell from {:?} to {:?}", w[0], w[1]);
        }
    }
}

#[test]
#[ignore = "validation run: minutes in release"]
fn isotropic_a_follows_eq69() {
    check_isotropic("isotropic_A", 0.833, 4.20, 0.30);
}

#[test]
#[ignore = "validation run: minutes in release"]
fn isotropic_b_follows_eq69() {
    check_isotropic("isotropic_B", 0.858, 4.22, 0.30);
}

fn check_oedometric(name: &str) {
    let (summary, rows) = run_shipped(name);
    let jam = summary
        .jamming
        .expect("the isotropic phase ends at jamming");
    let oedometric: Vec<&Row> = rows.iter().filter(|r| r.phase == "oedometric").collect();
    let last = oedometric.last().expect("an oedometric phase");
    println!(
        "{name}: jamming phi_0 = {:.4}, z_nr_0 = {:.3}",
        jam.phi, jam.z_nr
    );
    for target in [0.85, 0.87, 0.89, 0.91, 0.93] {
        if let Some(r) = oedometric
            .iter()
            .min_by(|a, b| (a.phi - target).abs().total_cmp(&(b.phi - target).abs()))
        {
            println!(
                "  phi {:.4}: sxx_c {:.4e}  syy_c {:.4e}  p_c {:.4e}  q_c {:.4e}  q/p {:.3}",
                r.phi,
                r.sxx_c,
                r.syy_c,
                r.p_c,
                r.q_c,
                r.q_c / r.p_c
            );
        }
    }
    assert!(last.phi >= 0.93);
    // Paper §5.2: the stress along the loading direction stays larger than across it, and
    // both are of the same order (frictionless soft grains relax the deviator).
    assert!(last.sxx_c > last.syy_c && last.syy_c > 0.0);
    assert!(last.q_c / last.p_c < 0.5, "q/p = {}", last.q_c / last.p_c);
}

#[test]
#[ignore = "validation run: minutes in release"]
fn oedometric_a_loads_the_axis_more_than_the_sides() {
    check_oedometric("oedometric_A");
}

#[test]
#[ignore = "validation run: minutes in release"]
fn oedometric_b_loads_the_axis_more_than_the_sides() {
    check_oedometric("oedometric_B");
}
