//! Multi-rate cycles of the adaptive level (issue #16): while some grains deform, the rigid
//! grains out of their reach take one step of twice the deforming grains' step. Momentum,
//! static equilibria, determinism and checkpoints.

use glam::DVec2;
mod common;
use sdem::boundary::periodic::PeriodicBoundary;
use sdem::boundary::walls::{Wall, box_walls};
use sdem::grain::{AdaptiveSettings, Grain, GrainLevel, Material, ModelLevel};
use sdem::integration::parameters::{Adaptive, ModeSettings};
use sdem::integration::{Parameters, World};
use sdem::run::checkpoint::Checkpoint;
use sdem::run::{resume_run, run_scenario};
use sdem::scenario::Scenario;
use std::path::Path;

fn material() -> Material {
    Material {
        young: 1.0,
        poisson: 0.5,
        density: 1.0,
    }
}

/// The adaptive level at `fraction` of each level's critical step for `radius`, with
/// multi-rate cycles on or off.
fn params(radius: f64, fraction: f64, multi_rate: bool) -> Parameters {
    let mut p = Parameters::new(material(), 0.0);
    p.adaptive = Some(Adaptive {
        multi_rate,
        ..Adaptive::fraction_of_critical(
            // Levels that never change: the roles of a cycle follow from where the grains are.
            AdaptiveSettings::HELD,
            fraction,
            &p.material,
            &p.law,
            radius,
            ModeSettings::default(),
        )
    });
    p
}

/// A triangular lattice of `columns x rows` grains of radius 0.5 at spacing 0.97 (every
/// neighbour pressed), in a box far from every grain; the grains whose x is below `split`
/// are at the full level, the others rigid.
fn pressed_lattice(p: Parameters, columns: usize, rows: usize, split: f64) -> World {
    let spacing = 0.97;
    let mut grains = Vec::new();
    for r in 0..rows {
        for c in 0..columns {
            let x = c as f64 * spacing + if r % 2 == 1 { 0.5 * spacing } else { 0.0 };
            let y = r as f64 * spacing * 3f64.sqrt() / 2.0;
            let mut g = Grain::at_rest(DVec2::new(x, y), 0.5);
            // A small shear of the rigid part too, so that every pair has a tangential arm.
            g.omega = 0.01 * ((r * columns + c) % 7) as f64 - 0.03;
            grains.push(g);
        }
    }
    let walls = box_walls(-50.0, 50.0, -50.0, 50.0);
    let levels: Vec<GrainLevel> = grains
        .iter()
        .map(|g| {
            GrainLevel::new(if g.center.x < split {
                ModelLevel::Full
            } else {
                ModelLevel::Rigid
            })
        })
        .collect();
    let mut world = World::new(p, grains, walls);
    world.set_levels(&levels);
    world
}

fn momentum(world: &World) -> (DVec2, f64) {
    let density = world.params.material.density;
    let mut total = DVec2::ZERO;
    let mut scale = 0.0;
    for g in world.grains() {
        total += g.mass(density) * g.velocity;
        scale += g.mass(density) * g.velocity.length();
    }
    (total, scale)
}

#[test]
fn a_cycle_is_taken_only_with_rigid_and_deforming_grains_side_by_side() {
    // Expectation: cycles need the option, a deforming grain, and a quarter of the grains
    // rigid; a cycle lasts twice the full level's step.
    let adaptive = params(0.5, 0.5, true).adaptive.unwrap();
    let full_step = adaptive.dt[ModelLevel::Full.index()];
    assert!(adaptive.dt[0] >= 2.0 * full_step, "{:?}", adaptive.dt);

    let mixed = pressed_lattice(params(0.5, 0.5, true), 12, 8, 5.0);
    assert_eq!(mixed.cycle_substep(), Some(full_step));
    assert_eq!(mixed.params.dt, 2.0 * full_step);

    // A periodic cell takes none (its carry and images are not written for cycles).
    let periodic = pressed_lattice(params(0.5, 0.5, true), 12, 8, 5.0)
        .with_periodic(PeriodicBoundary::default());
    assert_eq!(periodic.cycle_substep(), None);
    assert_eq!(periodic.params.dt, full_step);

    let off = pressed_lattice(params(0.5, 0.5, false), 12, 8, 5.0);
    assert_eq!(off.cycle_substep(), None);
    assert_eq!(off.params.dt, full_step);

    let all_rigid = pressed_lattice(params(0.5, 0.5, true), 12, 8, -1.0);
    assert_eq!(all_rigid.cycle_substep(), None);
    assert_eq!(all_rigid.params.dt, adaptive.dt[0]);

    // 12 x 8 grains, x < 10 full: only the last two columns (16 grains, under a quarter) rigid.
    let mostly_full = pressed_lattice(params(0.5, 0.5, true), 12, 8, 9.5);
    assert!(
        mostly_full
            .levels()
            .iter()
            .filter(|l| l.level == ModelLevel::Rigid)
            .count()
            < 24
    );
    assert_eq!(mostly_full.cycle_substep(), None);
    assert_eq!(mostly_full.params.dt, full_step);
}

