//! Explicit dynamics of an assembly: lumped mass, central differences, penalty contact (the
//! scheme of the public MELODY2D code). No equation is solved: a sub-step costs one residual
//! evaluation, and the sub-step is bounded by the highest frequency of the grains and of the
//! contact springs ([`ExplicitData::critical_step`]).
//!
//! Contacts are penalty springs of stiffness `k0`, with no augmentation: a contact carrying a
//! pressure `p` penetrates by about `p / k0`, so `k0` sets the accuracy of the contacts (and,
//! through the critical step, the cost).
//!
//! Friction (walls with `mu > 0`): a tangential penalty spring of stiffness `r_t k0` per
//! contact node with the Coulomb limit, the traction kept from sub-step to sub-step in
//! [`AssemblyState::friction`] (the same return mapping as the implicit scheme, with the slip
//! of one sub-step, `h` times the half-step velocity relative to the wall).

use rayon::prelude::*;

use super::{
    Assembly, AssemblyState, ContactMultipliers, Evaluation, FrictionInput, SlipOrigin, StepStats,
};
use crate::geometry::angle::sin;
use crate::meshfree::MeshfreeError;
use crate::meshfree::model::GrainModel;
use crate::meshfree::solver::{SolveStats, finite_residual_norm};

/// Fraction of the critical time step taken: the estimate is that of the undeformed grains
/// with every contact node loaded by both passes, and the margin covers the grains' stiffening
/// under compression.
pub const EXPLICIT_SAFETY: f64 = 0.5;

/// Power iterations for a grain's highest frequency.
const POWER_ITERATIONS: usize = 200;

/// What the explicit scheme adds to an assembly.
#[derive(Debug, Clone)]
pub struct ExplicitData {
    /// Lumped mass per DoF (HRZ: the consistent mass's diagonal scaled to the grain's mass,
    /// positive whatever the sign of the shape functions).
    pub lumped_mass: Vec<f64>,
    /// `M_L g - f_ext`: the body force made consistent with the lumped mass, so that a grain
    /// in free fall stays undeformed.
    pub body_force_correction: Vec<f64>,
    /// Critical time step `2 / omega_max`, with `omega_max^2` the largest eigenvalue of
    /// `M_L^-1 K_0` over the grains plus `4 k0 l / m` for the contact springs (`l`: the
    /// longest contour segment, `m`: the smallest contour node mass).
    pub critical_step: f64,
}

impl ExplicitData {
    /// The sub-step taken: [`EXPLICIT_SAFETY`] of the critical step.
    pub fn sub_step(&self) -> f64 {
        EXPLICIT_SAFETY * self.critical_step
    }
}

/// HRZ lumped mass of one grain, per node.
fn lumped_node_mass(model: &GrainModel) -> Vec<f64> {
    let n = model.node_count();
    let diagonal: Vec<f64> = (0..n).map(|a| model.scalar_mass.get(a, a)).collect();
    let total: f64 = model.scalar_mass.data.iter().sum();
    let trace: f64 = diagonal.iter().sum();
    diagonal.iter().map(|d| d * total / trace).collect()
}

/// Largest eigenvalue of `M_L^-1 K_0` for one grain (Rayleigh quotient after power
/// iterations from a fixed start: deterministic).
fn largest_eigenvalue(model: &GrainModel, node_mass: &[f64]) -> Result<f64, MeshfreeError> {
    let k = model.initial_stiffness()?;
    let n = k.n;
    let mass = |i: usize| node_mass[i / 2];
    let mut v: Vec<f64> = (0..n).map(|i| sin(1.7 * i as f64 + 0.3)).collect();
    let mut lambda = 0.0;
    for _ in 0..POWER_ITERATIONS {
        let mut w = vec![0.0; n];
        for (col, &vc) in v.iter().enumerate() {
            for (wi, &kij) in w.iter_mut().zip(&k.data[col * n..(col + 1) * n]) {
                *wi += kij * vc;
            }
        }
        let vkv: f64 = v.iter().zip(&w).map(|(a, b)| a * b).sum();
        let vmv: f64 = v.iter().enumerate().map(|(i, a)| a * a * mass(i)).sum();
        lambda = vkv / vmv;
        for (i, wi) in w.iter_mut().enumerate() {
            *wi /= mass(i);
        }
        let norm = w.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        if norm == 0.0 || !norm.is_finite() {
            break;
        }
        v = w.into_iter().map(|x| x / norm).collect();
    }
    Ok(lambda)
}

