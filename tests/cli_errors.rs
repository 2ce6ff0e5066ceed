//! The command line's handling of bad input: every case exits non-zero with a message that
//! names what is wrong (the field, the value, what is allowed; for malformed RON the
//! `file:line:column`), never with a panic.
//!
//! Each test writes a variant of a small valid scenario ([`BASE`]) to its own temporary folder
//! and runs the real `sdem` binary on it: `sdem check` (validation only) for most cases,
//! `sdem run --out DIR --quiet` for a few that must fail before any simulation starts (at
//! validation, at sample generation, or on the command line). Nothing here runs a simulation:
//! the whole file takes well under a second in a debug build.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A small, short, valid scenario (checked by `base_scenario_is_valid`). Every variant below
/// replaces one exact piece of it, so that it fails for exactly one reason. Should a variant
/// ever run by mistake, it stops after 10 steps of 50 grains.
const BASE: &str = r#"// Base scenario of the CLI error tests: small, short and valid as written.
Scenario(
    name: "cli_errors",
    seed: 1,
    sample: (
        count: 50,
        box_width: 1.0,
        box_height: 1.0,
        radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016),
    ),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    model: Full,
    contact: (a: 0.58, b: 2.0, resolution_deg: 1.0, damping: 1.0),
    deformation: (damping: 1.0, k_alpha: 1e-3, alpha_mass_scale: 1.0),
    time_step: FractionOfCritical(0.2),
    loading: [
        Isotropic(
            rate: QuasiStatic(inertial_number: 1e-3, max: 1e-2, fast: 1e-3, fast_until_phi: 0.78),
            until: Any([PackingFraction(0.95), Steps(10)]),
        ),
    ],
    output: (every: 500, jamming_pressure: 1e-5, max_steps: 10),
)
"#;

const RADII: &str = "radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)";
const LOADING_PHASE: &str = "Isotropic(
            rate: QuasiStatic(inertial_number: 1e-3, max: 1e-2, fast: 1e-3, fast_until_phi: 0.78),
            until: Any([PackingFraction(0.95), Steps(10)]),
        ),";

/// A scratch folder of its own for one test, removed again when the test passes.
struct Scratch(PathBuf);

