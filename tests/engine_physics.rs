//! Physics of the SDEM step against independent expectations (issue: SDEM engine).

use glam::{DMat2, DVec2};
use sdem::boundary::walls::{Wall, box_walls};
use sdem::contact::friction::FrictionSettings;
use sdem::grain::constitutive::principal_stress;
use sdem::grain::{Grain, Material, ModelLevel};
use sdem::integration::parameters::Friction;
use sdem::integration::parameters::critical_time_step;
use sdem::integration::{Parameters, World};
use std::f64::consts::PI;

fn material(poisson: f64) -> Material {
    Material {
        young: 1.0,
        poisson,
        density: 1.0,
    }
}

fn params(poisson: f64, fraction_of_critical: f64, radius: f64) -> Parameters {
    let mut p = Parameters::new(material(poisson), 0.0);
    p.dt = fraction_of_critical * critical_time_step(&p.material, &p.law, radius, p.level);
    p
}

/// A disc of radius `r` between two parallel walls through `±(gap/2) n` (n the unit normal of
/// the lower wall), walls at rest: the grain is squeezed along n.
fn squeezed_grain(poisson: f64, r: f64, gap: f64, tilt: f64) -> World {
    let n = DVec2::from_angle(PI / 2.0 + tilt);
    let walls = vec![
        Wall::new(-n * (0.5 * gap), n),
        Wall::new(n * (0.5 * gap), -n),
    ];
    World::new(
        params(poisson, 0.4, r),
        vec![Grain::at_rest(DVec2::ZERO, r)],
        walls,
    )
}

fn settle(world: &mut World, steps: usize) {
    for _ in 0..steps {
        world.step().expect("stable step");
    }
}

/// Grain stress tensor (global frame) from its principal values along e1 = (theta + alpha).
fn constitutive_tensor(world: &World) -> DMat2 {
    let g = &world.grains()[0];
    let s = &world.grain_stress[0];
    let (s1, s2) = (s.principal[0], s.principal[1]);
    let e1 = g.principal_direction();
    let e2 = e1.perp();
    let outer = |a: DVec2| DMat2::from_cols(a * a.x, a * a.y);
    outer(e1) * s1 + outer(e2) * s2
}

fn external_tensor(world: &World) -> DMat2 {
    let e = world.grain_stress[0].external;
    DMat2::from_cols(DVec2::new(e[0], e[2]), DVec2::new(e[2], e[1]))
}

#[test]
fn squeezed_grain_shortens_along_the_load_and_its_stress_balances_love_weber() {
    // Expectation (SPEC §4): walls along y give sigma_ext,yy < 0; the grain shortens along y
    // and settles where the grain stress equals the Love–Weber stress.
    let r = 0.5;
    let mut world = squeezed_grain(0.3, r, 0.9, 0.0);
    settle(&mut world, 20_000);
    let g = world.grains()[0];
    let shape = g.shape();
    let extent = |d: DVec2| (shape.map.transpose() * d).length();
    assert!(
        extent(DVec2::Y) < r,
        "half height {} not below R",
        extent(DVec2::Y)
    );
    assert!(
        extent(DVec2::X) > r,
        "compressible grain must bulge sideways"
    );
    let ext = external_tensor(&world);
    assert!(
        ext.y_axis.y < 0.0,
        "sigma_ext,yy = {} must be compressive",
        ext.y_axis.y
    );
    let grain = constitutive_tensor(&world);
    let scale = ext.y_axis.y.abs();
    let mismatch = (grain - ext)
        .to_cols_array()
        .iter()
        .map(|v| v.abs())
        .fold(0.0, f64::max);
    assert!(
        mismatch < 0.01 * scale,
        "grain stress {grain:?} vs Love–Weber {ext:?}"
    );
    // And the walls carry the same force: sum of wall normal forces over the two walls.
    let f = world.totals.wall_force;
    assert!((f[0] - f[1]).abs() < 1e-6 * f[0].abs() && f[0] > 0.0);
}

