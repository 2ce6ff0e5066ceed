//! The periodic cell (SPEC §14): contacts across the boundary, the affine deformation of the
//! cell, the cell stress, objectivity, runs with checkpoints and bad input.

mod common;

use glam::DVec2;
use sdem::boundary::periodic::{PeriodicBoundary, PeriodicCell};
use sdem::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP, box_size, box_walls};
use sdem::grain::Grain;
use sdem::integration::World;
use sdem::scenario::Scenario;

/// 200 grains of sample A's distribution in a periodic cell, compacted then relaxed (~6000
/// steps); `{nu}` and `{model}` are filled in.
const SMALL_PERIODIC: &str = r#"
Scenario(
    name: "small_periodic",
    sample: (count: 200, box_width: 0.45, box_height: 0.45,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: {nu}, density: 1.0),
    model: {model},
    boundary: Periodic,
    loading: [
        Isotropic(rate: Constant(5e-2), until: PackingFraction(0.86)),
        Relax(until: Steps(1000)),
    ],
    output: (every: 50),
)
"#;

fn small_periodic(nu: f64, model: &str) -> Scenario {
    let text = SMALL_PERIODIC
        .replace("{nu}", &nu.to_string())
        .replace("{model}", model);
    let s = Scenario::parse(&text, "small_periodic.ron").unwrap();
    s.validate().unwrap();
    s
}

/// Sets the virtual walls of a periodic world to compress it isotropically at `rate`.
fn drive_isotropic(world: &mut World, rate: f64) {
    let (w, h) = box_size(&world.walls);
    world.walls[LEFT].velocity.x = 0.5 * rate * w;
    world.walls[RIGHT].velocity.x = -0.5 * rate * w;
    world.walls[BOTTOM].velocity.y = 0.5 * rate * h;
    world.walls[TOP].velocity.y = -0.5 * rate * h;
}

/// The small periodic sample compressed at 5e-2 until phi = `phi`, then relaxed for `relax`
/// steps with the cell at rest.
fn compressed(nu: f64, phi: f64, relax: usize) -> World {
    let scenario = small_periodic(nu, "Full");
    let mut world = sdem::run::build_world(&scenario).unwrap();
    loop {
        drive_isotropic(&mut world, 5e-2);
        world.step().unwrap();
        let (w, h) = box_size(&world.walls);
        if world.totals.grain_area / (w * h) >= phi {
            break;
        }
    }
    drive_isotropic(&mut world, 0.0);
    for _ in 0..relax {
        world.step().unwrap();
    }
    world
}

/// Expectation: the contact stress of the cell is summed over each grain chunk's contacts in
/// pair order, whatever else the neighbour list holds, so a thin skin (many builds, few
/// candidates) and a thick one give the same cell stress, bit for bit, at every step; a stress
/// control feeds it back into the cell's motion.
#[test]
fn the_cell_stress_does_not_depend_on_the_neighbour_list_skin() {
    let start = compressed(0.5, 0.84, 0);
    let run = |skin: f64| {
        let mut world = start.clone();
        world.neighbors.skin = skin;
        world.neighbors.invalidate();
        let mut stresses = Vec::new();
        for _ in 0..300 {
            drive_isotropic(&mut world, 5e-2);
            world.step().unwrap();
            stresses.push(world.totals.cell_stress.map(f64::to_bits));
        }
        (stresses, world)
    };
    let (thin, thin_world) = run(0.05 * 0.012);
    let (thick, thick_world) = run(0.5 * 0.012);
    assert!(
        thin_world.neighbors.builds > thick_world.neighbors.builds + 5,
        "{} builds against {}",
        thin_world.neighbors.builds,
        thick_world.neighbors.builds
    );
    assert!(thin_world.totals.contacts > 100);
    assert_eq!(thin, thick);
    assert_eq!(thin_world.grains(), thick_world.grains());
}

