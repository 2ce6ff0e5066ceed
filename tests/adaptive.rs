//! The adaptive model level (issue #6): hysteresis, frozen shapes, agreement with the full
//! model, the time step it picks, determinism and checkpoints.

use glam::DVec2;
mod common;
use sdem::boundary::walls::{Wall, box_walls};
use sdem::grain::adaptive::stress_invariants;
use sdem::grain::{AdaptiveSettings, Grain, GrainLevel, Material, ModelLevel};
use sdem::integration::parameters::{Adaptive, ModeSettings, critical_time_step};
use sdem::integration::{Instability, Parameters, World};
use sdem::run::bench::dense_packing;
use sdem::run::checkpoint::Checkpoint;
use sdem::run::{RunOptions, resume_run, run_scenario};
use sdem::scenario::{Model, Scenario};
use std::path::Path;

fn material(poisson: f64) -> Material {
    Material {
        young: 1.0,
        poisson,
        density: 1.0,
    }
}

/// Parameters of the adaptive level at 0.4 of each level's critical step for `radius`.
fn adaptive_params(poisson: f64, radius: f64, settings: AdaptiveSettings) -> Parameters {
    let mut p = Parameters::new(material(poisson), 0.0);
    p.adaptive = Some(Adaptive::fraction_of_critical(
        settings,
        0.4,
        &p.material,
        &p.law,
        radius,
        ModeSettings::default(),
    ));
    p
}

/// Level, mean and deviatoric contact stress of grain 0 after each step.
struct Trace {
    levels: Vec<ModelLevel>,
    deviator: Vec<f64>,
}

/// One grain of radius 0.5 between a floor and a ceiling at `y = ±(0.5 - u(t))`: the walls
/// approach to `u = 2e-3`, oscillate about it (amplitude 1e-3, period 150) for four periods,
/// then withdraw to `u = -0.05` (no contact).
fn oscillating_squeeze(p: Parameters) -> (World, Trace) {
    let r = 0.5;
    let walls = vec![
        Wall::new(DVec2::new(0.0, -r), DVec2::Y),
        Wall::new(DVec2::new(0.0, r), -DVec2::Y),
    ];
    let mut world = World::new(p, vec![Grain::at_rest(DVec2::ZERO, r)], walls);
    let period = 150.0;
    let u = |t: f64| -> f64 {
        if t < 100.0 {
            2e-3 * t / 100.0
        } else if t < 100.0 + 4.0 * period {
            2e-3 + 1e-3 * (2.0 * std::f64::consts::PI * (t - 100.0) / period).sin()
        } else {
            (2e-3 - 0.052 * (t - 100.0 - 4.0 * period) / 100.0).max(-0.05)
        }
    };
    let mut trace = Trace {
        levels: Vec::new(),
        deviator: Vec::new(),
    };
    while world.time < 100.0 + 4.0 * period + 300.0 {
        // Wall velocities that bring the gap to u(t + dt) over this step.
        let dt = world.params.dt;
        let target = r - u(world.time + dt);
        world.walls[0].velocity.y = (-target - world.walls[0].point.y) / dt;
        world.walls[1].velocity.y = (target - world.walls[1].point.y) / dt;
        world.step().expect("stable");
        let (_, deviator) = stress_invariants(world.grain_stress[0].external);
        trace.levels.push(world.levels()[0].level);
        trace.deviator.push(deviator);
    }
    (world, trace)
}

fn transitions(levels: &[ModelLevel]) -> Vec<(usize, ModelLevel, ModelLevel)> {
    levels
        .windows(2)
        .enumerate()
        .filter(|(_, w)| w[0] != w[1])
        .map(|(k, w)| (k + 1, w[0], w[1]))
        .collect()
}

