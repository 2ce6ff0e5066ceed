//! `sdem calibrate` (SPEC §10): bad input in debug, the full calibration and the convergence
//! study in release (`cargo test --release --test calibration -- --ignored --nocapture`).

use sdem::calibration::{
    CalibrateOptions, CalibrationError, DENSITIES, compress_disc, run_calibration,
};
use sdem::meshfree::HyperelasticLaw;

fn tmp_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("sdem_calibration_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn bad_input_is_reported_not_panicked() {
    // Expectation: nu >= 0.5, a too coarse node density, an impossible box and a compression
    // that cannot converge each give a clear error.
    let mut o = CalibrateOptions {
        out_dir: tmp_dir("bad"),
        ..Default::default()
    };
    o.nus = vec![0.3, 0.5];
    let e = run_calibration(&o).unwrap_err();
    assert!(
        matches!(e, CalibrationError::BadInput(_)) && e.to_string().contains("0.5"),
        "{e}"
    );

    let mut o = CalibrateOptions {
        out_dir: tmp_dir("bad"),
        ..Default::default()
    };
    o.boundary_nodes = 8;
    let e = run_calibration(&o).unwrap_err();
    assert!(e.to_string().contains("too coarse"), "{e}");

    let mut o = CalibrateOptions {
        out_dir: tmp_dir("bad"),
        ..Default::default()
    };
    o.final_box_side = 0.4;
    assert!(matches!(
        run_calibration(&o).unwrap_err(),
        CalibrationError::BadInput(_)
    ));

    // A single step to a deep compression with a 1-iteration Newton budget cannot converge.
    let mut o = CalibrateOptions {
        out_dir: tmp_dir("bad"),
        ..Default::default()
    };
    o.boundary_nodes = 24;
    o.steps = 1;
    o.solver.max_newton = 1;
    let e = compress_disc(HyperelasticLaw::NeoHookean, 0.3, &o).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("nu = 0.3") && msg.contains("converge"),
        "{msg}"
    );
}

#[test]
#[ignore = "release: the default calibration (both laws, 7 nu)"]
fn default_calibration_runs_and_writes_its_files() {
    let o = CalibrateOptions {
        out_dir: tmp_dir("default"),
        ..Default::default()
    };
    let report = run_calibration(&o).unwrap();
    println!("{report}");
    let csv = std::fs::read_to_string(&report.csv_path).unwrap();
    assert!(csv.starts_with("nu,h,F,Lc,dn,F_model\n"));
    assert_eq!(csv.lines().count(), 1 + 7 * o.steps);
    assert!(report.a > 0.0 && report.b.is_finite());
    assert!(
        report
            .to_string()
            .lines()
            .last()
            .unwrap()
            .starts_with("a = ")
    );
    assert!(
        report.wall_time.as_secs_f64() < 120.0,
        "{:?}",
        report.wall_time
    );
}

#[test]
#[ignore = "release: convergence of the wall force in nodal density"]
fn wall_force_converges_in_nodal_density() {
    let mut table = vec![];
    for law in [
        HyperelasticLaw::NeoHookean,
        HyperelasticLaw::SaintVenantKirchhoff,
    ] {
        for nu in [0.0, 0.3, 0.45, 0.49] {
            let mut row = vec![];
            for &nb in &DENSITIES {
                let o = CalibrateOptions {
                    boundary_nodes: nb,
                    ..Default::default()
                };
                let steps = compress_disc(law, nu, &o).unwrap();
                let last = steps.last().unwrap();
                row.push((last.force, last.contact_length));
            }
            println!("{law:?} nu = {nu}: {row:?}");
            table.push((law, nu, row));
        }
    }
    for (law, nu, row) in &table {
        let (f1, f2) = (row[row.len() - 2].0, row[row.len() - 1].0);
        assert!(((f2 - f1) / f2).abs() < 0.02, "{law:?} nu = {nu}: {row:?}");
    }
}
