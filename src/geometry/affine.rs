//! The affine motion of a grain (SPEC §2): its map `A R` of the unit circle onto the contour and
//! the velocity gradient `L = dA/dt A^-1`, written once over [`Real`] so that the grain pass
//! computes them for lanes of grains side by side (issue #16) with the bits of one grain's
//! computation.
//!
//! [`Mat2`] performs glam's `DMat2` operations in glam's order (products as
//! `(a00 b0) + (a01 b1)`, the inverse through `1 / det`), so over `f64` these functions give
//! exactly what the same formulas give with `DMat2`.

use crate::lanes::{Lanes, Real};
use glam::{DMat2, DVec2};
use std::ops::{Add, Mul, Sub};

/// A 2×2 matrix by columns.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Mat2<T> {
    pub x_axis: [T; 2],
    pub y_axis: [T; 2],
}

impl<T: Real> Mat2<T> {
    #[inline(always)]
    pub fn from_cols(x_axis: [T; 2], y_axis: [T; 2]) -> Self {
        Self { x_axis, y_axis }
    }

    /// The same matrix in every lane.
    #[inline(always)]
    pub fn splat(m: DMat2) -> Self {
        Self::from_cols(
            [T::splat(m.x_axis.x), T::splat(m.x_axis.y)],
            [T::splat(m.y_axis.x), T::splat(m.y_axis.y)],
        )
    }

    /// `diag(a, b)` (off-diagonal +0, as `DMat2::from_diagonal`).
    #[inline(always)]
    pub fn diagonal(a: T, b: T) -> Self {
        let zero = T::splat(0.0);
        Self::from_cols([a, zero], [zero, b])
    }

    #[inline(always)]
    pub fn mul_vec(self, v: [T; 2]) -> [T; 2] {
        [
            (self.x_axis[0] * v[0]) + (self.y_axis[0] * v[1]),
            (self.x_axis[1] * v[0]) + (self.y_axis[1] * v[1]),
        ]
    }

    #[inline(always)]
    pub fn scale(self, s: T) -> Self {
        Self::from_cols(
            [self.x_axis[0] * s, self.x_axis[1] * s],
            [self.y_axis[0] * s, self.y_axis[1] * s],
        )
    }

    #[inline(always)]
    pub fn transpose(self) -> Self {
        Self::from_cols(
            [self.x_axis[0], self.y_axis[0]],
            [self.x_axis[1], self.y_axis[1]],
        )
    }

    #[inline(always)]
    pub fn inverse(self) -> Self {
        let det = self.x_axis[0] * self.y_axis[1] - self.x_axis[1] * self.y_axis[0];
        let inv_det = T::splat(1.0) / det;
        Self::from_cols(
            [self.y_axis[1] * inv_det, self.x_axis[1] * -inv_det],
            [self.y_axis[0] * -inv_det, self.x_axis[0] * inv_det],
        )
    }
}

impl<T: Real> Mul for Mat2<T> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, rhs: Self) -> Self {
        Self::from_cols(self.mul_vec(rhs.x_axis), self.mul_vec(rhs.y_axis))
    }
}

impl<T: Real> Add for Mat2<T> {
    type Output = Self;
    #[inline(always)]
    fn add(self, rhs: Self) -> Self {
        Self::from_cols(
            [
                self.x_axis[0] + rhs.x_axis[0],
                self.x_axis[1] + rhs.x_axis[1],
            ],
            [
                self.y_axis[0] + rhs.y_axis[0],
                self.y_axis[1] + rhs.y_axis[1],
            ],
        )
    }
}

impl<T: Real> Sub for Mat2<T> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, rhs: Self) -> Self {
        Self::from_cols(
            [
                self.x_axis[0] - rhs.x_axis[0],
                self.x_axis[1] - rhs.x_axis[1],
            ],
            [
                self.y_axis[0] - rhs.y_axis[0],
                self.y_axis[1] - rhs.y_axis[1],
            ],
        )
    }
}

impl Mat2<f64> {
    #[inline(always)]
    pub fn to_glam(self) -> DMat2 {
        DMat2::from_cols(
            DVec2::new(self.x_axis[0], self.x_axis[1]),
            DVec2::new(self.y_axis[0], self.y_axis[1]),
        )
    }
}

impl<const N: usize> Mat2<Lanes<N>> {
    /// The matrix of lane `l`.
    #[inline(always)]
    pub fn lane(&self, l: usize) -> DMat2 {
        DMat2::from_cols(
            DVec2::new(self.x_axis[0].0[l], self.x_axis[1].0[l]),
            DVec2::new(self.y_axis[0].0[l], self.y_axis[1].0[l]),
        )
    }
}

/// The rotation `Q` by the angle whose sine and cosine are given.
#[inline(always)]
pub fn rotation<T: Real>(sin: T, cos: T) -> Mat2<T> {
    Mat2::from_cols([cos, sin], [-sin, cos])
}