#[test]
fn a_grain_loaded_across_the_threshold_and_back_changes_level_once_each_way() {
    // Expectation: the oscillating squeeze takes the contact stress above `up` and back below
    // it several times while staying above `down` (tau swings over about [5.5e-4, 1.7e-3]);
    // with hysteresis the grain goes up once (to Full: a uniaxial load has tau = p) and down
    // once, after the walls withdraw.
    let (up, down) = (1.1e-3, 2e-4);
    let settings = AdaptiveSettings {
        volumetric_up: up,
        volumetric_down: down,
        full_up: up,
        full_down: down,
        confirm: 20,
        dwell: 200,
    };
    let (world, trace) = oscillating_squeeze(adaptive_params(0.3, 0.5, settings));
    // The load really crosses `up` back and forth while loaded (else the test proves nothing).
    let crossings = trace
        .deviator
        .windows(2)
        .filter(|w| (w[0] > up) != (w[1] > up))
        .count();
    assert!(crossings >= 6, "the stress crossed `up` {crossings} times");
    let changes = transitions(&trace.levels);
    assert_eq!(
        changes.iter().map(|c| (c.1, c.2)).collect::<Vec<_>>(),
        vec![
            (ModelLevel::Rigid, ModelLevel::Full),
            (ModelLevel::Full, ModelLevel::Rigid)
        ],
        "{changes:?}"
    );
    // Up only after `confirm` steps above `up`; down only once the stress has fallen below
    // `down`, and not before the dwell.
    // (trace[k] is the level chosen with the stress trace.deviator[k] of the same step.)
    let (k_up, k_down) = (changes[0].0, changes[1].0);
    assert!(trace.deviator[k_up - 20..=k_up].iter().all(|&t| t > up));
    assert!(trace.deviator[k_up - 21] <= up);
    assert!(trace.deviator[k_down] < down);
    assert!(trace.deviator[k_up + 1..k_down].iter().any(|&t| t < up));
    assert_eq!(world.levels()[0].level, ModelLevel::Rigid);

    // The same load without hysteresis (down = up, no confirmation, no dwell) flickers.
    let flicker = AdaptiveSettings {
        volumetric_down: up,
        full_down: up,
        confirm: 0,
        dwell: 0,
        ..settings
    };
    let (_, trace) = oscillating_squeeze(adaptive_params(0.3, 0.5, flicker));
    assert!(transitions(&trace.levels).len() >= 6);
}

#[test]
fn the_time_step_follows_the_highest_level_present() {
    // Expectation: dt = 0.4 x the rigid critical step while every grain is rigid,
    // 0.4 x the full one while one grain deforms. The rigid one is larger by sqrt(5) (the
    // contact mode's coupling) and more for these compressible grains (nu = 0.3), whose
    // volumetric strain mode adds to the deformable grain's contact mode:
    // omega_full^2 = 5 omega_rigid^2 + (2/R)^2 2 kappa / rho.
    let settings = AdaptiveSettings {
        volumetric_up: 5e-4,
        volumetric_down: 1e-4,
        full_up: 5e-4,
        full_down: 1e-4,
        confirm: 20,
        dwell: 200,
    };
    let p = adaptive_params(0.3, 0.5, settings);
    let m = p.material;
    let rigid = 0.4 * critical_time_step(&m, &p.law, 0.5, ModelLevel::Rigid);
    let full = 0.4 * critical_time_step(&m, &p.law, 0.5, ModelLevel::Full);
    let omega_rigid = 2.0 / (rigid / 0.4);
    let kappa = m.young / (3.0 - 6.0 * m.poisson);
    let omega_strain_squared = (2.0f64 / 0.5).powi(2) * 2.0 * kappa / m.density;
    let expected = (5.0 + omega_strain_squared / (omega_rigid * omega_rigid)).sqrt();
    assert!((rigid / full - expected).abs() < 1e-12 * expected);
    assert!(rigid / full > 5f64.sqrt());
    let world = World::new(p, vec![Grain::at_rest(DVec2::ZERO, 0.5)], Vec::new());
    assert_eq!(world.params.dt, rigid);
    let (world, trace) = oscillating_squeeze(p);
    // Ends rigid again: back to the large step.
    assert_eq!(world.params.dt, rigid);
    assert!(trace.levels.contains(&ModelLevel::Full));
    let mut w = world.clone();
    w.set_levels(&[GrainLevel::new(ModelLevel::Full)]);
    assert_eq!(w.params.dt, full);
}

