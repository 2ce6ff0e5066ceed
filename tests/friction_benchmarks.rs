//! The benchmarks of the frictional soft-particle paper (seed 002 §5; SPEC §11, §13; issue #15)
//! on the shipped scenarios. Heavy enough to be `--ignored`:
//!
//! ```text
//! cargo test --release --test friction_benchmarks -- --ignored --nocapture
//! ```
//!
//! prints `rolling_s_sdem = ...` (mu 0.6, full level), `rolling_s_sdem_slip = ...` (mu 0.1),
//! `rolling_s_meshfree = ...` (mu 0.6, the finest nodal density run) and
//! `compaction30_phi_gain_with_friction = ...` (phi(mu 0.5) - phi(mu 0) at the final strain,
//! SDEM), each on its own line, with the tables behind them; also
//! `compaction30_phi_gain_with_friction_meshfree = ...` (the same, meshfree solver).

mod common;
use common::rolling;

use sdem::run::{RunOptions, build_world, run_scenario};
use sdem::scenario::Scenario;
use std::path::{Path, PathBuf};

fn scenarios() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios")
}

/// A shipped scenario with its text edited by `edit`, loaded from the scenarios folder (its
/// sample file is read from there).
fn shipped(name: &str, edit: impl Fn(String) -> String) -> Scenario {
    let path = scenarios().join(name);
    let text = edit(std::fs::read_to_string(&path).unwrap());
    let mut s = Scenario::parse(&text, &path.display().to_string()).unwrap();
    s.load_sample(&scenarios()).unwrap();
    s.validate().unwrap();
    s
}

/// Rolls the disc of `rolling_disc.ron` at model `model` with coefficient `mu` (plane and
/// grains) and returns s = (x - x0)/(g t^2 sin theta), x measured down the plane, fitted by
/// least squares over the run (`d = s g sin(theta) t^2`).
fn rolling_s(model: &str, mu: f64) -> f64 {
    let scenario = shipped("rolling_disc.ron", |t| {
        t.replace("model: Full,", &format!("model: {model},"))
            .replace("friction: 0.6)", &format!("friction: {mu})"))
            .replace("grains: 0.6", &format!("grains: {mu}"))
    });
    let mut world = build_world(&scenario).unwrap();
    let theta = std::f64::consts::FRAC_PI_4;
    let downhill = glam::DVec2::new(1.0, -1.0).normalize();
    let g = 10.0;
    let start = world.grains()[0].center;
    let (mut moment, mut norm) = (0.0, 0.0);
    let end = 0.02;
    while world.time < end {
        world.step().unwrap();
        if world.step.is_multiple_of(100) {
            let t = world.time;
            let d = (world.grains()[0].center - start).dot(downhill);
            moment += d * t * t;
            norm += t.powi(4);
        }
    }
    moment / (norm * g * theta.sin())
}

#[test]
#[ignore = "benchmark: runs the rolling disc at four model levels and three coefficients"]
fn rolling_disc_sdem() {
    // Expectations (rigid disc on a 45° incline): rolls without slip for mu >= tan(theta)/3,
    // s = 1/3; slips for mu = 0.1, s = (1 - mu/tan theta)/2 = 0.45; slides for mu = 0, s = 1/2.
    // The grain is ~1e-7 as soft as its load would need to deform visibly (rho g R / E = 5e-7):
    // every level must give the rigid values.
    println!("level       mu    s       expected");
    let mut full = [0.0; 2];
    for model in ["Rigid", "Volumetric", "Full", "Adaptive()"] {
        for (k, (mu, expected)) in [(0.6, 1.0 / 3.0), (0.1, 0.45), (0.0, 0.5)]
            .into_iter()
            .enumerate()
        {
            let s = rolling_s(model, mu);
            println!("{model:<11} {mu:<5} {s:.5} {expected:.5}");
            assert!(
                (s - expected).abs() < 2e-3 * expected,
                "{model}, mu = {mu}: s = {s}, expected {expected}"
            );
            if model == "Full" && k < 2 {
                full[k] = s;
            }
        }
    }
    println!("rolling_s_sdem = {}", full[0]);
    println!("rolling_s_sdem_slip = {}", full[1]);
}

