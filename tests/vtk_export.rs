//! VTK export for ParaView (`sdem export --vtk`, `sdem run --vtk`): every file read back by the
//! official VTK Python package, its counts and decoded stresses checked against the run; a
//! damaged log gives `export` an error, never a panic.
//!
//! The Python check runs when `SDEM_VTK_PYTHON` names a Python with `vtk` installed, or when
//! `target/vtk-venv` exists:
//!
//! ```sh
//! python3 -m venv target/vtk-venv && target/vtk-venv/bin/pip install vtk
//! cargo test --release --test vtk_export
//! ```

mod common;

use sdem::output::mcap::{McapSettings, Trajectory};
use sdem::run::{RunOptions, run_scenario};
use sdem::scenario::Scenario;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// 150 frictional grains in a box, a few frames: contacts with tangential forces.
const FRICTIONAL: &str = r#"
Scenario(
    name: "vtk_small",
    seed: 5,
    sample: (count: 150, box_width: 0.4, box_height: 0.4,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    contact: (friction: (grains: 0.5, walls: 0.0, stiffness_ratio: 1.0)),
    loading: [ Isotropic(rate: Constant(2e-2), until: PackingFraction(0.86)) ],
    output: (every: 400),
)
"#;

fn temp_dir(name: &str) -> common::TempDir {
    common::temp_dir("vtk", name)
}

fn sdem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sdem"))
}

/// The Python interpreter with the `vtk` package, if this machine has one set up.
fn python_with_vtk() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("SDEM_VTK_PYTHON") {
        return Some(PathBuf::from(p));
    }
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/vtk-venv/bin/python");
    venv.exists().then_some(venv)
}

/// One dataset as VTK read it: (time, points, lines, polygons, cell array names).
type Dataset = (f64, usize, usize, usize, Vec<String>);

/// What `tools/check_vtk.py` read from one export.
#[derive(Debug, Default)]
struct Read {
    /// Per collection: the datasets it lists.
    collections: BTreeMap<String, usize>,
    datasets: BTreeMap<String, Vec<Dataset>>,
    /// (collection, array) -> values of the last frame.
    values: BTreeMap<(String, String), Vec<f64>>,
}

fn read_with_python(python: &Path, dir: &Path) -> Read {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/check_vtk.py");
    let output = Command::new(python)
        .arg(&script)
        .arg(dir)
        .output()
        .expect("running tools/check_vtk.py");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "check_vtk.py failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let mut read = Read::default();
    for line in stdout.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f[0] {
            "collection" => {
                read.collections.insert(f[1].into(), f[2].parse().unwrap());
            }
            "dataset" => read.datasets.entry(f[1].into()).or_default().push((
                f[3].parse().unwrap(),
                f[4].parse().unwrap(),
                f[5].parse().unwrap(),
                f[6].parse().unwrap(),
                f.get(7)
                    .map(|s| s.split(',').map(String::from).collect())
                    .unwrap_or_default(),
            )),
            "values" => {
                read.values.insert(
                    (f[1].into(), f[2].into()),
                    f[3..].iter().map(|v| v.parse().unwrap()).collect(),
                );
            }
            _ => panic!("unexpected line {line}"),
        }
    }
    read
}

/// The `mean_stress_c` column of grains.csv.
fn grains_csv_mean_stress(path: &Path) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "mean_stress_c").unwrap();
    lines
        .map(|l| l.split(',').nth(col).unwrap().parse().unwrap())
        .collect()
}

fn close(a: f64, b: f64, rel: f64, abs: f64) -> bool {
    (a - b).abs() <= rel * b.abs() + abs
}

/// Runs `scenario` into `dir` with its MCAP log at `log` and, with `vtk`, VTK files there.
fn run_logged(scenario: &Scenario, dir: &Path, log: &Path, vtk: Option<&Path>) {
    run_scenario(
        scenario,
        &RunOptions {
            out_dir: dir.to_path_buf(),
            mcap: Some(McapSettings::new(log)),
            vtk: vtk.map(Path::to_path_buf),
            ..Default::default()
        },
    )
    .unwrap();
}