#[test]
fn stepping_down_holds_the_shape() {
    // Expectation: a deformed full grain without contacts steps down to rigid (no dwell here:
    // at once) and keeps its strains and alpha exactly (held, not reset), with zero strain
    // rates.
    let settings = AdaptiveSettings {
        dwell: 0,
        ..Default::default()
    };
    let mut grain = Grain::at_rest(DVec2::ZERO, 0.5);
    grain.eps1 = 0.02;
    grain.eps2 = -0.015;
    grain.alpha = 0.3;
    grain.eps1_rate = 1e-3;
    grain.alpha_rate = 0.01;
    let mut world = World::new(adaptive_params(0.3, 0.5, settings), vec![grain], Vec::new());
    world.set_levels(&[GrainLevel::new(ModelLevel::Full)]);
    let mut at_step_down = None;
    for _ in 0..200 {
        world.step().unwrap();
        if world.levels()[0].level == ModelLevel::Rigid && at_step_down.is_none() {
            at_step_down = Some(world.grains()[0]);
            // The step that decides integrates at the old level: the full law moved the
            // strains by one step (towards the circle), no jump back to it.
            let g = world.grains()[0];
            assert!(g.eps1 - g.eps2 > 0.03, "{g:?}");
        }
    }
    let held = at_step_down.expect("the free grain steps down");
    let g = world.grains()[0];
    assert_eq!(
        [g.eps1, g.eps2, g.alpha].map(f64::to_bits),
        [held.eps1, held.eps2, held.alpha].map(f64::to_bits)
    );
    assert_eq!([g.eps1_rate, g.eps2_rate, g.alpha_rate], [0.0; 3]);

    // Level 1 holds the deviator and alpha while the mean strain evolves: a deformed grain
    // pinned at Volumetric (full_up out of reach) squeezed isotropically by four walls.
    let pinned = AdaptiveSettings {
        full_up: 1.0,
        full_down: 1.0,
        ..settings
    };
    let mut grain = Grain::at_rest(DVec2::ZERO, 0.5);
    grain.eps1 = 0.01;
    grain.eps2 = -0.01;
    grain.alpha = 0.3;
    let mut world = World::new(
        adaptive_params(0.3, 0.5, pinned),
        vec![grain],
        box_walls(-0.48, 0.48, -0.48, 0.48),
    );
    world.set_levels(&[GrainLevel::new(ModelLevel::Volumetric)]);
    for _ in 0..2000 {
        world.step().unwrap();
        assert_eq!(world.levels()[0].level, ModelLevel::Volumetric);
    }
    let g = world.grains()[0];
    assert!(
        0.5 * (g.eps1 + g.eps2) < -1e-3,
        "the mean strain evolved: {g:?}"
    );
    assert!(((g.eps1 - g.eps2) - 0.02).abs() < 1e-14, "{g:?}");
    assert_eq!(g.alpha.to_bits(), 0.3f64.to_bits());
    assert_eq!(g.alpha_rate, 0.0);
}

#[test]
fn adaptive_matches_full_on_a_grain_under_isotropic_load() {
    // Expectation: under a sustained isotropic load the adaptive grain leaves the rigid level
    // (for Volumetric: the deviatoric stress stays below full_up) and settles where the full
    // model does. Tolerance as in engine_physics' level test: the volumetric grain is an exact
    // circle, the full one its inscribed polygon, whose contact depth is short of the circle's
    // by at most the sagitta of an edge, R (1 - cos(dbeta/2)), twice over: the strains (depths
    // over R) differ by at most that, and the wall forces, which the strain sets, by that
    // much relative to the strain.
    let full_p = {
        let mut p = Parameters::new(material(0.3), 0.0);
        p.dt = 0.4 * critical_time_step(&p.material, &p.law, 0.5, ModelLevel::Full);
        p
    };
    let walls = box_walls(-0.47, 0.47, -0.47, 0.47);
    let grains = vec![Grain::at_rest(DVec2::ZERO, 0.5)];
    let mut full = World::new(full_p, grains.clone(), walls.clone());
    let mut adaptive = World::new(
        adaptive_params(0.3, 0.5, AdaptiveSettings::default()),
        grains,
        walls,
    );
    while full.time < 400.0 {
        full.step().unwrap();
    }
    while adaptive.time < 400.0 {
        adaptive.step().unwrap();
    }
    assert_eq!(adaptive.levels()[0].level, ModelLevel::Volumetric);
    let (a, b) = (full.grains()[0], adaptive.grains()[0]);
    let sagitta = 1.0 - (0.5 * full.contours.dbeta()).cos();
    let difference = (a.eps1 - b.eps1).abs();
    assert!(
        difference < 2.0 * sagitta,
        "strains differ by {difference:e}: full {a:?} adaptive {b:?}"
    );
    let force = |w: &World| w.totals.wall_force[0];
    let relative = (force(&full) - force(&adaptive)).abs() / force(&full);
    assert!(
        relative < 2.0 * sagitta / a.eps1.abs(),
        "wall force differs by {relative:e}"
    );
}