#[test]
fn cycles_keep_the_momentum_of_a_free_mixed_packing() {
    // Expectation: in each cycle a slow grain and its fast neighbour exchange the impulse of
    // one force over the cycle's length (the fast grain meets the first half's force in both
    // halves), so the total momentum of a free packing stays zero, as in plain steps, while
    // the pressed lattice flies apart. A pass that recomputed the fast grain's side of such a
    // pair in the second half would break it.
    let mut world = pressed_lattice(params(0.5, 0.5, true), 16, 10, 7.0);
    let mut cycles = 0;
    for step in 0..400 {
        cycles += world.cycle_substep().is_some() as u32;
        world.step().expect("stable");
        // Each cycle has slow grains; while the lattice is pressed, the rigid grains next to
        // the full ones are fast (the ten of the column beside them).
        let roles = world.cycle_roles();
        assert!(roles.iter().any(|&fast| !fast), "no slow grain");
        let fast = roles.iter().filter(|&&fast| fast).count() as u64;
        assert_eq!(world.totals.fast_grains, fast);
        if step == 0 {
            let rigid = |g: usize| world.levels()[g].level == ModelLevel::Rigid;
            let fast_rigid = (0..roles.len()).filter(|&g| roles[g] && rigid(g)).count();
            assert_eq!(fast_rigid, 10);
        }
        let (total, scale) = momentum(&world);
        assert!(
            total.length() <= 1e-12 * scale.max(1e-300),
            "step {}: momentum {total} against {scale}",
            world.step
        );
    }
    assert_eq!(cycles, 400, "every step a cycle");
    let (_, scale) = momentum(&world);
    assert!(scale > 1e-3, "the lattice moved ({scale})");
}

/// A column in a channel as wide as a grain: a full grain on the floor under four rigid
/// discs, pressed by a ceiling that comes down by `press` over 300 time units and stays;
/// returns the world once everything has settled. The discs next to the full grain take the
/// cycle's two substeps, those further up one.
fn column(multi_rate: bool) -> World {
    let r = 0.5;
    let p = params(r, 0.5, multi_rate);
    let grains: Vec<Grain> = (0..5)
        .map(|k| Grain::at_rest(DVec2::new(0.0, (2 * k + 1) as f64 * r), r))
        .collect();
    let height = 10.0 * r;
    let walls = vec![
        Wall::new(DVec2::new(0.0, 0.0), DVec2::Y),
        Wall::new(DVec2::new(0.0, height), -DVec2::Y),
        Wall::new(DVec2::new(-r, 0.0), DVec2::X),
        Wall::new(DVec2::new(r, 0.0), -DVec2::X),
    ];
    let mut world = World::new(p, grains, walls);
    let mut levels = vec![GrainLevel::new(ModelLevel::Rigid); 5];
    levels[0] = GrainLevel::new(ModelLevel::Full);
    world.set_levels(&levels);
    let press = 0.02;
    let (approach, settle) = (300.0, 1500.0);
    while world.time < approach + settle {
        let dt = world.params.dt;
        let target = height - press * ((world.time + dt) / approach).min(1.0);
        world.walls[1].velocity.y = (target - world.walls[1].point.y) / dt;
        world.step().expect("stable");
    }
    world
}

#[test]
fn a_pressed_column_settles_to_the_same_equilibrium_with_or_without_cycles() {
    // Expectation: a static equilibrium does not depend on how time was integrated to reach
    // it: the full grain's strains, the ceiling's force and the grains' places agree to a
    // millionth of their size.
    let plain = column(false);
    let cycled = column(true);
    assert!(
        cycled.cycle_substep().is_some(),
        "the cycled run ends in a cycle"
    );
    // The full grain and the disc on it take two substeps, the discs above one.
    assert_eq!(cycled.cycle_roles(), &[true, true, false, false, false]);
    assert!(plain.cycle_substep().is_none());
    let (a, b) = (&plain.grains()[0], &cycled.grains()[0]);
    let squeeze = (a.eps1 - a.eps2).abs();
    assert!(squeeze > 1e-3, "the full grain is squeezed ({a:?})");
    for (x, y) in [(a.eps1, b.eps1), (a.eps2, b.eps2)] {
        assert!((x - y).abs() <= 1e-6 * squeeze, "strains {x} and {y}");
    }
    let (fa, fb) = (plain.totals.wall_force[1], cycled.totals.wall_force[1]);
    assert!(fa > 1e-4, "the ceiling carries a load ({fa})");
    assert!((fa - fb).abs() <= 1e-6 * fa, "ceiling force {fa} and {fb}");
    for (g, h) in plain.grains().iter().zip(cycled.grains()) {
        assert!(
            g.center.distance(h.center) <= 1e-6,
            "{} and {}",
            g.center,
            h.center
        );
    }
}

