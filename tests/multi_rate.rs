//! Multi-rate steps of the adaptive level (issue #16): while some grains deform, the rigid ones
//! take one step of twice the deforming grains' step (`World::step_cycle`).

mod common;
use common::grain_bits;
use glam::DVec2;
use sdem::grain::{AdaptiveSettings, GrainLevel, ModelLevel};
use sdem::integration::parameters::{Adaptive, ModeSettings};
use sdem::integration::{Instability, World};
use sdem::run::bench::dense_packing;
use sdem::run::checkpoint::Checkpoint;
use sdem::run::{resume_run, run_scenario};
use sdem::scenario::Scenario;
use std::path::Path;

/// Levels that never change: every grain stays where `set_levels` puts it.
fn frozen(multi_rate: bool) -> AdaptiveSettings {
    AdaptiveSettings {
        volumetric_up: 1e9,
        volumetric_down: 0.0,
        full_up: 1e9,
        full_down: 0.0,
        dwell: u32::MAX,
        multi_rate,
        ..Default::default()
    }
}

/// The dense bench packing (400 grains, six contacts each) with the adaptive level at
/// `fraction` of each level's critical step, grains `g` with `deforming(g)` at the full level.
fn dense(fraction: f64, multi_rate: bool, deforming: impl Fn(usize) -> bool) -> World {
    let packed = dense_packing(400, 1.0);
    let mut p = packed.params;
    p.adaptive = Some(Adaptive::fraction_of_critical(
        frozen(multi_rate),
        fraction,
        &p.material,
        &p.law,
        0.5 * 0.024,
        ModeSettings::default(),
    ));
    let mut world = World::new(p, packed.grains.clone(), packed.walls.clone());
    let levels: Vec<GrainLevel> = (0..400)
        .map(|g| {
            GrainLevel::new(if deforming(g) {
                ModelLevel::Full
            } else {
                ModelLevel::Rigid
            })
        })
        .collect();
    world.set_levels(&levels);
    world
}

#[test]
fn a_cycle_with_every_grain_deforming_is_two_plain_steps() {
    // Expectation: with no rigid grain a cycle advances every grain twice by the full level's
    // step, from frames and pairs computed afresh each time: exactly two plain steps.
    let mut plain = dense(0.4, false, |_| true);
    let mut cycled = dense(0.4, true, |_| true);
    let substep = plain.params.dt;
    assert_eq!(cycled.params.dt, 2.0 * substep, "a cycle is two full steps");
    for _ in 0..50 {
        cycled.step().unwrap();
        plain.step().unwrap();
        plain.step().unwrap();
    }
    assert_eq!(cycled.step, 50);
    assert_eq!(plain.step, 100);
    // The clock adds 2 dt once where the plain steps add dt twice: equal to rounding.
    assert!((cycled.time - plain.time).abs() < 1e-12 * plain.time);
    assert_eq!(grain_bits(&cycled.grains), grain_bits(&plain.grains));
    assert_eq!(cycled.totals.contacts, plain.totals.contacts);
    assert_eq!(
        cycled.totals.wall_force.map(f64::to_bits),
        plain.totals.wall_force.map(f64::to_bits)
    );
}

#[test]
fn no_cycle_while_every_grain_is_rigid() {
    // Expectation: the rigid step alone, as without multi-rate steps: bitwise the same run.
    let mut plain = dense(0.4, false, |_| false);
    let mut cycled = dense(0.4, true, |_| false);
    assert_eq!(cycled.params.dt, plain.params.dt);
    for _ in 0..50 {
        cycled.step().unwrap();
        plain.step().unwrap();
    }
    assert_eq!(grain_bits(&cycled.grains), grain_bits(&plain.grains));
}

#[test]
fn a_mixed_packing_keeps_its_momentum_and_runs_stable_at_the_cycle_length() {
    // Expectation: a pair's impulse over a cycle is the same on both sides (the deforming side
    // takes F1 dt + F2 dt, a rigid side the mean of F1 and F2 over 2 dt), so with the walls
    // pushing symmetrically the total momentum moves only by the walls' impulses; without
    // walls (below) it stays at zero to rounding. And the cycle, 2 x 0.8 of the full level's
    // estimate = 0.72 of the rigid one, runs stable on the densest state, half the grains
    // deforming in stripes of four.
    let mut world = dense(0.8, true, |g| (g / 4) % 2 == 0);
    world.walls.clear();
    // A kick to every grain: momenta of one size, alternating in sign, summing to zero.
    let kick = DVec2::new(0.01, -0.007) * world.grains[0].mass(1.0);
    for (g, grain) in world.grains.iter_mut().enumerate() {
        let sign = if g % 2 == 0 { 1.0 } else { -1.0 };
        grain.velocity = kick * sign / grain.mass(1.0);
    }
    let momentum = |w: &World| {
        w.grains
            .iter()
            .map(|g| g.mass(w.params.material.density) * g.velocity)
            .fold(DVec2::ZERO, |a, b| a + b)
    };
    let scale: f64 = world
        .grains
        .iter()
        .map(|g| g.mass(1.0) * g.velocity.length())
        .sum();
    let before = momentum(&world);
    assert!(before.length() < 1e-12 * scale);
    let mut contacts = 0;
    for _ in 0..3000 {
        contacts = contacts.max(world.step().expect("stable at the cycle length").contacts);
    }
    assert_eq!(world.totals.level_counts, [200, 0, 200]);
    assert!(contacts > 800, "contacts {contacts}");
    let drift = (momentum(&world) - before).length();
    assert!(
        drift < 1e-12 * scale,
        "momentum moved by {drift:e} (scale {scale:e})"
    );
}