#[test]
fn the_deformation_mass_scale_slows_the_strain_but_not_where_it_settles() {
    // Expectation (SPEC §4 with M_eps scaled by s): from rest, the first step gives the strain
    // the rate (unbalanced stress / M_eps) dt, 1/s of the unscaled one, while the centre moves
    // alike; the equilibrium (grain stress = Love–Weber stress) involves no mass, so both
    // settle to the same shape and wall force.
    let r = 0.5;
    let mut own = squeezed_grain(0.3, r, 0.9, 0.0);
    let mut scaled = squeezed_grain(0.3, r, 0.9, 0.0);
    scaled.params.deformation_mass_scale = 4.0;
    own.step().unwrap();
    scaled.step().unwrap();
    let (a, b) = (own.grains()[0], scaled.grains()[0]);
    assert!(a.eps1_rate != 0.0 && a.eps2_rate < 0.0, "{a:?}");
    for (unscaled, with_scale) in [(a.eps1_rate, b.eps1_rate), (a.eps2_rate, b.eps2_rate)] {
        let ratio = with_scale / unscaled;
        assert!((ratio - 0.25).abs() < 1e-12, "rate ratio {ratio}");
    }
    assert_eq!(a.velocity, b.velocity);
    settle(&mut own, 20_000);
    settle(&mut scaled, 20_000);
    let (a, b) = (own.grains()[0], scaled.grains()[0]);
    assert!(a.eps2 < -1e-3, "squeezed: eps2 = {}", a.eps2);
    for (x, y) in [(a.eps1, b.eps1), (a.eps2, b.eps2)] {
        assert!(
            (x - y).abs() < 1e-6 * x.abs(),
            "settled strains {x} and {y}"
        );
    }
    let (f, g) = (own.totals.wall_force[0], scaled.totals.wall_force[0]);
    assert!((f - g).abs() < 1e-6 * f.abs(), "wall forces {f} and {g}");
}

#[test]
fn incompressible_grain_keeps_its_area() {
    // Expectation (SPEC §6): pi R^2 (1+eps1)(1+eps2) - sum S_j = pi R^2 for nu = 0.5.
    let r = 0.5;
    let mut world = squeezed_grain(0.5, r, 0.85, 0.0);
    settle(&mut world, 20_000);
    let g = world.grains()[0];
    // The step reports the area with the caps of the state it started from; one more step at
    // rest makes the two agree.
    world.step().unwrap();
    let area = world.totals.grain_area;
    let reference = PI * r * r;
    let relative = (area - reference).abs() / reference;
    assert!(relative < 1e-9, "area error {relative:e}");
    // It really is deformed and overlapping the walls.
    assert!(world.grain_stress[0].lost_area > 1e-3 * reference);
    assert!(g.eps1 - g.eps2 != 0.0);
}

#[test]
fn tilted_walls_give_the_same_force_and_align_the_short_axis_with_the_load() {
    // Expectation (SPEC §4): walls tilted 30 degrees give the same wall force as level walls;
    // the grain's short axis lines up with the wall normal.
    let r = 0.5;
    let mut level = squeezed_grain(0.3, r, 0.9, 0.0);
    let tilt = 30f64.to_radians();
    let mut tilted = squeezed_grain(0.3, r, 0.9, tilt);
    settle(&mut level, 20_000);
    settle(&mut tilted, 20_000);
    let (fl, ft) = (level.totals.wall_force[0], tilted.totals.wall_force[0]);
    assert!((fl - ft).abs() < 1e-3 * fl, "level {fl} vs tilted {ft}");
    let g = tilted.grains()[0];
    let short_axis = if g.eps1 < g.eps2 {
        g.principal_direction()
    } else {
        g.principal_direction().perp()
    };
    let load = DVec2::from_angle(PI / 2.0 + tilt);
    assert!(
        short_axis.dot(load).abs() > 0.9999,
        "short axis {short_axis} vs load {load}"
    );
}