/// Expectation: at every step of a compaction, every pair of grains whose bounding circles
/// overlap (minimum image, brute force over all pairs) is in the neighbour list with that
/// image: the Verlet criterion of a deforming cell misses no pair.
#[test]
fn the_neighbour_list_of_a_compressed_cell_misses_no_pair() {
    let scenario = small_periodic(0.5, "Full");
    let mut world = sdem::run::build_world(&scenario).unwrap();
    let n = world.grains().len();
    for step in 0..6000 {
        drive_isotropic(&mut world, 5e-2);
        world.step().unwrap_or_else(|e| panic!("step {step}: {e}"));
        let cell = world.cell().unwrap();
        let shapes: Vec<_> = world
            .grains()
            .iter()
            .map(|g| g.shape_and_velocity_gradient().0)
            .collect();
        for i in 0..n {
            for j in i + 1..n {
                let (d, [m1, m2]) = cell.minimum_image(shapes[j].center - shapes[i].center);
                if d.length() < shapes[i].bounding_radius + shapes[j].bounding_radius {
                    let k = world
                        .neighbors
                        .pairs
                        .iter()
                        .position(|p| *p == [i as u32, j as u32])
                        .unwrap_or_else(|| panic!("step {step}: pair {i} {j} missing"));
                    assert_eq!(
                        world.neighbors.images[k],
                        [-m1, -m2],
                        "step {step}: {i} {j}"
                    );
                }
            }
        }
    }
}

/// A deformed, moving grain.
fn moving_grain(center: DVec2, radius: f64, k: f64) -> Grain {
    Grain {
        velocity: DVec2::new(1e-3 * k, -2e-3),
        omega: 0.01 * k,
        theta: 0.2 + k,
        eps1: 0.02,
        eps2: -0.01 * k,
        alpha: 0.3,
        eps1_rate: 1e-3,
        eps2_rate: -2e-3 * k,
        alpha_rate: 1e-3,
        ..Grain::at_rest(center, radius)
    }
}

/// A world of two overlapping grains at `a` and `a + separation` (wrapped into the cell when
/// periodic), one step taken; returns the grains' changes of velocity, spin and strain rates,
/// and the world.
fn step_pair(cell: Option<PeriodicCell>, a: DVec2, separation: DVec2) -> (Vec<[f64; 5]>, World) {
    let scenario = small_periodic(0.3, "Full");
    let mut b = a + separation;
    let mut walls = box_walls(-5.0, 5.0, -5.0, 5.0);
    let mut periodic = None;
    if let Some(cell) = cell {
        b = cell.wrap(b).0;
        let (o, h1, h2) = (cell.origin, cell.h1(), cell.h2());
        walls = box_walls(o.x, o.x + h1.x, o.y, o.y + h2.y);
        periodic = Some(PeriodicBoundary {
            tilt: h2.x,
            ..Default::default()
        });
    }
    let grains = vec![moving_grain(a, 0.012, 1.0), moving_grain(b, 0.010, -0.5)];
    let before = grains.clone();
    let mut world = World::new(scenario.parameters(), grains, walls);
    world.periodic = periodic;
    world.step().unwrap();
    assert_eq!(world.totals.contacts, 1, "the pair is in contact");
    let changes = world
        .grains()
        .iter()
        .zip(&before)
        .map(|(g, g0)| {
            [
                g.velocity.x - g0.velocity.x,
                g.velocity.y - g0.velocity.y,
                g.omega - g0.omega,
                g.eps1_rate - g0.eps1_rate,
                g.eps2_rate - g0.eps2_rate,
            ]
        })
        .collect();
    (changes, world)
}