/// 600 grains compacted fast through jamming with multi-rate cycles, then relaxed.
const SMALL: &str = r#"
Scenario(
    name: "multi_rate_small",
    sample: (count: 600, box_width: 0.78, box_height: 0.78,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    model: Adaptive(confirm: 50, dwell: 200, multi_rate: true),
    time_step: FractionOfCritical(0.6),
    loading: [
        Isotropic(rate: Constant(5e-2), until: PackingFraction(0.86), affine: true),
        Relax(until: Steps(500)),
    ],
    output: (every: 100),
)
"#;

fn scenario(skin: Option<f64>) -> Scenario {
    let mut s = Scenario::parse(SMALL, "multi_rate_small.ron").unwrap();
    if let Some(skin) = skin {
        s.contact.skin = skin;
    }
    s.validate().unwrap();
    assert!(s.model.multi_rate());
    s
}

fn temp_dir(name: &str) -> common::TempDir {
    common::temp_dir("multi-rate", name)
}

fn assert_same_run(a_dir: &Path, b_dir: &Path) {
    let (a, b) = common::assert_same_run(a_dir, b_dir);
    assert!(a.complete && b.complete);
    assert_eq!((a.step, a.time.to_bits()), (b.step, b.time.to_bits()));
    assert_eq!(a.runner, b.runner);
}

#[test]
fn cycled_runs_are_deterministic_resume_bitwise_and_do_not_depend_on_the_skin() {
    let options = |dir: &Path| common::checkpointed(dir, 1_000_000_000);
    let mut dirs = Vec::new();
    for threads in [1, 2] {
        let dir = temp_dir(&format!("threads{threads}"));
        let summary =
            common::with_threads(threads, || run_scenario(&scenario(None), &options(&dir)))
                .unwrap();
        let stats = summary.adaptive.expect("adaptive statistics");
        assert!(stats.steps_by_highest_level[2] > 100, "{stats:?}");
        // Cycles were taken, each with some grains taking one substep.
        assert!(stats.cycles > 100, "{stats:?}");
        assert!(
            stats.cycle_fast_grains > 0 && stats.cycle_fast_grains < stats.cycles * 600,
            "{stats:?}"
        );
        dirs.push(dir);
    }
    assert_same_run(&dirs[0], &dirs[1]);
    // The run took cycles: its time passed faster than its steps at the full level's step.
    let c = Checkpoint::read(&dirs[0].join("checkpoint.bin")).unwrap();
    assert!(c.step > 1000);

    // A thicker skin lists more pairs and rebuilds less often: the same run (the roles of a
    // cycle come from the gaps, not from the list).
    let thick = temp_dir("thick");
    let skin = scenario(None).contact.skin;
    run_scenario(&scenario(Some(2.0 * skin)), &options(&thick)).unwrap();
    assert_same_run(&dirs[0], &thick);

    // Stopped and resumed (with the other thread count): bitwise the uninterrupted run.
    for stop in [c.step / 2, c.step - 50] {
        let dir = temp_dir(&format!("stop{stop}"));
        let (c, path) = common::run_interrupted_at(&scenario(None), &options(&dir), stop);
        common::with_threads(2, || resume_run(&c, &path, &options(&dir))).unwrap();
        assert_same_run(&dirs[0], &dir);
    }
}

#[test]
fn multi_rate_is_refused_with_friction_and_in_a_periodic_cell() {
    // Expectation: a clear error naming the field, for the two settings cycles do not cover;
    // the same scenarios validate without the option.
    for file in ["isotropic_A_friction.ron", "isotropic_A_periodic.ron"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenarios")
            .join(file);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("model: Adaptive(),"), "{file}");
        Scenario::parse(&text, file).unwrap().validate().unwrap();
        let cycled = text.replace("model: Adaptive(),", "model: Adaptive(multi_rate: true),");
        let error = Scenario::parse(&cycled, file)
            .unwrap()
            .validate()
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("model.Adaptive.multi_rate"),
            "{file}: {error}"
        );
        let why = if file.contains("friction") {
            "friction"
        } else {
            "periodic"
        };
        assert!(error.contains(why), "{file}: {error}");
    }
}
