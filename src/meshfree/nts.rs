//! Smoothed node-to-segment contact element with cubic Hermite splines (paper §3, eq. 15–23,
//! appendix B; SPEC §10b), with its exact consistent tangent. Pure functions, no allocation.
//!
//! # Geometry
//! Each grain's boundary nodes form a closed counter-clockwise (CCW) contour. A slave node `s1`
//! (contour neighbours `s0`, `s2`) is tested against a master segment `[m1, m2]` of another
//! grain, with the master's neighbours `m0`, `m3`. The segment is replaced by the cubic
//! `c(ξ) = Σ N_i(ξ) x_mi`, `ξ ∈ [-1, 1]` (eq. 16): it interpolates `m1` (ξ = -1) and `m2`
//! (ξ = 1) and has the tangent `(x_m2 - x_m0)/4` per unit ξ at `m1` and `(x_m3 - x_m1)/4` at
//! `m2`, so consecutive splines join with C¹ continuity (Catmull–Rom): the smooth contour that
//! keeps the global Newton from chattering at the corners of a polygonal contour.
//!
//! The closest point `ξ_c` solves `r(ξ) = (c(ξ) - x_s)·c'(ξ) = 0` (eq. 17–18) with
//! `r' = c'·c' + (c - x_s)·c'' > 0` (a minimum of the distance). With `t = c'/|c'|` and the
//! outward normal of a CCW contour `n = (t_y, -t_x)`, the gap is `g = (x_s - c(ξ_c))·n`
//! (negative when the slave penetrates the master).
//!
//! "Two-pass" is the caller's business: every boundary node of each grain of a pair is a slave
//! against the other grain's contour, so each grain is both slave and master (the one-pass
//! scheme lets master nodes sink into the slave, fig. 5). One call here is one slave node.
//!
//! # Force
//! `T = <λ - k g>` (the paper's `<-λ - k g>` with λ stored as a positive pressure, as in
//! [`super::contact`]), acting over the slave's tributary length
//! `A_s = (|x_s1 - x_s0| + |x_s2 - x_s1|)/2`. The force is `f = T A_s B` with
//! `B = [0, n, 0, -N_0 n, -N_1 n, -N_2 n, -N_3 n]` (DoF order `[s0, s1, s2, m0, m1, m2, m3]`, x
//! and y each): `+T A_s n` on the slave, `-T A_s N_i n` on the master nodes. Since `Σ N_i = 1`
//! the forces sum to zero, and since `x_s - c(ξ_c) = g n` is parallel to `n` their moment
//! `Σ x × f = T A_s (x_s - c) × n` vanishes too.
//!
//! # Consistent tangent (derivation)
//! Write `L = |c'|`, `κ = n·c''`, `a = r'(ξ_c) = L² - g κ` (using `c - x_s = -g n`) and the
//! 14-vectors
//! `B_t = [0, t, 0, -N_i t]` and `B_nξ = [0, 0, 0, N_i' n]` (all evaluated at `ξ_c`).
//! * Closest point, by implicit differentiation of `r(ξ_c, X) = 0`:
//!   `δr|_ξ = (Σ N_i δm_i - δx_s)·c' + (c - x_s)·Σ N_i' δm_i = -L B_t·δX - g B_nξ·δX`, so
//!   `δξ = -δr|_ξ / a = D·δX` with `D = (L B_t + g B_nξ)/a`.
//! * Normal: `δn = -t (n·δc')/L` (a unit vector turns, it does not stretch) with
//!   `δc' = Σ N_i' δm_i + c'' δξ`, i.e. `δn = -t W·δX`, `W = (B_nξ + κ D)/L`.
//! * Gap: `δg = n·(δx_s - Σ N_i δm_i) - n·c' δξ + (x_s - c)·δn = B·δX`, since `n·c' = 0` and
//!   `(x_s - c)·δn = g n·δn = 0`.
//! * `δB = -B_t (W·δX) - B_nξ (D·δX)` (slave part `δn`, master parts `-N_i δn - N_i' δξ n`).
//!   Expanding and using `1/L + κ g/(a L) = L/a`, the product is symmetric:
//!   `B_t W^T + B_nξ D^T = (κ B_t B_t^T + L (B_t B_nξ^T + B_nξ B_t^T) + g B_nξ B_nξ^T)/a`.
//! * Tributary length: `δA_s = G·δX`, `G = [-t0/2, (t0 - t1)/2, t1/2, 0, 0, 0, 0]` with the
//!   unit vectors `t0 = (x_s1 - x_s0)/|·|`, `t1 = (x_s2 - x_s1)/|·|`.
//!
//! With `δT = -k δg` while `T > 0`:
//! `df/dX = -k A_s B B^T + T B G^T - (T A_s/a) (κ B_t B_t^T + L (B_t B_nξ^T + B_nξ B_t^T)
//! + g B_nξ B_nξ^T)`.
//! These are the paper's `K_c3` (penalty), `K_c4` (tributary length) and `K_c1 + K_c2`
//! (rotation of the normal and sliding of the closest point), with the opposite sign because
//! [`NtsEvaluation::stiffness`] is the derivative of the force, not of the residual.

//!
//! # Friction
//! With a [`TangentialInput`] the element carries a Coulomb traction `τ` ([`super::friction`]).
//! The slip is arc length along the master contour: the spline parameter's change times the
//! segment's length, `Δg_T = ℓ (ξ_c - ξ_n) / 2`, `ℓ = |x_m2 - x_m1|`, where `ξ_n` (the input's
//! `origin`) is where the slave node's projection was at the last converged state, expressed in
//! this segment's parameter (a projection `j` segments back, at `ξ'`, is `ξ' - 2 j`). The
//! traction acts as `-τ A_s B_t` (slave `-τ A_s t`, master nodes `+τ A_s N_i t`: equal and
//! opposite). With `B_tξ = [0, 0, 0, N_i' t]`, `δt = n (W·δX)` and `δB_t = B (W·δX) - B_tξ
//! (D·δX)`, its linearisation is
//! `-A_s B_t ⊗ dτ/dX - τ B_t ⊗ G - τ A_s (B ⊗ W - B_tξ ⊗ D)`, with
//! `dτ/dX = ε_T (ℓ/2 D + (ξ_c - ξ_n)/2 G_ℓ)` (stick; `G_ℓ = dℓ/dX`: `-e` on m1, `+e` on m2) or
//! `-mu sign(τ*) k B` (slip).