/// Expectation (translation invariance of the lattice): a pair in contact across a side or a
/// corner of the cell, rectangular or sheared, gets the same forces, torques and strain
/// accelerations as the same pair in the middle of the cell, and as the same pair in a box far
/// from its walls.
#[test]
fn a_pair_across_the_boundary_gets_the_forces_of_the_same_pair_inside() {
    let cells = [
        PeriodicCell::rectangle(DVec2::ZERO, 1.0, 0.8).unwrap(),
        PeriodicCell::new(
            DVec2::new(0.1, -0.2),
            DVec2::new(1.0, 0.0),
            DVec2::new(0.35, 0.9),
        )
        .unwrap(),
    ];
    let separations = [
        DVec2::new(0.02, 0.003),
        DVec2::new(-0.004, 0.019),
        DVec2::new(0.014, 0.014),
    ];
    let (free, _) = step_pair(None, DVec2::new(0.3, 0.2), separations[0]);
    for cell in cells {
        for separation in separations {
            let (inside, world_inside) =
                step_pair(Some(cell), cell.position(DVec2::new(0.5, 0.5)), separation);
            // The first grain just inside the corner the separation points out of.
            let corner = DVec2::new(
                if separation.x > 0.0 { 0.995 } else { 0.005 },
                if separation.y > 0.0 { 0.995 } else { 0.005 },
            );
            let (across, world_across) = step_pair(Some(cell), cell.position(corner), separation);
            assert_ne!(
                world_across.neighbors.images[0],
                [0, 0],
                "the pair meets across"
            );
            for (g, (x, y)) in inside.iter().zip(&across).enumerate() {
                for k in 0..5 {
                    assert!(
                        (x[k] - y[k]).abs() <= 1e-9 * x[k].abs().max(1e-12),
                        "{cell:?} {separation:?} grain {g} component {k}: {} vs {}",
                        x[k],
                        y[k]
                    );
                }
            }
            let (s, t) = (
                world_inside.totals.cell_stress,
                world_across.totals.cell_stress,
            );
            for k in 0..3 {
                assert!((s[k] - t[k]).abs() <= 1e-9 * s[0].abs(), "{s:?} vs {t:?}");
            }
            if separation == separations[0] {
                for (x, y) in free.iter().zip(&inside) {
                    for k in 0..5 {
                        assert!((x[k] - y[k]).abs() <= 1e-9 * x[k].abs().max(1e-12));
                    }
                }
            }
        }
    }
}

/// A contact-free gas: grains of radius 0.005 on a 10 × 10 grid in the unit cell.
fn gas() -> World {
    let scenario = small_periodic(0.3, "Full");
    let grains = (0..100)
        .map(|k| {
            let s = DVec2::new((k % 10) as f64 + 0.5, (k / 10) as f64 + 0.5) * 0.1;
            Grain::at_rest(s + DVec2::new(0.0137 * (k % 3) as f64, 0.0), 0.005)
        })
        .collect();
    World::new(scenario.parameters(), grains, box_walls(0.0, 1.0, 0.0, 1.0))
        .with_periodic(PeriodicBoundary::default())
}

/// Expectation: a gas without contacts follows the cell's affine deformation exactly: each
/// grain keeps its reduced coordinates `H^-1 (x - origin)` (to round-off) and stays at rest
/// relative to the affine field, under compression along x, extension along y and shear.
#[test]
fn an_affine_deformation_carries_a_contact_free_gas_exactly() {
    let mut world = gas();
    let reduced = |w: &World| -> Vec<DVec2> {
        let cell = w.cell().unwrap();
        w.grains().iter().map(|g| cell.reduced(g.center)).collect()
    };
    let start = reduced(&world);
    for _ in 0..2000 {
        let (w, h) = box_size(&world.walls);
        world.walls[RIGHT].velocity.x = -0.1 * w;
        world.walls[TOP].velocity.y = 0.05 * h;
        world.periodic.as_mut().unwrap().shear_rate = 0.1;
        world.step().unwrap();
    }
    let p = world.periodic.unwrap();
    assert!(p.shear_strain > 0.19 && p.tilt > 0.15, "{p:?}");
    assert_eq!(world.totals.contacts, 0);
    for (g, (s, s0)) in world
        .grains()
        .iter()
        .zip(reduced(&world).iter().zip(&start))
    {
        assert!((*s - *s0).length() < 1e-12, "{s:?} vs {s0:?}");
        assert_eq!(g.velocity, DVec2::ZERO);
    }
}

