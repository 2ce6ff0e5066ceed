//! Newton–Raphson loops nested in augmented-Lagrangian loops (paper section 4, fig. 6), for
//! quasi-static load steps and for the dynamic schemes: the Bathe composite scheme
//! (trapezoidal on dt/2, then 3-point backward Euler, appendix D) and the plain Newmark
//! trapezoidal rule.
//!
//! Linear systems are solved with faer's dense LU, always sequential (`Par::Seq`): results do
//! not depend on the thread count.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::{factor, solve};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Conj, MatMut, Par};

use super::MeshfreeError;
use super::contact::{Multipliers, Wall, WallState, add_wall_contacts};
use super::model::{Dense, DiscModel};

/// Tolerances and the augmented-Lagrangian parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverSettings {
    /// Initial contact stiffness k0 (a pressure per length: of the order of E / R), reset at
    /// each step or sub-step.
    pub k0: f64,
    /// Factor alpha_k applied to k at each augmentation.
    pub alpha_k: f64,
    /// The augmentations stop when max |g| over the active contacts is below this.
    pub gap_tolerance: f64,
    /// Newton stops when the largest residual component is below this (absolute force).
    pub force_tolerance: f64,
    pub max_newton: usize,
    pub max_augmentations: usize,
}

impl Default for SolverSettings {
    fn default() -> Self {
        Self {
            k0: 1.0,
            alpha_k: 2.0,
            gap_tolerance: 1e-7,
            force_tolerance: 1e-11,
            max_newton: 40,
            max_augmentations: 40,
        }
    }
}

/// Iteration counts of one solve.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SolveStats {
    /// Newton steps, with the tangent or reusing the last factorization.
    pub newton_iterations: usize,
    /// Newton steps with a new tangent and factorization (the costly ones).
    pub factorizations: usize,
    pub augmentations: usize,
    /// max |g| over active contacts at the end.
    pub max_penetration: f64,
}

impl std::ops::AddAssign for SolveStats {
    fn add_assign(&mut self, o: Self) {
        self.newton_iterations += o.newton_iterations;
        self.factorizations += o.factorizations;
        self.augmentations += o.augmentations;
        self.max_penetration = self.max_penetration.max(o.max_penetration);
    }
}

/// Dynamic terms of a (sub-)step: the acceleration and velocity are affine in the unknown
/// displacement, `A = c_m U + a_const`, `V = c_v U + v_const`; the residual gets `M A + C V`
/// and the tangent `c_m M + c_v C`.
#[derive(Debug, Clone)]
pub struct DynamicTerms<'a> {
    pub c_m: f64,
    pub c_v: f64,
    pub a_const: Vec<f64>,
    pub v_const: Vec<f64>,
    pub damping: Option<&'a Dense>,
}

impl<'a> DynamicTerms<'a> {
    /// Trapezoidal rule on an interval `h` from `(u0, v0, a0)`:
    /// `U = U0 + h/2 (V0 + V)`, `V = V0 + h/2 (A0 + A)`.
    pub fn trapezoidal(
        h: f64,
        u0: &[f64],
        v0: &[f64],
        a0: &[f64],
        damping: Option<&'a Dense>,
    ) -> Self {
        let c_m = 4.0 / (h * h);
        let c_v = 2.0 / h;
        Self {
            c_m,
            c_v,
            a_const: (0..u0.len())
                .map(|i| -c_m * u0[i] - 4.0 / h * v0[i] - a0[i])
                .collect(),
            v_const: (0..u0.len()).map(|i| -c_v * u0[i] - v0[i]).collect(),
            damping,
        }
    }

    /// Three-point backward Euler over `dt` after the mid-step state `(u1, v1)` (second
    /// sub-step of Bathe's scheme): `V2 = (U0 - 4 U1 + 3 U2)/dt`, `A2 = (V0 - 4 V1 + 3 V2)/dt`.
    pub fn backward_euler3(
        dt: f64,
        u0: &[f64],
        u1: &[f64],
        v0: &[f64],
        v1: &[f64],
        damping: Option<&'a Dense>,
    ) -> Self {
        let c_v = 3.0 / dt;
        let v_const: Vec<f64> = (0..u0.len()).map(|i| (u0[i] - 4.0 * u1[i]) / dt).collect();
        let c_m = 9.0 / (dt * dt);
        let a_const: Vec<f64> = (0..u0.len())
            .map(|i| (v0[i] - 4.0 * v1[i]) / dt + 3.0 / dt * v_const[i])
            .collect();
        Self {
            c_m,
            c_v,
            a_const,
            v_const,
            damping,
        }
    }

