//! Frictionless rigid walls and the node-to-wall contact element (paper appendix C) with an
//! augmented-Lagrangian multiplier per (wall, boundary node).
//!
//! For boundary node s1 with contour neighbours s0 and s2 (current positions), the gap to a
//! wall through `p` with unit normal `n` (pointing to the side the grain lives on) is
//! `g = (x_s1 - p) . n` (negative when it penetrates). The contact pressure is
//! `T = <lambda - k g>` (the paper's `<-lambda - k g>` with lambda stored as a positive
//! pressure) and acts on s1 as the force `T A_s n`, `A_s = (|s1 - s0| + |s2 - s1|)/2` (eq. 22,
//! B.11). Its consistent linearisation is the paper's `K_c3 = k A_s n n^T` plus `K_c4`, the
//! change of `A_s` with the positions of s0, s1, s2.
//!
//! Coulomb friction ([`super::friction`]): the slip coordinate of s1 is `g_T = (x_s1 - p) . τ`
//! along the wall's tangent `τ` (the normal turned by +90°), its slip over the step
//! `Δg_T = g_T - g_T,n`; the return mapping gives the tangential traction `t`, which acts on
//! s1 as `-t A_s τ`. Its linearisation: `-τ ⊗ (A_s dt/dx + t dA_s/dx)` with
//! `dt/dx_s1 = ε_T τ` (stick) or `mu sign(t*) dT/dx_s1 = -mu sign(t*) k n` (slip).

use super::friction::{TangentialInput, return_map};
use super::model::{Dense, DiscModel};
use crate::portable::powf;

/// A rigid, frictionless wall: the line through `point` with unit `normal` pointing to the side
/// of the grain. Prescribed motion is done by moving `point` between steps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    pub point: [f64; 2],
    pub normal: [f64; 2],
}

impl Wall {
    pub fn new(point: [f64; 2], normal: [f64; 2]) -> Self {
        let l = (normal[0] * normal[0] + normal[1] * normal[1]).sqrt();
        Self {
            point,
            normal: [normal[0] / l, normal[1] / l],
        }
    }

    #[inline]
    pub fn gap(&self, x: [f64; 2]) -> f64 {
        (x[0] - self.point[0]) * self.normal[0] + (x[1] - self.point[1]) * self.normal[1]
    }

    /// Unit tangent, the normal turned by +90 degrees.
    pub fn tangent(&self) -> [f64; 2] {
        [-self.normal[1], self.normal[0]]
    }
}

/// Multipliers (contact pressures, >= 0) for every wall and boundary node, `[wall][node]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Multipliers {
    pub values: Vec<Vec<f64>>,
}

impl Multipliers {
    pub fn zeros(walls: usize, boundary: usize) -> Self {
        Self {
            values: vec![vec![0.0; boundary]; walls],
        }
    }
}

/// Contact state of one wall after a solve.
#[derive(Debug, Clone, PartialEq)]
pub struct WallState {
    /// Pressure T of each boundary node (>= 0).
    pub pressure: Vec<f64>,
    /// Gap of each boundary node.
    pub gap: Vec<f64>,
    /// Tributary length A_s of each boundary node.
    pub tributary: Vec<f64>,
}

impl WallState {
    /// Total force the grain exerts on the wall (>= 0), `sum T A_s`.
    pub fn force(&self) -> f64 {
        self.pressure
            .iter()
            .zip(&self.tributary)
            .map(|(t, a)| t * a)
            .sum()
    }
}

#[inline]
fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

#[inline]
fn norm(a: [f64; 2]) -> f64 {
    (a[0] * a[0] + a[1] * a[1]).sqrt()
}

/// One node-to-wall element (appendix C): slave node s1 with its contour neighbours s0, s2.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WallNodeElement {
    pub gap: f64,
    /// T = <lambda - k g> (>= 0).
    pub pressure: f64,
    /// A_s (0 when the node is free).
    pub tributary: f64,
    /// Tangential traction t (per unit length, resisting slip along `+τ`; 0 without friction
    /// or when the node is free).
    pub traction: f64,
    /// Slip of the step `Δg_T` (0 without friction).
    pub slip: f64,
    /// Whether the friction return mapping stuck (false without friction).
    pub sticking: bool,
    /// Contact force on the DoF of [s0, s1, s2] (to be subtracted from a residual
    /// `f_int - f_ext`).
    pub force: [f64; 6],
    /// `d force / d x` (to be subtracted from the residual's tangent); zero when free.
    pub stiffness: [[f64; 6]; 6],
}