/// Expectation (simple shear, Lees–Edwards): sheared to gamma = 1.6, past two remaps of the
/// cell, each grain of a gas sits at `x0 + gamma (y0 - y_origin)` along x, to a lattice vector;
/// every grain stays wrapped in the cell, and the tilt stays within half a width.
#[test]
fn a_sheared_gas_stays_on_the_sheared_lattice_through_remaps() {
    let mut world = gas();
    let start: Vec<DVec2> = world.grains().iter().map(|g| g.center).collect();
    let mut remaps = 0;
    let mut last_tilt = 0.0;
    while world.periodic.unwrap().shear_strain < 1.6 {
        world.periodic.as_mut().unwrap().shear_rate = 0.5;
        world.step().unwrap();
        let p = world.periodic.unwrap();
        if p.tilt < last_tilt {
            remaps += 1;
        }
        last_tilt = p.tilt;
        assert!(p.tilt.abs() <= 0.5 + 1e-12, "{p:?}");
    }
    assert_eq!(remaps, 2);
    let cell = world.cell().unwrap();
    let gamma = world.periodic.unwrap().shear_strain;
    for (g, x0) in world.grains().iter().zip(&start) {
        let s = cell.reduced(g.center);
        assert!(
            (0.0..1.0).contains(&s.x) && (0.0..1.0).contains(&s.y),
            "{s:?}"
        );
        let expected = *x0 + DVec2::new(gamma * x0.y, 0.0);
        let lattice = cell.reduced(g.center) - cell.reduced(expected);
        assert!(
            (lattice - lattice.round()).length() < 1e-9,
            "{:?} vs {expected:?}: {lattice:?}",
            g.center
        );
    }
}

/// The Love–Weber sum of every grain, `sum_g A_g sigma_ext,g`, and of the grains' constitutive
/// stresses `sum_g A_g sigma_g` (xx, yy, xy), with A_g the grain's current area.
fn grain_stress_sums(world: &World) -> ([f64; 3], [f64; 3]) {
    let (mut external, mut constitutive) = ([0.0; 3], [0.0; 3]);
    for (g, s) in world.grains().iter().zip(&world.grain_stress) {
        let area = g.ellipse_area() - s.lost_area;
        for (sum, x) in external.iter_mut().zip(s.external) {
            *sum += area * x;
        }
        let e1 = g.principal_direction();
        let e2 = e1.perp();
        let [s1, s2] = s.principal;
        let sigma = |a: DVec2, b: DVec2| s1 * e1.dot(a) * e1.dot(b) + s2 * e2.dot(a) * e2.dot(b);
        constitutive[0] += area * sigma(DVec2::X, DVec2::X);
        constitutive[1] += area * sigma(DVec2::Y, DVec2::Y);
        constitutive[2] += area * sigma(DVec2::X, DVec2::Y);
    }
    (external, constitutive)
}

/// Expectations, for a compressed and relaxed sample (nu = 0.3):
/// - the cell stress `(1/A) sum sym(f ⊗ d)` is the area sum of the grains' Love–Weber stresses
///   over the cell (an identity of the contact forces: equal and opposite forces at one point);
/// - in equilibrium each grain's constitutive stress balances its Love–Weber stress, so the
///   cell stress is the mean of the grain stresses (to the residual of the relaxation);
/// - it is compressive and nearly isotropic after an isotropic compression.
#[test]
fn the_cell_stress_is_the_mean_of_the_grain_stresses() {
    let world = compressed(0.3, 0.87, 4000);
    let area = world.cell().unwrap().area();
    let cell = world.totals.cell_stress;
    let (external, constitutive) = grain_stress_sums(&world);
    let p = -0.5 * (cell[0] + cell[1]);
    assert!(p > 1e-3, "p = {p}");
    assert!(
        (cell[0] - cell[1]).abs() < 0.2 * p && cell[2].abs() < 0.2 * p,
        "{cell:?}"
    );
    for (k, ((lw, constitutive), cell)) in external.iter().zip(&constitutive).zip(&cell).enumerate()
    {
        assert!(
            (lw / area - cell).abs() < 1e-6 * p,
            "Love–Weber {k}: {} vs {cell}",
            lw / area
        );
        assert!(
            (constitutive / area - cell).abs() < 0.03 * p,
            "constitutive {k}: {} vs {cell}",
            constitutive / area
        );
    }
}

