//! Coulomb friction of the meshfree solver (SPEC §13, §11): an elastic disc rolling or
//! slipping down a 45° incline (the seed's benchmark), blocks sticking and sliding on a plate,
//! the energy a sliding contact dissipates, determinism and the 2D Hertz contact.
//!
//! The incline is the bottom wall with gravity tilted by 45°: g = (g sin θ, -g cos θ).

use glam::DVec2;
use sdem::boundary::walls::Wall;
use sdem::meshfree::assembly::Assembly;
use sdem::meshfree::friction::FrictionCoefficients;
use sdem::meshfree::shape::StarShape;
use sdem::meshfree::{GrainModel, Hyperelastic, HyperelasticLaw, SolverSettings, TimeScheme};
use sdem::run::meshfree::{Meshfree, SampleGrain, grain_model};
use sdem::run::meshfree_checkpoint::MeshfreeCheckpoint;
use sdem::run::{RunError, resume_run, run_scenario};
use sdem::scenario::{MeshfreeSettings, Scenario};

mod common;
use common::rolling::{GRAVITY, Roll, THETA, fit_s, roll, roll_with, rolling_scenario};
use common::with_threads;

/// The seed's material and disc (SPEC §11): E = 10 MPa, nu = 0.45, rho = 990 kg/m^3,
/// R = 0.5 mm; g = 10 m/s^2 on a 45° incline.
const YOUNG: f64 = 10e6;
const POISSON: f64 = 0.45;
const DENSITY: f64 = 990.0;
const RADIUS: f64 = 0.5e-3;

fn disc(boundary_nodes: usize, centre: [f64; 2]) -> GrainModel {
    let material = Hyperelastic::new(HyperelasticLaw::NeoHookean, YOUNG, POISSON, DENSITY).unwrap();
    common::meshfree::disc_of(RADIUS, centre, boundary_nodes, material)
}

fn settings() -> SolverSettings {
    SolverSettings {
        k0: YOUNG / RADIUS,
        alpha_k: 2.0,
        gap_tolerance: 1e-5 * RADIUS,
        force_tolerance: 1e-12 * YOUNG * RADIUS,
        max_newton: 40,
        max_augmentations: 40,
    }
}

/// A disc resting on the floor (its lowest node on it), gravity tilted by θ, the floor's
/// friction coefficient `mu`; no damping but the Bathe scheme's own.
fn incline(boundary_nodes: usize, mu: f64) -> Assembly {
    let grain = disc(boundary_nodes, [0.0, RADIUS]);
    let walls = vec![Wall::new(DVec2::ZERO, DVec2::Y)];
    let gravity = [GRAVITY * THETA.sin(), -GRAVITY * THETA.cos()];
    let mut a = Assembly::new(vec![grain], walls, gravity, (0.0, 0.0), settings()).unwrap();
    a.set_friction(FrictionCoefficients {
        grains: 0.0,
        walls: vec![mu],
        stiffness_ratio: 1.0,
    })
    .unwrap();
    a
}

/// Mass per unit thickness of the disc.
fn disc_mass() -> f64 {
    DENSITY * std::f64::consts::PI * RADIUS * RADIUS
}

/// A coarse disc (24 contour nodes) for 10 ms (100 steps of 0.1 ms): the fit from 2 ms.
fn coarse_s(mu: f64) -> (f64, Roll) {
    coarse_s_over(mu, 100)
}

/// [`coarse_s`] over `steps` steps of 0.1 ms.
fn coarse_s_over(mu: f64, steps: usize) -> (f64, Roll) {
    let mut a = incline(24, mu);
    let r = roll(&mut a, 1e-4, steps, [1.0, 0.0]);
    (fit_s(&r.samples, 2e-3), r)
}

#[test]
fn frictionless_disc_slides_at_half() {
    // Expectation: without friction the disc slides without turning, a = g sin θ: s = 1/2
    // (a contact that stays closed: the fit's residual is the disc's vibration only).
    let (s, r) = coarse_s(0.0);
    println!("mu 0: s = {s:.5}");
    assert!((s - 0.5).abs() < 1e-3, "s = {s}");
    assert_eq!(r.dissipated, 0.0);
}

