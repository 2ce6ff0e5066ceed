//! Coulomb friction in the SDEM engine (SPEC §13, issue #15) against independent expectations:
//! a block on an incline, a rolling disc, the energy a sliding contact dissipates, objectivity,
//! and a frictional compaction that resumes bitwise and is the same on 1 and 2 threads.

mod common;

use glam::DVec2;
use sdem::boundary::walls::Wall;
use sdem::contact::friction::FrictionSettings;
use sdem::grain::{Grain, Material, ModelLevel};
use sdem::integration::parameters::{Friction, ModeSettings, frictional_critical_time_step};
use sdem::integration::{Parameters, World};
use sdem::scenario::Scenario;

const RADIUS: f64 = 0.5;
/// Gravity small against E: the contact's overlap stays ~1e-3 of the radius.
const G: f64 = 1e-3;

fn frictional_params(level: ModelLevel, poisson: f64, mu: f64, damping: f64) -> Parameters {
    let material = Material {
        young: 1.0,
        poisson,
        density: 1.0,
    };
    let mut p = Parameters::new(material, 0.0);
    p.level = level;
    let settings = FrictionSettings {
        grains: mu,
        walls: mu,
        stiffness_ratio: 1.0,
        damping,
        ..Default::default()
    };
    p.friction = Friction::new(&settings, &[mu]);
    let modes = ModeSettings {
        tangential_ratio: 1.0,
        ..Default::default()
    };
    p.dt = 0.4 * frictional_critical_time_step(&p.material, &p.law, RADIUS, level, modes);
    p.gravity = DVec2::new(0.0, -G);
    p
}

/// One disc resting on a plane through the origin inclined by `angle` (rising towards +x),
/// the plane its only wall. Returns the world and the plane's downhill direction.
fn disc_on_incline(params: Parameters, angle: f64) -> (World, DVec2) {
    let normal = DVec2::new(-angle.sin(), angle.cos());
    let downhill = normal.perp();
    let grain = Grain::at_rest(normal * RADIUS * 0.999, RADIUS);
    let world = World::new(params, vec![grain], vec![Wall::new(DVec2::ZERO, normal)]);
    (world, downhill)
}

/// Steps a world, holding every grain's rotation when `block` (a sliding block).
fn advance(world: &mut World, steps: usize, block: bool) {
    for _ in 0..steps {
        world.step().expect("stable step");
        if block {
            for g in world.grains_mut() {
                g.omega = 0.0;
                g.theta = 0.0;
            }
        }
    }
}

/// Acceleration of the grain's centre along `direction`, measured over `steps` after `settle`.
fn acceleration(
    world: &mut World,
    direction: DVec2,
    settle: usize,
    steps: usize,
    block: bool,
) -> f64 {
    advance(world, settle, block);
    let (v0, t0) = (world.grains()[0].velocity.dot(direction), world.time);
    advance(world, steps, block);
    (world.grains()[0].velocity.dot(direction) - v0) / (world.time - t0)
}

#[test]
fn a_block_slides_at_g_sin_minus_mu_cos_and_sticks_below_tan_theta_mu() {
    // Expectation: a block on an incline at theta with tan(theta) > mu accelerates at
    // g (sin theta - mu cos theta); with tan(theta) < mu it stays where it is.
    let theta = 30f64.to_radians();
    for mu in [0.0, 0.2, 0.4] {
        let (mut world, downhill) =
            disc_on_incline(frictional_params(ModelLevel::Rigid, 0.3, mu, 0.0), theta);
        let a = acceleration(&mut world, downhill, 500, 5_000, true);
        let expected = G * (theta.sin() - mu * theta.cos());
        assert!(
            (a - expected).abs() < 1e-3 * G,
            "mu = {mu}: a = {a:e}, expected {expected:e}"
        );
    }
    // tan 30° = 0.577 < 0.7: it sticks. Free of friction it would move g sin(theta) t^2 / 2.
    let (mut world, downhill) =
        disc_on_incline(frictional_params(ModelLevel::Rigid, 0.3, 0.7, 0.5), theta);
    let start = world.grains()[0].center;
    advance(&mut world, 20_000, true);
    let moved = (world.grains()[0].center - start).dot(downhill);
    let free_fall = 0.5 * G * theta.sin() * world.time * world.time;
    // It moves by the tangential spring's deflection m g sin(theta) / K_t only (K_t about E/a),
    // at most twice that while the undamped start overshoots.
    let mass = world.grains()[0].mass(1.0);
    let deflection = mass * G * theta.sin() / world.params.law.initial_stiffness();
    assert!(
        moved.abs() < 2.5 * deflection && moved.abs() < 1e-6 * free_fall,
        "moved {moved:e} (spring deflection {deflection:e}, frictionless: {free_fall:e})"
    );
    assert!(world.grains()[0].velocity.length() < 1e-4 * G * world.time);
}