    /// Velocity at the solved displacement `u`.
    pub fn velocity(&self, u: &[f64]) -> Vec<f64> {
        u.iter()
            .zip(&self.v_const)
            .map(|(u, v)| self.c_v * u + v)
            .collect()
    }

    /// Acceleration at the solved displacement `u`.
    pub fn acceleration(&self, u: &[f64]) -> Vec<f64> {
        u.iter()
            .zip(&self.a_const)
            .map(|(u, a)| self.c_m * u + a)
            .collect()
    }
}

/// The largest magnitude of a Newton residual; an error if it is not finite.
pub(crate) fn finite_residual_norm(r: &[f64]) -> Result<f64, MeshfreeError> {
    let norm = r.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    if !norm.is_finite() {
        return Err(MeshfreeError::NotConverged(
            "the residual is not finite (NaN or infinity)".into(),
        ));
    }
    Ok(norm)
}

/// Applies a Newton correction `du` to `u` with step length control: `u + alpha du` for
/// alpha = 1, 1/2, 1/4, … (30 tries), the first at which `valid` holds (no material point
/// inverted). Returns that alpha; an error if none does.
pub(crate) fn newton_update(
    u: &mut Vec<f64>,
    du: &[f64],
    valid: impl Fn(&[f64]) -> bool,
) -> Result<f64, MeshfreeError> {
    let mut alpha = 1.0;
    for _ in 0..30 {
        let trial: Vec<f64> = u.iter().zip(du).map(|(u, d)| u + alpha * d).collect();
        if valid(&trial) {
            *u = trial;
            return Ok(alpha);
        }
        alpha *= 0.5;
    }
    Err(MeshfreeError::NotConverged(
        "every Newton step inverts the material (det F <= 0)".into(),
    ))
}

/// Solves `K x = b` in place (dense LU with partial pivoting, sequential). `k` is overwritten.
pub fn lu_solve(k: &mut Dense, b: &mut [f64]) -> Result<(), MeshfreeError> {
    let n = k.n;
    let par = Par::Seq;
    let mut perm = vec![0usize; n];
    let mut perm_inv = vec![0usize; n];
    let mut a = MatMut::from_column_major_slice_mut(&mut k.data, n, n);
    let mut buf = MemBuffer::new(factor::lu_in_place_scratch::<usize, f64>(
        n,
        n,
        par,
        Default::default(),
    ));
    let (_, p) = factor::lu_in_place(
        a.rb_mut(),
        &mut perm,
        &mut perm_inv,
        par,
        MemStack::new(&mut buf),
        Default::default(),
    );
    let mut buf2 = MemBuffer::new(solve::solve_in_place_scratch::<usize, f64>(n, 1, par));
    let rhs = MatMut::from_column_major_slice_mut(b, n, 1);
    solve::solve_in_place_with_conj(
        a.rb(),
        a.rb(),
        p,
        Conj::No,
        rhs,
        par,
        MemStack::new(&mut buf2),
    );
    if b.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(MeshfreeError::Singular)
    }
}

/// A problem for the nonlinear solver: one grain, walls, external forces, fixed DoF.
#[derive(Debug, Clone)]
pub struct Problem<'a> {
    pub model: &'a DiscModel,
    pub walls: &'a [Wall],
    pub external: &'a [f64],
    /// DoF held at their current value (e.g. to remove a rigid rotation).
    pub fixed: &'a [usize],
    pub settings: SolverSettings,
}

