//! A small scenario through the whole pipeline: generation, compaction through jamming,
//! macro.csv, summary.txt.

use sdem::run::{RunOptions, run_scenario};
use sdem::scenario::Scenario;

const SMALL: &str = r#"
Scenario(
    name: "small",
    sample: (count: 200, box_width: 0.45, box_height: 0.45,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    loading: [ Isotropic(rate: Constant(5e-3), until: PackingFraction(0.86)) ],
    output: (every: 200),
)
"#;

#[test]
fn small_isotropic_compaction_jams_and_reports() {
    let scenario = Scenario::parse(SMALL, "small.ron").unwrap();
    let warnings = scenario.validate().unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let out = std::env::temp_dir().join(format!("sdem-pipeline-{}", std::process::id()));
    let summary = run_scenario(
        &scenario,
        &RunOptions {
            out_dir: out.clone(),
            progress_seconds: None,
            ..Default::default()
        },
    )
    .unwrap();
    let text = std::fs::read_to_string(out.join("macro.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    for column in [
        "step", "time", "phi", "sxx_c", "syy_c", "p_c", "q_c", "z", "z_nr",
    ] {
        assert!(header.contains(&column), "missing column {column}");
    }
    let phi_col = header.iter().position(|c| *c == "phi").unwrap();
    let phis: Vec<f64> = lines
        .map(|l| l.split(',').nth(phi_col).unwrap().parse().unwrap())
        .collect();
    assert!(phis.len() > 10);
    // Incompressible grains keep their areas, so phi only grows as the box shrinks.
    assert!(phis.windows(2).all(|w| w[1] >= w[0] - 1e-9));
    assert!(*phis.last().unwrap() >= 0.86);
    // Frictionless discs jam at or below random close packing (~0.84). This compaction is fast
    // (inertial number ~0.04 at p_jam, to keep the test short), which jams a small sample
    // dynamically well below it; the quasi-static validation is in tests/validation.rs.
    let jam = summary
        .jamming
        .expect("the sample must jam before phi = 0.86");
    assert!(jam.phi > 0.65 && jam.phi < 0.85, "phi_0 = {}", jam.phi);
    assert!(summary.last.p_c > 1e-3, "p_c = {}", summary.last.p_c);
    assert!(summary.eq69_rms_error.is_some());
    let summary_text = std::fs::read_to_string(out.join("summary.txt")).unwrap();
    assert!(summary_text.contains("phi_0 = "));
    std::fs::remove_dir_all(&out).ok();
}