#[test]
fn a_disc_rolls_at_two_thirds_g_sin_theta_unless_it_slips() {
    // Expectation (rigid disc, I = m R^2 / 2): rolling without slip while mu >= tan(theta)/3,
    // a = (2/3) g sin(theta), omega' = a / R; with mu below, it slides with
    // a = g (sin theta - mu cos theta). Both at the rigid and the full level.
    let theta = 45f64.to_radians();
    for level in [ModelLevel::Rigid, ModelLevel::Full] {
        for (mu, expected) in [
            (0.6, 2.0 / 3.0 * G * theta.sin()),
            (0.1, G * (theta.sin() - 0.1 * theta.cos())),
        ] {
            let (mut world, downhill) =
                disc_on_incline(frictional_params(level, 0.3, mu, 0.0), theta);
            let a = acceleration(&mut world, downhill, 500, 5_000, false);
            assert!(
                (a - expected).abs() < 0.01 * expected,
                "{level:?}, mu = {mu}: a = {a:e}, expected {expected:e}"
            );
            if mu == 0.6 {
                // Rolling: the contact point is at rest, v = omega R (omega < 0 rolling downhill
                // to the left).
                let g = &world.grains()[0];
                let v = g.velocity.dot(downhill);
                assert!(
                    (v - g.omega.abs() * RADIUS).abs() < 0.01 * v,
                    "v = {v:e}, omega R = {:e}",
                    g.omega * RADIUS
                );
            }
        }
    }
}

#[test]
fn a_sliding_disc_dissipates_its_kinetic_energy_by_coulomb_friction() {
    // Expectation: a block launched at v0 on a level plane stops after v0^2 / (2 mu g), and the
    // energy the engine counts as dissipated by sliding (mu |F_n| |slip| per step) is the
    // kinetic energy it lost.
    let mu = 0.3;
    let (mut world, _) = disc_on_incline(frictional_params(ModelLevel::Rigid, 0.3, mu, 0.0), 0.0);
    advance(&mut world, 2_000, true);
    let v0 = 0.02;
    world.grains_mut()[0].velocity = DVec2::new(v0, 0.0);
    let x0 = world.grains()[0].center.x;
    let density = world.params.material.density;
    let kinetic = |w: &World| w.grains()[0].kinetic_energy(density, 1.0);
    let k0 = kinetic(&world);
    let mut dissipated = 0.0;
    let mut steps = 0;
    while world.grains()[0].velocity.x > 0.0 {
        advance(&mut world, 1, true);
        dissipated += world.totals.friction_dissipation;
        steps += 1;
        assert!(steps < 1_000_000, "the block never stopped");
    }
    let distance = world.grains()[0].center.x - x0;
    let expected = v0 * v0 / (2.0 * mu * G);
    assert!(
        (distance - expected).abs() < 2e-3 * expected,
        "stopped after {distance}, expected {expected}"
    );
    let lost = k0 - kinetic(&world);
    assert!(
        (dissipated - lost).abs() < 2e-3 * lost,
        "dissipated {dissipated:e}, kinetic energy lost {lost:e}"
    );
}