#[test]
fn slipping_disc_follows_coulomb() {
    // Expectation: mu = 0.1 < tan θ / 3: the contact slips all the way, the friction force is
    // mu N and a = g (sin θ - mu cos θ): s = (1 - mu / tan θ) / 2 = 0.45, whatever the
    // faceting of the contour. The dissipation is mu N times the slip.
    let (s, r) = coarse_s(0.1);
    println!("mu 0.1: s = {s:.5}, dissipated {:.3e}", r.dissipated);
    assert!((s - 0.45).abs() < 2e-3, "s = {s}");
    assert!(r.dissipated > 0.0);
}

#[test]
fn rolling_disc_does_not_slip() {
    // Expectation: mu = 0.6 >= tan θ / 3: a smooth disc rolls without slipping,
    // a = (2/3) g sin θ, s = 1/3. The meshfree disc's contour is a polygon of 24 nodes against
    // the wall (node-to-wall elements): it rocks from node to node and, undamped, hops at each
    // landing (a landing node slips a little), so s is 1/3 only to the faceting's error. The
    // band 1/3 ± 0.02 tells rolling from slipping (0.45) and sliding (0.5); friction dissipates
    // a small part of the potential energy released (6% measured here; a disc slipping at
    // mu = 0.1 dissipates mu / tan θ = 10% of it).
    //
    // The fit runs over 20 ms. Over the first 10 ms the disc touches the wall in only 20 of
    // the 100 steps, and its s moved by 0.017 when exp, ln, pow and the trigonometric
    // functions changed their last bits (0.3454 with glibc's, 0.3623 with the portable ones
    // the solver calls): the hops are sensitive to round-off. Over 20 ms the same change
    // moves it by 0.006 (0.3336 and 0.3394; 0.327 to 0.337 at 24 to 48 nodes, both ways).
    let (s, r) = coarse_s_over(0.6, 200);
    let (_, d) = *r.samples.last().unwrap();
    let released = disc_mass() * GRAVITY * THETA.sin() * d;
    println!(
        "mu 0.6: s = {s:.5}, dissipated {:.3e} of {released:.3e} released, touching in {} of {} steps",
        r.dissipated,
        r.touching,
        r.samples.len()
    );
    assert!((s - 1.0 / 3.0).abs() < 0.02, "s = {s}");
    assert!(r.dissipated < 0.1 * released);
}

/// A square block of side `side` with 32 contour nodes on the floor (its bottom face on it),
/// gravity `(gx, -GRAVITY)`, the floor's friction `mu`.
fn block(side: f64, gx: f64, mu: f64) -> Assembly {
    block_of(YOUNG, side, gx, mu)
}

/// [`block`] of Young's modulus `young`.
fn block_of(young: f64, side: f64, gx: f64, mu: f64) -> Assembly {
    let grain = square(young, side, [0.0, 0.5 * side], 32);
    let walls = vec![Wall::new(DVec2::ZERO, DVec2::Y)];
    let solver = SolverSettings {
        k0: young / RADIUS,
        ..settings()
    };
    let mut a = Assembly::new(vec![grain], walls, [gx, -GRAVITY], (0.0, 0.0), solver).unwrap();
    a.set_friction(FrictionCoefficients {
        grains: 0.0,
        walls: vec![mu],
        stiffness_ratio: 1.0,
    })
    .unwrap();
    a
}

/// A square grain of side `side` (`boundary_nodes` contour nodes, the seed's material but
/// E = `young`) centred on `centre`.
fn square(young: f64, side: f64, centre: [f64; 2], boundary_nodes: usize) -> GrainModel {
    let h = 0.5 * side;
    let shape = StarShape::Polygon {
        vertices: vec![[-h, -h], [h, -h], [h, h], [-h, h]],
    };
    let nodes = MeshfreeSettings {
        boundary_nodes,
        ..MeshfreeSettings::default()
    };
    let material = Hyperelastic::new(HyperelasticLaw::NeoHookean, young, POISSON, DENSITY).unwrap();
    grain_model(&SampleGrain { shape, centre }, &nodes, material).unwrap()
}

