//! `sdem calibrate --assembly`: the secant law fitted to reference runs of whole assemblies.
//!
//! The reference here is an SDEM run of the same tiny scenario with a known law, so the
//! expectation is exact: the fit must find that law with zero error (a run is bitwise
//! deterministic), and every other pair must show an error. Bad input is refused with a message
//! that names the problem. Debug build, a few seconds.

mod common;

use std::path::Path;
use std::process::Command;

use sdem::calibration::assembly::{AssemblyCase, AssemblyOptions, Stage};
use sdem::calibration::{CalibrationError, run_assembly_calibration};
use sdem::run::{RunOptions, run_scenario};
use sdem::scenario::Scenario;

/// 16 grains compacted fast from a loose gas to phi = 0.88: loaded (p_c > 5e-3 E) over the last
/// few percent of strain.
const TINY: &str = r#"
Scenario(
    name: "tiny_assembly",
    seed: 4,
    sample: (count: 16, box_width: 0.13, box_height: 0.13,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.3, density: 1.0),
    model: Full,
    contact: (a: 0.58, b: 2.0, resolution_deg: 4.0, damping: 1.0),
    time_step: FractionOfCritical(0.4),
    loading: [
        Isotropic(rate: Constant(0.1), until: PackingFraction(0.88)),
    ],
    output: (every: 10),
)
"#;

fn tmp_dir(name: &str) -> common::TempDir {
    common::temp_dir("assembly", name)
}

fn tiny(a: f64, b: f64) -> Scenario {
    let mut s = Scenario::parse(TINY, "tiny.ron").unwrap();
    s.contact.a = a;
    s.contact.b = b;
    s.validate().unwrap();
    s
}

/// Runs the tiny scenario with the law (a, b) into `dir`: the synthetic reference.
fn reference_run(dir: &Path, a: f64, b: f64) {
    let options = RunOptions {
        out_dir: dir.to_path_buf(),
        ..Default::default()
    };
    run_scenario(&tiny(a, b), &options).unwrap();
}

#[test]
fn the_fit_recovers_the_law_of_the_reference_exactly() {
    // Expectation: the reference is SDEM itself with a = 0.75, b = 3 (on the grid); that pair
    // reproduces it bit for bit (error 0), the scenario's own law (0.58, 2) does not, and the
    // refinement cannot beat zero.
    let dir = tmp_dir("recover");
    reference_run(&dir.join("reference"), 0.75, 3.0);
    let case = AssemblyCase::new("tiny", tiny(0.58, 2.0), &dir.join("reference")).unwrap();
    let mut options = AssemblyOptions::new(vec![case], dir.join("fit"));
    options.a_values = vec![0.58, 0.75];
    options.b_values = vec![2.0, 3.0];
    options.refine_evaluations = 3;
    let report = run_assembly_calibration(&options).unwrap();
    let best = report.best().unwrap();
    assert_eq!((best.a, best.b), (0.75, 3.0), "{report}");
    let error = best.cases[0].as_ref().unwrap();
    assert!(
        error.points >= 3,
        "too few loaded points to test: {error:?}"
    );
    assert_eq!(error.rms, 0.0);
    let own = report
        .evaluations
        .iter()
        .find(|e| (e.a, e.b) == (0.58, 2.0))
        .unwrap();
    assert_eq!(
        own.stage,
        Stage::Grid,
        "the scenario's law is on the grid: run once"
    );
    assert!(own.pooled_rms() > 0.01, "{report}");
    assert_eq!(
        report
            .evaluations
            .iter()
            .filter(|e| e.stage == Stage::Refine)
            .count(),
        3
    );
    let csv = std::fs::read_to_string(dir.join("fit/assembly_fit.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + report.evaluations.len());
    let text = std::fs::read_to_string(dir.join("fit/assembly_fit.txt")).unwrap();
    assert!(text.ends_with("a = 0.75\nb = 3\n"), "{text}");
    assert!(dir.join("fit/runs/tiny_a0.75_b3/macro.csv").exists());
}

#[test]
fn bad_input_is_refused_with_a_message() {
    let dir = tmp_dir("bad");
    reference_run(&dir.join("reference"), 0.58, 2.0);
    let case = || AssemblyCase::new("tiny", tiny(0.58, 2.0), &dir.join("reference")).unwrap();

    // A pair outside the law's domain.
    let mut options = AssemblyOptions::new(vec![case()], dir.join("fit"));
    options.b_values = vec![0.0, 2.0];
    let e = run_assembly_calibration(&options).unwrap_err();
    assert!(
        matches!(e, CalibrationError::BadInput(_)) && e.to_string().contains("b = 0"),
        "{e}"
    );

    // A reference from another box: its first row is far from the scenario's box.
    let mut other = case();
    other.scenario.sample.box_width *= 1.5;
    let e =
        run_assembly_calibration(&AssemblyOptions::new(vec![other], dir.join("fit"))).unwrap_err();
    assert!(
        e.to_string().contains("must start from the scenario's box"),
        "{e}"
    );

    // A reference that never loads.
    let mut unloaded = case();
    for r in &mut unloaded.reference {
        r.p_c = 1e-4;
    }
    let e = run_assembly_calibration(&AssemblyOptions::new(vec![unloaded], dir.join("fit")))
        .unwrap_err();
    assert!(e.to_string().contains("nothing to fit"), "{e}");

    // Two cases with one label would share their run directories.
    let e = run_assembly_calibration(&AssemblyOptions::new(vec![case(), case()], dir.join("fit")))
        .unwrap_err();
    assert!(e.to_string().contains("two cases are labelled tiny"), "{e}");

    // A missing reference file names the path.
    let e = AssemblyCase::new("tiny", tiny(0.58, 2.0), &dir.join("nowhere")).unwrap_err();
    assert!(e.to_string().contains("nowhere"), "{e}");

    // On the command line: a scenario without its reference.
    std::fs::write(dir.join("tiny.ron"), TINY).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_sdem"))
        .args(["calibrate", "--assembly"])
        .arg(dir.join("tiny.ron"))
        .args(["--reference"])
        .arg(dir.join("reference"))
        .args(["--assembly"])
        .arg(dir.join("tiny.ron"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("2 --assembly scenarios but 1 --reference runs"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
}