/// Two deformable discs on a frictional floor, the first in the corner with a frictional left
/// wall, the second pressed against it by gravity and spinning, the whole scene turned by
/// `angle` about the origin.
fn spinning_pair(angle: f64) -> World {
    let turn = DVec2::from_angle(angle);
    let mut params = frictional_params(ModelLevel::Full, 0.3, 0.4, 0.2);
    params.friction = Friction::new(
        &FrictionSettings {
            grains: 0.4,
            walls: 0.0,
            stiffness_ratio: 1.0,
            damping: 0.2,
            ..Default::default()
        },
        &[0.3, 0.5],
    );
    params.gravity = turn.rotate(DVec2::new(-10.0 * G, -20.0 * G));
    let walls = vec![
        Wall::new(DVec2::ZERO, turn.rotate(DVec2::Y)),
        Wall::new(DVec2::ZERO, turn.rotate(DVec2::X)),
    ];
    let mut grains = vec![
        Grain::at_rest(DVec2::new(0.99, 0.99) * RADIUS, RADIUS),
        Grain::at_rest(DVec2::new(2.97, 0.99) * RADIUS, RADIUS),
    ];
    grains[1].velocity = DVec2::new(-0.01, 0.0);
    grains[1].omega = 0.05;
    for g in &mut grains {
        g.center = turn.rotate(g.center);
        g.velocity = turn.rotate(g.velocity);
        g.theta += angle;
    }
    World::new(params, grains, walls)
}

#[test]
fn frictional_forces_turn_with_the_scene() {
    // Expectation (objectivity): the same scene turned rigidly by 70 degrees gives the turned
    // motion: positions, velocities, spins and strains agree after 3000 steps of sliding,
    // sticking contacts between the grains and with the floor.
    let angle = 70f64.to_radians();
    let mut a = spinning_pair(0.0);
    let mut b = spinning_pair(angle);
    let turn = DVec2::from_angle(angle);
    let mut sliding_steps = 0;
    for _ in 0..3_000 {
        a.step().unwrap();
        b.step().unwrap();
        sliding_steps += (a.totals.sliding_contacts > 0) as u32;
    }
    assert!(
        a.totals.contacts == 1,
        "the grains stay in contact: {:?}",
        a.grains()
    );
    assert!(sliding_steps > 0, "some contact slid");
    for (ga, gb) in a.grains().iter().zip(b.grains()) {
        let scale = ga.velocity.length().max(1e-3);
        assert!(
            (turn.rotate(ga.center) - gb.center).length() < 1e-9,
            "{ga:?} vs {gb:?}"
        );
        assert!(
            (turn.rotate(ga.velocity) - gb.velocity).length() < 1e-6 * scale,
            "{ga:?} vs {gb:?}"
        );
        assert!((ga.omega - gb.omega).abs() < 1e-6 * ga.omega.abs().max(1e-3));
        assert!((ga.eps1 - gb.eps1).abs() < 1e-9 && (ga.eps2 - gb.eps2).abs() < 1e-9);
    }
    // The contact's history turned with it: the same tangential force.
    let (ha, hb) = (a.contact_history(), b.contact_history());
    assert_eq!(ha.pairs.len(), 1);
    let (fa, fb) = (ha.pairs[0].1, hb.pairs[0].1);
    assert!((fa - fb).abs() < 1e-6 * fa.abs(), "{fa:e} vs {fb:e}");
}

/// [`common::SMALL_COMPACTION`] with friction between the grains and at the walls.
fn frictional_compaction() -> Scenario {
    let text = common::SMALL_COMPACTION.replace(
        "material: (young: 1.0, poisson: 0.5, density: 1.0),",
        "material: (young: 1.0, poisson: 0.5, density: 1.0),
    contact: (friction: (grains: 0.5, walls: 0.3, damping: 0.1)),",
    );
    let s = Scenario::parse(&text, "friction.ron").unwrap();
    s.validate().unwrap();
    s
}