/// A block of side 0.6 mm (grain 0) on a block of side 1 mm (grain 1) on the floor, gravity
/// `(gx, -GRAVITY)`; grain–grain friction `mu`, the floor's 0.6.
///
/// The master splines round a polygon's corners (Catmull–Rom: the tangent at a corner node
/// points between its two faces), so the spline of a face's last segment dips below the face
/// by a fraction of the spacing: the upper block (48 nodes, spacing 0.05 mm, corners at
/// ±0.3 mm) is laid so that no node of the lower face (spacing 0.125 mm) falls on those
/// segments, which would start the run overlapping.
fn stacked_blocks(gx: f64, mu: f64) -> Assembly {
    let (lower, upper) = (2.0 * RADIUS, 1.2 * RADIUS);
    let grains = vec![
        square(YOUNG, upper, [0.0, lower + 0.5 * upper], 48),
        square(YOUNG, lower, [0.0, 0.5 * lower], 32),
    ];
    let walls = vec![Wall::new(DVec2::ZERO, DVec2::Y)];
    let mut a = Assembly::new(grains, walls, [gx, -GRAVITY], (0.0, 0.0), settings()).unwrap();
    a.set_friction(FrictionCoefficients {
        grains: mu,
        walls: vec![0.6],
        stiffness_ratio: 1.0,
    })
    .unwrap();
    a
}

#[test]
#[ignore]
fn block_on_block_sticks_and_slides() {
    // Grain–grain friction (node-to-segment element) between a block of 0.6 mm and one of
    // 1 mm on the floor (mu 0.6), pushed by gx = 0.3 g. Coulomb expects: with mu = 0.5 the
    // upper block sticks, with mu = 0.2 it slides at 0.1 g and friction dissipates mu m g d,
    // the lower block held by the floor. Measured (release, 40 steps of 0.1 ms): the stuck
    // block creeps 1.4e-6 m (6% of the 2.4e-5 m it slides frictionless), the sliding one
    // accelerates at 0.920 of 0.1 g and dissipates 1.056 mu m g d, the lower block moves
    // 6.6e-8 m (below the stick tolerance's creep bound). Why not better: a master spline is
    // Catmull–Rom, so at a polygon's corner it dips below the face by a fraction of the node
    // spacing; the lower face's nodes that pass
    // under the upper block's corners meet that dip (a geometric bump, present without
    // friction), and the undamped upper block rocks, its contacts opening and closing. The
    // bounds below are those of the measurement (friction acts, Coulomb's order), not of
    // Coulomb's law; the element itself is checked exactly by finite differences (nts.rs).
    let (dt, steps) = (1e-4, 40);
    let free = 0.5 * 0.3 * GRAVITY * (dt * steps as f64).powi(2);
    let mut a = stacked_blocks(0.3 * GRAVITY, 0.5);
    let stuck = roll(&mut a, dt, steps, [1.0, 0.0]);
    let moved = stuck.samples.iter().map(|p| p.1.abs()).fold(0.0, f64::max);
    println!(
        "block on block, mu 0.5: largest displacement {moved:.3e} m ({:.3} of the free slide)",
        moved / free
    );
    let mut a = stacked_blocks(0.3 * GRAVITY, 0.2);
    let slid = roll(&mut a, dt, steps, [1.0, 0.0]);
    let acceleration = 2.0 * fit_s(&slid.samples, 1e-3) * GRAVITY * THETA.sin();
    let (_, distance) = *slid.samples.last().unwrap();
    let mass = DENSITY * (1.2 * RADIUS).powi(2);
    let expected_work = 0.2 * mass * GRAVITY * distance;
    let (_, lower) = a.grains[1].contour_area_centroid(a.grain_slice(&slid.state.u, 1));
    println!(
        "block on block, mu 0.2: a = {acceleration:.5} (expected 1), dissipated {:.5e}, mu m g d = {expected_work:.5e}, lower block at x = {:.3e}",
        slid.dissipated, lower[0]
    );
    assert!(moved < 0.1 * free, "the upper block moved by {moved:e}");
    assert!(
        (acceleration / (0.1 * GRAVITY) - 1.0).abs() < 0.1,
        "a = {acceleration}"
    );
    assert!((slid.dissipated / expected_work - 1.0).abs() < 0.1);
    // The floor's sticking nodes may slip by up to the gap tolerance per sub-step.
    let creep = 2.0 * steps as f64 * settings().gap_tolerance;
    assert!(
        lower[0].abs() < creep,
        "the lower block moved by {:e}",
        lower[0]
    );
}