#[test]
fn a_run_and_its_log_export_files_that_vtk_reads_back() {
    let dir = temp_dir("run");
    let scenario = Scenario::parse(FRICTIONAL, "vtk_small.ron").unwrap();
    let log_path = dir.join("run.mcap");
    let run_vtk = dir.join("vtk_run");
    run_logged(&scenario, &dir, &log_path, Some(&run_vtk));
    let log = Trajectory::open(&log_path).unwrap();
    let frames = log.frame_count();
    assert!(frames >= 3, "{frames} frames");
    let last = log.frame(-1).unwrap();
    assert!(!last.contacts.is_empty());
    // A frictional run's log carries the tangential force.
    assert!(last.contacts.iter().any(|c| c.tangential_force != 0.0));

    let log_vtk = dir.join("vtk_log");
    let out = sdem()
        .arg("export")
        .arg(&log_path)
        .arg("--vtk")
        .arg(&log_vtk)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for d in [&run_vtk, &log_vtk] {
        for part in ["grains", "contacts", "boundary"] {
            let pvd = std::fs::read_to_string(d.join(format!("{part}.pvd"))).unwrap();
            assert_eq!(pvd.matches("<DataSet ").count(), frames, "{part}");
        }
    }

    let Some(python) = python_with_vtk() else {
        eprintln!("note: Python vtk check skipped (set SDEM_VTK_PYTHON or create target/vtk-venv)");
        std::fs::remove_dir_all(&dir).ok();
        return;
    };
    let expected_csv = grains_csv_mean_stress(&dir.join("grains.csv"));
    for (d, from_run) in [(&run_vtk, true), (&log_vtk, false)] {
        let read = read_with_python(&python, d);
        for part in ["grains.pvd", "contacts.pvd", "boundary.pvd"] {
            assert_eq!(read.collections[part], frames, "{part}");
        }
        for k in 0..frames {
            let frame = log.frame(k as i64).unwrap();
            let n = frame.grains.len();
            let (time, points, lines, polys, arrays) = &read.datasets["grains.pvd"][k];
            assert_eq!(*time, frame.time);
            assert_eq!((*polys, *lines), (n, 0), "frame {k}: one polygon per grain");
            assert!(*points >= 8 * n, "frame {k}: {points} points");
            for a in [
                "id",
                "radius",
                "mean_stress_c",
                "von_mises",
                "x",
                "y",
                "theta",
                "eps1",
                "eps2",
                "alpha",
                "level",
                "contacts",
            ] {
                assert!(arrays.iter().any(|x| x == a), "{a} missing");
            }
            let (_, points, lines, polys, _) = &read.datasets["contacts.pvd"][k];
            let c = frame.contacts.len();
            assert_eq!((*lines, *points, *polys), (c, 2 * c, 0), "frame {k}");
            let (_, points, lines, _, _) = &read.datasets["boundary.pvd"][k];
            assert_eq!((*lines, *points), (4, 8), "frame {k}");
        }
        // The last frame's mean stress, decoded by VTK: that of grains.csv (10 digits there).
        let mean = &read.values[&("grains.pvd".into(), "mean_stress_c".into())];
        assert_eq!(mean.len(), expected_csv.len());
        for (k, (v, e)) in mean.iter().zip(&expected_csv).enumerate() {
            assert!(close(*v, *e, 1e-8, 1e-14), "grain {k}: {v} vs {e}");
        }
        assert!(mean.iter().any(|v| *v > 0.0));
        // Forces: compression positive normal forces, tangential ones below mu times them.
        let normal = &read.values[&("contacts.pvd".into(), "normal_force".into())];
        let tangential = &read.values[&("contacts.pvd".into(), "tangential_force".into())];
        assert_eq!(normal.len(), last.contacts.len());
        for ((f, t), c) in normal.iter().zip(tangential).zip(&last.contacts) {
            assert!(close(*f, -c.force, 1e-6, 0.0), "{f} vs {}", -c.force);
            assert!(close(*t, c.tangential_force, 1e-6, 1e-12));
            assert!(t.abs() <= 0.5 * f * (1.0 + 1e-5) + 1e-12);
        }
        assert!(tangential.iter().any(|t| *t != 0.0));
        // Levels: known in a run (the scenario's fixed level, Full = 2), not in a log.
        let levels = &read.values[&("grains.pvd".into(), "level".into())];
        let expected_level = if from_run { 2.0 } else { -1.0 };
        assert!(levels.iter().all(|l| *l == expected_level), "{levels:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_meshfree_log_exports_its_boundary_contours() {
    let dir = temp_dir("meshfree");
    let scenarios = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    std::fs::copy(
        scenarios.join("meshfree_bouncing_disc_grains.csv"),
        dir.join("meshfree_bouncing_disc_grains.csv"),
    )
    .unwrap();
    let text = std::fs::read_to_string(scenarios.join("meshfree_bouncing_disc.ron"))
        .unwrap()
        .replace("Time(4.0)", "Time(0.1)");
    let scenario_path = dir.join("disc.ron");
    std::fs::write(&scenario_path, text).unwrap();
    let log_path = dir.join("disc.mcap");
    let status = sdem()
        .arg("run")
        .arg(&scenario_path)
        .arg("--out")
        .arg(&dir)
        .arg("--quiet")
        .arg("--mcap")
        .arg(&log_path)
        .arg("--vtk")
        .arg(dir.join("vtk_run"))
        .status()
        .unwrap();
    assert!(status.success());
    let log = Trajectory::open(&log_path).unwrap();
    let vtk = dir.join("vtk");
    let status = sdem()
        .arg("export")
        .arg(&log_path)
        .arg("--vtk")
        .arg(&vtk)
        .status()
        .unwrap();
    assert!(status.success());
    // No contact network in a meshfree export.
    assert!(!vtk.join("contacts.pvd").exists());
    let Some(python) = python_with_vtk() else {
        eprintln!("note: Python vtk check skipped");
        return;
    };
    let read = read_with_python(&python, &vtk);
    assert_eq!(read.collections["grains.pvd"], log.frame_count());
    // `sdem run --vtk` wrote the same polygons and stresses as the export of its log.
    let run = read_with_python(&python, &dir.join("vtk_run"));
    assert_eq!(run.datasets["grains.pvd"], read.datasets["grains.pvd"]);
    assert_eq!(run.values, read.values);
    for (k, (time, points, lines, polys, _)) in read.datasets["grains.pvd"].iter().enumerate() {
        let frame = log.frame(k as i64).unwrap();
        let contours = frame.contours.as_ref().unwrap();
        assert_eq!(*time, frame.time);
        assert_eq!((*polys, *lines), (contours.len(), 0));
        let nodes: usize = contours.iter().map(|c| c.points.len()).sum();
        assert_eq!(*points, nodes);
    }
    let last = log.frame(-1).unwrap();
    let mean = &read.values[&("grains.pvd".into(), "mean_stress_c".into())];
    let expected: Vec<f64> = last
        .contours
        .unwrap()
        .iter()
        .map(|c| c.mean_stress_c)
        .collect();
    assert_eq!(mean, &expected);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_periodic_run_draws_each_contact_to_the_nearest_image() {
    let dir = temp_dir("periodic");
    let text = FRICTIONAL.replace("output:", "boundary: Periodic,\n    output:");
    let scenario = Scenario::parse(&text, "vtk_periodic.ron").unwrap();
    let log_path = dir.join("run.mcap");
    let vtk = dir.join("vtk");
    run_logged(&scenario, &dir, &log_path, Some(&vtk));
    let log = Trajectory::open(&log_path).unwrap();
    let last = log.frame(-1).unwrap();
    let cell = last.cell.expect("a periodic log has a cell");
    let Some(python) = python_with_vtk() else {
        eprintln!("note: Python vtk check skipped");
        return;
    };
    let read = read_with_python(&python, &vtk);
    assert_eq!(read.collections["contacts.pvd"], log.frame_count());
    let (_, _, lines, _, _) = read.datasets["contacts.pvd"].last().unwrap();
    assert_eq!(*lines, last.contacts.len());
    let (_, points, lines, _, _) = read.datasets["boundary.pvd"].last().unwrap();
    assert_eq!((*lines, *points), (4, 8));
    // Each contact line joins two touching grains: no longer than their two largest radii
    // (contacts across the cell's sides included; there are some).
    let lengths = &read.values[&("contacts.pvd".into(), "segment_length".into())];
    assert_eq!(lengths.len(), last.contacts.len());
    for (l, c) in lengths.iter().zip(&last.contacts) {
        let (a, b) = (
            &last.grains[c.first as usize],
            &last.grains[c.second as usize],
        );
        let reach = a.radius * (1.0 + a.eps1.max(a.eps2)) + b.radius * (1.0 + b.eps1.max(b.eps2));
        assert!(*l <= reach * (1.0 + 1e-5), "{l} > {reach}");
    }
    let width = cell.widths()[0].min(cell.widths()[1]);
    let across = last
        .contacts
        .iter()
        .filter(|c| {
            let d = last.grains[c.first as usize].center - last.grains[c.second as usize].center;
            d.length() > 0.5 * width
        })
        .count();
    assert!(across > 0, "no contact across the cell's sides");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_truncated_or_corrupt_log_gives_export_an_error_not_a_panic() {
    let dir = temp_dir("damaged");
    let scenario = Scenario::parse(FRICTIONAL, "vtk_small.ron").unwrap();
    let log_path = dir.join("good.mcap");
    run_logged(&scenario, &dir, &log_path, None);
    let bytes = std::fs::read(&log_path).unwrap();
    let export = |name: &str, data: &[u8]| {
        let path = dir.join(name);
        std::fs::write(&path, data).unwrap();
        let out = sdem()
            .arg("export")
            .arg(&path)
            .arg("--vtk")
            .arg(dir.join(format!("{name}.vtk")))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(!stderr.contains("panicked"), "{name}: {stderr}");
        assert_ne!(out.status.code(), Some(101), "{name}: {stderr}");
        (out.status.success(), stderr)
    };
    // Truncated: the summary section is gone.
    for cut in [bytes.len() / 2, bytes.len() - 10, 20] {
        let (ok, stderr) = export("truncated.mcap", &bytes[..cut]);
        assert!(!ok, "cut at {cut}");
        assert!(
            stderr.contains("truncated.mcap") && stderr.contains("not a complete MCAP file"),
            "{stderr}"
        );
    }
    // Corrupt chunks: bytes flipped across the middle of the file.
    let mut corrupt = bytes.clone();
    let mid = bytes.len() / 2;
    for b in &mut corrupt[mid - 200..mid + 200] {
        *b ^= 0x5a;
    }
    let (ok, stderr) = export("corrupt.mcap", &corrupt);
    assert!(!ok, "a corrupt chunk was exported");
    assert!(stderr.contains("corrupt.mcap"), "{stderr}");
    // Not an MCAP file at all.
    let (ok, stderr) = export("text.mcap", b"grains,x,y\n0,1,2\n");
    assert!(!ok);
    assert!(stderr.contains("text.mcap"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}