impl Problem<'_> {
    /// Residual `f_int - f_ext - f_c + M A + C V` and, if asked, its tangent.
    fn residual(
        &self,
        u: &[f64],
        multipliers: &Multipliers,
        k: f64,
        dynamic: Option<&DynamicTerms>,
        mut tangent: Option<&mut Dense>,
    ) -> Result<(Vec<f64>, Vec<WallState>), MeshfreeError> {
        let m = self.model;
        let mut r: Vec<f64> = self.external.iter().map(|f| -f).collect();
        if let Some(t) = tangent.as_deref_mut() {
            t.fill_zero();
        }
        m.internal(u, &mut r, tangent.as_deref_mut())?;
        let states = add_wall_contacts(
            m,
            u,
            self.walls,
            multipliers,
            k,
            &mut r,
            tangent.as_deref_mut(),
        );
        if let Some(d) = dynamic {
            let acc: Vec<f64> = u
                .iter()
                .zip(&d.a_const)
                .map(|(u, a)| d.c_m * u + a)
                .collect();
            let ma = m.mass_mul(&acc);
            r.iter_mut().zip(&ma).for_each(|(r, v)| *r += v);
            if let Some(c) = d.damping {
                let vel: Vec<f64> = u
                    .iter()
                    .zip(&d.v_const)
                    .map(|(u, v)| d.c_v * u + v)
                    .collect();
                let cv = c.mul_vec(&vel);
                r.iter_mut().zip(&cv).for_each(|(r, v)| *r += v);
            }
            if let Some(t) = tangent.as_deref_mut() {
                m.add_mass(d.c_m, t);
                if let Some(c) = d.damping {
                    t.add_scaled(d.c_v, c);
                }
            }
        }
        for &i in self.fixed {
            r[i] = 0.0;
            if let Some(t) = tangent.as_deref_mut() {
                for j in 0..t.n {
                    t.data[i * t.n + j] = 0.0;
                    t.data[j * t.n + i] = 0.0;
                }
                t.data[i * t.n + i] = 1.0;
            }
        }
        Ok((r, states))
    }

    /// Newton iterations at fixed multipliers and stiffness.
    fn newton(
        &self,
        u: &mut Vec<f64>,
        multipliers: &Multipliers,
        k: f64,
        dynamic: Option<&DynamicTerms>,
        stats: &mut SolveStats,
    ) -> Result<Vec<WallState>, MeshfreeError> {
        let n = self.model.dofs();
        let mut tangent = Dense::zeros(n);
        let mut last_norm = f64::INFINITY;
        for _ in 0..self.settings.max_newton {
            let (r, states) = self.residual(u, multipliers, k, dynamic, Some(&mut tangent))?;
            let norm = finite_residual_norm(&r)?;
            last_norm = norm;
            if norm <= self.settings.force_tolerance {
                return Ok(states);
            }
            stats.newton_iterations += 1;
            stats.factorizations += 1;
            let mut du: Vec<f64> = r.iter().map(|v| -v).collect();
            lu_solve(&mut tangent, &mut du)?;
            newton_update(u, &du, |trial| self.model.all_points_valid(trial))?;
        }
        Err(MeshfreeError::NotConverged(format!(
            "Newton did not converge in {} iterations (residual {last_norm:.3e} > {:.1e})",
            self.settings.max_newton, self.settings.force_tolerance
        )))
    }

    /// Newton loops nested in augmentation loops; `u` and `multipliers` are updated in place.
    pub fn solve(
        &self,
        u: &mut Vec<f64>,
        multipliers: &mut Multipliers,
        dynamic: Option<&DynamicTerms>,
    ) -> Result<(Vec<WallState>, SolveStats), MeshfreeError> {
        let s = self.settings;
        let mut k = s.k0;
        let mut stats = SolveStats::default();
        for _ in 0..s.max_augmentations {
            let states = self.newton(u, multipliers, k, dynamic, &mut stats)?;
            let mut pen = 0.0f64;
            for (w, st) in states.iter().enumerate() {
                for (i, &t) in st.pressure.iter().enumerate() {
                    if t > 0.0 {
                        pen = pen.max(st.gap[i].abs());
                    }
                    multipliers.values[w][i] = t;
                }
            }
            stats.augmentations += 1;
            stats.max_penetration = pen;
            if pen <= s.gap_tolerance {
                return Ok((states, stats));
            }
            k *= s.alpha_k;
        }
        Err(MeshfreeError::NotConverged(format!(
            "the augmented Lagrangian did not reach the gap tolerance {:.1e} in {} augmentations \
             (max gap {:.3e})",
            s.gap_tolerance, s.max_augmentations, stats.max_penetration
        )))
    }
}

/// Time integration schemes for the dynamic runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum TimeScheme {
    /// Bathe's composite scheme: trapezoidal rule on dt/2, then 3-point backward Euler.
    #[default]
    Bathe,
    /// Plain Newmark trapezoidal rule (average acceleration) on dt.
    Trapezoidal,
    /// Explicit central differences with lumped mass and penalty contacts, in sub-steps below
    /// the critical step (assemblies only; see `assembly::explicit`).
    CentralDifference,
}