#[test]
fn rigid_step_is_stable_on_a_dense_packing_of_rigid_grains() {
    // Expectation (SPEC §9, as tests/stability.rs for the full model): while every grain is
    // rigid the adaptive level takes 0.4 x the rigid critical step, sqrt(5) x the full one.
    // The rigid estimate must hold on the densest state, where every grain has six contacts:
    // stable at 0.8 of it, stopped with a diagnostic well above it.
    let dense = dense_packing(400, 1.0);
    let never = AdaptiveSettings {
        volumetric_up: 1e9,
        volumetric_down: 1e9,
        full_up: 1e9,
        full_down: 1e9,
        ..Default::default()
    };
    let run = |fraction: f64| -> Result<World, Instability> {
        let mut p = dense.params;
        p.adaptive = Some(Adaptive::fraction_of_critical(
            never,
            fraction,
            &p.material,
            &p.law,
            0.5 * 0.024,
            ModeSettings::default(),
        ));
        let mut world = World::new(p, dense.grains().to_vec(), dense.walls.clone());
        for _ in 0..3000 {
            world.step()?;
        }
        Ok(world)
    };
    let world = run(0.8).expect("stable below the rigid estimate");
    assert!(world.totals.contacts > 800, "{}", world.totals.contacts);
    assert_eq!(world.totals.level_counts, [400, 0, 0]);
    assert!(run(2.5).is_err());
}

// ---------------------------------------------------------------------------------------------
// Runs: determinism, checkpoints.

/// 600 grains (three chunks of the grain pass) compacted fast through jamming, then relaxed.
const SMALL: &str = r#"
Scenario(
    name: "adaptive_small",
    sample: (count: 600, box_width: 0.78, box_height: 0.78,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    model: Adaptive(confirm: 50, dwell: 200),
    loading: [
        Isotropic(rate: Constant(5e-2), until: PackingFraction(0.86)),
        Relax(until: Steps(500)),
    ],
    output: (every: 100),
)
"#;

fn scenario() -> Scenario {
    let s = Scenario::parse(SMALL, "adaptive_small.ron").unwrap();
    s.validate().unwrap();
    assert!(s.model.adaptive().is_some());
    s
}

fn temp_dir(name: &str) -> common::TempDir {
    common::temp_dir("adaptive", name)
}

fn options(out: &Path, every: u64) -> RunOptions {
    common::checkpointed(out, every)
}

fn assert_same_run(a_dir: &Path, b_dir: &Path) {
    let (a, b) = common::assert_same_run(a_dir, b_dir);
    assert!(a.complete && b.complete);
    assert_eq!((a.step, a.time.to_bits()), (b.step, b.time.to_bits()));
    assert_eq!(a.runner, b.runner);
}

/// Level counts of each macro.csv row.
fn level_rows(dir: &Path) -> Vec<[u64; 3]> {
    let text = std::fs::read_to_string(dir.join("macro.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let cols = [
        col("grains_rigid"),
        col("grains_volumetric"),
        col("grains_full"),
    ];
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            cols.map(|c| f[c].parse().unwrap())
        })
        .collect()
}

#[test]
fn adaptive_runs_are_deterministic_and_resume_bitwise() {
    let scenario = scenario();
    // 1 and 2 threads: bitwise the same run.
    let mut dirs = Vec::new();
    for threads in [1, 2] {
        let dir = temp_dir(&format!("threads{threads}"));
        let summary = common::with_threads(threads, || {
            run_scenario(&scenario, &options(&dir, 1_000_000_000))
        })
        .unwrap();
        let stats = summary.adaptive.expect("adaptive statistics");
        // Both time steps were used, and grains sat at every level at some point.
        assert!(stats.steps_by_highest_level[0] > 100, "{stats:?}");
        assert!(stats.steps_by_highest_level[2] > 100, "{stats:?}");
        assert!(
            stats.grain_steps_by_level.iter().all(|&n| n > 0),
            "{stats:?}"
        );
        dirs.push(dir);
    }
    assert_same_run(&dirs[0], &dirs[1]);
    let rows = level_rows(&dirs[0]);
    assert!(rows.iter().all(|r| r.iter().sum::<u64>() == 600));
    assert_eq!(rows[0], [600, 0, 0]);
    let mixed = rows.iter().position(|r| r[0] > 0 && r[2] > 0);
    assert!(mixed.is_some(), "no row with both rigid and full grains");
    let summary = std::fs::read_to_string(dirs[0].join("summary.txt")).unwrap();
    assert!(
        summary.contains("adaptive_steps_highest_rigid = "),
        "{summary}"
    );

    // Stopped and resumed (with the other thread count): bitwise the uninterrupted run, at a
    // step where every grain is still rigid and at one where the levels are mixed.
    let total = Checkpoint::read(&dirs[0].join("checkpoint.bin"))
        .unwrap()
        .step;
    let mixed_step: u64 = {
        let text = std::fs::read_to_string(dirs[0].join("macro.csv")).unwrap();
        let line = text.lines().nth(1 + mixed.unwrap()).unwrap();
        line.split(',').next().unwrap().parse().unwrap()
    };
    for stop in [500, mixed_step + 37, total - 100] {
        let dir = temp_dir(&format!("stop{stop}"));
        let (c, path) = common::run_interrupted_at(&scenario, &options(&dir, 1_000_000_000), stop);
        assert_eq!(c.runner.levels.len(), 600);
        common::with_threads(2, || resume_run(&c, &path, &options(&dir, 1_000_000_000))).unwrap();
        assert_same_run(&dirs[0], &dir);
        std::fs::remove_dir_all(&dir).ok();
    }
    for d in dirs {
        std::fs::remove_dir_all(&d).ok();
    }
}

