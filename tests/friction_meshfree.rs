//! Coulomb friction of the meshfree solver (SPEC §13, §11): an elastic disc rolling or
//! slipping down a 45° incline (the seed's benchmark), blocks sticking and sliding on a plate,
//! the energy a sliding contact dissipates, determinism and the 2D Hertz contact.
//!
//! The incline is the bottom wall with gravity tilted by 45°: g = (g sin θ, -g cos θ).

use glam::DVec2;
use sdem::boundary::walls::Wall;
use sdem::meshfree::assembly::{Assembly, AssemblyState};
use sdem::meshfree::friction::FrictionCoefficients;
use sdem::meshfree::{
    DiscNodes, GrainModel, Hyperelastic, HyperelasticLaw, NodeDensity, NodeSet, SolverSettings,
    TimeScheme,
};

/// The seed's material and disc (SPEC §11): E = 10 MPa, nu = 0.45, rho = 990 kg/m^3,
/// R = 0.5 mm; g = 10 m/s^2 on a 45° incline.
const YOUNG: f64 = 10e6;
const POISSON: f64 = 0.45;
const DENSITY: f64 = 990.0;
const RADIUS: f64 = 0.5e-3;
const GRAVITY: f64 = 10.0;
const THETA: f64 = std::f64::consts::FRAC_PI_4;

fn disc(boundary_nodes: usize, centre: [f64; 2]) -> GrainModel {
    let mut nodes: NodeSet = DiscNodes::disc(RADIUS, NodeDensity::new(boundary_nodes))
        .unwrap()
        .into();
    for p in &mut nodes.positions {
        p[0] += centre[0];
        p[1] += centre[1];
    }
    let material = Hyperelastic::new(HyperelasticLaw::NeoHookean, YOUNG, POISSON, DENSITY).unwrap();
    GrainModel::from_nodes(nodes, material).unwrap()
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

/// Time and centroid x of the disc after each of `steps` Bathe steps of `dt`.
fn roll(a: &mut Assembly, dt: f64, steps: usize) -> (Vec<(f64, f64)>, AssemblyState) {
    let mut state = a.initial_state();
    let mut out = Vec::with_capacity(steps);
    for _ in 0..steps {
        a.step(&mut state, dt, TimeScheme::Bathe).unwrap();
        let (_, c) = a.grains[0].contour_area_centroid(&state.u);
        out.push((state.time, c[0]));
    }
    (out, state)
}

/// `s = c / (g sin θ)` of the least-squares fit `x = x0 + c t^2` over the samples with
/// `t >= from`.
fn fit_s(samples: &[(f64, f64)], from: f64) -> f64 {
    let pts: Vec<(f64, f64)> = samples
        .iter()
        .filter(|(t, _)| *t >= from)
        .map(|&(t, x)| (t * t, x))
        .collect();
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    sxy / sxx / (GRAVITY * THETA.sin())
}

#[test]
#[ignore]
fn explore_rolling() {
    for (nb, mu, dt) in [(32, 0.6, 1e-4), (32, 0.6, 5e-5), (48, 0.6, 1e-4)] {
        let t0 = std::time::Instant::now();
        let mut a = incline(nb, mu);
        let steps = (0.02 / dt) as usize;
        let mut state = a.initial_state();
        let mut xs = Vec::new();
        let mut dissipated = 0.0;
        let mut stuck = (0, 0);
        for _ in 0..steps {
            let (eval, _) = a.step(&mut state, dt, TimeScheme::Bathe).unwrap();
            dissipated += eval.friction_dissipation();
            for e in &eval.elements {
                if let Some(f) = e.friction {
                    if f.sticking { stuck.0 += 1 } else { stuck.1 += 1 }
                }
            }
            let (_, c) = a.grains[0].contour_area_centroid(&state.u);
            xs.push((state.time, c[0]));
        }
        println!(
            "nb {nb} mu {mu} dt {dt}: s = {:.4} (from 2 ms) {:.4} (from 5 ms), x_end {:.3e}, stick/slip {stuck:?}, dissipated {dissipated:.3e}, {:.1} s",
            fit_s(&xs, 2e-3),
            fit_s(&xs, 5e-3),
            xs.last().unwrap().1,
            t0.elapsed().as_secs_f64()
        );
    }
}