use super::friction::{TangentialInput, return_map};

/// Number of degrees of freedom of one element: 7 nodes `[s0, s1, s2, m0, m1, m2, m3]` × (x, y).
pub const DOF: usize = 14;

/// Range of ξ searched by the bracketed fallback of [`closest_xi_from`]. Beyond `|ξ| = 1` the
/// extrapolated spline is only meaningful a little way: a slave that far belongs to the
/// neighbouring segment.
pub const XI_SEARCH: f64 = 1.5;

/// Newton iterates beyond this |ξ| are taken as diverging.
const XI_DIVERGED: f64 = 3.0;
const NEWTON_MAX_ITERATIONS: usize = 50;
/// Steps below this are converged (the paper aims at a residual of 1e-16).
const XI_TOLERANCE: f64 = 1e-15;
/// Below this step size a step that no longer shrinks means round-off has been reached.
const XI_ROUNDOFF_ZONE: f64 = 1e-9;
/// Samples of the distance on `[-XI_SEARCH, XI_SEARCH]` for the bracketed fallback.
const FALLBACK_SAMPLES: usize = 60;

#[inline]
fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

#[inline]
fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

#[inline]
fn norm(a: [f64; 2]) -> f64 {
    dot(a, a).sqrt()
}

/// `Σ w_i m_i`.
#[inline]
fn combine(w: &[f64; 4], m: &[[f64; 2]; 4]) -> [f64; 2] {
    let mut p = [0.0; 2];
    for (wi, mi) in w.iter().zip(m) {
        p[0] += wi * mi[0];
        p[1] += wi * mi[1];
    }
    p
}

/// Cubic Hermite contact shape functions (eq. 16): values, first and second derivatives at `xi`.
///
/// With `P = (ξ²-1)(ξ-1)` and `Q = (ξ²-1)(ξ+1)`: `N0 = -P/16`, `N1 = (1-ξ)/2 + P/8 + Q/16`,
/// `N2 = (1+ξ)/2 - P/16 - Q/8`, `N3 = Q/16`.
pub fn hermite(xi: f64) -> ([f64; 4], [f64; 4], [f64; 4]) {
    let x2 = xi * xi;
    let p = (x2 - 1.0) * (xi - 1.0);
    let q = (x2 - 1.0) * (xi + 1.0);
    let dp = 3.0 * x2 - 2.0 * xi - 1.0;
    let dq = 3.0 * x2 + 2.0 * xi - 1.0;
    let ddp = 6.0 * xi - 2.0;
    let ddq = 6.0 * xi + 2.0;
    let n = [
        -p / 16.0,
        0.5 * (1.0 - xi) + p / 8.0 + q / 16.0,
        0.5 * (1.0 + xi) - p / 16.0 - q / 8.0,
        q / 16.0,
    ];
    let dn = [
        -dp / 16.0,
        -0.5 + dp / 8.0 + dq / 16.0,
        0.5 - dp / 16.0 - dq / 8.0,
        dq / 16.0,
    ];
    let ddn = [
        -ddp / 16.0,
        ddp / 8.0 + ddq / 16.0,
        -ddp / 16.0 - ddq / 8.0,
        ddq / 16.0,
    ];
    (n, dn, ddn)
}

/// Point, first and second derivatives of the spline of master nodes `m` at `xi`.
pub fn spline_point(m: &[[f64; 2]; 4], xi: f64) -> ([f64; 2], [f64; 2], [f64; 2]) {
    let (n, dn, ddn) = hermite(xi);
    (combine(&n, m), combine(&dn, m), combine(&ddn, m))
}

/// `r(ξ) = (c - x_s)·c'` and `r'(ξ) = c'·c' + (c - x_s)·c''`.
#[inline]
fn stationarity(m: &[[f64; 2]; 4], x_s: [f64; 2], xi: f64) -> (f64, f64) {
    let (c, c1, c2) = spline_point(m, xi);
    let d = sub(c, x_s);
    (dot(d, c1), dot(c1, c1) + dot(d, c2))
}

/// Closest point of `x_s` on the spline of master nodes `m[0..4]` (segment `m[1]`–`m[2]`),
/// Newton started at ξ = 0. See [`closest_xi_from`].
pub fn closest_xi(m: &[[f64; 2]; 4], x_s: [f64; 2]) -> Option<f64> {
    closest_xi_from(m, x_s, 0.0)
}

/// Closest point of `x_s` on the spline of master nodes `m`, Newton started at `xi0`.
///
/// Returns ξ of a local minimum of the distance (`r = 0`, `r' > 0`), which may lie outside
/// `[-1, 1]` (then the neighbouring segment is the better master), or `None` when none is found.
/// Newton is iterated to `|Δξ| < 1e-15` or until round-off stops it (a step below 1e-9 that no
/// longer shrinks): the global Newton needs ξ_c to full precision, since the tangent assumes
/// `r(ξ_c) = 0` exactly. If Newton meets `r' <= 0` (it would head for a maximum) or diverges,
/// the distance is sampled on `[-1.5, 1.5]`, the lowest interior local minimum is bracketed and
/// refined by Newton safeguarded with bisection.
pub fn closest_xi_from(m: &[[f64; 2]; 4], x_s: [f64; 2], xi0: f64) -> Option<f64> {
    newton(m, x_s, xi0).or_else(|| bracketed(m, x_s))
}

fn newton(m: &[[f64; 2]; 4], x_s: [f64; 2], xi0: f64) -> Option<f64> {
    let mut xi = xi0;
    let mut previous = f64::INFINITY;
    for _ in 0..NEWTON_MAX_ITERATIONS {
        let (r, dr) = stationarity(m, x_s, xi);
        if dr.is_nan() || dr <= 0.0 {
            return None;
        }
        let step = -r / dr;
        xi += step;
        if !xi.is_finite() || xi.abs() > XI_DIVERGED {
            return None;
        }
        let s = step.abs();
        if s < XI_TOLERANCE || (s < XI_ROUNDOFF_ZONE && s >= previous) {
            return (stationarity(m, x_s, xi).1 > 0.0).then_some(xi);
        }
        previous = s;
    }
    None
}