#[test]
fn block_sticks_below_the_cone_and_slides_above_it() {
    // Expectation (Coulomb): a block pushed along the floor by a body force gx sticks while
    // gx <= mu g and slides with a = gx - mu g above: gx = 0.3 g with mu = 0.5 stays put (the
    // stick constraint holds to the gap tolerance, 1e-5 R per step); with mu = 0.2 it slides at
    // a = 0.1 g, the friction dissipating mu m g times the distance, which is also the work of
    // gx minus the kinetic energy gained.
    let side = 2.0 * RADIUS;
    let (dt, steps) = (1e-4, 60);
    let mut a = block(side, 0.3 * GRAVITY, 0.5);
    let stuck = roll(&mut a, dt, steps, [1.0, 0.0]);
    let moved = stuck.samples.iter().map(|p| p.1.abs()).fold(0.0, f64::max);
    println!(
        "gx 0.3 g, mu 0.5: largest displacement {moved:.3e} m, dissipated {:.3e}",
        stuck.dissipated
    );
    assert!(moved < 1e-4 * side, "the block moved by {moved:e}");

    let mut a = block(side, 0.3 * GRAVITY, 0.2);
    let slid = roll(&mut a, dt, steps, [1.0, 0.0]);
    let acceleration = 2.0 * fit_s(&slid.samples, 1e-3) * GRAVITY * THETA.sin();
    let (_, distance) = *slid.samples.last().unwrap();
    let mass = DENSITY * side * side;
    let expected_work = 0.2 * mass * GRAVITY * distance;
    let kinetic = a.kinetic_energy(&slid.state.v);
    let balance = mass * 0.3 * GRAVITY * distance - kinetic;
    println!(
        "gx 0.3 g, mu 0.2: a = {acceleration:.5} (expected {:.5}), dissipated {:.5e}, mu m g d = {expected_work:.5e}, work - kinetic = {balance:.5e}",
        0.1 * GRAVITY,
        slid.dissipated
    );
    assert!(
        (acceleration / (0.1 * GRAVITY) - 1.0).abs() < 5e-3,
        "a = {acceleration}"
    );
    assert!((slid.dissipated / expected_work - 1.0).abs() < 5e-3);
    assert!((slid.dissipated / balance - 1.0).abs() < 5e-3);
}