/// Evaluates the element of node s1 (`x = [x_s0, x_s1, x_s2]`, current positions) against a
/// wall through `point` with unit `normal` (towards the grain); with `friction`, a frictional
/// wall (the slip origin `g_T,n` measured as `(x_s1,n - p_n) . τ`).
pub fn wall_node_element(
    x: &[[f64; 2]; 3],
    point: [f64; 2],
    normal: [f64; 2],
    lambda: f64,
    stiffness: f64,
    friction: Option<&TangentialInput>,
    with_tangent: bool,
) -> WallNodeElement {
    let n = normal;
    let g = (x[1][0] - point[0]) * n[0] + (x[1][1] - point[1]) * n[1];
    let t = (lambda - stiffness * g).max(0.0);
    let mut e = WallNodeElement {
        gap: g,
        pressure: t,
        tributary: 0.0,
        traction: 0.0,
        slip: 0.0,
        sticking: false,
        force: [0.0; 6],
        stiffness: [[0.0; 6]; 6],
    };
    if t <= 0.0 {
        return e;
    }
    let d0 = sub(x[1], x[0]);
    let d1 = sub(x[2], x[1]);
    let (l0, l1) = (norm(d0), norm(d1));
    let (t0, t1) = ([d0[0] / l0, d0[1] / l0], [d1[0] / l1, d1[1] / l1]);
    let a_s = 0.5 * (l0 + l1);
    e.tributary = a_s;
    e.force[2] = t * a_s * n[0];
    e.force[3] = t * a_s * n[1];
    if with_tangent {
        // d(T A_s n)/dx = n ⊗ (A_s dT/dx + T dA_s/dx), dT/dx_s1 = -k n,
        // dA_s/dx_s0 = -t0/2, dA_s/dx_s1 = (t0 - t1)/2, dA_s/dx_s2 = t1/2.
        for i in 0..2 {
            for j in 0..2 {
                e.stiffness[2 + i][j] = -t * n[i] * 0.5 * t0[j];
                e.stiffness[2 + i][2 + j] =
                    -stiffness * a_s * n[i] * n[j] + t * n[i] * 0.5 * (t0[j] - t1[j]);
                e.stiffness[2 + i][4 + j] = t * n[i] * 0.5 * t1[j];
            }
        }
    }
    if let Some(input) = friction {
        let tau = [-n[1], n[0]];
        let slip = (x[1][0] - point[0]) * tau[0] + (x[1][1] - point[1]) * tau[1] - input.origin;
        let c = return_map(input, slip, t);
        e.traction = c.traction;
        e.slip = slip;
        e.sticking = c.sticking;
        e.force[2] -= c.traction * a_s * tau[0];
        e.force[3] -= c.traction * a_s * tau[1];
        if with_tangent {
            // dt/dx_s1: ε_T τ (stick) or mu sign(t*) (-k n) (slip).
            let dt = [
                c.d_slip * tau[0] - c.d_pressure * stiffness * n[0],
                c.d_slip * tau[1] - c.d_pressure * stiffness * n[1],
            ];
            let tr = c.traction;
            for (i, &tau_i) in tau.iter().enumerate() {
                for j in 0..2 {
                    e.stiffness[2 + i][j] -= tau_i * tr * (-0.5 * t0[j]);
                    e.stiffness[2 + i][2 + j] -= tau_i * (a_s * dt[j] + tr * 0.5 * (t0[j] - t1[j]));
                    e.stiffness[2 + i][4 + j] -= tau_i * tr * 0.5 * t1[j];
                }
            }
        }
    }
    e
}