fn bracketed(m: &[[f64; 2]; 4], x_s: [f64; 2]) -> Option<f64> {
    let h = 2.0 * XI_SEARCH / FALLBACK_SAMPLES as f64;
    let at = |j: usize| -XI_SEARCH + h * j as f64;
    let dist2 = |xi: f64| {
        let d = sub(spline_point(m, xi).0, x_s);
        dot(d, d)
    };
    // Lowest interior local minimum of the sampled squared distance.
    let (mut f_prev, mut f_here) = (dist2(at(0)), dist2(at(1)));
    let mut best: Option<(usize, f64)> = None;
    for j in 1..FALLBACK_SAMPLES {
        let f_next = dist2(at(j + 1));
        if f_here <= f_prev && f_here <= f_next && best.is_none_or(|(_, fb)| f_here < fb) {
            best = Some((j, f_here));
        }
        (f_prev, f_here) = (f_here, f_next);
    }
    let (j, _) = best?;
    let (mut lo, mut hi) = (at(j - 1), at(j + 1));
    // r = (1/2) d(dist²)/dξ goes from <= 0 to >= 0 across a minimum.
    if stationarity(m, x_s, lo).0 > 0.0 || stationarity(m, x_s, hi).0 < 0.0 {
        return None;
    }
    let mut xi = at(j);
    for _ in 0..200 {
        let (r, dr) = stationarity(m, x_s, xi);
        if r == 0.0 {
            break;
        }
        if r < 0.0 {
            lo = xi;
        } else {
            hi = xi;
        }
        let newton = xi - r / dr;
        let next = if dr > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        let step = (next - xi).abs();
        xi = next;
        if step < XI_TOLERANCE || hi - lo < XI_TOLERANCE {
            break;
        }
    }
    (stationarity(m, x_s, xi).1 > 0.0).then_some(xi)
}

/// The four spline nodes of the segment `[contour[i], contour[i+1]]` of a closed contour.
pub fn segment_nodes(contour: &[[f64; 2]], i: usize) -> [[f64; 2]; 4] {
    let n = contour.len();
    [
        contour[(i + n - 1) % n],
        contour[i % n],
        contour[(i + 1) % n],
        contour[(i + 2) % n],
    ]
}

/// Which of the two candidate segments around the master node closest to the slave is the
/// master segment (paper §3: both `[m0 m1]` and `[m1 m2]` are tried).
///
/// `contour` is the master's boundary (closed, CCW, at least 3 nodes), `closest` the index of
/// its node nearest to `x_s`. Returns `(i, ξ)`: the segment is `[contour[i],
/// contour[(i+1) % n]]`. The candidate whose ξ lies in `[-1, 1]` is chosen; if both do (a
/// concave stretch, where the two splines' normal fans overlap), the one nearer to `x_s`.
///
/// If neither does, the slave "faces a convex corner": the candidate ending at `closest` is
/// returned with ξ clamped to 1, i.e. the node `closest` itself. The choice between the two
/// candidates is immaterial there: both splines pass through that node with the same tangent
/// (C¹), hence the same normal. Because the splines are C¹ the normal fans of the two
/// candidates leave no gap near a node (on a 4-node square, no point within 0.4 of a corner
/// falls in neither), so in practice this branch serves a slave far from the contour, a stale
/// `closest`, or a failed closest-point search. [`evaluate`] recomputes ξ on the chosen spline
/// by itself ([`evaluate_from`] can start from the ξ returned here).
///
/// Returns `None` only for a contour of fewer than 3 nodes or `closest` out of range.
pub fn master_segment(contour: &[[f64; 2]], closest: usize, x_s: [f64; 2]) -> Option<(usize, f64)> {
    let n = contour.len();
    if n < 3 || closest >= n {
        return None;
    }
    let before = (closest + n - 1) % n;
    let candidate = |i: usize| {
        let m = segment_nodes(contour, i);
        closest_xi(&m, x_s)
            .filter(|xi| xi.abs() <= 1.0)
            .map(|xi| (i, xi, norm(sub(x_s, spline_point(&m, xi).0))))
    };
    match (candidate(before), candidate(closest)) {
        (Some((i, xi, da)), Some((j, xj, db))) => Some(if db < da { (j, xj) } else { (i, xi) }),
        (Some((i, xi, _)), None) | (None, Some((i, xi, _))) => Some((i, xi)),
        (None, None) => Some((before, 1.0)),
    }
}

/// One contact element evaluated at the current positions.
#[derive(Debug, Clone, PartialEq)]
pub struct NtsEvaluation {
    /// Closest-point parameter ξ_c on the master spline (may lie slightly outside `[-1, 1]`).
    pub xi: f64,
    /// Signed gap `(x_s - c(ξ_c))·n`, negative when penetrating.
    pub gap: f64,
    /// Outward normal of the master at the closest point.
    pub normal: [f64; 2],
    /// Tributary length A_s of the slave node.
    pub tributary: f64,
    /// Contact pressure `T = <λ - k g> >= 0`.
    pub pressure: f64,
    /// Tangential traction τ (0 without friction), slip of the step `Δg_T` and whether the
    /// return mapping stuck.
    pub traction: f64,
    pub slip: f64,
    pub sticking: bool,
    /// Contact force ON each of the 14 DoF `[s0, s1, s2, m0, m1, m2, m3] × (x, y)`.
    /// The residual is `f_int - f_ext - f_contact`: the caller does `residual -= force`.
    pub force: [f64; DOF],
    /// `d(force)/d(x)`, row = force DoF, column = position DoF: the negative of this element's
    /// contribution to the residual's tangent, so the caller does `tangent -= stiffness`.
    /// All zero when `pressure == 0` or the tangent was not requested.
    pub stiffness: [[f64; DOF]; DOF],
}

