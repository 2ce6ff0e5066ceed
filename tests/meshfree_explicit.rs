//! The explicit scheme of the multibody meshfree solver (lumped mass, central differences,
//! penalty contacts): free fall, a collision, determinism.

mod common;

use common::meshfree::disc_at;
use sdem::meshfree::TimeScheme;
use sdem::meshfree::assembly::Assembly;
use sdem::meshfree::{GrainModel, SolverSettings};

fn settings(k0: f64) -> SolverSettings {
    SolverSettings {
        k0,
        alpha_k: 2.0,
        gap_tolerance: 1e-3,
        force_tolerance: 1e-9,
        max_newton: 40,
        max_augmentations: 40,
    }
}

fn assembly(grains: Vec<GrainModel>, gravity: [f64; 2], k0: f64) -> Assembly {
    Assembly::new(grains, Vec::new(), gravity, (0.0, 0.0), settings(k0)).unwrap()
}

/// Total momentum `sum m_i v_i` with the lumped mass, x and y.
fn momentum(a: &Assembly, v: &[f64]) -> [f64; 2] {
    let m = &a.explicit_data().unwrap().lumped_mass;
    let mut p = [0.0; 2];
    for (i, (m, v)) in m.iter().zip(v).enumerate() {
        p[i % 2] += m * v;
    }
    p
}

#[test]
fn free_fall_is_exact_and_leaves_the_grain_undeformed() {
    // Expectation: under uniform gravity every node falls by g t^2 / 2 (central differences
    // are exact for a constant acceleration, with the second-order start), and the grain
    // stays undeformed (the lumped body force is m_a g at every node).
    let mut a = assembly(vec![disc_at([0.0, 0.0], 24, 0.3)], [0.0, -1.0], 1.0);
    a.use_explicit().unwrap();
    let mut state = a.initial_state();
    let dt = 0.1;
    let mut last = None;
    for _ in 0..10 {
        let (eval, stats) = a
            .step(&mut state, dt, TimeScheme::CentralDifference)
            .unwrap();
        assert!(stats.sub_steps >= 1);
        last = Some(eval);
    }
    let t = state.time;
    assert!((t - 1.0).abs() < 1e-12, "{t}");
    for (i, u) in state.u.iter().enumerate() {
        let expected = if i % 2 == 1 { -0.5 * t * t } else { 0.0 };
        assert!((u - expected).abs() < 1e-12, "DoF {i}: {u} vs {expected}");
    }
    // Undeformed: the elastic energy is nil next to the work of gravity (m g t^2 / 2 per unit
    // mass). Not exactly 0: RPIM derivatives reproduce a translation to ~1e-9 only.
    let work = 0.25 * std::f64::consts::PI * 0.5 * t * t;
    let elastic = last.unwrap().elastic_energy;
    assert!(elastic.abs() < 1e-12 * work, "elastic energy {elastic:e}");
}

/// Two discs of radius 0.5 (E = 1), 0.05 apart, the left one moving right at `speed`; no
/// gravity, no damping. Returns the assembly, the initial and final total energy
/// (kinetic + elastic), the largest momentum change relative to the initial momentum, and
/// the second disc's final mean x velocity.
fn collision(threads: usize, speed: f64) -> (Vec<u64>, f64, f64, f64, f64) {
    common::with_threads(threads, || {
        let grains = vec![disc_at([0.0, 0.0], 32, 0.3), disc_at([1.05, 0.0], 32, 0.3)];
        let mut a = assembly(grains, [0.0, 0.0], 20.0);
        a.use_explicit().unwrap();
        let mut state = a.initial_state();
        state.a.iter_mut().for_each(|x| *x = 0.0);
        let first = a.dofs() / 2;
        for i in (0..first).step_by(2) {
            state.v[i] = speed;
        }
        let p0 = momentum(&a, &state.v)[0];
        let e0 = a.kinetic_energy(&state.v);
        let mut worst = 0.0f64;
        let mut touched = false;
        let mut eval = None;
        // Contact lasts about a grain's crossing time (~0.5 / c, c ~ 1); 6 time units see
        // the discs meet (0.05 / speed) and part.
        for _ in 0..60 {
            let (e, _) = a
                .step(&mut state, 0.1, TimeScheme::CentralDifference)
                .unwrap();
            touched |= !e.elements.is_empty();
            let p = momentum(&a, &state.v);
            worst = worst.max((p[0] - p0).abs().max(p[1].abs()) / p0);
            eval = Some(e);
        }
        let eval = eval.unwrap();
        assert!(touched, "the discs never met");
        assert!(eval.elements.is_empty(), "the discs are still in contact");
        let e1 = a.kinetic_energy(&state.v) + eval.elastic_energy;
        let m = &a.explicit_data().unwrap().lumped_mass;
        let (mut p2, mut m2) = (0.0, 0.0);
        for i in (first..a.dofs()).step_by(2) {
            p2 += m[i] * state.v[i];
            m2 += m[i];
        }
        let bits = state.u.iter().map(|u| u.to_bits()).collect();
        (bits, e0, e1, worst, p2 / m2)
    })
}

#[test]
fn a_collision_keeps_momentum_and_energy() {
    // Expectations: the contact forces are equal and opposite (the two-pass elements act on
    // both grains), so the total momentum stays that of the start to round-off; the
    // frictionless, undamped collision is elastic and central differences keep the energy
    // (kinetic + elastic, once the discs have parted) to O(h^2); and momentum passes to the
    // struck disc, which leaves at most at the speed of the striker (equal masses).
    let speed = 0.2;
    let (_, e0, e1, momentum_error, v2) = collision(1, speed);
    println!(
        "collision: energy {e0:.6e} -> {e1:.6e}, momentum error {momentum_error:.1e}, struck disc {v2:.4}"
    );
    assert!(
        momentum_error < 1e-10,
        "momentum changed by {momentum_error:e}"
    );
    let energy_error = (e1 - e0).abs() / e0;
    assert!(energy_error < 0.01, "energy {e0} -> {e1}");
    assert!(
        v2 > 0.5 * speed && v2 <= speed * (1.0 + 1e-9),
        "struck disc leaves at {v2}"
    );
}

#[test]
fn explicit_steps_are_identical_with_one_and_two_threads() {
    let (one, ..) = collision(1, 0.2);
    let (two, ..) = collision(2, 0.2);
    assert!(one == two, "1 and 2 threads differ");
}