/// Evaluates the wall contacts: subtracts the contact forces from `residual` (which holds
/// `f_int - f_ext`), adds their linearisation to `tangent`, and returns the wall states.
pub fn add_wall_contacts(
    model: &DiscModel,
    u: &[f64],
    walls: &[Wall],
    multipliers: &Multipliers,
    stiffness: f64,
    residual: &mut [f64],
    mut tangent: Option<&mut Dense>,
) -> Vec<WallState> {
    let nb = model.nodes.boundary_count;
    let mut states = Vec::with_capacity(walls.len());
    for (w, wall) in walls.iter().enumerate() {
        let mut st = WallState {
            pressure: vec![0.0; nb],
            gap: vec![0.0; nb],
            tributary: vec![0.0; nb],
        };
        for s in 0..nb {
            let nodes = [(s + nb - 1) % nb, s, (s + 1) % nb];
            let x = nodes.map(|a| model.position(u, a));
            let e = wall_node_element(
                &x,
                wall.point,
                wall.normal,
                multipliers.values[w][s],
                stiffness,
                None,
                tangent.is_some(),
            );
            st.gap[s] = e.gap;
            if e.pressure <= 0.0 {
                continue;
            }
            st.pressure[s] = e.pressure;
            st.tributary[s] = e.tributary;
            for (p, &a) in nodes.iter().enumerate() {
                residual[2 * a] -= e.force[2 * p];
                residual[2 * a + 1] -= e.force[2 * p + 1];
            }
            if let Some(k) = tangent.as_deref_mut() {
                for (p, &a) in nodes.iter().enumerate() {
                    for (q, &b) in nodes.iter().enumerate() {
                        for i in 0..2 {
                            for j in 0..2 {
                                let v = e.stiffness[2 * p + i][2 * q + j];
                                if v != 0.0 {
                                    k.add(2 * a + i, 2 * b + j, -v);
                                }
                            }
                        }
                    }
                }
            }
        }
        states.push(st);
    }
    states
}