/// Evaluates one element, Newton for the closest point started at ξ = 0. See [`evaluate_from`].
pub fn evaluate(
    x: &[[f64; 2]; 7],
    lambda: f64,
    k: f64,
    with_tangent: bool,
) -> Option<NtsEvaluation> {
    evaluate_from(x, lambda, k, with_tangent, 0.0)
}

/// Evaluates one element; `x` = current positions of `[s0, s1, s2, m0, m1, m2, m3]`, `lambda`
/// the multiplier (a pressure, >= 0), `k` the penalty stiffness, `xi_guess` the starting ξ of
/// the closest-point Newton (e.g. the last one; 0 if none).
///
/// ξ_c is the closest point on this spline, extrapolated if need be: it is not clamped to
/// `[-1, 1]`, so force and tangent stay smooth and exact when the slave slides just past the
/// segment's end before the caller re-selects the segment with [`master_segment`].
///
/// Returns `None` when no closest point is found, the spline is degenerate at it (`c' = 0`) or
/// the slave's tributary length is degenerate (coincident contour nodes).
pub fn evaluate_from(
    x: &[[f64; 2]; 7],
    lambda: f64,
    k: f64,
    with_tangent: bool,
    xi_guess: f64,
) -> Option<NtsEvaluation> {
    evaluate_frictional(x, lambda, k, None, with_tangent, xi_guess)
}