/// The symmetric stretch `U = I + Q(alpha) diag(eps1, eps2) Q(alpha)^T`, from the sine `s` and
/// cosine `c` of alpha.
#[inline(always)]
pub fn stretch<T: Real>(eps1: T, eps2: T, s: T, c: T) -> Mat2<T> {
    let one = T::splat(1.0);
    let u11 = one + eps1 * c * c + eps2 * s * s;
    let u22 = one + eps1 * s * s + eps2 * c * c;
    let u12 = (eps1 - eps2) * c * s;
    Mat2::from_cols([u11, u12], [u12, u22])
}

/// What a grain's affine motion depends on: the sines and cosines of its rotation theta and of
/// its principal axes' angle alpha, its strains and their rates, its spin and radius.
#[derive(Debug, Clone, Copy, Default)]
pub struct AffineState<T> {
    pub sin_theta: T,
    pub cos_theta: T,
    pub sin_alpha: T,
    pub cos_alpha: T,
    pub eps1: T,
    pub eps2: T,
    pub eps1_rate: T,
    pub eps2_rate: T,
    pub alpha_rate: T,
    pub omega: T,
    pub radius: T,
}

impl<const N: usize> AffineState<Lanes<N>> {
    /// Puts `state` in lane `l`.
    #[inline(always)]
    pub fn set_lane(&mut self, l: usize, state: &AffineState<f64>) {
        self.sin_theta.0[l] = state.sin_theta;
        self.cos_theta.0[l] = state.cos_theta;
        self.sin_alpha.0[l] = state.sin_alpha;
        self.cos_alpha.0[l] = state.cos_alpha;
        self.eps1.0[l] = state.eps1;
        self.eps2.0[l] = state.eps2;
        self.eps1_rate.0[l] = state.eps1_rate;
        self.eps2_rate.0[l] = state.eps2_rate;
        self.alpha_rate.0[l] = state.alpha_rate;
        self.omega.0[l] = state.omega;
        self.radius.0[l] = state.radius;
    }
}

/// The grain's map `A R = Q(theta) U R` and the velocity gradient of its affine motion,
/// `L = omega J + Q(theta) (dU/dt) U^-1 Q(theta)^T` with
/// `dU/dt = Q(alpha) (alpha_rate (J D - D J) + dD/dt) Q(alpha)^T`, `D = diag(eps1, eps2)` and
/// J the rotation by 90 degrees: a material point at x moves at `velocity + L (x - center)`.
#[inline(always)]
pub fn map_and_velocity_gradient<T: Real>(state: &AffineState<T>) -> (Mat2<T>, Mat2<T>) {
    let rot = rotation(state.sin_theta, state.cos_theta);
    let q = rotation(state.sin_alpha, state.cos_alpha);
    let u = stretch(state.eps1, state.eps2, state.sin_alpha, state.cos_alpha);
    let map = (rot * u).scale(state.radius);

    let j = Mat2::splat(super::contour::QUARTER_TURN);
    let d = Mat2::diagonal(state.eps1, state.eps2);
    let d_rate = Mat2::diagonal(state.eps1_rate, state.eps2_rate);
    let du = q * ((j * d - d * j).scale(state.alpha_rate) + d_rate) * q.transpose();
    let gradient = j.scale(state.omega) + rot * du * u.inverse() * rot.transpose();
    (map, gradient)
}