impl Assembly {
    /// Prepares the explicit scheme (lumped mass, critical step); computed once, before the
    /// first explicit step. Fails when `rayleigh_beta` is not 0 (stiffness damping would need
    /// `K_0 v` at every sub-step).
    pub fn use_explicit(&mut self) -> Result<&ExplicitData, MeshfreeError> {
        if self.rayleigh.1 != 0.0 {
            return Err(MeshfreeError::BadInput(
                "rayleigh_beta: the explicit scheme (CentralDifference) takes mass-proportional \
                 damping only: set it to 0"
                    .into(),
            ));
        }
        if self.explicit.is_none() {
            let per_grain: Vec<(Vec<f64>, f64)> = self
                .grains
                .par_iter()
                .map(|g| {
                    let m = lumped_node_mass(g);
                    let lambda = largest_eigenvalue(g, &m)?;
                    Ok((m, lambda))
                })
                .collect::<Result<_, MeshfreeError>>()?;
            let mut lumped_mass = Vec::with_capacity(self.dofs());
            let (mut lambda_max, mut contour_mass) = (0.0f64, f64::INFINITY);
            for (g, (m, lambda)) in per_grain.iter().enumerate() {
                if m.iter().any(|&x| x.is_nan() || x <= 0.0) {
                    return Err(MeshfreeError::BadInput(format!(
                        "grain {g}: a lumped node mass is not positive"
                    )));
                }
                lumped_mass.extend(m.iter().flat_map(|&x| [x, x]));
                lambda_max = lambda_max.max(*lambda);
                let nb = self.grains[g].nodes.boundary_count;
                contour_mass = m[..nb].iter().fold(contour_mass, |a, &b| a.min(b));
            }
            // `near_distance` is twice the longest contour segment.
            let segment = 0.5 * self.near_distance;
            // A tangential spring stiffer than the normal one bounds the step instead.
            let spring = if self.friction.any() {
                self.friction.stiffness_ratio.max(1.0)
            } else {
                1.0
            };
            let omega2 = lambda_max + 4.0 * spring * self.settings.k0 * segment / contour_mass;
            let body_force_correction = lumped_mass
                .iter()
                .enumerate()
                .map(|(i, m)| m * self.gravity[i % 2] - self.external[i])
                .collect();
            self.explicit = Some(ExplicitData {
                lumped_mass,
                body_force_correction,
                critical_step: 2.0 / omega2.sqrt(),
            });
        }
        Ok(self.explicit.as_ref().expect("set above"))
    }

    /// The slip origin of an explicit sub-step of `h` ending at `state.u`: the nodes at
    /// `u - h v` (`state.v`: the half-step velocity of the sub-step), the walls `h` earlier.
    fn explicit_slip_origin(&self, state: &AssemblyState, h: f64) -> SlipOrigin {
        let before: Vec<f64> = state
            .u
            .iter()
            .zip(&state.v)
            .map(|(u, v)| u - h * v)
            .collect();
        let mut origin = self.slip_origin(&before);
        for (p, w) in origin.wall_points.iter_mut().zip(&self.walls) {
            p[0] -= h * w.velocity.x;
            p[1] -= h * w.velocity.y;
        }
        origin
    }

    /// Evaluation at `state.u` with penalty contacts, the friction of a sub-step of `h` when
    /// a wall has friction.
    fn explicit_evaluation(
        &self,
        state: &AssemblyState,
        h: f64,
    ) -> Result<Evaluation, MeshfreeError> {
        let no_multipliers = ContactMultipliers::new();
        let k = self.settings.k0;
        if !self.friction.any() {
            return self.evaluate(&state.u, &no_multipliers, k, None, false);
        }
        let origin = self.explicit_slip_origin(state, h);
        let input = FrictionInput {
            tractions: &state.friction,
            origin: &origin,
        };
        self.evaluate_with(&state.u, &no_multipliers, Some(input), k, None, false)
    }

    /// `sub_steps` central-difference steps of `h` from `state` (walls moved from `walls0` at
    /// their velocities); returns the deepest penetration met and the energy friction
    /// dissipated.
    fn central_differences(
        &mut self,
        state: &mut AssemblyState,
        data: &ExplicitData,
        walls0: &[crate::boundary::walls::Wall],
        h: f64,
        sub_steps: usize,
    ) -> Result<(f64, f64), MeshfreeError> {
        let alpha = self.rayleigh.0;
        let mut fixed = vec![false; self.dofs()];
        for &i in &self.fixed {
            fixed[i] = true;
        }
        let (mut max_penetration, mut dissipation) = (0.0f64, 0.0);
        let (keep, gain) = (1.0 - 0.5 * alpha * h, 1.0 / (1.0 + 0.5 * alpha * h));
        // At the start of a run `state.v` is the velocity at t = 0, not at -h/2: the first
        // sub-step takes a half step from it (second-order start, exact in free fall).
        let mut start_up = state.time == 0.0;
        for s in 0..sub_steps {
            self.move_walls(walls0, s as f64 * h);
            let eval = self.explicit_evaluation(state, h)?;
            finite_residual_norm(&eval.residual)?;
            if self.friction.any() {
                state.friction = eval.tractions();
                dissipation += eval.friction_dissipation();
            }
            max_penetration = max_penetration.max(eval.max_penetration());
            // One DoF reads seven arrays: an index reads better than a seven-way zip.
            #[allow(clippy::needless_range_loop)]
            for i in 0..state.u.len() {
                if fixed[i] {
                    state.v[i] = 0.0;
                    state.a[i] = 0.0;
                    continue;
                }
                let force = data.body_force_correction[i] - eval.residual[i];
                let acceleration = force / data.lumped_mass[i];
                let v = if start_up {
                    state.v[i] + 0.5 * h * (acceleration - alpha * state.v[i])
                } else {
                    (keep * state.v[i] + h * acceleration) * gain
                };
                state.a[i] = (v - state.v[i]) / h;
                state.v[i] = v;
                state.u[i] += h * v;
            }
            start_up = false;
        }
        Ok((max_penetration, dissipation))
    }