/// A cluster of 7 grains pressed into each other (a hexagon around a centre, overlapping).
fn cluster(rotation: f64, level: ModelLevel) -> World {
    let q = DMat2::from_angle(rotation);
    let mut grains = vec![Grain::at_rest(DVec2::new(0.01, -0.02), 1.0)];
    for k in 0..6 {
        let dir = DVec2::from_angle(k as f64 * PI / 3.0 + 0.1 * k as f64);
        let mut g = Grain::at_rest(dir * (1.75 + 0.04 * k as f64), 0.9 + 0.03 * k as f64);
        g.theta = 0.3 * k as f64;
        g.eps1 = 0.02 * k as f64 - 0.05;
        g.eps2 = -0.01 * k as f64;
        g.alpha = 0.7 * k as f64;
        g.velocity = DVec2::new(0.001 * k as f64, -0.002);
        g.omega = 0.01 * k as f64;
        grains.push(g);
    }
    for g in &mut grains {
        g.center = q * g.center;
        g.velocity = q * g.velocity;
        g.theta += rotation;
    }
    let mut p = params(0.3, 0.4, 0.9);
    p.level = level;
    World::new(p, grains, Vec::new())
}

#[test]
fn rotated_scene_gives_rotated_stresses() {
    // Expectation: objectivity. Rotating positions and orientations by phi rotates every grain's
    // Love–Weber stress to Q sigma Q^T; principal constitutive stresses are unchanged.
    let mut reference = cluster(0.0, ModelLevel::Full);
    reference.step().unwrap();
    for phi in [0.123, 1.0, 2.5, -2.0] {
        let mut rotated = cluster(phi, ModelLevel::Full);
        rotated.step().unwrap();
        let q = DMat2::from_angle(phi);
        for (a, b) in reference.grain_stress.iter().zip(&rotated.grain_stress) {
            let sa = DMat2::from_cols(
                DVec2::new(a.external[0], a.external[2]),
                DVec2::new(a.external[2], a.external[1]),
            );
            let sb = DMat2::from_cols(
                DVec2::new(b.external[0], b.external[2]),
                DVec2::new(b.external[2], b.external[1]),
            );
            let expected = q * sa * q.transpose();
            let scale = sa
                .to_cols_array()
                .iter()
                .map(|v| v.abs())
                .fold(0.0, f64::max);
            let error = (expected - sb)
                .to_cols_array()
                .iter()
                .map(|v| v.abs())
                .fold(0.0, f64::max);
            assert!(scale > 0.0);
            assert!(error < 1e-9 * scale, "phi {phi}: {error:e} vs {scale:e}");
            assert!((a.principal[0] - b.principal[0]).abs() < 1e-12);
            assert_eq!(a.contacts, b.contacts);
        }
    }
}

#[test]
fn free_cluster_conserves_momentum_newtons_third_law() {
    // Expectation: every contact force acts on both grains with opposite signs, so without
    // walls the total momentum stays what it was, to rounding.
    let mut world = cluster(0.4, ModelLevel::Full);
    let momentum = |w: &World| {
        w.grains()
            .iter()
            .map(|g| g.velocity * g.mass(1.0))
            .sum::<DVec2>()
    };
    let before = momentum(&world);
    let mut peak_force: f64 = 0.0;
    for _ in 0..200 {
        world.step().unwrap();
        for (_, c, _) in world.contacts() {
            peak_force = peak_force.max(c.force.abs());
        }
    }
    assert!(peak_force > 0.0);
    let change = (momentum(&world) - before).length();
    // Impulse scale: the largest force over the elapsed time.
    let impulse = peak_force * world.time;
    assert!(
        change < 1e-12 * impulse,
        "momentum changed by {change:e} (impulse scale {impulse:e})"
    );
}

