//! The multibody meshfree solver (SPEC §10b, issue #12): grain–grain contact by the two-pass
//! smoothed node-to-segment element, in a global sparse problem.
//!
//! Quick checks run in the suite; the full set (two densities, two Poisson's ratios) and the
//! 100-grain scenario with
//! `cargo test --release --test meshfree_multibody -- --ignored --nocapture`.

mod common;

use common::meshfree::{column, settings};

/// Largest relative difference between two discs compressed by 2Δ and one disc by Δ.
fn symmetry_error(boundary_nodes: usize, nu: f64, approach: f64, steps: usize) -> f64 {
    let one = column(1, boundary_nodes, nu, approach, steps);
    let two = column(2, boundary_nodes, nu, 2.0 * approach, steps);
    println!(
        "nb {boundary_nodes} nu {nu}: one disc {:?}\n two discs {:?}",
        one.force, two.force
    );
    assert!(
        two.momentum < 1e-10,
        "momentum imbalance {:e}",
        two.momentum
    );
    assert!(
        two.penetration <= settings().gap_tolerance,
        "penetration {:e}",
        two.penetration
    );
    one.force
        .iter()
        .zip(&two.force)
        .map(|(f1, f2)| {
            assert!(*f1 > 0.0, "the top wall must be pushed up: force {f1}");
            (f2 / f1 - 1.0).abs()
        })
        .fold(0.0, f64::max)
}

#[test]
fn two_stacked_discs_carry_the_force_of_one_disc_quick() {
    // Expectation: the contact plane between two equal discs is a plane of symmetry, so each
    // disc is a disc between two walls: the force at approach 2Δ of the pair is the force at Δ
    // of one disc.
    let err = symmetry_error(32, 0.3, 0.1, 4);
    println!("two_disc_force_rel_err = {err:e}");
    assert!(err < 0.01, "{err}");
}

#[test]
#[ignore = "release: two densities and two Poisson's ratios to 20% strain"]
fn two_stacked_discs_carry_the_force_of_one_disc() {
    // Same expectation, over the whole loading (approach 0.2 of the diameter), for nu = 0.3
    // and 0.45, at two nodal densities.
    let mut worst = 0.0f64;
    for nb in [32, 64] {
        for nu in [0.3, 0.45] {
            let err = symmetry_error(nb, nu, 0.2, 10);
            println!("nb {nb} nu {nu}: max relative force difference {err:e}");
            worst = worst.max(err);
        }
    }
    println!("two_disc_force_rel_err = {worst:e}");
    assert!(worst < 0.01, "{worst}");
}

/// Reads a CSV into its header and rows.
fn read_csv(path: &std::path::Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    (header, rows)
}

#[test]
#[ignore = "release: the 100-grain scenario, about 40 minutes on 2 cores"]
fn biaxial_100_runs_its_three_phases() {
    // The two-disc check first (its lines are part of this test's report).
    let mut worst = 0.0f64;
    for nb in [32, 64] {
        for nu in [0.3, 0.45] {
            worst = worst.max(symmetry_error(nb, nu, 0.2, 10));
        }
    }
    println!("two_disc_force_rel_err = {worst:e}");
    assert!(worst < 0.01, "{worst}");

    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/meshfree_biaxial_100.ron");
    let out = std::env::temp_dir().join(format!("sdem-biaxial-100-{}", std::process::id()));
    let started = std::time::Instant::now();
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_sdem"))
        .args([
            "run",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            // The trajectory for pictures, and a checkpoint to resume from if it stops.
            "--mcap",
            out.join("run.mcap").to_str().unwrap(),
            "--checkpoint-every",
            "20",
        ])
        .status()
        .unwrap();
    let seconds = started.elapsed().as_secs_f64();
    let (header, rows) = read_csv(&out.join("macro.csv"));
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (phase, penetration) = (col("phase"), col("max_penetration"));
    // Phases the run got through: those it left for a later one, plus the last if it ended.
    let mut phases: Vec<&str> = Vec::new();
    for r in &rows {
        if phases.last() != Some(&r[phase].as_str()) {
            phases.push(&r[phase]);
        }
    }
    let completed = if status.success() {
        phases.len()
    } else {
        phases.len().saturating_sub(1)
    };
    let max_penetration = rows
        .iter()
        .map(|r| r[penetration].parse::<f64>().unwrap())
        .fold(0.0, f64::max);
    // The solver's own gap tolerance (absolute) and mean radius, from the same scenario.
    let (scenario, _) = sdem::scenario::Scenario::load(&path).unwrap();
    let built = sdem::run::meshfree::Meshfree::new(&scenario).unwrap();
    let gap_tolerance = built.assembly.settings.gap_tolerance;
    let mean_radius = match scenario.model {
        sdem::scenario::Model::Meshfree(m) => gap_tolerance / m.gap_tolerance,
        _ => unreachable!(),
    };
    println!("biaxial_100_phases_completed = {completed}");
    println!(
        "biaxial_100_max_penetration_over_radius = {:e}",
        max_penetration / mean_radius
    );
    println!("biaxial_100_wall_seconds = {seconds:.0}");
    println!("(output in {})", out.display());
    assert!(status.success(), "the run failed: see {}", out.display());
    assert_eq!(completed, 3, "phases {phases:?}");
    assert!(
        max_penetration <= gap_tolerance,
        "{max_penetration} > {gap_tolerance}"
    );
}
