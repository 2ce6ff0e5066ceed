//! Runs started from a sample file: a run's own `grains.csv` (with the box from its
//! `summary.txt`) starts a new run from its final state; such a run resumes bitwise from its
//! checkpoints; a stress target the packing cannot reach ends the run with an error naming the
//! target and the stress reached. An old (version 1) checkpoint still reads.

mod common;

use sdem::run::checkpoint::Checkpoint;
use sdem::run::{RunError, RunOptions, build_world, resume_run, run_scenario};
use sdem::scenario::Scenario;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A fast compaction of 60 grains to phi = 0.88 (~2500 steps).
const FIRST: &str = r#"
Scenario(
    name: "first",
    sample: (count: 60, box_width: 0.25, box_height: 0.25,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    loading: [Isotropic(rate: Constant(1e-1), until: PackingFraction(0.88))],
    output: (every: 100),
)
"#;

fn temp_dir(name: &str) -> common::TempDir {
    common::temp_dir("sample-file", name)
}

fn options(out: &Path) -> RunOptions {
    RunOptions {
        out_dir: out.to_path_buf(),
        ..Default::default()
    }
}

/// Runs FIRST into `dir/first` and returns the `final_box` line of its summary, as a RON
/// fragment for a sample section.
fn first_run(dir: &Path) -> String {
    let scenario = Scenario::parse(FIRST, "first.ron").unwrap();
    scenario.validate().unwrap();
    run_scenario(&scenario, &options(&dir.join("first"))).unwrap();
    let summary = std::fs::read_to_string(dir.join("first/summary.txt")).unwrap();
    let line = summary
        .lines()
        .find_map(|l| l.strip_prefix("final_box = "))
        .expect("summary.txt has final_box");
    // "(origin: (..), box_width: .., box_height: ..)" -> the fields inside the parentheses.
    line.trim_start_matches('(')
        .trim_end_matches(')')
        .to_string()
}

/// Writes `dir/second.ron`: a scenario reading `first/grains.csv` in the box `fields`, and
/// returns its path.
fn write_second(dir: &Path, fields: &str, loading: &str) -> PathBuf {
    let path = dir.join("second.ron");
    let text = format!(
        r#"Scenario(
    name: "second",
    sample: ({fields}, file: "first/grains.csv"),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    loading: [{loading}],
    output: (every: 50),
)"#
    );
    std::fs::write(&path, text).unwrap();
    path
}

fn grains_csv(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect()
}