#[test]
fn explicit_block_sticks_and_slides() {
    // Expectation: the explicit scheme's penalty friction (MELODY2D's) obeys Coulomb's law:
    // with mu = 0.2 a block pushed by gx = 0.3 g slides at a = 0.1 g; with mu = 0.5 and
    // gx = 0.05 g it stays put. Undamped, the block vibrates on its contact springs: contour
    // nodes lift off and land again, losing their traction history, and land sticking. The
    // measured consequences (E = 1 MPa, 32 contour nodes): the sliding block's acceleration is
    // 2.6% above 0.1 g (landing nodes stick for a while: less friction), and the stuck block
    // creeps, 1.2e-8 m in 5 ms, 1e-5 of the side. The bounds say that much and no more:
    // a within 3% of 0.1 g, the stuck block's motion below 1e-3 of the sliding one's.
    let (young, side) = (1e6, 2.0 * RADIUS);
    let (dt, steps) = (2e-4, 25);
    let mut a = block_of(young, side, 0.3 * GRAVITY, 0.2);
    a.use_explicit().unwrap();
    let slid = roll_with(&mut a, dt, steps, [1.0, 0.0], TimeScheme::CentralDifference);
    let acceleration = 2.0 * fit_s(&slid.samples, 1e-3) * GRAVITY * THETA.sin();
    let (_, distance) = *slid.samples.last().unwrap();
    let expected_work = 0.2 * DENSITY * side * side * GRAVITY * distance;
    println!(
        "explicit, gx 0.3 g, mu 0.2: a = {acceleration:.5} (expected 1), dissipated {:.5e}, mu m g d = {expected_work:.5e}",
        slid.dissipated
    );
    assert!(
        (acceleration / (0.1 * GRAVITY) - 1.0).abs() < 0.03,
        "a = {acceleration}"
    );
    assert!((slid.dissipated / expected_work - 1.0).abs() < 0.03);
    let mut a = block_of(young, side, 0.05 * GRAVITY, 0.5);
    a.use_explicit().unwrap();
    let stuck = roll_with(&mut a, dt, steps, [1.0, 0.0], TimeScheme::CentralDifference);
    let moved = stuck.samples.iter().map(|p| p.1.abs()).fold(0.0, f64::max);
    println!("explicit, gx 0.05 g, mu 0.5: largest displacement {moved:.3e} m");
    assert!(moved < 1e-3 * distance, "the block moved by {moved:e}");
}

#[test]
fn bad_friction_is_refused() {
    let mut a = incline(24, 0.0);
    for (f, expect) in [
        (
            FrictionCoefficients {
                walls: vec![-0.1],
                ..FrictionCoefficients::default()
            },
            "wall 0",
        ),
        (
            FrictionCoefficients {
                stiffness_ratio: 0.0,
                ..FrictionCoefficients::default()
            },
            "stiffness_ratio",
        ),
    ] {
        let e = a.set_friction(f).unwrap_err().to_string();
        assert!(e.contains(expect), "{e}");
    }
}

fn temp_dir(name: &str) -> common::TempDir {
    common::temp_dir("mffriction", name)
}