#[test]
fn a_frictional_compaction_resumes_bitwise_and_is_the_same_on_any_thread_count() {
    // Expectation (determinism): with tangential history in the checkpoint, a resumed run
    // gives the uninterrupted run's files and grains bit for bit; so does a run on 2 threads.
    use sdem::run::{resume_run, run_scenario};
    let scenario = frictional_compaction();
    let reference = common::temp_dir("friction", "ref");
    common::with_threads(1, || {
        run_scenario(&scenario, &common::checkpointed(&reference, 1_000_000_000))
    })
    .unwrap();
    let two = common::temp_dir("friction", "two");
    common::with_threads(2, || {
        run_scenario(&scenario, &common::checkpointed(&two, 1_000_000_000))
    })
    .unwrap();
    let same = |a: &std::path::Path, b: &std::path::Path| {
        let (ca, cb) = common::assert_same_run(a, b);
        assert_eq!(ca.contact_history, cb.contact_history);
    };
    same(&reference, &two);
    // macro.csv reports the sliding contacts and the energy friction dissipated (it only grows).
    let text = std::fs::read_to_string(reference.join("macro.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let column = |name: &str| -> Vec<f64> {
        let k = header.iter().position(|h| *h == name).unwrap();
        text.lines()
            .skip(1)
            .map(|l| l.split(',').nth(k).unwrap().parse().unwrap())
            .collect()
    };
    let work = column("friction_work");
    assert!(work.windows(2).all(|w| w[1] >= w[0]) && *work.last().unwrap() > 0.0);
    assert!(column("sliding_contacts").iter().any(|&n| n > 0.0));
    for stop in [3000, 5000] {
        let dir = common::temp_dir("friction", &format!("stop{stop}"));
        let (c, path) =
            common::run_interrupted_at(&scenario, &common::checkpointed(&dir, 777), stop);
        assert!(
            c.contact_history.pairs.len() > 50,
            "the checkpoint at {stop} holds {} frictional pairs",
            c.contact_history.pairs.len()
        );
        resume_run(&c, &path, &common::checkpointed(&dir, 777)).unwrap();
        same(&reference, &dir);
        std::fs::remove_dir_all(&dir).ok();
    }
    for d in [reference, two] {
        std::fs::remove_dir_all(&d).ok();
    }
}

#[test]
fn bad_friction_input_is_refused_with_a_clear_message() {
    let refused = |replace: &str, field: &str, words: &str| {
        let text = common::SMALL_COMPACTION.replace(
            "output: (every: 50),",
            &format!("output: (every: 50),\n{replace}"),
        );
        let e = Scenario::parse(&text, "bad.ron")
            .and_then(|s| s.validate().map(|_| ()))
            .unwrap_err()
            .to_string();
        assert!(e.contains(field) && e.contains(words), "{e}");
    };
    refused(
        "contact: (friction: (grains: -0.5)),",
        "contact.friction.grains",
        ">= 0",
    );
    refused(
        "contact: (friction: (grains: 0.5, stiffness_ratio: 20.0)),",
        "contact.friction.stiffness_ratio",
        "(0, 10]",
    );
    refused(
        "contact: (friction: (each_wall: (0.5, 0.5, -0.1, 0.5))),",
        "contact.friction.each_wall",
        ">= 0",
    );
    refused(
        "planes: [(point: (0.0, 0.0), normal: (0.0, 0.0), friction: 0.5)],",
        "planes[0].normal",
        "non-zero length",
    );
    refused(
        "planes: [(point: (0.0, 0.0), normal: (0.0, 1.0), friction: -1.0)],",
        "planes[0].friction",
        ">= 0",
    );
    // A plane across the box with grains behind it: refused before the first step.
    let text = common::SMALL_COMPACTION.replace(
        "output: (every: 50),",
        "output: (every: 50),\nplanes: [(point: (0.2, 0.2), normal: (1.0, 1.0), friction: 0.5)],",
    );
    let scenario = Scenario::parse(&text, "plane.ron").unwrap();
    scenario.validate().unwrap();
    let e = sdem::run::build_world(&scenario).unwrap_err().to_string();
    assert!(
        e.contains("beyond planes[0]") && e.contains("far side"),
        "{e}"
    );
}

/// 200 grains in a periodic cell, compacted, then sheared past a remap of the cell, with
/// friction `mu` between the grains.
fn frictional_shear(mu: f64) -> Scenario {
    let text = format!(
        r#"
Scenario(
    name: "frictional_shear",
    sample: (count: 200, box_width: 0.45, box_height: 0.45,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    contact: (friction: (grains: {mu})),
    boundary: Periodic,
    loading: [
        Isotropic(rate: Constant(5e-2), until: PackingFraction(0.85)),
        Shear(rate: 5e-2, syy: 2e-3, gain: 0.5, max_rate: 5e-2, until: ShearStrain(0.6)),
    ],
    output: (every: 100),
)
"#
    );
    let s = Scenario::parse(&text, "frictional_shear.ron").unwrap();
    s.validate().unwrap();
    s
}

/// Mean of -sxy_c / p_c over the last quarter of the shear phase's rows.
fn late_stress_ratio(dir: &std::path::Path) -> f64 {
    let text = std::fs::read_to_string(dir.join("macro.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (phase, sxy, p) = (col("phase"), col("sxy_c"), col("p_c"));
    let rows: Vec<Vec<&str>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|r| r[phase] == "shear")
        .collect();
    let late = &rows[rows.len() * 3 / 4..];
    late.iter()
        .map(|r| -r[sxy].parse::<f64>().unwrap() / r[p].parse::<f64>().unwrap())
        .sum::<f64>()
        / late.len() as f64
}

#[test]
fn a_frictional_periodic_shear_resumes_bitwise_across_a_remap_and_resists_more() {
    // Expectations: with histories carried through wraps and the cell's remap, a resumed
    // sheared run is bitwise the uninterrupted one; grain friction raises the shear stress the
    // sample carries at the same normal stress.
    use sdem::run::checkpoint::Checkpoint;
    use sdem::run::{resume_run, run_scenario};
    let scenario = frictional_shear(0.5);
    let reference = common::temp_dir("friction", "shear-ref");
    let summary = common::with_threads(1, || {
        run_scenario(&scenario, &common::checkpointed(&reference, 1_000_000_000))
    })
    .unwrap();
    let end = Checkpoint::read(&reference.join("checkpoint.bin")).unwrap();
    assert!(
        end.periodic.unwrap().tilt < 0.0,
        "the cell was remapped (its tilt went past +1/2)"
    );
    let same = |a: &std::path::Path, b: &std::path::Path| {
        let (ca, cb) = common::assert_same_run(a, b);
        assert_eq!(ca.contact_history, cb.contact_history);
    };
    let two = common::temp_dir("friction", "shear-two");
    common::with_threads(2, || {
        run_scenario(&scenario, &common::checkpointed(&two, 1_000_000_000))
    })
    .unwrap();
    same(&reference, &two);
    for stop in [summary.steps - 3000, summary.steps - 200] {
        let dir = common::temp_dir("friction", &format!("shear-stop{stop}"));
        let (c, path) =
            common::run_interrupted_at(&scenario, &common::checkpointed(&dir, 777), stop);
        assert!(!c.contact_history.pairs.is_empty());
        resume_run(&c, &path, &common::checkpointed(&dir, 777)).unwrap();
        same(&reference, &dir);
        std::fs::remove_dir_all(&dir).ok();
    }
    let frictionless = common::temp_dir("friction", "shear-mu0");
    run_scenario(
        &frictional_shear(0.0),
        &common::checkpointed(&frictionless, 1_000_000_000),
    )
    .unwrap();
    let (with, without) = (
        late_stress_ratio(&reference),
        late_stress_ratio(&frictionless),
    );
    assert!(
        with > 1.3 * without,
        "shear stress ratio {with} with friction against {without} without"
    );
    for d in [reference, two, frictionless] {
        std::fs::remove_dir_all(&d).ok();
    }
}

#[test]
fn every_wall_gets_its_own_coefficient() {
    // The box walls' coefficients (one for all, or one each), then each plane's, in the order
    // of the run's walls.
    let parse = |extra: &str| {
        let text = common::SMALL_COMPACTION.replace(
            "output: (every: 50),",
            &format!("output: (every: 50),\n{extra}"),
        );
        let s = Scenario::parse(&text, "walls.ron").unwrap();
        s.validate().unwrap();
        s
    };
    let s = parse(
        "contact: (friction: (walls: 0.3)), planes: [(point: (0.0, 0.0), normal: (1.0, 1.0), friction: 0.6)],",
    );
    assert_eq!(s.wall_friction(), vec![0.3, 0.3, 0.3, 0.3, 0.6]);
    let s = parse("contact: (friction: (walls: 0.3, each_wall: (0.1, 0.2, 0.0, 0.4))),");
    assert_eq!(s.wall_friction(), vec![0.1, 0.2, 0.0, 0.4]);
    assert!(s.tangential_ratio() > 0.0);
    let walls = s.parameters().friction.expect("frictional walls").walls;
    assert_eq!(&walls[..4], &[0.1, 0.2, 0.0, 0.4]);
    // Frictionless everywhere: no friction at all, and the frictionless time step.
    let s = parse("contact: (friction: (each_wall: (0.0, 0.0, 0.0, 0.0))),");
    assert!(s.parameters().friction.is_none());
    assert_eq!(
        s.critical_time_step(),
        common::small_compaction().critical_time_step()
    );
}
