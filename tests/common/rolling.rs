//! The meshfree disc rolling down a 45° incline (seed 002 §5.2): a run of an assembly measured
//! along the slope, the fit of s = (x - x0)/(g t^2 sin θ), and the shipped scenario
//! `rolling_disc_meshfree.ron` at a given nodal density and coefficient.

use sdem::meshfree::TimeScheme;
use sdem::meshfree::assembly::{Assembly, AssemblyState};
use sdem::run::meshfree::Meshfree;
use sdem::scenario::{Model, Scenario};
use std::path::Path;

/// Gravity (m/s^2) and the incline's angle of the benchmark.
pub const GRAVITY: f64 = 10.0;
pub const THETA: f64 = std::f64::consts::FRAC_PI_4;

/// What a run down the incline measured.
pub struct Roll {
    /// Time and distance travelled downhill by the area centroid, after each step.
    pub samples: Vec<(f64, f64)>,
    /// Energy dissipated by friction, all steps together.
    pub dissipated: f64,
    /// Steps that ended with the disc touching the incline.
    pub touching: usize,
    /// Steps that ended with a friction history (an active frictional contact).
    pub with_history: usize,
    pub state: AssemblyState,
}

/// `steps` Bathe steps of `dt` of grain 0 of `a`, its progress measured along `downhill`.
pub fn roll(a: &mut Assembly, dt: f64, steps: usize, downhill: [f64; 2]) -> Roll {
    roll_with(a, dt, steps, downhill, TimeScheme::Bathe)
}

/// [`roll`] with the time scheme `scheme`.
pub fn roll_with(
    a: &mut Assembly,
    dt: f64,
    steps: usize,
    downhill: [f64; 2],
    scheme: TimeScheme,
) -> Roll {
    let mut state = a.initial_state();
    let (_, c0) = a.grains[0].contour_area_centroid(&state.u);
    let mut out = Roll {
        samples: Vec::with_capacity(steps),
        dissipated: 0.0,
        touching: 0,
        with_history: 0,
        state: state.clone(),
    };
    for _ in 0..steps {
        let (eval, _) = a.step(&mut state, dt, scheme).unwrap();
        out.dissipated += eval.dissipation;
        out.touching += usize::from(!eval.elements.is_empty());
        out.with_history += usize::from(!state.friction.is_empty());
        let (_, c) = a.grains[0].contour_area_centroid(&state.u);
        let d = (c[0] - c0[0]) * downhill[0] + (c[1] - c0[1]) * downhill[1];
        out.samples.push((state.time, d));
    }
    out.state = state;
    out
}

/// `s = c / (g sin θ)` of the least-squares fit `x = x0 + c t^2` over the samples with
/// `t >= from`.
pub fn fit_s(samples: &[(f64, f64)], from: f64) -> f64 {
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

/// The shipped scenario (mu 0.6 on the incline), `boundary_nodes` and the plane's `mu` as
/// given, run until `until` seconds.
pub fn rolling_scenario(boundary_nodes: usize, mu: f64, until: f64) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/rolling_disc_meshfree.ron");
    let (mut s, _) = Scenario::load(&path).unwrap();
    if let Model::Meshfree(m) = &mut s.model {
        m.boundary_nodes = boundary_nodes;
    }
    s.planes[0].friction = mu;
    s.loading = vec![sdem::boundary::loading::Phase::Relax {
        until: sdem::boundary::loading::StopWhen::Time(until),
    }];
    s.validate().unwrap();
    s
}

/// s of the shipped scenario at `boundary_nodes` with the plane's `mu`, over 20 ms; the
/// fraction of steps touching the plane and the CPU time.
pub fn scenario_s(boundary_nodes: usize, mu: f64) -> (f64, f64, f64) {
    let t0 = std::time::Instant::now();
    let s = rolling_scenario(boundary_nodes, mu, 0.02);
    let mut sim = Meshfree::new(&s).unwrap();
    let dt = match s.time_step {
        sdem::scenario::TimeStep::Fixed(dt) => dt,
        _ => unreachable!(),
    };
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let r = roll(&mut sim.assembly, dt, 200, [h, -h]);
    (
        fit_s(&r.samples, 2e-3),
        r.touching as f64 / r.samples.len() as f64,
        t0.elapsed().as_secs_f64(),
    )
}