#[test]
fn rolling_is_bitwise_identical_on_one_and_two_threads() {
    // Expectation: contacts gathered in a fixed order, the friction history in a sorted map:
    // the same bits whatever the thread count.
    let run = |threads| {
        with_threads(threads, || {
            let mut a = incline(24, 0.6);
            let r = roll(&mut a, 1e-4, 30, [1.0, 0.0]);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let track: Vec<f64> = r.samples.iter().map(|p| p.1).collect();
            let history: Vec<u64> = r.state.friction.values().map(|t| t.to_bits()).collect();
            assert!(
                r.with_history > 10,
                "{} steps with friction",
                r.with_history
            );
            (
                bits(&track),
                bits(&r.state.u),
                bits(&r.state.v),
                history,
                r.dissipated.to_bits(),
            )
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn a_rolling_run_resumes_bitwise_with_its_friction_history() {
    // Expectation: the friction history is part of the checkpoint: a run stopped while the
    // disc rolls (the history not empty) and resumed writes the same files, byte for byte.
    let scenario = rolling_scenario(24, 0.6, 0.003);
    let reference = temp_dir("ref");
    run_scenario(&scenario, &common::checkpointed(&reference, 5)).unwrap();
    let dir = temp_dir("stopped");
    let mut options = common::checkpointed(&dir, 5);
    // At step 10 the disc is rolling on a stuck node (the history is checked below).
    options.stop_after_step = Some(10);
    match run_scenario(&scenario, &options) {
        Err(RunError::Interrupted { step, .. }) => assert_eq!(step, 10),
        other => panic!("expected an interruption, got {other:?}"),
    }
    let path = dir.join("checkpoint.bin");
    let c = MeshfreeCheckpoint::read(&path).unwrap();
    assert!(
        !c.state.friction.is_empty(),
        "no friction history in the checkpoint"
    );
    with_threads(1, || resume_run(&c, &path, &common::checkpointed(&dir, 5))).unwrap();
    for file in ["macro.csv", "grains.csv", "checkpoint.bin"] {
        let (a, b) = (
            std::fs::read(reference.join(file)).unwrap(),
            std::fs::read(dir.join(file)).unwrap(),
        );
        assert!(a == b, "{file} differs after the resume");
    }
}

/// The plane-strain force per unit length that presses a cylinder of radius `r` between two
/// plates to an approach `2 d` (Johnson 1985, SPEC §11):
/// `2 d = (2 F / (π E*)) (2 ln(4 R / b) - 1)`, `b = sqrt(4 F R / (π E*))`, solved for F by
/// fixed-point iteration.
fn johnson_force(d: f64, r: f64, e_star: f64) -> f64 {
    let mut f = 0.1 * e_star * d;
    for _ in 0..200 {
        let b = (4.0 * f * r / (std::f64::consts::PI * e_star)).sqrt();
        f = d * std::f64::consts::PI * e_star / (2.0 * (4.0 * r / b).ln() - 1.0);
    }
    f
}

#[test]
#[ignore]
fn hertz_2d_table() {
    // A disc (nu = 0.45, neo-Hookean; E = 1, R = 0.5: F / (E R) against d / R is the same for
    // E = 10 MPa, R = 0.5 mm) pressed quasi-statically between two frictionless rigid plates
    // (each moves in by d), at increasing nodal density, against Johnson's cylinder law.
    let (nu, r) = (0.45, common::meshfree::RADIUS);
    let e_star = 1.0 / (1.0 - nu * nu);
    let steps = 25;
    let approach = 0.05; // 2 d at the last step: d / R = 0.05
    let rows = [1usize, 2, 5, 10, 25];
    let mut table = Vec::new();
    for nb in [32, 64, 128, 256] {
        let t0 = std::time::Instant::now();
        let c = common::meshfree::column(1, nb, nu, approach, steps);
        table.push((nb, c.force, t0.elapsed().as_secs_f64()));
    }
    print!("d/R     Johnson F/(E R)");
    for (nb, _, _) in &table {
        print!("  nb {nb:4} (ratio)");
    }
    println!();
    for &k in &rows {
        let d = 0.5 * approach * k as f64 / steps as f64;
        let fj = johnson_force(d, r, e_star);
        print!("{:.3}   {:.5e}", d / r, fj / r);
        for (_, f, _) in &table {
            print!("  {:.5e} ({:.3})", f[k - 1] / r, f[k - 1] / fj);
        }
        println!();
    }
    for (nb, _, cpu) in &table {
        println!("nb {nb}: {cpu:.1} s");
    }
}

#[test]
fn meshfree_scenarios_take_friction_but_no_dashpot() {
    // The scenario's friction reaches the meshfree model (walls, planes, grains); the
    // tangential dashpot is SDEM's and a meshfree scenario asking for it is refused, naming it.
    let text = |friction: &str| {
        format!(
            r#"Scenario(
                name: "mf_friction",
                sample: (count: 2, box_width: 0.4, box_height: 0.4,
                         radii: Uniform(min: 0.06, max: 0.07)),
                material: (young: 1.0, poisson: 0.3, density: 1.0),
                model: Meshfree((boundary_nodes: 16)),
                contact: (friction: ({friction})),
                planes: [(point: (0.0, 0.05), normal: (0.2, 1.0), friction: 0.3)],
                time_step: Fixed(0.01),
                loading: [Relax(until: Steps(1))],
            )"#
        )
    };
    let ok = Scenario::parse(
        &text("grains: 0.5, walls: 0.4, stiffness_ratio: 2.0"),
        "ok.ron",
    )
    .unwrap();
    ok.validate().unwrap();
    let sim = Meshfree::new(&ok).unwrap();
    let f = sim.assembly.friction();
    assert_eq!(f.grains, 0.5);
    assert_eq!(f.walls, vec![0.4, 0.4, 0.4, 0.4, 0.3]);
    assert_eq!(f.stiffness_ratio, 2.0);
    assert_eq!(sim.assembly.walls.len(), 5);
    let bad = Scenario::parse(&text("grains: 0.5, damping: 0.1"), "bad.ron").unwrap();
    let e = bad.validate().unwrap_err().to_string();
    assert!(e.contains("contact.friction.damping"), "{e}");
}