/// State of a dynamic run.
#[derive(Debug, Clone)]
pub struct DynamicState {
    pub time: f64,
    pub u: Vec<f64>,
    pub v: Vec<f64>,
    pub a: Vec<f64>,
    pub multipliers: Multipliers,
    pub walls: Vec<WallState>,
}

/// One grain under gravity among walls, with Rayleigh damping `C = alpha M + beta K_i0`.
#[derive(Debug, Clone)]
pub struct Dynamics<'a> {
    pub model: &'a DiscModel,
    pub walls: Vec<Wall>,
    pub external: Vec<f64>,
    pub damping: Option<Dense>,
    pub settings: SolverSettings,
}

impl<'a> Dynamics<'a> {
    pub fn new(
        model: &'a DiscModel,
        walls: Vec<Wall>,
        gravity: [f64; 2],
        rayleigh: (f64, f64),
        settings: SolverSettings,
    ) -> Result<Self, MeshfreeError> {
        let damping = if rayleigh.0 != 0.0 || rayleigh.1 != 0.0 {
            let mut c = model.initial_stiffness()?;
            c.data.iter_mut().for_each(|v| *v *= rayleigh.1);
            model.add_mass(rayleigh.0, &mut c);
            Some(c)
        } else {
            None
        };
        Ok(Self {
            model,
            walls,
            external: model.body_force(gravity),
            damping,
            settings,
        })
    }

    fn problem(&self) -> Problem<'_> {
        Problem {
            model: self.model,
            walls: &self.walls,
            external: &self.external,
            fixed: &[],
            settings: self.settings,
        }
    }

    /// State at rest shape with a uniform velocity; the acceleration solves `M a = f_ext -
    /// f_int - C v + f_c`.
    pub fn initial_state(&self, velocity: [f64; 2]) -> Result<DynamicState, MeshfreeError> {
        let n = self.model.dofs();
        let u = vec![0.0; n];
        let v: Vec<f64> = (0..n).map(|i| velocity[i % 2]).collect();
        let multipliers = Multipliers::zeros(self.walls.len(), self.model.nodes.boundary_count);
        let (r, walls) = self
            .problem()
            .residual(&u, &multipliers, self.settings.k0, None, None)?;
        let mut rhs: Vec<f64> = r.iter().map(|x| -x).collect();
        if let Some(c) = &self.damping {
            let cv = c.mul_vec(&v);
            rhs.iter_mut().zip(&cv).for_each(|(r, x)| *r -= x);
        }
        let mut m = Dense::zeros(n);
        self.model.add_mass(1.0, &mut m);
        lu_solve(&mut m, &mut rhs)?;
        Ok(DynamicState {
            time: 0.0,
            u,
            v,
            a: rhs,
            multipliers,
            walls,
        })
    }

    /// Advances `state` by `dt`.
    pub fn step(
        &self,
        state: &mut DynamicState,
        dt: f64,
        scheme: TimeScheme,
    ) -> Result<SolveStats, MeshfreeError> {
        let p = self.problem();
        let damping = self.damping.as_ref();
        let (u0, v0, a0) = (state.u.clone(), state.v.clone(), state.a.clone());
        let mut stats = SolveStats::default();
        let mid = match scheme {
            TimeScheme::Trapezoidal => dt,
            TimeScheme::Bathe => 0.5 * dt,
            TimeScheme::CentralDifference => {
                return Err(MeshfreeError::BadInput(
                    "the single-disc solver is implicit: use Bathe or Trapezoidal".into(),
                ));
            }
        };
        let terms = DynamicTerms::trapezoidal(mid, &u0, &v0, &a0, damping);
        let mut u1 = u0.clone();
        let (walls, s) = p.solve(&mut u1, &mut state.multipliers, Some(&terms))?;
        stats += s;
        let v1 = terms.velocity(&u1);
        match scheme {
            TimeScheme::Trapezoidal | TimeScheme::CentralDifference => {
                state.a = terms.acceleration(&u1);
                state.v = v1;
                state.u = u1;
                state.walls = walls;
            }
            TimeScheme::Bathe => {
                let terms = DynamicTerms::backward_euler3(dt, &u0, &u1, &v0, &v1, damping);
                let mut u2 = u1.clone();
                let (walls, s) = p.solve(&mut u2, &mut state.multipliers, Some(&terms))?;
                stats += s;
                state.v = terms.velocity(&u2);
                state.a = terms.acceleration(&u2);
                state.u = u2;
                state.walls = walls;
            }
        }
        state.time += dt;
        Ok(stats)
    }
}