#[test]
#[ignore = "benchmark: the meshfree rolling disc at three nodal densities, about 2.5 minutes"]
fn rolling_disc_meshfree() {
    // The shipped scenario (the disc on a plane inclined at 45°) at increasing nodal density,
    // mu = 0.6 (rolls: s -> 1/3), and at the finest density mu = 0.1 (s = 0.45) and 0 (1/2).
    let densities = [32, 64, 128];
    let mut last = 0.0;
    for &nb in &densities {
        let (s, touching, cpu) = rolling::scenario_s(nb, 0.6);
        println!(
            "boundary_nodes {nb:4}  mu 0.6  s = {s:.5}  touching {:.0}% of steps  {cpu:.1} s",
            100.0 * touching
        );
        assert!((s - 1.0 / 3.0).abs() < 0.02, "s = {s}");
        last = s;
    }
    for mu in [0.1, 0.0] {
        let (s, touching, cpu) = rolling::scenario_s(64, mu);
        let expected = 0.5 * (1.0 - mu / rolling::THETA.tan());
        println!(
            "boundary_nodes   64  mu {mu}  s = {s:.5} (expected {expected:.3})  touching {:.0}% of steps  {cpu:.1} s",
            100.0 * touching
        );
        assert!((s - expected).abs() < 2e-3, "s = {s}");
    }
    println!("rolling_s_meshfree = {last}");
}

/// The last row of a run's macro.csv, by column name.
fn last_row(dir: &Path) -> impl Fn(&str) -> f64 {
    let text = std::fs::read_to_string(dir.join("macro.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let last: Vec<String> = text
        .lines()
        .last()
        .unwrap()
        .split(',')
        .map(String::from)
        .collect();
    move |name| {
        let k = header.iter().position(|h| h == name).unwrap();
        last[k].parse().unwrap()
    }
}

/// Runs the frictionless and the frictional scenario of a 30-disc compaction (the same start,
/// the same loading) and checks what both solvers must show: the same final box (30% vertical
/// strain), and a higher axial stress with friction, which resists the rearrangements. Returns
/// phi(mu 0.5) - phi(mu 0) there (phi = V_s / V at the same box compares the grains' volumes).
fn compaction30_phi_gain(frictionless: &str, frictional: &str) -> f64 {
    let mut rows = Vec::new();
    for name in [frictionless, frictional] {
        let scenario = shipped(name, |t| t);
        let dir = common::temp_dir("friction-bench", name);
        run_scenario(
            &scenario,
            &RunOptions {
                out_dir: dir.to_path_buf(),
                ..Default::default()
            },
        )
        .unwrap();
        let row = last_row(&dir);
        let (phi, syy, height) = (row("phi"), row("syy_c"), row("box_height"));
        println!("{name}: phi = {phi:.5}, syy_c = {syy:.4e} Pa, box height = {height:.6e} m");
        rows.push((phi, syy, height));
        std::fs::remove_dir_all(&dir).ok();
    }
    let (frictionless, frictional) = (rows[0], rows[1]);
    // The phase ends on the first step past the strain: the boxes differ by a step's travel.
    assert!(
        (frictionless.2 - frictional.2).abs() < 1e-5 * frictionless.2,
        "the same final box: {} against {}",
        frictionless.2,
        frictional.2
    );
    assert!(
        frictional.1 > frictionless.1,
        "friction raises the axial stress at the same strain"
    );
    frictional.0 - frictionless.0
}

#[test]
#[ignore = "benchmark: two 30-grain compactions to 30% vertical strain"]
fn compaction30_sdem() {
    let gain = compaction30_phi_gain("compaction30_mu0.ron", "compaction30_mu05.ron");
    println!("compaction30_phi_gain_with_friction = {gain}");
}

#[test]
#[ignore = "benchmark: two meshfree 30-grain compactions to 30% vertical strain, about 6 minutes"]
fn compaction30_meshfree() {
    // The same packing (radii x 0.998) at the paper's 5 m/s, 32 contour nodes per disc. The
    // frictional run reaches the final strain only because Newton shortens its steps when it
    // cycles between a contact's stick and slip states (it stopped at 20% strain without).
    let gain = compaction30_phi_gain(
        "compaction30_meshfree_mu0.ron",
        "compaction30_meshfree_mu05.ron",
    );
    println!("compaction30_phi_gain_with_friction_meshfree = {gain}");
}