/// The grain's principal direction `e1` (at the angle theta + alpha; SPEC §3) as
/// `Q(theta) (cos alpha, sin alpha)`: from the sines and cosines of theta and alpha that the
/// map reads, so that the step computes two of them a grain, not three (issue #16: the sine
/// and cosine of theta + alpha were 4% of a full-level step). Within an ulp or two of
/// `(cos(theta + alpha), sin(theta + alpha))`, and of unit length as closely.
#[inline(always)]
pub fn principal_direction<T: Real>(state: &AffineState<T>) -> [T; 2] {
    rotation(state.sin_theta, state.cos_theta).mul_vec([state.cos_alpha, state.sin_alpha])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bits(m: Mat2<f64>) -> [u64; 4] {
        [m.x_axis[0], m.x_axis[1], m.y_axis[0], m.y_axis[1]].map(f64::to_bits)
    }

    fn random_states(count: usize) -> Vec<AffineState<f64>> {
        let mut unit = super::super::intersection::tests::unit_randoms(23);
        (0..count)
            .map(|k| {
                let (theta, alpha) = (40.0 * unit() - 20.0, 6.0 * unit() - 3.0);
                // Some grains at rest and undeformed: the zeros (and their signs) of a grain
                // that never moved.
                let at_rest = k % 7 == 0;
                let value = |scale: f64, unit: f64| if at_rest { 0.0 } else { scale * unit };
                AffineState {
                    sin_theta: theta.sin(),
                    cos_theta: theta.cos(),
                    sin_alpha: alpha.sin(),
                    cos_alpha: alpha.cos(),
                    eps1: value(0.3, unit() - 0.5),
                    eps2: value(0.3, unit() - 0.5),
                    eps1_rate: value(2.0, unit() - 0.5),
                    eps2_rate: -value(2.0, unit() - 0.5),
                    alpha_rate: value(4.0, unit() - 0.5),
                    omega: value(6.0, unit() - 0.5),
                    radius: 0.5 + unit(),
                }
            })
            .collect()
    }

    #[test]
    fn one_grain_gives_the_bits_of_the_same_formulas_with_glam() {
        // Expectation: Mat2 is DMat2's arithmetic in DMat2's order, so the map and the velocity
        // gradient come out as the formulas written with glam give them, bit for bit.
        for s in random_states(500) {
            let (map, gradient) = map_and_velocity_gradient(&s);
            let rot = DMat2::from_cols(
                DVec2::new(s.cos_theta, s.sin_theta),
                DVec2::new(-s.sin_theta, s.cos_theta),
            );
            let q = DMat2::from_cols(
                DVec2::new(s.cos_alpha, s.sin_alpha),
                DVec2::new(-s.sin_alpha, s.cos_alpha),
            );
            let u = stretch(s.eps1, s.eps2, s.sin_alpha, s.cos_alpha).to_glam();
            let j = crate::geometry::contour::QUARTER_TURN;
            let d = DMat2::from_diagonal(DVec2::new(s.eps1, s.eps2));
            let d_rate = DMat2::from_diagonal(DVec2::new(s.eps1_rate, s.eps2_rate));
            let du = q * ((j * d - d * j) * s.alpha_rate + d_rate) * q.transpose();
            let expected_gradient = j * s.omega + rot * du * u.inverse() * rot.transpose();
            let expected_map = rot * u * s.radius;
            let glam_bits = |m: DMat2| m.to_cols_array().map(f64::to_bits);
            assert_eq!(bits(map), glam_bits(expected_map), "{s:?}");
            assert_eq!(bits(gradient), glam_bits(expected_gradient), "{s:?}");
        }
    }

    #[test]
    fn the_principal_direction_is_the_rotated_first_axis_at_theta_plus_alpha() {
        // Expectation: Q(theta) (cos alpha, sin alpha) is glam's product of the rotation by
        // theta with that vector, bit for bit, and the unit vector at theta + alpha (libm's
        // sine and cosine of the sum) to within rounding: a few ulps of 1.
        let mut largest_gap: f64 = 0.0;
        let mut unit = super::super::intersection::tests::unit_randoms(29);
        for _ in 0..2000 {
            let (theta, alpha) = (40.0 * unit() - 20.0, 6.0 * unit() - 3.0);
            let (sin_theta, cos_theta) = crate::geometry::angle::sin_cos(theta);
            let (sin_alpha, cos_alpha) = crate::geometry::angle::sin_cos(alpha);
            let state = AffineState {
                sin_theta,
                cos_theta,
                sin_alpha,
                cos_alpha,
                ..AffineState::default()
            };
            let direction = principal_direction(&state);
            let rot = DMat2::from_cols(
                DVec2::new(cos_theta, sin_theta),
                DVec2::new(-sin_theta, cos_theta),
            );
            let expected = rot * DVec2::new(cos_alpha, sin_alpha);
            assert_eq!(
                direction.map(f64::to_bits),
                expected.to_array().map(f64::to_bits)
            );
            let at_sum = crate::geometry::angle::unit_vector(theta + alpha);
            largest_gap = largest_gap.max((DVec2::from(direction) - at_sum).length());
            assert!((DVec2::from(direction).length() - 1.0).abs() < 4.0 * f64::EPSILON);
        }
        // theta + alpha itself is rounded (|theta + alpha| < 23: an ulp of 3.6e-15).
        assert!(largest_gap < 1e-14, "{largest_gap:e}");
    }

    #[test]
    fn lanes_give_each_grains_bits() {
        // Expectation: four grains side by side are four one-grain computations, every bit.
        let states = random_states(400);
        for block in states.chunks_exact(4) {
            let mut lanes = AffineState::<Lanes<4>>::default();
            for (l, s) in block.iter().enumerate() {
                lanes.set_lane(l, s);
            }
            let (maps, gradients) = map_and_velocity_gradient(&lanes);
            let directions = principal_direction(&lanes);
            for (l, s) in block.iter().enumerate() {
                let (map, gradient) = map_and_velocity_gradient(s);
                let glam_bits = |m: DMat2| m.to_cols_array().map(f64::to_bits);
                assert_eq!(glam_bits(maps.lane(l)), bits(map));
                assert_eq!(glam_bits(gradients.lane(l)), bits(gradient));
                let direction = principal_direction(s);
                assert_eq!(
                    directions.map(|x| x.0[l].to_bits()),
                    direction.map(f64::to_bits)
                );
            }
        }
    }
}
