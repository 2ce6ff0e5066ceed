//! Stability of the dynamic schemes (paper fig. 7–8, SPEC §10): a damped disc dropped under
//! gravity on a rigid wall. Release only:
//! `cargo test --release --test meshfree_dynamics -- --ignored --nocapture`.

use sdem::meshfree::{
    DiscModel, Dynamics, Hyperelastic, HyperelasticLaw, NodeDensity, SolverSettings, TimeScheme,
    Wall,
};

/// Max |gap|, |velocity| and |acceleration| of the lowest node B over the last 40% of the run.
fn drop_disc(scheme: TimeScheme, dt: f64, t_end: f64, gap_tolerance: f64) -> (f64, f64, f64) {
    let nb = 24;
    let mat = Hyperelastic::new(HyperelasticLaw::NeoHookean, 50.0, 0.3, 1.0).unwrap();
    let model = DiscModel::disc(0.5, NodeDensity::new(nb), mat).unwrap();
    let settings = SolverSettings {
        k0: 1000.0,
        alpha_k: 2.0,
        gap_tolerance,
        force_tolerance: 1e-10,
        max_newton: 40,
        max_augmentations: 60,
    };
    // Wall 0.05 below the disc; gravity 1; mass-proportional Rayleigh damping alpha = 1.
    let walls = vec![Wall::new([0.0, -0.55], [0.0, 1.0])];
    let dynamics = Dynamics::new(&model, walls, [0.0, -1.0], (1.0, 0.0), settings).unwrap();
    let mut state = dynamics.initial_state([0.0, 0.0]).unwrap();
    let b = 3 * nb / 4; // the node at angle 270 degrees
    let steps = (t_end / dt).round() as usize;
    let (mut g, mut v, mut a) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..steps {
        dynamics.step(&mut state, dt, scheme).unwrap();
        if state.time > 0.6 * t_end {
            g = g.max(state.walls[0].gap[b].abs());
            v = v.max(state.v[2 * b + 1].abs());
            a = a.max(state.a[2 * b + 1].abs());
        }
    }
    (g, v, a)
}

#[test]
#[ignore = "release: ~15 s of implicit dynamics"]
fn composite_scheme_rests_within_the_gap_tolerance_trapezoidal_rule_oscillates() {
    // Expectation (paper fig. 8): once the disc has settled, the lowest node stays within the
    // gap tolerance with the Bathe composite scheme; the trapezoidal rule, at half the step
    // (same cost), keeps spurious oscillations and loses contact (|gap| > 1e-5).
    let tol = 1e-10;
    let (t_end, dt) = (4.0, 0.02);
    let bathe = drop_disc(TimeScheme::Bathe, dt, t_end, tol);
    let trap = drop_disc(TimeScheme::Trapezoidal, dt / 2.0, t_end, tol);
    println!("late max |g_B|, |v_B|, |a_B|: composite {bathe:?}, trapezoidal {trap:?}");
    assert!(bathe.0 < 2.0 * tol, "composite gap {:e}", bathe.0);
    assert!(bathe.1 < 1e-6, "composite velocity {:e}", bathe.1);
    assert!(trap.0 > 1e-5, "trapezoidal gap {:e}", trap.0);
    assert!(trap.1 > 1e-2, "trapezoidal velocity {:e}", trap.1);
}
