//! `sdem run` on meshfree scenarios (issue #12): a small run end to end, and bad input that
//! must end with a clear message and a non-zero exit, never a panic or a NaN in the output.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Four discs in a box, compressed isotropically for a few steps (a few seconds).
const BASE: &str = r#"Scenario(
    name: "meshfree_cli",
    seed: 4,
    sample: (
        count: 4,
        box_width: 0.6,
        box_height: 0.6,
        radii: Uniform(min: 0.09, max: 0.11),
    ),
    material: (young: 1.0, poisson: 0.3, density: 1.0),
    model: Meshfree((boundary_nodes: 16, rayleigh_alpha: 5.0, gap_tolerance: 1e-4)),
    time_step: Fixed(0.02),
    loading: [
        Isotropic(rate: Constant(2.0), until: PackingFraction(0.7)),
    ],
    output: (every: 2, max_steps: 40),
)
"#;

struct Scratch(PathBuf);

impl Scratch {
    fn new(test: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("sdem-meshfree-cli-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }

    fn write(&self, name: &str, text: &str) -> PathBuf {
        let p = self.0.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

fn sdem(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sdem"))
        .args(args)
        .output()
        .expect("running sdem")
}

fn run(scenario: &Path, out: &Path) -> Output {
    sdem(&[
        "run",
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ])
}

fn replaced(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "{from}");
    BASE.replace(from, to)
}

/// Runs a variant that must fail; returns its stderr.
fn failing(test: &str, scenario: &str, files: &[(&str, &str)]) -> String {
    let s = Scratch::new(test);
    for (name, text) in files {
        s.write(name, text);
    }
    let path = s.write("scenario.ron", scenario);
    let out = run(&path, &s.0.join("out"));
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "{test} should fail:\n{stderr}");
    assert!(!stderr.contains("panicked"), "{test} panicked:\n{stderr}");
    stderr
}

/// Runs `scenario` in a fresh folder `test`, which must succeed; its `macro.csv`, `summary.txt`
/// and output folder.
fn succeeding(test: &str, scenario: &str) -> (String, String, Scratch) {
    let s = Scratch::new(test);
    let path = s.write("scenario.ron", scenario);
    let out_dir = s.0.join("out");
    let out = run(&path, &out_dir);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let read = |name: &str| std::fs::read_to_string(out_dir.join(name)).unwrap();
    (read("macro.csv"), read("summary.txt"), s)
}

#[test]
fn a_small_meshfree_run_writes_its_outputs() {
    let (macro_csv, summary, s) = succeeding("run", BASE);
    let out_dir = s.0.join("out");
    let header = macro_csv.lines().next().unwrap();
    for column in [
        "phi",
        "sxx_c",
        "newton_iterations",
        "factorizations",
        "augmentations",
        "max_penetration",
    ] {
        assert!(header.split(',').any(|c| c == column), "{column}: {header}");
    }
    assert!(macro_csv.lines().count() > 5, "{macro_csv}");
    assert!(!macro_csv.contains("NaN") && !macro_csv.contains("inf,"));
    let grains = std::fs::read_to_string(out_dir.join("grains.csv")).unwrap();
    assert_eq!(grains.lines().count(), 5, "{grains}");
    assert!(grains.starts_with("id,x,y,area,"));
    // An implicit solver has no critical step (SDEM's formula would mean nothing here).
    assert!(
        summary.contains("critical_dt = none (implicit solver)"),
        "{summary}"
    );
    // `sdem check` describes the model.
    let path = s.0.join("scenario.ron");
    let check = sdem(&["check", path.to_str().unwrap()]);
    assert!(check.status.success());
    assert!(String::from_utf8_lossy(&check.stdout).contains("meshfree"));
}

#[test]
fn incompressible_grains_are_refused() {
    let e = failing("nu05", &replaced("poisson: 0.3", "poisson: 0.5"), &[]);
    assert!(
        e.contains("material.poisson") && e.contains("below 0.5"),
        "{e}"
    );
}

#[test]
fn a_critical_fraction_time_step_is_refused() {
    let e = failing(
        "dt",
        &replaced("Fixed(0.02)", "FractionOfCritical(0.4)"),
        &[],
    );
    assert!(e.contains("time_step") && e.contains("Fixed(dt)"), "{e}");
}

#[test]
fn too_few_nodes_for_the_supports_is_refused() {
    let e = failing(
        "coarse",
        &replaced("boundary_nodes: 16", "boundary_nodes: 8"),
        &[],
    );
    assert!(
        e.contains("too coarse") && e.contains("20 neighbours"),
        "{e}"
    );
}

const IMPLICIT_MODEL: &str =
    "model: Meshfree((boundary_nodes: 16, rayleigh_alpha: 5.0, gap_tolerance: 1e-4)),";

#[test]
fn an_explicit_meshfree_run_sub_steps_below_its_critical_step() {
    let (macro_csv, summary, _) = succeeding(
        "explicit",
        &replaced(
            IMPLICIT_MODEL,
            "model: Meshfree((boundary_nodes: 16, rayleigh_alpha: 5.0, scheme: CentralDifference, \
             k0: 10.0)),",
        ),
    );
    let line = summary
        .lines()
        .find_map(|l| l.strip_prefix("critical_dt = "))
        .unwrap_or_else(|| panic!("{summary}"));
    let critical: f64 = line.parse().unwrap_or_else(|_| panic!("{line}"));
    // Expectation: every step is cut into sub-steps of at most half the critical step, and
    // no implicit solve happens.
    let header: Vec<&str> = macro_csv.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    for row in macro_csv.lines().skip(1) {
        let r: Vec<&str> = row.split(',').collect();
        let sub_steps: f64 = r[col("sub_steps")].parse().unwrap();
        assert!(0.02 / sub_steps <= 0.5 * critical * (1.0 + 1e-12), "{row}");
        assert_eq!(r[col("newton_iterations")], "0", "{row}");
    }
}

#[test]
fn stiffness_damping_with_the_explicit_scheme_is_refused() {
    let e = failing(
        "explicit_beta",
        &replaced(
            IMPLICIT_MODEL,
            "model: Meshfree((boundary_nodes: 16, scheme: CentralDifference, \
             rayleigh_beta: 0.01)),",
        ),
        &[],
    );
    assert!(
        e.contains("rayleigh_beta") && e.contains("CentralDifference"),
        "{e}"
    );
}

#[test]
fn gravity_pulls_sdem_grains_too() {
    // Expectation: gravity is a body force of both solvers; the same SDEM scenario with
    // gravity (0, -1) ends with its grains lower than without it.
    let sdem_scenario = |gravity: &str| {
        replaced(IMPLICIT_MODEL, &format!("model: Full,{gravity}")).replace(
            "time_step: Fixed(0.02)",
            "time_step: FractionOfCritical(0.4)",
        )
    };
    let mean_height = |test: &str, scenario: &str| {
        let (_, _, s) = succeeding(test, scenario);
        let grains = std::fs::read_to_string(s.0.join("out/grains.csv")).unwrap();
        let ys: Vec<f64> = grains
            .lines()
            .skip(1)
            .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
            .collect();
        ys.iter().sum::<f64>() / ys.len() as f64
    };
    let free = mean_height("gravity-off", &sdem_scenario(""));
    let pulled = mean_height("gravity-on", &sdem_scenario("\n    gravity: (0.0, -1.0),"));
    assert!(
        pulled < free - 1e-3,
        "{pulled} against {free} without gravity"
    );
}

const SHAPES_SAMPLE: &str = "box_width: 0.5,
        box_height: 0.5,
        shapes: File(\"grains.shapes\"),";

fn with_shapes() -> String {
    replaced(
        "count: 4,
        box_width: 0.6,
        box_height: 0.6,
        radii: Uniform(min: 0.09, max: 0.11),",
        SHAPES_SAMPLE,
    )
    // A square's interior takes fewer nodes than a disc's: 24 on the contour give 21 or more.
    .replace("boundary_nodes: 16", "boundary_nodes: 24")
}

#[test]
fn grains_from_a_shape_file_run() {
    let s = Scratch::new("shapes");
    // Two squares side by side, 0.02 apart.
    s.write(
        "grains.shapes",
        "grain a\n0.05 0.05\n0.2 0.05\n0.2 0.2\n0.05 0.2\ngrain b\n0.22 0.05\n0.37 0.05\n0.37 0.2\n0.22 0.2\n",
    );
    let path = s.write("scenario.ron", &with_shapes());
    let out = run(&path, &s.0.join("out"));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let grains = std::fs::read_to_string(s.0.join("out/grains.csv")).unwrap();
    assert_eq!(grains.lines().count(), 3, "{grains}");
}

#[test]
fn a_shape_file_that_does_not_parse_names_file_and_line() {
    let e = failing(
        "badshape",
        &with_shapes(),
        &[("grains.shapes", "grain a\n0.05 0.05\n0.2 zero\n0.2 0.2\n")],
    );
    assert!(e.contains("grains.shapes:3"), "{e}");
}

#[test]
fn a_self_intersecting_contour_is_refused() {
    let e = failing(
        "bowtie",
        &with_shapes(),
        &[(
            "grains.shapes",
            "grain bowtie\n0.05 0.05\n0.2 0.2\n0.2 0.05\n0.05 0.2\n",
        )],
    );
    assert!(e.contains("grains.shapes") && e.contains("bowtie"), "{e}");
}

#[test]
fn a_contour_that_is_not_star_shaped_is_refused() {
    // A C shape: its centroid lies outside the material.
    let e = failing(
        "cshape",
        &with_shapes(),
        &[(
            "grains.shapes",
            "grain c\n0.05 0.05\n0.3 0.05\n0.3 0.08\n0.08 0.08\n0.08 0.27\n0.3 0.27\n0.3 0.3\n0.05 0.3\n",
        )],
    );
    assert!(e.contains("grains.shapes") && e.contains("star"), "{e}");
}

#[test]
fn grains_overlapping_at_the_start_are_refused() {
    let e = failing(
        "overlap",
        &with_shapes(),
        &[(
            "grains.shapes",
            "grain a\n0.05 0.05\n0.2 0.05\n0.2 0.2\n0.05 0.2\ngrain b\n0.15 0.05\n0.3 0.05\n0.3 0.2\n0.15 0.2\n",
        )],
    );
    assert!(e.contains("overlap at the start"), "{e}");
}

#[test]
fn non_convergence_stops_with_a_diagnostic_and_the_last_good_state() {
    // One Newton iteration and one augmentation per solve, no sub-steps: the first step that
    // needs more fails.
    let s = Scratch::new("diverge");
    let path = s.write(
        "scenario.ron",
        &replaced(
            "model: Meshfree((boundary_nodes: 16, rayleigh_alpha: 5.0, gap_tolerance: 1e-4)),",
            "model: Meshfree((boundary_nodes: 16, rayleigh_alpha: 5.0, gap_tolerance: 1e-12, \
             max_newton: 2, max_augmentations: 1, min_sub_step: 1.0)),",
        ),
    );
    let out_dir = s.0.join("out");
    let out = run(&path, &out_dir);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{e}");
    assert!(
        e.contains("converge") && e.contains("last good state"),
        "{e}"
    );
    let last_good = std::fs::read_to_string(out_dir.join("grains_last_good.csv")).unwrap();
    assert_eq!(last_good.lines().count(), 5);
    let macro_csv = std::fs::read_to_string(out_dir.join("macro.csv")).unwrap();
    assert!(!macro_csv.to_lowercase().contains("nan"), "{macro_csv}");
}