#[test]
fn a_run_without_level_columns_resumes_with_them() {
    // Expectation: a checkpoint and macro.csv of an sdem before the adaptive level (no level
    // columns, no z_nr3, no levels in the checkpoint) resume; the kept rows get the fixed
    // level's counts and z_nr3 = nan, and the result is otherwise the uninterrupted run.
    resumes_an_older_macro_csv(4, sdem::output::Measures::HEADER_WITHOUT_LEVELS);
}

#[test]
fn a_run_without_the_z_nr3_column_resumes_with_it() {
    // Expectation: a macro.csv of an sdem before the 3-contact rattler rule resumes; its kept
    // rows get z_nr3 = nan, and the result is otherwise the uninterrupted run.
    resumes_an_older_macro_csv(1, sdem::output::Measures::HEADER_WITHOUT_Z_NR3);
}

/// Stops a run of the full model (its checkpoint has no levels, as one of an sdem before the
/// adaptive level) at step 1500, cuts the last `columns` columns off its macro.csv (which must
/// then start with `header`), resumes it and compares it with the uninterrupted run.
fn resumes_an_older_macro_csv(columns: usize, header: &str) {
    let mut scenario = scenario();
    scenario.model = Model::Full;
    scenario.sample.count = Some(200);
    scenario.sample.box_width = 0.45;
    scenario.sample.box_height = 0.45;
    scenario.validate().unwrap();
    let reference = temp_dir(&format!("legacy{columns}-ref"));
    run_scenario(&scenario, &options(&reference, 1_000_000_000)).unwrap();
    let dir = temp_dir(&format!("legacy{columns}"));
    let mut opts = options(&dir, 1_000_000_000);
    opts.stop_after_step = Some(1500);
    assert!(run_scenario(&scenario, &opts).is_err());
    let path = dir.join("macro.csv");
    let old: String = std::fs::read_to_string(&path)
        .unwrap()
        .lines()
        .map(|l| l.rsplitn(columns + 1, ',').last().unwrap().to_string() + "\n")
        .collect();
    assert!(old.starts_with(&format!("{header}\n")));
    let kept_rows = old.lines().count() - 1;
    std::fs::write(&path, old).unwrap();
    let checkpoint = dir.join("checkpoint.bin");
    let c = Checkpoint::read(&checkpoint).unwrap();
    assert!(c.runner.levels.is_empty());
    resume_run(&c, &checkpoint, &options(&dir, 1_000_000_000)).unwrap();
    // z_nr3 (the last column) is nan in the rows kept from before, the reference's after them.
    let split = |dir: &Path| -> Vec<(String, String)> {
        std::fs::read_to_string(dir.join("macro.csv"))
            .unwrap()
            .lines()
            .map(|l| {
                let (rest, last) = l.rsplit_once(',').unwrap();
                (rest.to_string(), last.to_string())
            })
            .collect()
    };
    let (resumed, uninterrupted) = (split(&dir), split(&reference));
    assert_eq!(resumed.len(), uninterrupted.len());
    for (k, (r, u)) in resumed.iter().zip(&uninterrupted).enumerate() {
        assert_eq!(r.0, u.0, "row {k}");
        if (1..=kept_rows).contains(&k) {
            assert_eq!(r.1, "nan", "row {k}");
        } else {
            assert_eq!(r.1, u.1, "row {k}");
        }
    }
    std::fs::copy(reference.join("macro.csv"), &path).unwrap();
    assert_same_run(&reference, &dir);
    assert!(level_rows(&dir).iter().all(|r| *r == [0, 0, 200]));
    for d in [reference, dir] {
        std::fs::remove_dir_all(&d).ok();
    }
}
