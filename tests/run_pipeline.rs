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
        "step", "time", "phi", "sxx_c", "syy_c", "p_c", "q_c", "z", "z_nr", "z_nr3",
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

/// A dilute sample compressed by 20% with and without `affine: true`.
fn dilute_compression(affine: bool) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    let text = format!(
        r#"
Scenario(
    name: "dilute",
    sample: (count: 10, box_width: 1.0, box_height: 1.0,
             radii: Gaussian(mean: 0.01, std_dev: 0.001, min: 0.008, max: 0.012)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    loading: [ Isotropic(rate: Constant(0.05), until: Strain(0.2), affine: {affine}) ],
    output: (every: 1000),
)
"#
    );
    let scenario = Scenario::parse(&text, "dilute.ron").unwrap();
    let start = sdem::run::build_world(&scenario).unwrap();
    let before: Vec<[f64; 2]> = start
        .grains()
        .iter()
        .map(|g| [g.center.x, g.center.y])
        .collect();
    // The expectation needs a gas that never collides: no two grains come within touching
    // distance once the box has shrunk by 20%.
    for (i, a) in start.grains().iter().enumerate() {
        for b in &start.grains()[..i] {
            assert!(0.79 * a.center.distance(b.center) > a.radius + b.radius);
        }
    }
    let out = std::env::temp_dir().join(format!("sdem-affine-{affine}-{}", std::process::id()));
    run_scenario(
        &scenario,
        &RunOptions {
            out_dir: out.clone(),
            progress_seconds: None,
            ..Default::default()
        },
    )
    .unwrap();
    let text = std::fs::read_to_string(out.join("grains.csv")).unwrap();
    let after = text
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<f64> = l.split(',').map(|v| v.parse().unwrap()).collect();
            [f[1], f[2]]
        })
        .collect();
    std::fs::remove_dir_all(&out).ok();
    (before, after)
}

#[test]
fn affine_compression_moves_grains_with_the_box() {
    // Expectation: with no contacts, an affine compression is the homogeneous map of the box
    // onto itself shrunk about its centre: each grain keeps its position relative to the box
    // (x - 0.5) / W; without `affine` the grains stay where they are.
    let (before, after) = dilute_compression(true);
    let (_, still) = dilute_compression(false);
    // The box side after the run, from the grain farthest from the centre (the CSV keeps 13
    // digits, so the ratio is sharpest there).
    let (b, a) = before
        .iter()
        .zip(&after)
        .max_by(|x, y| (x.0[0] - 0.5).abs().total_cmp(&(y.0[0] - 0.5).abs()))
        .unwrap();
    let width = (a[0] - 0.5) / (b[0] - 0.5);
    for (b, a) in before.iter().zip(&after) {
        for axis in 0..2 {
            let predicted = 0.5 + (b[axis] - 0.5) * width;
            assert!((a[axis] - predicted).abs() < 1e-10, "{b:?} -> {a:?}");
        }
    }
    assert!(width < 0.8 + 1e-3 && width > 0.79, "W = {width}");
    // Without it, grains that the walls never reach (within 0.4 - 0.012 of the centre) stay put.
    let mut untouched = 0;
    for (b, s) in before.iter().zip(&still) {
        if (b[0] - 0.5).abs().max((b[1] - 0.5).abs()) < 0.388 {
            assert!((b[0] - s[0]).abs() < 1e-12 && (b[1] - s[1]).abs() < 1e-12);
            untouched += 1;
        }
    }
    assert!(untouched >= 3, "{untouched}");
}