impl Scratch {
    fn new(test: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("sdem-cli-errors-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("creating the scratch folder");
        Scratch(dir)
    }

    fn write(&self, file: &str, text: &str) -> PathBuf {
        let path = self.0.join(file);
        std::fs::write(&path, text).expect("writing a scenario");
        path
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Runs the real binary (backtraces off, so stderr is what a user normally sees).
fn sdem<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sdem"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env_remove("RUST_BACKTRACE")
        .env_remove("RUST_LIB_BACKTRACE")
        .output()
        .expect("starting the sdem binary")
}

/// Asserts a clean failure (non-zero exit, not a panic, not a signal) and returns stderr.
fn clean_failure(what: &str, out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let code = out.status.code();
    assert!(
        !out.status.success(),
        "{what}: expected a failure, got success\nstdout:\n{}\nstderr:\n{stderr}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(
        code.is_some(),
        "{what}: killed by a signal ({:?})\nstderr:\n{stderr}",
        out.status
    );
    assert_ne!(
        code,
        Some(101),
        "{what}: exit code 101 is a panic\nstderr:\n{stderr}"
    );
    assert!(
        !stderr.contains("panicked"),
        "{what}: panicked\nstderr:\n{stderr}"
    );
    // `error: ...` (or anyhow's default `Error: ...`), one line per failure.
    assert!(
        stderr.to_lowercase().contains("error: "),
        "{what}: no `error: ` line\nstderr:\n{stderr}"
    );
    stderr
}

fn assert_mentions(what: &str, stderr: &str, needles: &[&str]) {
    for needle in needles {
        assert!(
            stderr.contains(needle),
            "{what}: stderr does not mention {needle:?}\nstderr:\n{stderr}"
        );
    }
}

/// `BASE` with the one occurrence of `from` replaced by `to`.
fn variant(from: &str, to: &str) -> String {
    assert_eq!(
        BASE.matches(from).count(),
        1,
        "{from:?} must occur exactly once in BASE"
    );
    BASE.replacen(from, to, 1)
}

/// Writes `text` as a scenario, runs `sdem check` on it, asserts a clean failure that mentions
/// every needle, and returns stderr.
fn check_fails(scratch: &Scratch, what: &str, text: &str, needles: &[&str]) -> String {
    let path = scratch.write("scenario.ron", text);
    let stderr = clean_failure(what, &sdem(&[Path::new("check"), &path]));
    assert_mentions(what, &stderr, needles);
    stderr
}

/// 1-based line and column (in characters) of byte offset `at` in `text`.
fn line_col(text: &str, at: usize) -> (usize, usize) {
    let before = &text[..at];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// `path:line:column` of the first occurrence of `token` in `text`.
fn location(path: &Path, text: &str, token: &str) -> String {
    let at = text.find(token).expect("token in text");
    let (line, column) = line_col(text, at);
    format!("{}:{line}:{column}", path.display())
}

// ---------------------------------------------------------------------------------------------
// Valid input

#[test]
fn every_shipped_scenario_checks_ok() {
    let mut shipped: Vec<_> =
        std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "ron"))
            .collect();
    shipped.sort();
    assert!(shipped.len() >= 5, "scenarios/ holds {shipped:?}");
    for path in shipped {
        let out = sdem(&[Path::new("check"), &path]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "{}: status {:?}\nstderr:\n{stderr}",
            path.display(),
            out.status
        );
        assert!(String::from_utf8_lossy(&out.stdout).contains("valid"));
    }
}

#[test]
fn base_scenario_is_valid() {
    let scratch = Scratch::new("base");
    let path = scratch.write("base.ron", BASE);
    let out = sdem(&[Path::new("check"), &path]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "status {:?}\nstderr:\n{stderr}",
        out.status
    );
}

// ---------------------------------------------------------------------------------------------
// Malformed RON: `file:line:column`, the parser's message and the offending line

#[test]
fn missing_comma_reports_file_line_and_column() {
    let scratch = Scratch::new("missing_comma");
    let text = variant("count: 50,", "count: 50");
    let path = scratch.path("scenario.ron");
    // The parser notices the missing comma at the next token, `box_width` (line 7, column 9).
    let at = location(&path, &text, "box_width");
    assert!(at.ends_with(":7:9"), "{at}");
    let stderr = check_fails(&scratch, "missing comma", &text, &[&at, "comma"]);
    // The offending line is quoted, with a caret under the column.
    assert_mentions("missing comma", &stderr, &["box_width: 1.0,", "^"]);
}

#[test]
fn bad_number_points_at_the_value() {
    let scratch = Scratch::new("bad_number");
    let text = variant("box_width: 1.0,", "box_width: 1.0.0,");
    let path = scratch.path("scenario.ron");
    let at = location(&path, &text, "1.0.0");
    assert!(at.ends_with(":7:20"), "{at}");
    check_fails(&scratch, "1.0.0", &text, &[&at, "float"]);
}

#[test]
fn wrong_type_points_at_the_value() {
    let scratch = Scratch::new("wrong_type");
    let text = variant("poisson: 0.5", "poisson: \"half\"");
    let path = scratch.path("scenario.ron");
    let at = location(&path, &text, "\"half\"");
    check_fails(&scratch, "string for a number", &text, &[&at]);
}

#[test]
fn negative_count_is_a_parse_error_with_position() {
    let scratch = Scratch::new("negative_count");
    let text = variant("count: 50,", "count: -5,");
    let path = scratch.path("scenario.ron");
    // ron points at the digits of the out-of-range integer.
    let at = location(&path, &text, "5,\n        box_width");
    check_fails(&scratch, "count: -5", &text, &[&at, "out of bounds"]);
}

#[test]
fn truncated_file_is_a_parse_error() {
    let scratch = Scratch::new("truncated");
    let cut = BASE.find("    output:").unwrap();
    let text = &BASE[..cut];
    let path = scratch.path("scenario.ron");
    check_fails(
        &scratch,
        "truncated",
        text,
        &[&format!("{}:", path.display()), "end"],
    );
}

#[test]
fn empty_file_is_a_parse_error() {
    let scratch = Scratch::new("empty_file");
    let path = scratch.path("scenario.ron");
    check_fails(
        &scratch,
        "empty file",
        "",
        &[&format!("{}:1:1", path.display()), "Scenario"],
    );
}

#[test]
fn lowercase_nan_is_not_ron() {
    // RON spells NaN `NaN` (and infinity `inf`); `nan` is a parse error at the value.
    let scratch = Scratch::new("lowercase_nan");
    let text = variant("FractionOfCritical(0.2)", "FractionOfCritical(nan)");
    let path = scratch.path("scenario.ron");
    let at = location(&path, &text, "nan)");
    check_fails(&scratch, "nan", &text, &[&at]);
}

// ---------------------------------------------------------------------------------------------
// Unknown fields and variants: the name, where it is, and what is expected instead

#[test]
fn unknown_top_level_field() {
    let scratch = Scratch::new("unknown_top");
    let text = variant("    seed: 1,\n", "    seed: 1,\n    colour: 3,\n");
    let at = location(&scratch.path("scenario.ron"), &text, "colour");
    check_fails(
        &scratch,
        "colour",
        &text,
        &[&at, "`colour`", "`name`", "`loading`", "`output`"],
    );
}

#[test]
fn unknown_nested_field() {
    let scratch = Scratch::new("unknown_nested");
    let text = variant("(damping: 1.0, k_alpha", "(dampnig: 1.0, k_alpha");
    let at = location(&scratch.path("scenario.ron"), &text, "dampnig");
    check_fails(
        &scratch,
        "dampnig",
        &text,
        &[&at, "`dampnig`", "`damping`", "`k_alpha`"],
    );
}

#[test]
fn unknown_field_in_a_loading_phase() {
    let scratch = Scratch::new("unknown_phase_field");
    let text = variant(
        "Steps(10)]),\n",
        "Steps(10)]),\n            max_steps: 100,\n",
    );
    let at = location(&scratch.path("scenario.ron"), &text, "max_steps: 100");
    check_fails(
        &scratch,
        "max_steps in a phase",
        &text,
        &[&at, "`max_steps`", "`rate`", "`until`"],
    );
}

#[test]
fn unknown_field_in_a_strain_rate() {
    let scratch = Scratch::new("unknown_rate_field");
    let text = variant(
        "fast_until_phi: 0.78)",
        "fast_until_phi: 0.78, fast_untill: 0.8)",
    );
    let at = location(&scratch.path("scenario.ron"), &text, "fast_untill");
    check_fails(
        &scratch,
        "fast_untill",
        &text,
        &[&at, "`fast_untill`", "`fast_until_phi`"],
    );
}

#[test]
fn unknown_field_in_the_radius_distribution() {
    let scratch = Scratch::new("unknown_radii_field");
    let text = variant("Gaussian(mean", "Gaussian(sigma: 0.1, mean");
    let at = location(&scratch.path("scenario.ron"), &text, "sigma");
    check_fails(&scratch, "sigma", &text, &[&at, "`sigma`", "`std_dev`"]);
}

#[test]
fn missing_field() {
    let scratch = Scratch::new("missing_field");
    let text = variant(", density: 1.0)", ")");
    check_fails(&scratch, "no density", &text, &["`density`", "Material"]);
}

#[test]
fn unknown_variants() {
    let scratch = Scratch::new("unknown_variants");
    for (from, to, needles) in [
        ("Full,", "Ful,", &["`Ful`", "`Full`", "`Rigid`"][..]),
        (
            "Isotropic(",
            "Isotropc(",
            &["`Isotropc`", "`Isotropic`", "`Servo`"],
        ),
        (
            "QuasiStatic(",
            "QuasiStatc(",
            &["`QuasiStatc`", "`QuasiStatic`", "`Constant`"],
        ),
        (
            "Gaussian(",
            "Gauss(",
            &["`Gauss`", "`Gaussian`", "`Fractal`"],
        ),
    ] {
        let text = variant(from, to);
        let at = location(&scratch.path("scenario.ron"), &text, to);
        let mut all = vec![at.as_str()];
        all.extend_from_slice(needles);
        check_fails(&scratch, to, &text, &all);
    }
}

// ---------------------------------------------------------------------------------------------
// Material

#[test]
fn poisson_outside_zero_to_half() {
    let scratch = Scratch::new("poisson");
    for (value, shown) in [("0.7", "0.7"), ("-0.1", "-0.1"), ("0.5000001", "0.5000001")] {
        let text = variant("poisson: 0.5", &format!("poisson: {value}"));
        check_fails(
            &scratch,
            value,
            &text,
            &["material.poisson", &format!("= {shown}"), "[0, 0.5]"],
        );
    }
}

#[test]
fn non_positive_young_modulus() {
    let scratch = Scratch::new("young");
    for (value, shown) in [("0.0", "0"), ("-1", "-1"), ("-2.5e3", "-2500")] {
        let text = variant("young: 1.0", &format!("young: {value}"));
        check_fails(
            &scratch,
            value,
            &text,
            &["material.young", &format!("= {shown}"), "> 0"],
        );
    }
}

#[test]
fn deformation_mass_scale_below_one() {
    let scratch = Scratch::new("mass_scale");
    for (value, shown) in [("0.5", "0.5"), ("0.0", "0"), ("-4.0", "-4")] {
        let text = variant(
            "alpha_mass_scale: 1.0)",
            &format!("alpha_mass_scale: 1.0, mass_scale: {value})"),
        );
        check_fails(
            &scratch,
            value,
            &text,
            &["deformation.mass_scale", &format!("= {shown}"), ">= 1"],
        );
    }
}

#[test]
fn a_deformation_mass_scale_is_checked_and_warned_about() {
    let scratch = Scratch::new("mass_scale_warning");
    let path = scratch.write(
        "scenario.ron",
        &variant(
            "alpha_mass_scale: 1.0)",
            "alpha_mass_scale: 1.0, mass_scale: 4.0)",
        ),
    );
    let out = sdem(&[Path::new("check"), &path]);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{stderr}");
    assert_mentions(
        "warning",
        &stderr,
        &["deformation.mass_scale = 4", "2.00 times", "quasi-static"],
    );
    assert!(stdout.contains("M_eps and M_alpha x 4"), "{stdout}");
    // The base scenario's time step, 0.2 of the critical estimate, grows by sqrt(5 / 2).
    let base = scratch.write("base.ron", BASE);
    let base_out = sdem(&[Path::new("check"), &base]);
    let step = |text: &str| -> f64 {
        let line = text
            .lines()
            .find(|l| l.starts_with("time step:"))
            .unwrap_or_else(|| panic!("{text}"));
        line["time step:".len()..].trim().parse().unwrap()
    };
    let gain = step(&stdout) / step(&String::from_utf8_lossy(&base_out.stdout));
    assert!((gain - 2.5_f64.sqrt()).abs() < 1e-3, "gain {gain}");
}

#[test]
fn non_positive_density() {
    let scratch = Scratch::new("density");
    for (value, shown) in [("0.0", "0"), ("-2.0", "-2")] {
        let text = variant("density: 1.0", &format!("density: {value}"));
        check_fails(
            &scratch,
            value,
            &text,
            &["material.density", &format!("= {shown}"), "> 0"],
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Sample

#[test]
fn non_positive_radii() {
    let scratch = Scratch::new("radii");
    for (radii, needles) in [
        (
            "radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: -0.008, max: 0.016)",
            &["sample.radii.min", "-0.008", "> 0"][..],
        ),
        (
            "radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.0)",
            &["sample.radii.max", "0", "> 0"],
        ),
        (
            "radii: Gaussian(mean: -0.012, std_dev: 0.0024, min: 0.008, max: 0.016)",
            &["sample.radii.mean", "-0.012"],
        ),
        (
            "radii: Gaussian(mean: 0.012, std_dev: -0.0024, min: 0.008, max: 0.016)",
            &["sample.radii.std_dev", "-0.0024", ">= 0"],
        ),
        (
            "radii: Monodisperse(radius: 0.0)",
            &["sample.radii.radius", "0", "> 0"],
        ),
        (
            "radii: Uniform(min: -0.01, max: 0.02)",
            &["sample.radii.min", "-0.01"],
        ),
        (
            "radii: Fractal(dimension: 0.0, min: 0.004, max: 0.038)",
            &["sample.radii.dimension", "0", "> 0"],
        ),
    ] {
        let text = variant(RADII, radii);
        check_fails(&scratch, radii, &text, needles);
    }
}

#[test]
fn radius_interval_is_empty() {
    let scratch = Scratch::new("empty_interval");
    let text = variant(RADII, "radii: Uniform(min: 0.02, max: 0.01)");
    check_fails(
        &scratch,
        "min > max",
        &text,
        &["sample.radii.min", "0.02", "sample.radii.max", "0.01"],
    );
}

#[test]
fn truncation_interval_holds_no_radius() {
    let scratch = Scratch::new("truncation");
    // N(0.012, 0.0024) has practically no probability on [0.1, 0.2].
    let text = variant(
        RADII,
        "radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.1, max: 0.2)",
    );
    check_fails(
        &scratch,
        "empty truncation",
        &text,
        &[
            "sample.radii",
            "mean = 0.012",
            "std_dev = 0.0024",
            "[0.1, 0.2]",
            "probability",
        ],
    );
    // Zero spread: every radius is the mean, which lies outside [min, max].
    let text = variant(
        RADII,
        "radii: Gaussian(mean: 0.02, std_dev: 0.0, min: 0.008, max: 0.016)",
    );
    check_fails(
        &scratch,
        "std_dev 0 outside",
        &text,
        &["sample.radii", "mean = 0.02", "[0.008, 0.016]"],
    );
}

#[test]
fn more_grains_than_fit_in_the_box() {
    let scratch = Scratch::new("too_many");
    let text = variant("count: 50,", "count: 100000,");
    check_fails(
        &scratch,
        "100000 grains",
        &text,
        &["sample.count", "100000", "0.55", "sample.box_width"],
    );
}

#[test]
fn count_above_the_hard_limit() {
    let scratch = Scratch::new("count_limit");
    let text = variant("count: 50,", "count: 1000000000,");
    check_fails(
        &scratch,
        "1e9 grains",
        &text,
        &["sample.count", "1000000000", "too large"],
    );
}

#[test]
fn grain_larger_than_the_box() {
    let scratch = Scratch::new("grain_too_large");
    let text = variant(RADII, "radii: Monodisperse(radius: 0.6)");
    check_fails(
        &scratch,
        "radius 0.6 in a unit box",
        &text,
        &["0.6", "1.2", "sample.box_width", "sample.radii.max"],
    );
}

#[test]
fn zero_grains() {
    let scratch = Scratch::new("zero_grains");
    let text = variant("count: 50,", "count: 0,");
    check_fails(
        &scratch,
        "count 0",
        &text,
        &["sample.count", "0", "at least 1"],
    );
}

#[test]
fn non_positive_box() {
    let scratch = Scratch::new("box");
    let text = variant("box_height: 1.0", "box_height: 0.0");
    check_fails(
        &scratch,
        "box_height 0",
        &text,
        &["sample.box_height", "0", "> 0"],
    );
}

// ---------------------------------------------------------------------------------------------
// Time step

#[test]
fn time_step_zero_negative_nan_or_infinite() {
    let scratch = Scratch::new("time_step");
    for (step, field, shown) in [
        ("Fixed(0.0)", "time_step.Fixed", "= 0:"),
        ("Fixed(-1e-5)", "time_step.Fixed", "= -0.00001"),
        ("Fixed(NaN)", "time_step.Fixed", "= NaN"),
        ("Fixed(-NaN)", "time_step.Fixed", "= NaN"),
        ("Fixed(inf)", "time_step.Fixed", "= inf"),
        ("Fixed(1e999)", "time_step.Fixed", "= inf"),
        (
            "FractionOfCritical(0.0)",
            "time_step.FractionOfCritical",
            "= 0:",
        ),
        (
            "FractionOfCritical(-0.2)",
            "time_step.FractionOfCritical",
            "= -0.2",
        ),
        (
            "FractionOfCritical(NaN)",
            "time_step.FractionOfCritical",
            "= NaN",
        ),
        (
            "FractionOfCritical(-inf)",
            "time_step.FractionOfCritical",
            "= -inf",
        ),
    ] {
        let text = variant("FractionOfCritical(0.2)", step);
        check_fails(&scratch, step, &text, &[field, shown, "> 0"]);
    }
}

#[test]
fn time_step_that_comes_out_zero() {
    // Every field is legal, but the critical estimate for radius 1e-200 underflows to 0.
    let scratch = Scratch::new("time_step_underflow");
    let text = variant(RADII, "radii: Monodisperse(radius: 1e-200)");
    check_fails(
        &scratch,
        "radius 1e-200",
        &text,
        &["time_step", "FractionOfCritical(0.2)", "critical", "1e-200"],
    );
}

// ---------------------------------------------------------------------------------------------
// NaN and infinity anywhere: caught by validation, with the field's name

#[test]
fn non_finite_numbers_name_their_field() {
    let scratch = Scratch::new("non_finite");
    // (field in the message, text in BASE, the same text with X for the bad value)
    let cases = [
        ("sample.box_width", "box_width: 1.0", "box_width: X"),
        ("sample.box_height", "box_height: 1.0", "box_height: X"),
        ("sample.radii.mean", "mean: 0.012", "mean: X"),
        ("sample.radii.std_dev", "std_dev: 0.0024", "std_dev: X"),
        ("sample.radii.min", "min: 0.008", "min: X"),
        ("sample.radii.max", "max: 0.016", "max: X"),
        ("material.young", "young: 1.0", "young: X"),
        ("material.poisson", "poisson: 0.5", "poisson: X"),
        ("material.density", "density: 1.0", "density: X"),
        ("contact.a", "(a: 0.58", "(a: X"),
        ("contact.b", "b: 2.0", "b: X"),
        (
            "contact.resolution_deg",
            "resolution_deg: 1.0",
            "resolution_deg: X",
        ),
        ("contact.damping", "1.0, damping: 1.0)", "1.0, damping: X)"),
        ("deformation.damping", "(damping: 1.0", "(damping: X"),
        ("deformation.k_alpha", "k_alpha: 1e-3", "k_alpha: X"),
        (
            "deformation.alpha_mass_scale",
            "alpha_mass_scale: 1.0",
            "alpha_mass_scale: X",
        ),
        (
            "deformation.mass_scale",
            "alpha_mass_scale: 1.0)",
            "alpha_mass_scale: 1.0, mass_scale: X)",
        ),
        (
            "time_step.FractionOfCritical",
            "FractionOfCritical(0.2)",
            "FractionOfCritical(X)",
        ),
        (
            "loading[0].rate.inertial_number",
            "inertial_number: 1e-3",
            "inertial_number: X",
        ),
        ("loading[0].rate.max", "max: 1e-2", "max: X"),
        ("loading[0].rate.fast", "fast: 1e-3", "fast: X"),
        (
            "loading[0].rate.fast_until_phi",
            "fast_until_phi: 0.78",
            "fast_until_phi: X",
        ),
        (
            "loading[0].until[0]",
            "PackingFraction(0.95)",
            "PackingFraction(X)",
        ),
        (
            "output.jamming_pressure",
            "jamming_pressure: 1e-5",
            "jamming_pressure: X",
        ),
        // Pieces that BASE does not use: other variants of the same types.
        ("time_step.Fixed", "FractionOfCritical(0.2)", "Fixed(X)"),
        (
            "loading[0].rate",
            "QuasiStatic(inertial_number: 1e-3, max: 1e-2, fast: 1e-3, fast_until_phi: 0.78)",
            "Constant(X)",
        ),
        (
            "loading[0].until[0]",
            "PackingFraction(0.95)",
            "MeanStress(X)",
        ),
        ("loading[0].until[0]", "PackingFraction(0.95)", "Time(X)"),
        ("loading[0].until[0]", "PackingFraction(0.95)", "Strain(X)"),
        (
            "sample.radii.radius",
            RADII,
            "radii: Monodisperse(radius: X)",
        ),
        (
            "sample.radii.dimension",
            RADII,
            "radii: Fractal(dimension: X, min: 0.004, max: 0.038)",
        ),
        (
            "sample.radii.min",
            RADII,
            "radii: Uniform(min: X, max: 0.02)",
        ),
        (
            "loading[0].sxx",
            LOADING_PHASE,
            "Servo(sxx: X, syy: 1e-4, gain: 1.0, max_rate: 1e-2, until: Steps(10)),",
        ),
        (
            "loading[0].syy",
            LOADING_PHASE,
            "Servo(sxx: 1e-4, syy: X, gain: 1.0, max_rate: 1e-2, until: Steps(10)),",
        ),
        (
            "loading[0].gain",
            LOADING_PHASE,
            "Servo(sxx: 1e-4, syy: 1e-4, gain: X, max_rate: 1e-2, until: Steps(10)),",
        ),
        (
            "loading[0].max_rate",
            LOADING_PHASE,
            "Servo(sxx: 1e-4, syy: 1e-4, gain: 1.0, max_rate: X, until: Steps(10)),",
        ),
        ("loading[0].until", LOADING_PHASE, "Relax(until: Time(X)),"),
    ];
    for (field, from, to) in cases {
        for (bad, shown) in [("NaN", "NaN"), ("inf", "inf"), ("-inf", "-inf")] {
            let text = variant(from, &to.replace('X', bad));
            let what = format!("{field} = {bad}");
            check_fails(&scratch, &what, &text, &[field, shown]);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Loading program and output

#[test]
fn empty_loading_program() {
    let scratch = Scratch::new("empty_loading");
    let start = BASE.find("    loading: [").unwrap();
    let end = BASE.find("    output:").unwrap();
    let text = format!("{}    loading: [],\n{}", &BASE[..start], &BASE[end..]);
    check_fails(
        &scratch,
        "loading: []",
        &text,
        &["loading", "at least one phase"],
    );
}

#[test]
fn empty_any_condition() {
    let scratch = Scratch::new("empty_any");
    let text = variant(
        "Any([PackingFraction(0.95), Steps(10)])",
        "Any([PackingFraction(0.95), Any([])])",
    );
    check_fails(
        &scratch,
        "Any([])",
        &text,
        &["loading[0].until[1]", "Any([])"],
    );
}

#[test]
fn packing_fraction_target_out_of_range() {
    let scratch = Scratch::new("phi_target");
    let text = variant("PackingFraction(0.95)", "PackingFraction(1.2)");
    check_fails(
        &scratch,
        "phi 1.2",
        &text,
        &["loading[0].until[0]", "1.2", "(0, 1)"],
    );
}

#[test]
fn output_every_zero() {
    let scratch = Scratch::new("every_zero");
    let text = variant("every: 500", "every: 0");
    check_fails(
        &scratch,
        "every 0",
        &text,
        &["output.every", "0", "at least 1"],
    );
}

#[test]
fn unusable_name() {
    let scratch = Scratch::new("name");
    for name in ["", "../../elsewhere", "/tmp/x"] {
        let text = variant("\"cli_errors\"", &format!("{name:?}"));
        check_fails(&scratch, name, &text, &["`name`", &format!("{name:?}")]);
    }
}

// ---------------------------------------------------------------------------------------------
// Files and command line

#[test]
fn missing_scenario_file() {
    let scratch = Scratch::new("missing_file");
    let path = scratch.path("no_such_scenario.ron");
    let reason = std::fs::read_to_string(&path).unwrap_err().to_string();
    let stderr = clean_failure("check missing", &sdem(&[Path::new("check"), &path]));
    let shown = path.display().to_string();
    assert_mentions(
        "check missing",
        &stderr,
        &["cannot read scenario", &shown, &reason],
    );
    // The reason is printed once, not repeated.
    assert_eq!(stderr.matches(&reason).count(), 1, "{stderr}");

    let out = scratch.path("out");
    let stderr = clean_failure(
        "run missing",
        &sdem(&[
            Path::new("run"),
            &path,
            Path::new("--out"),
            &out,
            Path::new("--quiet"),
        ]),
    );
    assert_mentions(
        "run missing",
        &stderr,
        &["cannot read scenario", &shown, &reason],
    );
    assert!(!out.exists(), "no output for a missing scenario");
}

#[test]
fn directory_as_scenario_file() {
    let scratch = Scratch::new("directory");
    let shown = scratch.0.display().to_string();
    let stderr = clean_failure("check DIR", &sdem(&[Path::new("check"), &scratch.0]));
    assert_mentions("check DIR", &stderr, &["cannot read scenario", &shown]);
}

#[test]
fn run_rejects_an_invalid_scenario_before_writing_anything() {
    let scratch = Scratch::new("run_invalid");
    let path = scratch.write("scenario.ron", &variant("poisson: 0.5", "poisson: 0.7"));
    let out = scratch.path("out");
    let stderr = clean_failure(
        "run poisson 0.7",
        &sdem(&[
            Path::new("run"),
            &path,
            Path::new("--out"),
            &out,
            Path::new("--quiet"),
        ]),
    );
    assert_mentions(
        "run poisson 0.7",
        &stderr,
        &["material.poisson", "0.7", "[0, 0.5]"],
    );
    assert!(!out.exists(), "output written for an invalid scenario");
}

#[test]
fn run_reports_a_sample_that_cannot_be_placed() {
    // 200 equal discs covering 0.549 of the box pass validation (limit 0.55) but random
    // sequential addition jams near 0.547: generation fails within its attempt budget.
    let scratch = Scratch::new("run_placement");
    let radius = (0.549 / (200.0 * std::f64::consts::PI)).sqrt();
    let text = variant("count: 50,", "count: 200,");
    let text = text.replacen(RADII, &format!("radii: Monodisperse(radius: {radius})"), 1);
    let path = scratch.write("scenario.ron", &text);
    let check = sdem(&[Path::new("check"), &path]);
    assert!(
        check.status.success(),
        "the placement case must pass validation: {}",
        String::from_utf8_lossy(&check.stderr)
    );
    let out = scratch.path("out");
    let stderr = clean_failure(
        "run crowded",
        &sdem(&[
            Path::new("run"),
            &path,
            Path::new("--out"),
            &out,
            Path::new("--quiet"),
        ]),
    );
    assert_mentions(
        "run crowded",
        &stderr,
        &["of 200 grains", "sample.count", "sample.box_width"],
    );
}

#[test]
fn zero_threads() {
    let scratch = Scratch::new("threads");
    let path = scratch.write("scenario.ron", BASE);
    let out = scratch.path("out");
    let stderr = clean_failure(
        "--threads 0",
        &sdem(&[
            Path::new("run"),
            &path,
            Path::new("--out"),
            &out,
            Path::new("--threads"),
            Path::new("0"),
            Path::new("--quiet"),
        ]),
    );
    assert_mentions("--threads 0", &stderr, &["--threads", "at least 1"]);
}

#[test]
fn bad_command_line_is_a_usage_error() {
    // clap's usage errors exit with 2.
    for args in [
        &["frobnicate"][..],
        &["run"],
        &["run", "scenarios/isotropic_A.ron", "--threads", "-1"],
        &["run", "scenarios/isotropic_A.ron", "--threads", "many"],
    ] {
        let out = sdem(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}\nstderr:\n{stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}\nstderr:\n{stderr}");
    }
}

// ---------------------------------------------------------------------------------------------
// Samples read from a file (`sample: (.., file: "g.csv")`): every problem names the file, the
// line, the column or value, and what is allowed

/// `BASE` with its sample read from `g.csv` (next to the scenario) instead of generated.
fn file_variant() -> String {
    variant("count: 50,\n", "").replacen(RADII, "file: \"g.csv\"", 1)
}

/// Writes `grains` as g.csv and `text` as the scenario, runs `sdem check`.
fn check_with_grains(scratch: &Scratch, text: &str, grains: &str) -> Output {
    scratch.write("g.csv", grains);
    let path = scratch.write("scenario.ron", text);
    sdem(&[Path::new("check"), &path])
}

fn sample_file_fails(scratch: &Scratch, text: &str, grains: &str, needles: &[&str]) -> String {
    let what = format!("g.csv = {grains:?}");
    let stderr = clean_failure(&what, &check_with_grains(scratch, text, grains));
    assert_mentions(&what, &stderr, needles);
    stderr
}

#[test]
fn sample_file_is_read_relative_to_the_scenario() {
    let scratch = Scratch::new("sample_file_ok");
    // Headerless x,y,radius; a header with optional columns; sdem's own grains.csv columns.
    for grains in [
        "0.3,0.3,0.02\n0.6,0.6,0.01\n",
        "# two grains\nx,y,radius,theta\n0.3,0.3,0.02,0.5\n\n0.6,0.6,0.01,0\n",
        "id,x,y,radius,theta,eps1,eps2,alpha,stress_xx,stress_yy,stress_xy,mean_stress_c,contacts\n\
         0,0.3,0.3,0.02,0,0.01,-0.01,0.3,0,0,0,0,0\n1,0.6,0.6,0.01,0,0,0,0,0,0,0,0,0\n",
    ] {
        let out = check_with_grains(&scratch, &file_variant(), grains);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{grains:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(stdout.contains("sample: 2 grains from"), "{stdout}");
        // The smallest radius of the file sets the critical time step.
        assert!(stdout.contains("1.0000e-2"), "{stdout}");
    }
    // Run from another working directory: the file is found next to the scenario.
    let path = scratch.path("scenario.ron");
    let out = scratch.path("out");
    let run = sdem(&[
        Path::new("run"),
        &path,
        Path::new("--out"),
        &out,
        Path::new("--quiet"),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(out.join("grains.csv").exists());
}

#[test]
fn sample_file_missing_or_empty() {
    let scratch = Scratch::new("sample_file_missing");
    let path = scratch.write("scenario.ron", &file_variant());
    let stderr = clean_failure("no g.csv", &sdem(&[Path::new("check"), &path]));
    assert_mentions(
        "no g.csv",
        &stderr,
        &["cannot read the sample file", "g.csv"],
    );
    sample_file_fails(
        &scratch,
        &file_variant(),
        "x,y,radius\n# nothing\n",
        &["g.csv", "no grains", "at least one grain"],
    );
}

#[test]
fn sample_file_bad_lines() {
    let scratch = Scratch::new("sample_file_lines");
    let text = file_variant();
    for (grains, needles) in [
        (
            "x,y,radius\n0.5,0.5,0.01\n0.5,0.2,abc\n",
            &["g.csv:3", "`radius`", "\"abc\"", "not a number"][..],
        ),
        (
            "x,y\n0.5,0.5\n",
            &["g.csv:1", "no `radius` column", "theta"],
        ),
        (
            "x,y,radius,colour\n0.5,0.5,0.01,3\n",
            &["g.csv:1", "unknown column `colour`", "eps1"],
        ),
        (
            "x,y,radius\n0.5,0.5\n",
            &["g.csv:2", "2 fields, expected 3"],
        ),
        ("0.5,0.5\n", &["g.csv:1", "2 fields", "x,y,radius"]),
        ("x,y,x,radius\n", &["g.csv:1", "`x` appears twice"]),
        (
            "0.5,abc,0.01\n",
            &["g.csv:1", "neither a header", "nor a grain"],
        ),
        (
            "x,y,radius\n0.5,0.5,inf\n",
            &["g.csv:2", "`radius` = inf", "finite"],
        ),
        ("0.5,NaN,0.01\n", &["g.csv:1", "`y` = NaN", "finite"]),
        ("0.5,0.5,-0.01\n", &["g.csv:1", "`radius` = -0.01", "> 0"]),
        ("0.5,0.5,0\n", &["g.csv:1", "`radius` = 0", "> 0"]),
        (
            "x,y,radius,eps2\n0.5,0.5,0.01,-1\n",
            &["g.csv:2", "`eps2` = -1", "> -1"],
        ),
    ] {
        sample_file_fails(&scratch, &text, grains, needles);
    }
}

#[test]
fn sample_file_grain_outside_the_box() {
    let scratch = Scratch::new("sample_file_box");
    let text = file_variant();
    // Centre beyond the right wall; centre on the bottom wall.
    sample_file_fails(
        &scratch,
        &text,
        "x,y,radius\n0.5,0.5,0.01\n1.2,0.5,0.01\n",
        &["g.csv:3", "(1.2, 0.5)", "outside the box [0, 1] x [0, 1]"],
    );
    sample_file_fails(
        &scratch,
        &text,
        "0.5,0,0.01\n",
        &["g.csv:1", "outside the box"],
    );
    // sample.origin moves the box: the same grain is now outside it.
    let moved = text.replacen("box_width: 1.0,", "box_width: 1.0, origin: (0.6, 0.0),", 1);
    sample_file_fails(
        &scratch,
        &moved,
        "0.5,0.5,0.01\n",
        &["g.csv:1", "outside the box [0.6, 1.6] x [0, 1]"],
    );
    // A contour that crosses a wall more than the contact law allows (a strict domain floor).
    let strict = text.replacen("damping: 1.0)", "damping: 1.0, domain_floor: 0.5)", 1);
    assert_ne!(strict, text);
    sample_file_fails(
        &scratch,
        &strict,
        "x,y,radius\n0.005,0.5,0.02\n",
        &[
            "g.csv:2",
            "crosses the left wall x = 0",
            "domain of the contact law",
        ],
    );
    // With the default law the same shallow crossing is a contact a compacted state may have.
    let out = check_with_grains(&scratch, &text, "x,y,radius\n0.005,0.5,0.02\n");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn sample_file_overlapping_grains() {
    let scratch = Scratch::new("sample_file_overlap");
    let text = file_variant();
    // Two equal discs whose caps overlap by a quarter radius each: inside the law's domain with
    // the default a = 0.58, b = 2 (a compacted packing has such overlaps) ...
    let pair = "x,y,radius\n0.2,0.2,0.01\n0.5,0.5,0.02\n0.53,0.5,0.02\n";
    let out = check_with_grains(&scratch, &text, pair);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // ... but outside it with b = 5: both lines named.
    let stiff = text.replacen("b: 2.0", "b: 5.0", 1);
    sample_file_fails(
        &scratch,
        &stiff,
        pair,
        &[
            "g.csv:3 and line 4",
            "overlap beyond the domain of the contact law",
        ],
    );
    // A centre inside the other grain, a swallowed grain, a duplicated line.
    for (grains, needles) in [
        (
            "0.5,0.5,0.02\n0.51,0.5,0.02\n",
            &["g.csv:1 and line 2", "a centre lies inside the other grain"][..],
        ),
        (
            "0.5,0.5,0.05\n0.7,0.7,0.01\n0.51,0.5,0.01\n",
            &["g.csv:1 and line 3", "inside the other grain"],
        ),
        (
            "0.5,0.5,0.02\n0.5,0.5,0.02\n",
            &["g.csv:1 and line 2", "duplicated line"],
        ),
    ] {
        sample_file_fails(&scratch, &text, grains, needles);
    }
}

#[test]
fn sample_file_and_generation_fields() {
    let scratch = Scratch::new("sample_file_fields");
    let grains = "0.3,0.3,0.02\n0.6,0.6,0.01\n";
    // radii with a file; a count that differs from the file's.
    let both = variant("count: 50,\n", "").replacen(RADII, &format!("{RADII}, file: \"g.csv\""), 1);
    sample_file_fails(&scratch, &both, grains, &["sample.radii", "sample.file"]);
    let count = variant(RADII, "file: \"g.csv\"");
    sample_file_fails(
        &scratch,
        &count,
        grains,
        &["sample.count", "= 50", "(2)", "g.csv"],
    );
    // Neither a file nor count/radii.
    let neither = variant("count: 50,\n", "").replacen(&format!("{RADII},\n"), "", 1);
    check_fails(
        &scratch,
        "no count",
        &neither,
        &["sample.count", "sample.file"],
    );
    let no_radii = variant(&format!("{RADII},\n"), "");
    check_fails(
        &scratch,
        "no radii",
        &no_radii,
        &["sample.radii", "sample.file"],
    );
    // The Some(..) spelling is accepted too.
    let some = variant("count: 50,\n", "").replacen(RADII, "file: Some(\"g.csv\")", 1);
    let out = check_with_grains(&scratch, &some, grains);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

// ---------------------------------------------------------------------------------------------
// Checkpoint interval in the scenario

#[test]
fn checkpoint_interval_values() {
    let scratch = Scratch::new("checkpoint_interval");
    let with = |c: &str| {
        variant(
            "max_steps: 10)",
            &format!("max_steps: 10, checkpoint: {c})"),
        )
    };
    for ok in [
        "EverySteps(5)",
        "EverySeconds(600.0)",
        "Some(EverySteps(1))",
    ] {
        let path = scratch.write("scenario.ron", &with(ok));
        let out = sdem(&[Path::new("check"), &path]);
        assert!(
            out.status.success(),
            "{ok}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    for (bad, needles) in [
        (
            "EverySteps(0)",
            &["output.checkpoint", "EverySteps(0)", "n >= 1"][..],
        ),
        (
            "EverySeconds(0.0)",
            &["output.checkpoint.EverySeconds", "= 0", "> 0"],
        ),
        (
            "EverySeconds(-5.0)",
            &["output.checkpoint.EverySeconds", "= -5", "> 0"],
        ),
        (
            "EverySeconds(inf)",
            &["output.checkpoint.EverySeconds", "inf"],
        ),
        (
            "EveryMinute(3)",
            &["`EveryMinute`", "`EverySteps`", "`EverySeconds`"],
        ),
    ] {
        check_fails(&scratch, bad, &with(bad), needles);
    }
}

#[test]
fn checkpoint_every_seconds_on_the_command_line() {
    let scratch = Scratch::new("checkpoint_seconds_cli");
    let path = scratch.write("scenario.ron", BASE);
    for (value, needle) in [
        ("0", "> 0"),
        ("-1", "> 0"),
        ("inf", "> 0"),
        ("soon", "soon"),
    ] {
        let out = sdem(&[
            Path::new("run"),
            &path,
            Path::new("--checkpoint-every-seconds"),
            Path::new(value),
            Path::new("--quiet"),
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{value}: {stderr}");
        assert!(
            stderr.contains("--checkpoint-every-seconds") && stderr.contains(needle),
            "{stderr}"
        );
    }
    // Steps and seconds together: one or the other.
    let out = sdem(&[
        Path::new("run"),
        &path,
        Path::new("--checkpoint-every"),
        Path::new("5"),
        Path::new("--checkpoint-every-seconds"),
        Path::new("5"),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot be used with"));
}

// ---------------------------------------------------------------------------------------------
// Stress targets the material cannot reach

const SERVO: &str = "Servo(sxx: 0.01, syy: 0.01, gain: 0.5, max_rate: 1e-2, until: Steps(10)),";

#[test]
fn tensile_or_zero_stress_targets() {
    let scratch = Scratch::new("stress_targets");
    for (phase, needles) in [
        (
            SERVO.replace("sxx: 0.01", "sxx: -0.01"),
            &[
                "loading[0].sxx",
                "= -0.01",
                "compressive stress > 0",
                "tension",
            ][..],
        ),
        (
            SERVO.replace("syy: 0.01", "syy: 0.0"),
            &["loading[0].syy", "= 0", "compressive stress > 0"],
        ),
        (
            LOADING_PHASE.replace("Steps(10)", "MeanStress(-1e-3)"),
            &["loading[0].until[1]", "= -0.001", "compressive stress > 0"],
        ),
        (
            LOADING_PHASE.replace("Steps(10)", "MeanStress(0.0)"),
            &["loading[0].until[1]", "= 0", "tension"],
        ),
        // The servo holds p_c at 0.01: a phase that only ends at p_c = 0.02 never ends.
        (
            SERVO.replace("Steps(10)", "MeanStress(0.02)"),
            &[
                "loading[0].until",
                "MeanStress(0.02)",
                "(sxx + syy)/2 = 0.01",
                "never end",
            ],
        ),
    ] {
        check_fails(&scratch, &phase, &variant(LOADING_PHASE, &phase), needles);
    }
    // With another way out, the same condition is fine.
    let path = scratch.write(
        "scenario.ron",
        &variant(
            LOADING_PHASE,
            &SERVO.replace("Steps(10)", "Any([MeanStress(0.02), Steps(10)])"),
        ),
    );
    let out = sdem(&[Path::new("check"), &path]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn stress_targets_out_of_reach_are_warned_about() {
    let scratch = Scratch::new("stress_warnings");
    let check_warns = |text: &str, needles: &[&str]| {
        let path = scratch.write("scenario.ron", text);
        let out = sdem(&[Path::new("check"), &path]);
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{stderr}");
        assert!(stderr.contains("warning: "), "{stderr}");
        assert_mentions("warning", &stderr, needles);
        stderr
    };
    // Of the order of E.
    check_warns(
        &variant(LOADING_PHASE, &SERVO.replace("sxx: 0.01", "sxx: 0.8")),
        &["loading[0].sxx = 0.8", "0.80 x E"],
    );
    check_warns(
        &variant(
            LOADING_PHASE,
            &LOADING_PHASE.replace("Steps(10)", "MeanStress(2.0)"),
        ),
        &["loading[0].until[1] = 2", "2.00 x E"],
    );
    // Beyond what the contact law carries before leaving its domain: with b = 2 and the
    // default floor, E (1 - 0.05) / 0.05 = 19 E.
    check_warns(
        &variant(LOADING_PHASE, &SERVO.replace("syy: 0.01", "syy: 25.0")),
        &["loading[0].syy = 25", "contact law", "= 19", "domain"],
    );
    // A modest target: no warning.
    let path = scratch.write("scenario.ron", &variant(LOADING_PHASE, SERVO));
    let out = sdem(&[Path::new("check"), &path]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && !stderr.contains("warning"),
        "{stderr}"
    );
}

/// `sdem sort-sample` on a file it cannot sort: a missing file names itself; a malformed line
/// names `file:line` and the fault, and nothing is written; the output's folder must exist.
#[test]
fn sort_sample_on_bad_input() {
    let scratch = Scratch::new("sort_sample");
    let sort_fails = |what: &str, input: &Path, output: &Path, needles: &[&str]| {
        let out = sdem(&[
            std::ffi::OsStr::new("sort-sample"),
            input.as_os_str(),
            output.as_os_str(),
        ]);
        assert_mentions(what, &clean_failure(what, &out), needles);
    };
    let out = scratch.path("out.csv");
    sort_fails(
        "missing file",
        &scratch.path("missing.csv"),
        &out,
        &["cannot read the sample file", "missing.csv"],
    );
    let bad = scratch.write("bad.csv", "x,y,radius\n0.1,0.1,0.01\n0.2,0.1\n");
    sort_fails(
        "short line",
        &bad,
        &out,
        &["bad.csv:3:", "2 fields, expected 3"],
    );
    assert!(!out.exists(), "a failed sort wrote {}", out.display());
    let good = scratch.write("good.csv", "x,y,radius\n0.1,0.1,0.01\n");
    sort_fails(
        "output folder missing",
        &good,
        &scratch.path("no/such/folder/out.csv"),
        &["cannot write", "out.csv"],
    );
}

#[test]
fn an_unknown_vector_instruction_choice_is_refused() {
    // Expectation: SDEM_SIMD takes auto, avx or avx512; a misspelt value fails at once, naming
    // the value and the allowed ones, rather than passing for the default.
    let out = Command::new(env!("CARGO_BIN_EXE_sdem"))
        .args(["bench", "--grains", "100", "--steps", "1"])
        .env("SDEM_SIMD", "avx2")
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("starting the sdem binary");
    let stderr = clean_failure("SDEM_SIMD=avx2", &out);
    assert!(
        stderr.contains("SDEM_SIMD=\"avx2\"") && stderr.contains("auto, avx or avx512"),
        "{stderr}"
    );
}