/// Expectation (objectivity): the same sample turned by 90 degrees (positions, orientations,
/// velocities and the cell) evolves as the turned image of the original: after 300 steps of
/// compression, the stresses are the turned ones (sxx and syy swapped, sxy negated) and every
/// grain is where the turn puts it, to round-off amplified over the steps.
#[test]
fn a_turned_sample_gives_the_turned_stresses() {
    let world = compressed(0.3, 0.85, 0);
    let (w, h) = box_size(&world.walls);
    let origin = world.cell().unwrap().origin;
    // Turn by +90 degrees about the origin, then shift into the cell [o.x, o.x + h] x [o.y, o.y + w].
    let turn =
        |x: DVec2| DVec2::new(-(x.y - origin.y), x.x - origin.x) + origin + DVec2::new(h, 0.0);
    let turned_grains: Vec<Grain> = world
        .grains()
        .iter()
        .map(|g| Grain {
            center: turn(g.center),
            velocity: g.velocity.perp(),
            theta: g.theta + std::f64::consts::FRAC_PI_2,
            ..*g
        })
        .collect();
    let mut turned = World::new(
        world.params,
        turned_grains,
        box_walls(origin.x, origin.x + h, origin.y, origin.y + w),
    )
    .with_periodic(PeriodicBoundary::default());
    let mut original = world;
    for _ in 0..300 {
        drive_isotropic(&mut original, 2e-2);
        drive_isotropic(&mut turned, 2e-2);
        original.step().unwrap();
        turned.step().unwrap();
    }
    let (s, t) = (original.totals.cell_stress, turned.totals.cell_stress);
    let p = -0.5 * (s[0] + s[1]);
    assert!(p > 1e-4, "{s:?}");
    for (a, b) in [(s[0], t[1]), (s[1], t[0]), (s[2], -t[2])] {
        assert!((a - b).abs() < 1e-6 * p, "{s:?} vs turned {t:?}");
    }
    let cell = turned.cell().unwrap();
    let o = original.cell().unwrap().origin;
    let (_, h) = box_size(&original.walls);
    for (g, u) in original.grains().iter().zip(turned.grains()) {
        let expected = DVec2::new(-(g.center.y - o.y), g.center.x - o.x) + o + DVec2::new(h, 0.0);
        let (d, _) = cell.minimum_image(u.center - expected);
        assert!(d.length() < 1e-8, "{:?} vs {expected:?}", u.center);
    }
}