#[test]
fn a_cycle_too_long_for_the_packing_is_stopped() {
    // Expectation: the cycle's stability comes from its length, not from the scheme: at 2 x 2.0
    // of the full level's estimate (1.8 x the rigid one) the rigid grains run away, and the
    // engine stops the run with a diagnostic.
    let mut world = dense(2.0, true, |g| g % 2 == 0);
    let outcome = (0..3000).try_for_each(|_| world.step().map(|_| ()));
    let err = outcome.expect_err("unstable");
    assert!(!matches!(err, Instability::NonFinite { .. }), "{err}");
}

/// 600 grains compacted fast through jamming, then relaxed, with multi-rate steps.
const SMALL: &str = r#"
Scenario(
    name: "multi_rate_small",
    sample: (count: 600, box_width: 0.78, box_height: 0.78,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    model: Adaptive(confirm: 50, dwell: 200, multi_rate: true),
    loading: [
        Isotropic(rate: Constant(5e-2), until: PackingFraction(0.86)),
        Relax(until: Steps(300)),
    ],
    output: (every: 100),
)
"#;

fn assert_same_run(a_dir: &Path, b_dir: &Path) {
    let a = Checkpoint::read(&a_dir.join("checkpoint.bin")).unwrap();
    let b = Checkpoint::read(&b_dir.join("checkpoint.bin")).unwrap();
    assert!(a.complete && b.complete);
    assert_eq!(a.step, b.step);
    assert_eq!(a.time.to_bits(), b.time.to_bits());
    assert_eq!(grain_bits(&a.grains), grain_bits(&b.grains));
    for file in ["macro.csv", "grains.csv"] {
        let x = std::fs::read(a_dir.join(file)).unwrap();
        let y = std::fs::read(b_dir.join(file)).unwrap();
        assert!(x == y, "{file} differs between {a_dir:?} and {b_dir:?}");
    }
}

#[test]
fn multi_rate_runs_are_deterministic_and_resume_bitwise() {
    let scenario = Scenario::parse(SMALL, "multi_rate_small.ron").unwrap();
    scenario.validate().unwrap();
    assert!(scenario.model.adaptive().unwrap().multi_rate);
    let mut dirs = Vec::new();
    for threads in [1, 2] {
        let dir = common::temp_dir("multi-rate", &format!("threads{threads}"));
        let summary = common::with_threads(threads, || {
            run_scenario(&scenario, &common::checkpointed(&dir, 1_000_000_000))
        })
        .unwrap();
        let stats = summary.adaptive.expect("adaptive statistics");
        // Cycles were taken (a step of the full level) and so were rigid steps.
        assert!(stats.steps_by_highest_level[0] > 100, "{stats:?}");
        assert!(stats.steps_by_highest_level[2] > 100, "{stats:?}");
        dirs.push(dir);
    }
    assert_same_run(&dirs[0], &dirs[1]);
    let total = Checkpoint::read(&dirs[0].join("checkpoint.bin"))
        .unwrap()
        .step;
    for stop in [total / 2, total - 50] {
        let dir = common::temp_dir("multi-rate", &format!("stop{stop}"));
        let options = common::checkpointed(&dir, 1_000_000_000);
        let (c, path) = common::run_interrupted_at(&scenario, &options, stop);
        common::with_threads(2, || resume_run(&c, &path, &options)).unwrap();
        assert_same_run(&dirs[0], &dir);
    }
}

#[test]
fn multi_rate_steps_refuse_friction_and_periodic_cells() {
    let text = SMALL.replace(
        "material: (young: 1.0, poisson: 0.5, density: 1.0),",
        "material: (young: 1.0, poisson: 0.5, density: 1.0),\n    contact: (friction: (grains: 0.5)),",
    );
    let scenario = Scenario::parse(&text, "friction.ron").unwrap();
    let err = scenario.validate().unwrap_err().to_string();
    assert!(err.contains("model.Adaptive.multi_rate"), "{err}");
    assert!(err.contains("friction"), "{err}");
}