#[test]
fn results_are_bitwise_identical_with_one_and_two_threads() {
    // Expectation: fixed-chunk reductions and per-pair slots make the sums independent of the
    // thread count.
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut grains = Vec::new();
            // 40 x 30 lattice of slightly overlapping, randomly sized grains in a box.
            let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(7);
            let mut next = || sdem::sample::unit_random(&mut rng);
            for i in 0..40 {
                for j in 0..30 {
                    let r = 0.0105 + 0.001 * next();
                    grains.push(Grain::at_rest(
                        DVec2::new(0.02 + 0.02 * i as f64, 0.02 + 0.02 * j as f64),
                        r,
                    ));
                }
            }
            let walls = box_walls(0.0105, 0.8095, 0.0105, 0.6095);
            let mut world = World::new(params(0.5, 0.4, 0.0105), grains, walls);
            for _ in 0..100 {
                world.step().unwrap();
            }
            (world.grains().to_vec(), world.totals)
        })
    };
    let (a, ta) = run(1);
    let (b, tb) = run(2);
    assert!(ta.contacts > 1000);
    assert_eq!(ta, tb);
    for (ga, gb) in a.iter().zip(&b) {
        assert_eq!(ga, gb);
    }
}

#[test]
fn results_do_not_depend_on_the_neighbour_list_skin() {
    // Expectation: the candidate list only decides which pairs are tested. Contacts are summed
    // in pair order (i, j) whatever else the list holds, a pair in contact is always listed,
    // and its search hint and tangential spring carry over a rebuild; a wrong or missing hint
    // costs more tests, never another result. So a thin skin (many builds, few candidates) and
    // a thick one give the same bits. Frictional, so that the springs must carry over.
    let run = |skin_fraction: f64| {
        let mut world = sdem::run::bench::dense_packing(400, 1.0);
        sdem::run::bench::with_friction(&mut world, 0.5);
        world.neighbors.skin = skin_fraction * 0.012;
        for _ in 0..300 {
            world.step().unwrap();
        }
        world
    };
    let (thin, thick) = (run(0.05), run(0.5));
    assert!(
        thin.neighbors.builds > thick.neighbors.builds + 5,
        "{} builds against {}",
        thin.neighbors.builds,
        thick.neighbors.builds
    );
    assert!(thin.totals.contacts > 300 && thin.totals.sliding_contacts > 0);
    assert_eq!(thin.totals, thick.totals);
    assert_eq!(thin.grains(), thick.grains());
    assert_eq!(thin.contact_history(), thick.contact_history());
}

#[test]
fn volumetric_and_full_levels_agree_under_isotropic_load() {
    // Expectation (SPEC §1): under an exactly isotropic load the full grain stays circular, so
    // level 1 (eps1 = eps2) and level 3 give the same state. Four walls squeeze one grain.
    let make = |level| {
        let mut p = params(0.3, 0.4, 0.5);
        p.level = level;
        World::new(
            p,
            vec![Grain::at_rest(DVec2::ZERO, 0.5)],
            box_walls(-0.47, 0.47, -0.47, 0.47),
        )
    };
    let mut full = make(ModelLevel::Full);
    let mut volumetric = make(ModelLevel::Volumetric);
    settle(&mut full, 5000);
    settle(&mut volumetric, 5000);
    let (a, b) = (full.grains()[0], volumetric.grains()[0]);
    // The full grain stays circular: the load has the square's symmetry.
    assert!((a.eps1 - a.eps2).abs() < 1e-12 * a.eps1.abs());
    // Both levels reach the same strain, up to the full grain's polygon: the volumetric grain
    // is an exact circle (closed-form contacts, issue #16), the full one its inscribed 360-gon,
    // whose contact depth against a flat wall is short of the circle's by at most the sagitta
    // of an edge, R (1 - cos(dbeta/2)) = 3.8e-5 R at 1 degree (a vertex or mid-edge on the wall,
    // as the polygon turns). A strain is a depth over R: they may differ by that sagitta, twice
    // over (two opposite walls). (tests/exact_contours.rs: with exact ellipses, to 1e-12.)
    let sagitta = 1.0 - (0.5 * full.contours.dbeta()).cos();
    let difference = (a.eps1 - b.eps1).abs();
    assert!(
        difference < 2.0 * sagitta,
        "strains differ by {difference:e}: full {a:?} volumetric {b:?}"
    );
    assert!(a.eps1 < 0.0);
    let (s1, _) = principal_stress(
        &full.params.material.moduli(),
        a.eps1,
        a.eps2,
        full.grain_stress[0].lost_area / (PI * 0.25),
    );
    assert!(s1 < 0.0);
}