/// 200 grains compacted in a periodic cell, then sheared at constant normal stress through one
/// remap of the cell (~14 000 steps).
const SMALL_SHEAR: &str = r#"
Scenario(
    name: "small_shear",
    sample: (count: 200, box_width: 0.45, box_height: 0.45,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    boundary: Periodic,
    loading: [
        Isotropic(rate: Constant(5e-2), until: PackingFraction(0.85)),
        Shear(rate: 5e-2, syy: 2e-3, gain: 0.5, max_rate: 5e-2, until: ShearStrain(0.6)),
    ],
    output: (every: 100),
)
"#;

fn small_shear() -> Scenario {
    let s = Scenario::parse(SMALL_SHEAR, "small_shear.ron").unwrap();
    s.validate().unwrap();
    s
}

/// Reads a column of macro.csv by name.
fn column(dir: &std::path::Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(dir.join("macro.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let k = header.iter().position(|h| *h == name).unwrap();
    lines
        .map(|l| l.split(',').nth(k).unwrap().parse().unwrap())
        .collect()
}

/// Expectations: a sheared periodic run resumes bitwise from checkpoints before and after the
/// cell's remap and gives the same results with 1 and 2 threads (SPEC determinism); its
/// macro.csv has the cell's columns; the servo keeps syy_c near its target; a positive shear
/// rate needs a positive shear stress sigma_xy (the power sigma_xy gamma' is dissipated), i.e.
/// `sxy_c < 0` in the compression-positive report.
#[test]
fn a_sheared_cell_resumes_bitwise_and_is_the_same_on_any_thread_count() {
    use sdem::run::checkpoint::Checkpoint;
    use sdem::run::{resume_run, run_scenario};
    let scenario = small_shear();
    let reference = common::temp_dir("periodic", "ref");
    let log = reference.join("shear.mcap");
    let summary = common::with_threads(1, || {
        run_scenario(
            &scenario,
            &sdem::run::RunOptions {
                mcap: Some(sdem::output::mcap::McapSettings::new(&log)),
                ..common::checkpointed(&reference, 1_000_000_000)
            },
        )
    })
    .unwrap();
    // The log's frames carry the cell, sheared as the run left it; a picture of it draws.
    let trajectory = sdem::output::mcap::Trajectory::open(&log).unwrap();
    let last = trajectory.frame(-1).unwrap();
    let end = Checkpoint::read(&reference.join("checkpoint.bin")).unwrap();
    let cell = last.cell.expect("a periodic log's frames have the cell");
    let tilt = end.periodic.unwrap().tilt;
    assert!(
        (cell.h2().x - tilt).abs() < 1e-12 * cell.h1().x,
        "{cell:?} vs tilt {tilt}"
    );
    assert_eq!(cell.h1().x, box_size(&end.walls).0);
    let png = reference.join("last.png");
    sdem::output::render::render_frame(&last, &png, &Default::default()).unwrap();
    assert!(std::fs::metadata(&png).unwrap().len() > 10_000);
    let total = summary.steps;
    let shear = column(&reference, "shear_strain");
    let tilt = column(&reference, "cell_tilt");
    assert!(*shear.last().unwrap() >= 0.6, "{shear:?}");
    assert!(
        tilt.iter().any(|t| *t < -0.3),
        "the cell was remapped: {tilt:?}"
    );
    let sxy = column(&reference, "sxy_c");
    let syy = column(&reference, "syy_c");
    let rows = sxy.len();
    let late = rows - rows / 4..rows;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(mean(&sxy[late.clone()]) < 0.0, "{:?}", &sxy[late.clone()]);
    // A loose bound: the servo is slow against the stiffness of this short run.
    let syy_late = mean(&syy[late]);
    assert!(syy_late > 1e-3 && syy_late < 4e-3, "syy_c = {syy_late}");
    let two = common::temp_dir("periodic", "two");
    common::with_threads(2, || {
        run_scenario(&scenario, &common::checkpointed(&two, 1_000_000_000))
    })
    .unwrap();
    let same_files = |a: &std::path::Path, b: &std::path::Path| {
        let (ca, cb) = common::assert_same_run(a, b);
        assert_eq!(ca.periodic, cb.periodic);
        assert_eq!(ca.program, cb.program);
    };
    same_files(&reference, &two);
    // Stops in the compaction, in the shear before the remap and after it.
    for stop in [2000, total - 6000, total - 300] {
        let dir = common::temp_dir("periodic", &format!("stop{stop}"));
        let (c, path) =
            common::run_interrupted_at(&scenario, &common::checkpointed(&dir, 777), stop);
        assert!(c.periodic.is_some());
        resume_run(&c, &path, &common::checkpointed(&dir, 777)).unwrap();
        same_files(&reference, &dir);
        std::fs::remove_dir_all(&dir).ok();
    }
    for d in [reference, two] {
        std::fs::remove_dir_all(&d).ok();
    }
}

/// Expectation: bad input of a periodic cell is refused before the run with a message naming
/// the field, the value and what is allowed; a cell compressed below twice the interaction
/// range stops the run with the last good state written, never a panic.
#[test]
fn bad_periodic_input_is_refused_with_a_clear_message() {
    let refused = |text: &str, field: &str, words: &str| {
        let e = Scenario::parse(text, "bad.ron")
            .and_then(|s| s.validate().map(|_| ()))
            .unwrap_err()
            .to_string();
        assert!(e.contains(field) && e.contains(words), "{e}");
    };
    let narrow = SMALL_SHEAR.replace("count: 200, box_width: 0.45", "count: 10, box_width: 0.06");
    refused(
        &narrow,
        "sample.box_width",
        "twice the largest grain diameter",
    );
    let no_gain = SMALL_SHEAR.replace("gain: 0.5", "gain: 0.0");
    refused(&no_gain, "loading[1].gain", "servo gain");
    let walls = SMALL_SHEAR.replace("boundary: Periodic,", "");
    refused(&walls, "loading[1]", "periodic cell");
    let strain_stop = SMALL_PERIODIC
        .replace("{nu}", "0.5")
        .replace("{model}", "Full")
        .replace("boundary: Periodic,", "")
        .replace("Steps(1000)", "ShearStrain(1.0)");
    refused(&strain_stop, "loading[1].until", "periodic cell");
    let zero_rate = SMALL_SHEAR.replace("Shear(rate: 5e-2", "Shear(rate: 0.0");
    refused(&zero_rate, "loading[1].rate", "non-zero");
    // A shear rate far above the quasi-static limit is legal, with a warning that says so.
    let fast = Scenario::parse(
        &SMALL_SHEAR.replace("Shear(rate: 5e-2", "Shear(rate: 5.0"),
        "fast.ron",
    )
    .unwrap();
    let warnings = fast.validate().unwrap();
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("loading[1].rate") && w.contains("quasi-static")),
        "{warnings:?}"
    );
    // 4 grains in a cell compressed until it is too narrow for them (at phi = 0.65).
    let squeezed = r#"
Scenario(
    name: "squeezed",
    sample: (count: 4, box_width: 0.1, box_height: 0.1, radii: Monodisperse(radius: 0.016)),
    material: (young: 1.0, poisson: 0.3, density: 1.0),
    boundary: Periodic,
    contact: (on_domain_exit: Cap),
    loading: [ Isotropic(rate: Constant(5e-2), until: PackingFraction(0.999)) ],
    output: (every: 100),
)
"#;
    let scenario = Scenario::parse(squeezed, "squeezed.ron").unwrap();
    scenario.validate().unwrap();
    let dir = common::temp_dir("periodic", "squeezed");
    let e = sdem::run::run_scenario(&scenario, &common::checkpointed(&dir, 0)).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("periodic cell is") && text.contains("last good state"),
        "{text}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Expectation: on the command line a periodic scenario that cannot run exits non-zero with the
/// message naming the field; `sdem check` of a valid one prints the cell's least width.
#[test]
fn the_command_line_refuses_a_narrow_cell_and_reports_a_valid_one() {
    let dir = common::temp_dir("periodic", "cli");
    let narrow = dir.join("narrow.ron");
    std::fs::write(
        &narrow,
        SMALL_SHEAR.replace("count: 200, box_width: 0.45", "count: 10, box_width: 0.06"),
    )
    .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sdem"))
        .args(["run", narrow.to_str().unwrap(), "--out"])
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("sample.box_width") && stderr.contains("periodic cell"),
        "{stderr}"
    );
    let valid = dir.join("valid.ron");
    std::fs::write(&valid, SMALL_SHEAR).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sdem"))
        .args(["check", valid.to_str().unwrap()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(
        stdout.contains("boundary: periodic cell 0.45 x 0.45"),
        "{stdout}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