    /// Advances `state` by `dt` in explicit sub-steps of at most
    /// [`ExplicitData::sub_step`]: central differences on `M_L a = f_ext + f_c - f_int`, with
    /// the mass-proportional damping `alpha M_L v` taken at mid-step (`state.v` holds the
    /// half-step velocity). Walls move at their velocities. On failure `state` and the walls
    /// are left part-way: the caller restores them.
    pub(super) fn explicit_step(
        &mut self,
        state: &mut AssemblyState,
        dt: f64,
    ) -> Result<(Evaluation, StepStats), MeshfreeError> {
        self.use_explicit()?;
        // Taken out for the step (no copy of the lumped mass), put back whatever happens.
        let data = self.explicit.take().expect("use_explicit set it");
        let sub_steps = (dt / data.sub_step()).ceil().max(1.0) as usize;
        let walls0 = self.walls.clone();
        let advanced =
            self.central_differences(state, &data, &walls0, dt / sub_steps as f64, sub_steps);
        self.explicit = Some(data);
        let (max_penetration, dissipation) = advanced?;
        self.move_walls(&walls0, dt);
        // The tractions of the next sub-step (not committed: that sub-step commits them).
        let mut eval = self.explicit_evaluation(state, dt / sub_steps as f64)?;
        eval.dissipation = dissipation;
        finite_residual_norm(&eval.residual)?;
        let max_penetration = max_penetration.max(eval.max_penetration());
        state.time += dt;
        Ok((
            eval,
            StepStats {
                solve: SolveStats {
                    max_penetration,
                    ..SolveStats::default()
                },
                sub_steps,
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::meshfree::solver::SolverSettings;
    use crate::meshfree::{DiscNodes, Hyperelastic, HyperelasticLaw, NodeDensity, NodeSet};

    /// One free disc (E = 1, nu = 0.3, rho = 1, R = 0.5, 24 contour nodes), no gravity, no
    /// damping, contact springs negligible: its critical step is the grain's alone.
    fn free_disc() -> Assembly {
        let nodes: NodeSet = DiscNodes::disc(0.5, NodeDensity::new(24)).unwrap().into();
        let material = Hyperelastic::new(HyperelasticLaw::NeoHookean, 1.0, 0.3, 1.0).unwrap();
        let grain = GrainModel::from_nodes(nodes, material).unwrap();
        let settings = SolverSettings {
            k0: 1e-12,
            ..SolverSettings::default()
        };
        Assembly::new(vec![grain], Vec::new(), [0.0, 0.0], (0.0, 0.0), settings).unwrap()
    }

    /// Largest kinetic + elastic energy over `steps` central-difference steps of `h` from a
    /// small deterministic perturbation, relative to the starting energy.
    fn energy_growth(h: f64, steps: usize) -> f64 {
        let mut a = free_disc();
        let data = a.use_explicit().unwrap().clone();
        let mut state = a.initial_state();
        state.time = 1.0; // not a start-up step
        state.a.iter_mut().for_each(|x| *x = 0.0);
        for (i, u) in state.u.iter_mut().enumerate() {
            *u = 1e-6 * (0.77 * i as f64 + 0.1).sin();
        }
        // An inverted material point is a blow-up: infinite growth.
        let energy = |a: &Assembly, s: &AssemblyState| {
            a.evaluate(&s.u, &ContactMultipliers::new(), 0.0, None, false)
                .map_or(f64::INFINITY, |e| e.elastic_energy + a.kinetic_energy(&s.v))
        };
        let e0 = energy(&a, &state);
        let walls = a.walls.clone();
        let mut worst = 1.0f64;
        for _ in 0..steps / 50 {
            if a.central_differences(&mut state, &data, &walls, h, 50)
                .is_err()
            {
                return f64::INFINITY;
            }
            worst = worst.max(energy(&a, &state) / e0);
        }
        worst
    }

    #[test]
    fn the_critical_step_estimate_bounds_stability() {
        // Expectation: central differences are stable for h < 2 / omega_max and unstable
        // above. Just below the estimate the energy of a free vibration stays bounded (it
        // oscillates: the half-step velocities make its kinetic part inexact); 10% above it,
        // the highest mode grows without bound.
        let critical = free_disc().use_explicit().unwrap().critical_step;
        assert!(critical > 0.0 && critical.is_finite());
        let below = energy_growth(0.97 * critical, 3000);
        let above = energy_growth(1.1 * critical, 3000);
        println!("energy growth: x {below:.3} at 0.97 x critical, x {above:e} at 1.1 x");
        assert!(below < 20.0, "0.97 x critical: energy x {below:e}");
        assert!(above > 1e6, "1.1 x critical: energy x {above:e}");
    }
}