#[test]
fn a_run_starts_from_its_own_grains_csv() {
    let dir = temp_dir("restart");
    let fields = first_run(&dir);
    let path = write_second(&dir, &fields, "Relax(until: Steps(300))");
    let (scenario, warnings) = Scenario::load(&path).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    // The world starts from the file's grains (12 significant digits), at rest, in the box.
    let world = build_world(&scenario).unwrap();
    let rows = grains_csv(&dir.join("first/grains.csv"));
    assert_eq!(world.grains().len(), 60);
    for (g, row) in world.grains().iter().zip(&rows) {
        let file = [row[1], row[2], row[3], row[4], row[5], row[6], row[7]];
        let read = [
            g.center.x, g.center.y, g.radius, g.theta, g.eps1, g.eps2, g.alpha,
        ];
        assert_eq!(file, read);
        assert_eq!(g.velocity.length(), 0.0);
    }
    assert!(
        rows.iter().any(|r| r[5] != 0.0),
        "the first run deformed no grain"
    );
    // It runs, and the compacted state carries load from its first step.
    let out = dir.join("second");
    let summary = run_scenario(&scenario, &options(&out)).unwrap();
    assert_eq!(summary.steps, 300);
    let first_p: Vec<f64> = std::fs::read_to_string(dir.join("first/macro.csv"))
        .unwrap()
        .lines()
        .last()
        .unwrap()
        .split(',')
        .map(|x| x.parse().unwrap_or(f64::NAN))
        .collect();
    let macro_csv = std::fs::read_to_string(out.join("macro.csv")).unwrap();
    let row1: Vec<f64> = macro_csv
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .map(|x| x.parse().unwrap_or(f64::NAN))
        .collect();
    // p_c (column 6) of the first row of the new run, against the last row of the old one.
    assert!(
        row1[6] > 0.3 * first_p[6] && first_p[6] > 0.0,
        "p_c {} after restart, {} at the end of the first run",
        row1[6],
        first_p[6]
    );
    // The same through the command line, from another working directory.
    let cli = Command::new(env!("CARGO_BIN_EXE_sdem"))
        .args(["run", path.to_str().unwrap(), "--out"])
        .arg(dir.join("cli"))
        .arg("--quiet")
        .current_dir(std::env::temp_dir())
        .output()
        .unwrap();
    assert!(
        cli.status.success(),
        "{}",
        String::from_utf8_lossy(&cli.stderr)
    );
    assert_eq!(
        std::fs::read(out.join("macro.csv")).unwrap(),
        std::fs::read(dir.join("cli/macro.csv")).unwrap()
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_run_from_a_file_resumes_bitwise() {
    let dir = temp_dir("resume");
    let fields = first_run(&dir);
    let path = write_second(
        &dir,
        &fields,
        "Relax(until: Steps(100)), Servo(sxx: 0.1, syy: 0.08, gain: 0.5, max_rate: 1e-2, until: Steps(400))",
    );
    let (scenario, _) = Scenario::load(&path).unwrap();
    let reference = dir.join("ref");
    let mut opts = options(&reference);
    opts.checkpoint_every = 1_000_000;
    run_scenario(&scenario, &opts).unwrap();
    let cut = dir.join("cut");
    let mut opts = options(&cut);
    opts.checkpoint_every = 1_000_000;
    opts.stop_after_step = Some(237);
    assert!(matches!(
        run_scenario(&scenario, &opts),
        Err(RunError::Interrupted { step: 237, .. })
    ));
    // The sample file is not needed any more: resume reads only the checkpoint.
    std::fs::rename(dir.join("first"), dir.join("moved")).unwrap();
    let ckpt = cut.join("checkpoint.bin");
    let saved = Checkpoint::read(&ckpt).unwrap();
    assert_eq!(saved.scenario, scenario);
    let mut opts = options(&cut);
    opts.checkpoint_every = 1_000_000;
    resume_run(&saved, &ckpt, &opts).unwrap();
    for file in ["macro.csv", "grains.csv"] {
        assert!(
            std::fs::read(reference.join(file)).unwrap() == std::fs::read(cut.join(file)).unwrap(),
            "{file} differs"
        );
    }
    let (a, b) = (
        Checkpoint::read(&reference.join("checkpoint.bin")).unwrap(),
        Checkpoint::read(&ckpt).unwrap(),
    );
    assert!(a.complete && b.complete);
    assert_eq!(a.grains, b.grains);
    std::fs::remove_dir_all(&dir).ok();
}

/// `sdem run SCENARIO --out OUT --quiet`, which must fail with exit status 1: its stderr.
fn sdem_run_fails(scenario: &Path, out: &Path) -> String {
    let result = Command::new(env!("CARGO_BIN_EXE_sdem"))
        .arg("run")
        .arg(scenario)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr).into_owned();
    assert_eq!(result.status.code(), Some(1), "{stderr}");
    stderr
}

#[test]
fn an_unreachable_stress_target_stops_the_run_with_an_error() {
    let dir = temp_dir("unreachable");
    let fields = first_run(&dir);
    // Incompressible grains under a servo at 5 E: the grains fill the box long before.
    let path = write_second(
        &dir,
        &fields,
        "Servo(sxx: 5.0, syy: 5.0, gain: 0.5, max_rate: 0.2, until: Steps(1000000))",
    );
    let stderr = sdem_run_fails(&path, &dir.join("servo"));
    for needle in [
        "warning: loading[0].sxx = 5",
        "error: step ",
        "loading[0] (servo) cannot reach its target sxx_c = 5, syy_c = 5",
        "the grains fill the box",
        "the stress reached is sxx_c = ",
        "grains_last_good.csv",
    ] {
        assert!(stderr.contains(needle), "no {needle:?} in\n{stderr}");
    }
    assert!(dir.join("servo/grains_last_good.csv").exists());
    // A strain-driven phase waiting for a mean stress the law cannot carry (b = 40: about
    // 0.49 E): it ends at the law's domain exit, and says which target it was after. (The
    // compacted state of the first run has overlaps outside this law's domain: generated.)
    let text = FIRST
        .replace("PackingFraction(0.88)", "MeanStress(0.6)")
        .replace("material:", "contact: (b: 40.0),\n    material:");
    std::fs::write(&path, text).unwrap();
    let stderr = sdem_run_fails(&path, &dir.join("iso"));
    for needle in [
        "warning: loading[0].until = 0.6",
        "contact law can carry",
        "error: step ",
        "loading[0] (isotropic)",
        "target p_c = 0.6",
        "stress reached is",
    ] {
        assert!(stderr.contains(needle), "no {needle:?} in\n{stderr}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A checkpoint written before samples could come from files and before the checkpoint
/// interval could be set in a scenario (`count: 12`, no `Some`, no `checkpoint_seconds`).
#[test]
fn a_version_1_checkpoint_still_reads() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let c = Checkpoint::read(&data.join("v1_checkpoint.bin")).unwrap();
    let (scenario, _) = Scenario::load(&data.join("v1_checkpoint.ron")).unwrap();
    assert_eq!(c.scenario, scenario);
    assert!(c.complete);
    assert_eq!((c.step, c.grains.len(), c.checkpoint_every), (40, 12, 15));
    assert_eq!(c.checkpoint_seconds, None);
    // The grains are those the scenario generates, moved by 40 steps. (The checkpoint numbers
    // them in placement order; a generated sample is now numbered along a Hilbert curve.)
    let start = build_world(&scenario).unwrap();
    assert_eq!(start.grains().len(), c.grains.len());
    for b in &c.grains {
        let matches = start
            .grains()
            .iter()
            .filter(|a| a.radius == b.radius && a.center.distance(b.center) < 0.01)
            .count();
        assert_eq!(matches, 1, "checkpoint grain {b:?}");
    }
}

/// Expectation: a sample file of 10^4 grains whose rows are scattered in space draws
/// `Scenario::load`'s warning that names `sample.file` and asks for its rows sorted with `sdem
/// sort-sample`; the same grains row by row draw none, and so does the scattered file once
/// `sdem sort-sample` has sorted it, whose lines are the scattered file's, each once (issue #16:
/// a scattered order of LAMMPS's 10^5 packing stepped half as fast). The grains of the left
/// half row by row, then those of the right half (as two MPI processes write a packing) draw
/// the other warning: every chunk of the right half has a grain that touches the left half, so
/// the step's sweep would wait on two threads.
#[test]
fn a_sample_file_in_a_scattered_order_draws_a_warning() {
    let dir = temp_dir("scattered");
    let (side, radius) = (100usize, 0.01);
    let width = 2.0 * side as f64 * radius;
    let row = |k: usize| {
        let (i, j) = (k % side, k / side);
        format!(
            "{},{},{radius}",
            (2 * i + 1) as f64 * radius,
            (2 * j + 1) as f64 * radius
        )
    };
    let n = side * side;
    for (name, order) in [
        ("rows", Some((0..n).collect::<Vec<_>>())),
        ("scattered", Some((0..n).map(|k| k * 7919 % n).collect())),
        ("sorted", None),
        (
            "halves",
            Some(
                (0..n)
                    .filter(|k| k % side < side / 2)
                    .chain((0..n).filter(|k| k % side >= side / 2))
                    .collect(),
            ),
        ),
    ] {
        match order {
            Some(order) => {
                let rows: Vec<String> = order.into_iter().map(row).collect();
                std::fs::write(
                    dir.join(format!("{name}.csv")),
                    format!("x,y,radius\n{}\n", rows.join("\n")),
                )
                .unwrap();
            }
            None => {
                let cli = Command::new(env!("CARGO_BIN_EXE_sdem"))
                    .arg("sort-sample")
                    .arg(dir.join("scattered.csv"))
                    .arg(dir.join("sorted.csv"))
                    .output()
                    .unwrap();
                assert!(cli.status.success(), "{cli:?}");
                let lines = |file: &str| {
                    let text = std::fs::read_to_string(dir.join(file)).unwrap();
                    let mut lines: Vec<String> = text.lines().map(String::from).collect();
                    lines.sort();
                    lines
                };
                assert_eq!(lines("sorted.csv"), lines("scattered.csv"));
            }
        }
        let path = dir.join(format!("{name}.ron"));
        std::fs::write(
            &path,
            format!(
                r#"Scenario(
    name: "{name}",
    sample: (box_width: {width}, box_height: {width}, file: "{name}.csv"),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    model: Rigid,
    loading: [Relax(until: Steps(1))],
)"#
            ),
        )
        .unwrap();
        let (_, warnings) = Scenario::load(&path).unwrap();
        let ordering: Vec<&String> = warnings
            .iter()
            .filter(|w| w.starts_with("sample.file: grains numbered one after the other"))
            .collect();
        let waiting: Vec<&String> = warnings
            .iter()
            .filter(|w| w.starts_with("sample.file: grains meet grains far back"))
            .collect();
        let sort_hint = "sdem sort-sample FILE SORTED.csv";
        match name {
            "scattered" => assert!(
                ordering.len() == 1 && ordering[0].contains(sort_hint) && waiting.is_empty(),
                "{warnings:?}"
            ),
            "halves" => assert!(
                ordering.is_empty() && waiting.len() == 1 && waiting[0].contains(sort_hint),
                "{warnings:?}"
            ),
            _ => assert!(ordering.is_empty() && waiting.is_empty(), "{warnings:?}"),
        }
    }
}