#[test]
fn stress_servo_brings_the_wall_stresses_to_their_targets() {
    // Expectation: with walls driven by the servo, the wall stresses settle at the targets
    // (the servo's fixed point), different on the two axes.
    use sdem::boundary::loading::{LoadState, LoadingProgram, Phase, StopWhen};
    use sdem::output::Measures;
    let r = 0.5;
    let mut world = World::new(
        params(0.3, 0.4, r),
        vec![Grain::at_rest(DVec2::ZERO, r)],
        box_walls(-0.5, 0.5, -0.5, 0.5),
    );
    let (sxx, syy) = (0.02, 0.01);
    let mut program = LoadingProgram::new(
        vec![Phase::Servo {
            sxx,
            syy,
            gain: 0.5,
            max_rate: 0.05,
            until: StopWhen::Steps(4000),
        }],
        &world.walls,
    );
    let state = |w: &World| LoadState {
        jammed: true,
        mean_diameter: 2.0 * r,
        ..Measures::load_state(w, true, 2.0 * r)
    };
    while !program.finished() {
        let s = state(&world);
        program.drive(&mut world.walls, &s);
        world.step().unwrap();
        let s = state(&world);
        program.advance(world.step, world.time, &world.walls, &s);
    }
    let s = state(&world);
    assert!((s.sxx - sxx).abs() < 0.01 * sxx, "sxx = {}", s.sxx);
    assert!((s.syy - syy).abs() < 0.01 * syy, "syy = {}", s.syy);
}

#[test]
fn contacts_are_exactly_the_overlapping_candidates_and_end_when_the_grains_part() {
    // Expectation: a contact is listed for the candidates whose discs overlap and for no other
    // (a candidate within the skin but apart has none), with the chord of the two circles as
    // its length, 2 sqrt(r^2 - (d/2)^2) for equal radii r at distance d, and a repulsive
    // force. A sliding contact loads its tangential spring; once the grains part, the contact
    // is gone and its pair carries no spring.
    let r = 0.5;
    let d = 0.95;
    let mut grains = vec![
        Grain::at_rest(DVec2::ZERO, r),
        Grain::at_rest(DVec2::new(d, 0.0), r),
        Grain::at_rest(DVec2::new(0.0, -1.02), r),
    ];
    grains[1].velocity = DVec2::new(0.05, 0.02);
    let mut p = params(0.3, 0.4, r);
    p.level = ModelLevel::Rigid;
    p.friction = Friction::new(
        &FrictionSettings {
            grains: 0.5,
            ..Default::default()
        },
        &[],
    );
    let mut world = World::new(p, grains, Vec::new());
    world.step().unwrap();
    assert!(
        world.neighbors.pairs.contains(&[0, 2]),
        "the apart pair is a candidate"
    );
    let contacts: Vec<_> = world.contacts().collect();
    assert_eq!(contacts.len(), 1);
    let ([i, j], contact, state) = contacts[0];
    assert_eq!([i, j], [0, 1]);
    let chord = 2.0 * (r * r - 0.25 * d * d).sqrt();
    assert!((state.contact_length - chord).abs() < 1e-12 * chord);
    assert!(contact.force < 0.0, "repulsive: {}", contact.force);
    assert_eq!(world.totals.contacts, 1);
    let springs = world.contact_history().pairs;
    assert_eq!(springs.len(), 1, "the sliding contact loads its spring");
    assert_eq!(springs[0].0, [0, 1]);
    let mut steps = 0;
    while world.contacts().next().is_some() {
        world.step().unwrap();
        steps += 1;
        assert!(steps < 100_000, "the grains never parted");
    }
    assert_eq!(world.totals.contacts, 0);
    assert!(world.contact_history().pairs.is_empty());
}