/// [`evaluate_from`] with Coulomb friction (see the module docs); `friction.origin` is the
/// slip origin `ξ_n` in this segment's parameter.
pub fn evaluate_frictional(
    x: &[[f64; 2]; 7],
    lambda: f64,
    k: f64,
    friction: Option<&TangentialInput>,
    with_tangent: bool,
    xi_guess: f64,
) -> Option<NtsEvaluation> {
    let m = [x[3], x[4], x[5], x[6]];
    let x_s = x[1];
    let xi = closest_xi_from(&m, x_s, xi_guess)?;
    let (nv, dnv, ddnv) = hermite(xi);
    let c = combine(&nv, &m);
    let c1 = combine(&dnv, &m);
    let c2 = combine(&ddnv, &m);
    let len = norm(c1);
    if len.is_nan() || len <= 0.0 {
        return None;
    }
    let t = [c1[0] / len, c1[1] / len];
    let n = [t[1], -t[0]];
    let gap = dot(sub(x_s, c), n);

    let e0 = sub(x_s, x[0]);
    let e1 = sub(x[2], x_s);
    let (l0, l1) = (norm(e0), norm(e1));
    if l0.is_nan() || l1.is_nan() || l0 <= 0.0 || l1 <= 0.0 {
        return None;
    }
    let tributary = 0.5 * (l0 + l1);
    let pressure = (lambda - k * gap).max(0.0);

    let mut eval = NtsEvaluation {
        xi,
        gap,
        normal: n,
        tributary,
        pressure,
        traction: 0.0,
        slip: 0.0,
        sticking: false,
        force: [0.0; DOF],
        stiffness: [[0.0; DOF]; DOF],
    };
    if pressure <= 0.0 {
        return Some(eval);
    }

    // B (gap gradient), B_t and B_nξ of the module docs.
    let mut b = [0.0; DOF];
    let mut bt = [0.0; DOF];
    let mut bnx = [0.0; DOF];
    for d in 0..2 {
        b[2 + d] = n[d];
        bt[2 + d] = t[d];
        for i in 0..4 {
            b[6 + 2 * i + d] = -nv[i] * n[d];
            bt[6 + 2 * i + d] = -nv[i] * t[d];
            bnx[6 + 2 * i + d] = dnv[i] * n[d];
        }
    }
    let ta = pressure * tributary;
    for (f, bi) in eval.force.iter_mut().zip(&b) {
        *f = ta * bi;
    }
    // Friction: the slip as arc length, the return mapping, the force -τ A_s B_t.
    let seg = sub(m[2], m[1]);
    let ell = norm(seg);
    let coulomb = friction.map(|input| {
        let slip = 0.5 * ell * (xi - input.origin);
        (input, slip, return_map(input, slip, pressure))
    });
    if let Some((_, slip, c)) = coulomb {
        eval.traction = c.traction;
        eval.slip = slip;
        eval.sticking = c.sticking;
        for (f, bti) in eval.force.iter_mut().zip(&bt) {
            *f -= c.traction * tributary * bti;
        }
    }
    if !with_tangent {
        return Some(eval);
    }

    // Gradient of A_s.
    let (t0, t1) = ([e0[0] / l0, e0[1] / l0], [e1[0] / l1, e1[1] / l1]);
    let mut ga = [0.0; DOF];
    for d in 0..2 {
        ga[d] = -0.5 * t0[d];
        ga[2 + d] = 0.5 * (t0[d] - t1[d]);
        ga[4 + d] = 0.5 * t1[d];
    }
    let kappa = dot(n, c2);
    let a = len * len - gap * kappa;
    let (w_tt, w_tn, w_nn) = (ta * kappa / a, ta * len / a, ta * gap / a);
    let kp = k * tributary;
    for (r, row) in eval.stiffness.iter_mut().enumerate() {
        let (br, btr, bnr) = (b[r], bt[r], bnx[r]);
        for (col, kij) in row.iter_mut().enumerate() {
            *kij = -kp * br * b[col] + pressure * br * ga[col]
                - w_tt * btr * bt[col]
                - w_tn * (btr * bnx[col] + bnr * bt[col])
                - w_nn * bnr * bnx[col];
        }
    }
    if let Some((input, _, c)) = coulomb {
        // D = dξ/dX, W = (B_nξ + κ D)/L (module docs), B_tξ, G_ℓ.
        let mut dxi = [0.0; DOF];
        let mut w = [0.0; DOF];
        let mut btx = [0.0; DOF];
        let mut gl = [0.0; DOF];
        for col in 0..DOF {
            dxi[col] = (len * bt[col] + gap * bnx[col]) / a;
            w[col] = (bnx[col] + kappa * dxi[col]) / len;
        }
        for d in 0..2 {
            for i in 0..4 {
                btx[6 + 2 * i + d] = dnv[i] * t[d];
            }
            gl[8 + d] = -seg[d] / ell;
            gl[10 + d] = seg[d] / ell;
        }
        let half_arc = 0.5 * (xi - input.origin);
        let mut dtau = [0.0; DOF];
        for col in 0..DOF {
            dtau[col] =
                c.d_slip * (0.5 * ell * dxi[col] + half_arc * gl[col]) - c.d_pressure * k * b[col];
        }
        let tau = c.traction;
        for (r, row) in eval.stiffness.iter_mut().enumerate() {
            for (col, kij) in row.iter_mut().enumerate() {
                *kij -= tributary * bt[r] * dtau[col]
                    + tau * bt[r] * ga[col]
                    + tau * tributary * (b[r] * w[col] - btx[r] * dxi[col]);
            }
        }
    }
    Some(eval)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SplitMix64: deterministic random numbers without a dependency.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            (z >> 11) as f64 / (1u64 << 53) as f64
        }

        /// Uniform in `[lo, hi)`.
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.next()
        }
    }

    /// A random element: a gently curved master along +x (outward normal ≈ -y, body above),
    /// the slave near the middle segment at height `depth` above the curve (inside the master
    /// when `depth > 0`), its neighbours on either side.
    fn random_element(rng: &mut Rng, depth: f64) -> [[f64; 2]; 7] {
        let curv = rng.range(-0.3, 0.3);
        let mut x = [[0.0; 2]; 7];
        for i in 0..4 {
            let u = i as f64 - 1.5 + rng.range(-0.15, 0.15);
            x[3 + i] = [u, curv * u * u + rng.range(-0.05, 0.05)];
        }
        let m = [x[3], x[4], x[5], x[6]];
        let xi = rng.range(-0.9, 0.9);
        let (c, c1, _) = spline_point(&m, xi);
        let l = norm(c1);
        let n = [c1[1] / l, -c1[0] / l];
        let s1 = [c[0] - depth * n[0], c[1] - depth * n[1]];
        x[1] = s1;
        x[0] = [s1[0] + rng.range(0.6, 1.2), s1[1] + rng.range(-0.3, 0.3)];
        x[2] = [s1[0] - rng.range(0.6, 1.2), s1[1] + rng.range(-0.3, 0.3)];
        x
    }

    fn circle(nodes: usize, radius: f64) -> Vec<[f64; 2]> {
        (0..nodes)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / nodes as f64;
                [radius * a.cos(), radius * a.sin()]
            })
            .collect()
    }

    #[test]
    fn shape_functions_partition_interpolation_and_c1() {
        for j in 0..=40 {
            let xi = -1.5 + 3.0 * j as f64 / 40.0;
            let (n, dn, ddn) = hermite(xi);
            assert!((n.iter().sum::<f64>() - 1.0).abs() < 1e-15);
            assert!(dn.iter().sum::<f64>().abs() < 1e-15);
            assert!(ddn.iter().sum::<f64>().abs() < 1e-14);
            // Derivatives against finite differences of the values.
            let h = 1e-6;
            let (np, dnp, _) = hermite(xi + h);
            let (nm, dnm, _) = hermite(xi - h);
            for i in 0..4 {
                assert!((dn[i] - (np[i] - nm[i]) / (2.0 * h)).abs() < 1e-9);
                assert!((ddn[i] - (dnp[i] - dnm[i]) / (2.0 * h)).abs() < 1e-9);
            }
        }
        assert_eq!(hermite(-1.0).0, [0.0, 1.0, 0.0, 0.0]);
        assert_eq!(hermite(1.0).0, [0.0, 0.0, 1.0, 0.0]);

        let mut rng = Rng(7);
        for _ in 0..100 {
            let p: Vec<[f64; 2]> = (0..5)
                .map(|_| [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)])
                .collect();
            let first = [p[0], p[1], p[2], p[3]];
            let second = [p[1], p[2], p[3], p[4]];
            let (a, da, _) = spline_point(&first, 1.0);
            let (b, db, _) = spline_point(&second, -1.0);
            for d in 0..2 {
                assert!((a[d] - p[2][d]).abs() < 1e-15 && (b[d] - p[2][d]).abs() < 1e-15);
                // Same tangent vector per unit ξ: (p3 - p1)/4.
                assert!((da[d] - db[d]).abs() < 1e-15);
                assert!((da[d] - 0.25 * (p[3][d] - p[1][d])).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn straight_master_is_a_line() {
        let mut rng = Rng(11);
        for _ in 0..50 {
            let p = [rng.range(-2.0, 2.0), rng.range(-2.0, 2.0)];
            let ang = rng.range(0.0, std::f64::consts::TAU);
            let e = [ang.cos(), ang.sin()];
            let h = rng.range(0.1, 2.0);
            let m: [[f64; 2]; 4] =
                std::array::from_fn(|i| [p[0] + i as f64 * h * e[0], p[1] + i as f64 * h * e[1]]);
            // Outward normal of a CCW contour running along e.
            let n = [e[1], -e[0]];
            // Points at arc position s from m1 and signed distance d.
            let s = rng.range(-0.3, 1.3) * h;
            let d = rng.range(-0.5, 0.5) * h;
            let xs = [m[1][0] + s * e[0] + d * n[0], m[1][1] + s * e[1] + d * n[1]];
            let xi = closest_xi(&m, xs).unwrap();
            // ξ linear in the position along the line: -1 at m1, +1 at m2.
            assert!(
                (xi - (2.0 * s / h - 1.0)).abs() < 1e-13,
                "{xi} vs {}",
                2.0 * s / h - 1.0
            );
            // The spline is the straight line.
            for j in 0..=10 {
                let z = -1.0 + 0.2 * j as f64;
                let (c, _, _) = spline_point(&m, z);
                let along = (z + 1.0) / 2.0 * h;
                assert!((c[0] - m[1][0] - along * e[0]).abs() < 1e-13);
                assert!((c[1] - m[1][1] - along * e[1]).abs() < 1e-13);
            }
            let x = [
                [xs[0] - h * e[0], xs[1] - h * e[1]],
                xs,
                [xs[0] + h * e[0], xs[1] + h * e[1]],
                m[0],
                m[1],
                m[2],
                m[3],
            ];
            let ev = evaluate(&x, 0.0, 1.0, false).unwrap();
            assert!((ev.gap - d).abs() < 1e-13, "gap {} vs {d}", ev.gap);
            assert!((ev.normal[0] - n[0]).abs() < 1e-14 && (ev.normal[1] - n[1]).abs() < 1e-14);
        }
    }

    /// A CCW circle of radius 1 with 64 nodes. The spline (Catmull–Rom) has its largest radial
    /// error at segment midpoints: `(9(m1 + m2) - (m0 + m3))/16` has radius
    /// `1 - 3θ⁴/128 + O(θ⁶) ≈ 2.2e-6` below 1 for `θ = 2π/64`. The normal deviates from the
    /// radial direction by the slope of that error, about `3θ³/16 ≈ 1.8e-4` rad at most.
    #[test]
    fn closest_point_on_a_circle() {
        let nodes = 64;
        let theta = std::f64::consts::TAU / nodes as f64;
        let radial_bound = 3.0 * theta.powi(4) / 128.0;
        let contour = circle(nodes, 1.0);
        let mut rng = Rng(3);
        let mut worst: f64 = 0.0;
        for _ in 0..500 {
            let phi = rng.range(0.0, std::f64::consts::TAU);
            let r = rng.range(0.8, 1.2);
            let xs = [r * phi.cos(), r * phi.sin()];
            let closest = (0..nodes)
                .min_by(|&a, &b| norm(sub(contour[a], xs)).total_cmp(&norm(sub(contour[b], xs))))
                .unwrap();
            let (i, xi) = master_segment(&contour, closest, xs).unwrap();
            assert!(xi.abs() <= 1.0);
            let m = segment_nodes(&contour, i);
            let tangent_neighbours = [[xs[0] + 0.05, xs[1]], xs, [xs[0] - 0.05, xs[1]]];
            let x = [
                tangent_neighbours[0],
                xs,
                tangent_neighbours[2],
                m[0],
                m[1],
                m[2],
                m[3],
            ];
            let ev = evaluate(&x, 0.0, 1.0, false).unwrap();
            assert!((ev.xi - xi).abs() < 1e-12);
            let err = (ev.gap - (r - 1.0)).abs();
            worst = worst.max(err);
            assert!(err < 1.05 * radial_bound, "gap {} vs {}", ev.gap, r - 1.0);
            let radial = [phi.cos(), phi.sin()];
            let angle = (ev.normal[0] * radial[1] - ev.normal[1] * radial[0]).abs();
            assert!(dot(ev.normal, radial) > 0.0 && angle < 3.0 * theta.powi(3) / 16.0);
        }
        // The bound is not vacuous: the error does reach a good part of it.
        assert!(
            worst > 0.5 * radial_bound,
            "worst {worst} vs bound {radial_bound}"
        );
    }

    #[test]
    fn forces_conserve_momentum_and_angular_momentum() {
        let mut rng = Rng(5);
        for _ in 0..500 {
            let depth = rng.range(0.0, 0.2);
            let mut x = random_element(&mut rng, depth);
            // Random rigid shift, so the moment check is not about the origin only.
            let shift = [rng.range(-5.0, 5.0), rng.range(-5.0, 5.0)];
            for p in &mut x {
                p[0] += shift[0];
                p[1] += shift[1];
            }
            let ev = evaluate(&x, rng.range(0.0, 0.1), 10.0, false).unwrap();
            assert!(ev.pressure > 0.0);
            let scale = ev.pressure * ev.tributary;
            let (mut fx, mut fy, mut mz, mut mscale) = (0.0, 0.0, 0.0, 0.0);
            for (p, f) in x.iter().zip(ev.force.chunks(2)) {
                fx += f[0];
                fy += f[1];
                mz += p[0] * f[1] - p[1] * f[0];
                mscale += norm(*p) * scale;
            }
            assert!(
                fx.abs() < 1e-14 * scale && fy.abs() < 1e-14 * scale,
                "{fx} {fy}"
            );
            assert!(mz.abs() < 1e-13 * mscale, "moment {mz} vs {mscale}");
        }
    }

    fn max_abs(k: &[[f64; DOF]; DOF]) -> f64 {
        k.iter().flatten().fold(0.0, |a, v| a.max(v.abs()))
    }

    /// Central differences of the force, column by column.
    fn fd_stiffness(x: &[[f64; 2]; 7], lambda: f64, k: f64, h: f64) -> [[f64; DOF]; DOF] {
        let mut kfd = [[0.0; DOF]; DOF];
        for col in 0..DOF {
            let mut xp = *x;
            let mut xm = *x;
            xp[col / 2][col % 2] += h;
            xm[col / 2][col % 2] -= h;
            let fp = evaluate(&xp, lambda, k, false).unwrap().force;
            let fm = evaluate(&xm, lambda, k, false).unwrap().force;
            for row in 0..DOF {
                kfd[row][col] = (fp[row] - fm[row]) / (2.0 * h);
            }
        }
        kfd
    }

    #[test]
    fn frictional_tangent_matches_finite_differences() {
        // Expectation: with friction the tangent is still the exact derivative of the force,
        // in the stick branch (τ = λ_T + ε_T ℓ (ξ - ξ_n)/2: through the closest point's
        // sliding and the segment's length) and in the slip branch (τ = mu p_N sign: through
        // the pressure), on random elements; the forces still sum to zero.
        let mut rng = Rng(29);
        let mut worst: f64 = 0.0;
        let (mut sticks, mut slips) = (0, 0);
        for trial in 0..200 {
            let depth = rng.range(0.02, 0.3);
            let x = random_element(&mut rng, depth);
            let (lambda, k) = (rng.range(0.0, 1.0), rng.range(1.0, 100.0));
            let xi = evaluate(&x, lambda, k, false).unwrap().xi;
            let stick = trial % 2 == 0;
            let input = TangentialInput {
                mu: rng.range(0.2, 0.8),
                penalty: k * rng.range(0.5, 2.0),
                lambda: rng.range(-0.05, 0.05),
                // A slip of ~1e-3 (stick) or ~0.5 (slip) of the segment.
                origin: xi
                    - if stick {
                        rng.range(-2e-3, 2e-3)
                    } else {
                        rng.range(0.5, 1.0)
                    },
            };
            let eval = |x: &[[f64; 2]; 7], t: bool| {
                evaluate_frictional(x, lambda, k, Some(&input), t, 0.0).unwrap()
            };
            let ev = eval(&x, true);
            assert!(ev.pressure > 0.0);
            if ev.sticking {
                sticks += 1;
            } else {
                slips += 1;
                assert!((ev.traction.abs() - input.mu * ev.pressure).abs() < 1e-14);
            }
            let sum: [f64; 2] = [0, 1].map(|d| (0..7).map(|n| ev.force[2 * n + d]).sum());
            let scale = max_abs(&ev.stiffness);
            assert!(sum[0].abs().max(sum[1].abs()) < 1e-14 * (1.0 + scale));
            let h = 1e-7;
            for col in 0..DOF {
                let (mut xp, mut xm) = (x, x);
                xp[col / 2][col % 2] += h;
                xm[col / 2][col % 2] -= h;
                let (fp, fm) = (eval(&xp, false).force, eval(&xm, false).force);
                for row in 0..DOF {
                    let fd = (fp[row] - fm[row]) / (2.0 * h);
                    let e = (ev.stiffness[row][col] - fd).abs() / scale;
                    worst = worst.max(e);
                    assert!(
                        e < 1e-5,
                        "trial {trial} K[{row}][{col}] = {} vs fd {fd}",
                        ev.stiffness[row][col]
                    );
                }
            }
        }
        assert!(
            sticks > 50 && slips > 50,
            "{sticks} stick, {slips} slip cases"
        );
        assert!(worst < 1e-7, "worst relative error {worst}");
    }

    #[test]
    fn tangent_matches_finite_differences() {
        let mut rng = Rng(13);
        let mut worst: f64 = 0.0;
        for trial in 0..300 {
            // Every third case: λ alone keeps the contact closed over a positive gap.
            let open = trial % 3 == 0;
            let depth = rng.range(0.02, 0.3);
            let x = random_element(&mut rng, if open { -depth } else { depth });
            let (lambda, k) = if open {
                (5.0, 10.0)
            } else {
                (rng.range(0.0, 1.0), rng.range(1.0, 100.0))
            };
            let ev = evaluate(&x, lambda, k, true).unwrap();
            assert!(ev.pressure > 0.0);
            let kfd = fd_stiffness(&x, lambda, k, 1e-7);
            let scale = max_abs(&ev.stiffness);
            for (row, (k_row, fd_row)) in ev.stiffness.iter().zip(&kfd).enumerate() {
                for (col, (kij, fdij)) in k_row.iter().zip(fd_row).enumerate() {
                    let e = (kij - fdij).abs() / scale;
                    worst = worst.max(e);
                    assert!(
                        e < 1e-5,
                        "trial {trial} K[{row}][{col}] = {kij} vs fd {fdij}"
                    );
                }
            }
        }
        // Central differences with h = 1e-7 carry round-off ~1e-9: the agreement is that good.
        assert!(worst < 1e-7, "worst relative error {worst}");
    }

    /// Each part of the tangent matters: without the geometric part (sliding of the closest
    /// point, rotation of the normal) or without the tributary part, the finite differences
    /// disagree, so the comparison above does test them.
    #[test]
    fn geometric_and_tributary_terms_are_not_negligible() {
        let mut rng = Rng(17);
        let x = random_element(&mut rng, 0.2);
        let (lambda, k) = (0.5, 5.0);
        let ev = evaluate(&x, lambda, k, true).unwrap();
        let kfd = fd_stiffness(&x, lambda, k, 1e-7);
        let (nv, _, _) = hermite(ev.xi);
        let mut b = [0.0; DOF];
        for d in 0..2 {
            b[2 + d] = ev.normal[d];
            for i in 0..4 {
                b[6 + 2 * i + d] = -nv[i] * ev.normal[d];
            }
        }
        let (e0, e1) = (sub(x[1], x[0]), sub(x[2], x[1]));
        let (t0, t1) = (
            [e0[0] / norm(e0), e0[1] / norm(e0)],
            [e1[0] / norm(e1), e1[1] / norm(e1)],
        );
        let ga = [
            -t0[0] / 2.0,
            -t0[1] / 2.0,
            (t0[0] - t1[0]) / 2.0,
            (t0[1] - t1[1]) / 2.0,
            t1[0] / 2.0,
            t1[1] / 2.0,
        ];
        let (mut without_geometric, mut without_tributary): (f64, f64) = (0.0, 0.0);
        for row in 0..DOF {
            for col in 0..DOF {
                let penalty = -k * ev.tributary * b[row] * b[col];
                let tributary = if col < 6 {
                    ev.pressure * b[row] * ga[col]
                } else {
                    0.0
                };
                without_geometric =
                    without_geometric.max((penalty + tributary - kfd[row][col]).abs());
                without_tributary = without_tributary
                    .max((ev.stiffness[row][col] - tributary - kfd[row][col]).abs());
            }
        }
        let scale = max_abs(&kfd);
        assert!(
            without_geometric > 1e-2 * scale,
            "{without_geometric} vs {scale}"
        );
        assert!(
            without_tributary > 1e-2 * scale,
            "{without_tributary} vs {scale}"
        );
    }

    #[test]
    fn master_segment_picks_the_side_of_the_slave() {
        let nodes = 16;
        let contour = circle(nodes, 1.0);
        let theta = std::f64::consts::TAU / nodes as f64;
        for node in 0..nodes {
            let phi0 = theta * node as f64;
            for (offset, expected) in [(0.3, node), (-0.3, (node + nodes - 1) % nodes)] {
                for r in [0.95, 1.0, 1.05] {
                    let phi = phi0 + offset * theta;
                    let xs = [r * phi.cos(), r * phi.sin()];
                    let (i, xi) = master_segment(&contour, node, xs).unwrap();
                    assert_eq!(i, expected, "node {node} offset {offset} r {r}");
                    assert!(xi.abs() <= 1.0);
                    // Slave after the node (CCW) lies near the start of [node, node+1].
                    if offset > 0.0 {
                        assert!(xi < 0.0);
                    } else {
                        assert!(xi > 0.0);
                    }
                }
            }
        }
        assert_eq!(master_segment(&contour[..2], 0, [0.0, 0.0]), None);
        assert_eq!(master_segment(&contour, nodes, [0.0, 0.0]), None);
    }

    /// Brute-force closest point on the union of the two candidate splines (ξ in [-1, 1]).
    fn brute_force(contour: &[[f64; 2]], closest: usize, xs: [f64; 2]) -> f64 {
        let n = contour.len();
        let mut best = f64::INFINITY;
        for i in [(closest + n - 1) % n, closest] {
            let m = segment_nodes(contour, i);
            for j in 0..=20000 {
                let xi = -1.0 + j as f64 / 10000.0;
                best = best.min(norm(sub(spline_point(&m, xi).0, xs)));
            }
        }
        best
    }

    #[test]
    fn master_segment_near_a_convex_corner() {
        // A coarse square (CCW): sharp polygon corners, rounded by the splines.
        let contour = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let corner = 1;
        let mut rng = Rng(19);
        let mut sides = [0usize; 2];
        for _ in 0..400 {
            // Points around the corner (1, 0), outside and inside, nearer to it than to others.
            let phi = rng.range(-std::f64::consts::PI, std::f64::consts::PI);
            let r = rng.range(0.02, 0.4);
            let xs = [1.0 + r * phi.cos(), r * phi.sin()];
            let nearest = (0..4)
                .min_by(|&a, &b| norm(sub(contour[a], xs)).total_cmp(&norm(sub(contour[b], xs))))
                .unwrap();
            if nearest != corner {
                continue;
            }
            let (i, xi) = master_segment(&contour, corner, xs).unwrap();
            assert!(i == 0 || i == 1);
            sides[i] += 1;
            let m = segment_nodes(&contour, i);
            let d = norm(sub(spline_point(&m, xi).0, xs));
            let best = brute_force(&contour, corner, xs);
            // The chosen point is the closest on the smoothed contour (sampling error ~1e-8).
            assert!(
                d <= best + 1e-7,
                "xs {xs:?}: chose {i} ξ={xi} at {d}, best {best}"
            );
        }
        assert!(sides[0] > 20 && sides[1] > 20, "{sides:?}");

        // On the outward normal at the corner node (the corner's bisector) both candidates
        // meet at the node: ξ = 1 on [0, 1] or ξ = -1 on [1, 2], the same point.
        let xs = [1.3, -0.3];
        let (i, xi) = master_segment(&contour, corner, xs).unwrap();
        let node = if i == 0 { 1.0 } else { -1.0 };
        assert!((xi - node).abs() < 1e-12, "{i} {xi}");
    }

    /// Neither candidate has a closest point on its segment (here: `closest` is stale, the
    /// slave lies at radius 5 and angle -0.2 rad, far from the circle's node 4 at 90°): the node itself is
    /// returned, on the segment ending at it.
    #[test]
    fn master_segment_falls_back_to_the_node() {
        let contour = circle(16, 1.0);
        let xs = [5.0 * (-0.2f64).cos(), 5.0 * (-0.2f64).sin()];
        let (i, xi) = master_segment(&contour, 4, xs).unwrap();
        assert_eq!((i, xi), (3, 1.0));
    }

    #[test]
    fn open_contact_has_no_force() {
        let mut rng = Rng(23);
        for _ in 0..100 {
            let depth = -rng.range(1e-6, 0.3);
            let x = random_element(&mut rng, depth);
            let ev = evaluate(&x, 0.0, 100.0, true).unwrap();
            assert!(ev.gap > 0.0);
            assert!(
                (ev.gap + depth).abs() < 1e-12,
                "gap {} vs {}",
                ev.gap,
                -depth
            );
            assert_eq!(ev.pressure, 0.0);
            assert!(ev.force.iter().all(|&f| f == 0.0));
            assert_eq!(max_abs(&ev.stiffness), 0.0);
        }
        // While penetrating, there is a force, and it pushes the slave out (along n).
        let x = random_element(&mut rng, 0.1);
        let ev = evaluate(&x, 0.0, 100.0, false).unwrap();
        assert!(ev.pressure > 0.0 && dot([ev.force[2], ev.force[3]], ev.normal) > 0.0);
    }

    #[test]
    fn newton_is_precise_and_the_fallback_finds_minima() {
        let mut rng = Rng(29);
        for _ in 0..200 {
            let depth = rng.range(-0.3, 0.3);
            let x = random_element(&mut rng, depth);
            let m = [x[3], x[4], x[5], x[6]];
            let xi = closest_xi(&m, x[1]).unwrap();
            let (r, dr) = stationarity(&m, x[1], xi);
            assert!(r.abs() < 1e-15 && dr > 0.0, "r {r}");
            // The bracketed search agrees with Newton.
            let xb = bracketed(&m, x[1]).unwrap();
            assert!((xb - xi).abs() < 1e-13, "{xb} vs {xi}");
        }
        // A start where Newton heads for a maximum of the distance (the centre side of a
        // strongly curved master, r' < 0 at ξ = 3): the fallback still finds the minimum.
        let contour = circle(8, 1.0);
        let m = segment_nodes(&contour, 0);
        let xs = [0.5, 0.2];
        assert!(newton(&m, xs, 2.9).is_none());
        let xi = closest_xi_from(&m, xs, 2.9).unwrap();
        let (r, dr) = stationarity(&m, xs, xi);
        assert!(r.abs() < 1e-14 && dr > 0.0 && xi.abs() <= XI_SEARCH);
    }

    /// Not a unit test: `cargo test --release --lib meshfree::nts -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing() {
        let mut rng = Rng(31);
        let xs: Vec<_> = (0..1000).map(|_| random_element(&mut rng, 0.1)).collect();
        let start = std::time::Instant::now();
        let mut sum = 0.0;
        for _ in 0..100 {
            for x in &xs {
                sum += evaluate(x, 0.1, 10.0, true).unwrap().stiffness[3][3];
            }
        }
        let per = start.elapsed().as_secs_f64() / 1e5;
        println!("evaluate with tangent: {:.3} µs ({sum})", per * 1e6);
    }
}