/// Length of the contact of a wall, measured along the wall (see [`contact_length`] docs).
///
/// The active nodes (T > 0) around the deepest node form the contact arc. Its ends lie between
/// the last active node and the first free one; they are placed where the gap of the free nodes,
/// extrapolated as `g ∝ s^(3/2)` (the shape of the gap just outside a smooth elastic contact),
/// vanishes, clamped to that interval. Returns 0 when no node is active.
pub fn contact_length(model: &DiscModel, u: &[f64], wall: &Wall, state: &WallState) -> f64 {
    let nb = model.nodes.boundary_count;
    let Some(centre) = (0..nb)
        .filter(|&s| state.pressure[s] > 0.0)
        .min_by(|&a, &b| state.gap[a].total_cmp(&state.gap[b]))
    else {
        return 0.0;
    };
    let tang = wall.tangent();
    let coord = |s: usize| {
        let x = model.position(u, s);
        x[0] * tang[0] + x[1] * tang[1]
    };
    let mut ends = [0.0; 2];
    for (e, dir) in [(0usize, 1isize), (1, -1)] {
        let step = |s: usize| ((s as isize + dir).rem_euclid(nb as isize)) as usize;
        let mut last = centre;
        let mut count = 0;
        while state.pressure[step(last)] > 0.0 && count < nb {
            last = step(last);
            count += 1;
        }
        let b = step(last);
        let c = step(b);
        let (sa, sb, sc) = (coord(last), coord(b), coord(c));
        let (gb, gc) = (state.gap[b].max(0.0), state.gap[c].max(0.0));
        let (pb, pc) = (powf(gb, 2.0 / 3.0), powf(gc, 2.0 / 3.0));
        let mut se = if pc > pb {
            sb - pb * (sc - sb) / (pc - pb)
        } else {
            0.5 * (sa + sb)
        };
        let (lo, hi) = if sa < sb { (sa, sb) } else { (sb, sa) };
        se = se.clamp(lo, hi);
        ends[e] = se;
    }
    (ends[0] - ends[1]).abs()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slave node s1 pressed 0.01 into a wall tilted by 0.3 rad, its neighbours unequally
    /// spaced (so that `dA_s/dx` matters).
    fn geometry() -> ([[f64; 2]; 3], [f64; 2], [f64; 2]) {
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        let normal = [-s, c];
        let x = [[-0.21, 0.06], [0.02, -0.003], [0.17, 0.09]];
        (x, [0.0, 0.0], normal)
    }

    /// Largest |analytic - central difference| of the element's force over all 6 x 6 entries,
    /// relative to the largest entry.
    fn tangent_error(friction: Option<&TangentialInput>) -> (f64, WallNodeElement) {
        let (x, p, n) = geometry();
        let (lambda, k) = (0.4, 50.0);
        let e = wall_node_element(&x, p, n, lambda, k, friction, true);
        let h = 1e-7;
        let (mut worst, mut scale) = (0.0f64, 0.0f64);
        for col in 0..6 {
            let (mut xp, mut xm) = (x, x);
            xp[col / 2][col % 2] += h;
            xm[col / 2][col % 2] -= h;
            let fp = wall_node_element(&xp, p, n, lambda, k, friction, false).force;
            let fm = wall_node_element(&xm, p, n, lambda, k, friction, false).force;
            for row in 0..6 {
                let fd = (fp[row] - fm[row]) / (2.0 * h);
                worst = worst.max((fd - e.stiffness[row][col]).abs());
                scale = scale.max(e.stiffness[row][col].abs());
            }
        }
        (worst / scale, e)
    }

    #[test]
    fn frictional_wall_tangent_matches_finite_differences() {
        // Expectation: the assembled tangent is the exact derivative of the force, in the stick
        // branch (t = λ_T + ε_T Δg_T) and in the slip branch (t = mu p_N sign, depending on the
        // current pressure: a non-symmetric tangent), to central-difference accuracy.
        let (x, p, n) = geometry();
        let tau = [-n[1], n[0]];
        let g_t = (x[1][0] - p[0]) * tau[0] + (x[1][1] - p[1]) * tau[1];
        // p_N = 0.4 + 50 x 0.01... ~ 0.9: stick with a slip of 0.001 (trial 0.1 + 0.05).
        let stick = TangentialInput {
            mu: 0.5,
            penalty: 50.0,
            lambda: 0.1,
            origin: g_t - 0.001,
        };
        let (err, e) = tangent_error(Some(&stick));
        assert!(e.sticking && e.pressure > 0.0, "{e:?}");
        assert!((e.slip - 0.001).abs() < 1e-15);
        assert!(err < 1e-7, "stick: relative tangent error {err:e}");
        let slip = TangentialInput {
            origin: g_t + 0.05,
            ..stick
        };
        let (err, e) = tangent_error(Some(&slip));
        assert!(!e.sticking, "{e:?}");
        assert!((e.traction + 0.5 * e.pressure).abs() < 1e-15, "{e:?}");
        assert!(err < 1e-7, "slip: relative tangent error {err:e}");
        // The slip tangent is not symmetric: row s1 depends on the pressure's derivative.
        let asym = (0..6)
            .flat_map(|i| (0..6).map(move |j| (i, j)))
            .map(|(i, j)| (e.stiffness[i][j] - e.stiffness[j][i]).abs())
            .fold(0.0, f64::max);
        assert!(asym > 1e-3, "slip tangent unexpectedly symmetric");
        let (err, _) = tangent_error(None);
        assert!(err < 1e-7, "frictionless: relative tangent error {err:e}");
    }

    #[test]
    fn friction_force_resists_slip_and_is_bounded_by_the_cone() {
        // Expectation: a node slipping along +τ receives a tangential force along -τ of
        // magnitude mu T A_s, whatever the slip beyond the cone.
        let (x, p, n) = geometry();
        let tau = [-n[1], n[0]];
        let g_t = (x[1][0] - p[0]) * tau[0] + (x[1][1] - p[1]) * tau[1];
        for origin in [g_t - 0.1, g_t - 1.0] {
            let input = TangentialInput {
                mu: 0.3,
                penalty: 50.0,
                lambda: 0.0,
                origin,
            };
            let e = wall_node_element(&x, p, n, 0.4, 50.0, Some(&input), false);
            let ft = e.force[2] * tau[0] + e.force[3] * tau[1];
            let fn_ = e.force[2] * n[0] + e.force[3] * n[1];
            assert!((ft + 0.3 * fn_).abs() < 1e-14 * fn_, "{ft} vs {fn_}");
            assert!((fn_ - e.pressure * e.tributary).abs() < 1e-14 * fn_);
        }
    }
}
