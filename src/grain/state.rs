//! The state of one grain: six degrees of freedom and their rates (SPEC §2).
//!
//! Grains are stored as an array of these records because the time step reads and writes every
//! field of a grain together; the contact kernels read a separate compact array of
//! [`GrainShape`](crate::geometry::GrainShape)s built once per step.

use crate::geometry::affine::{AffineState, map_and_velocity_gradient, principal_direction};
use crate::geometry::angle;
use crate::geometry::contour::GrainShape;
use glam::{DMat2, DVec2};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Which degrees of freedom a grain has (SPEC §1). All levels share one contact geometry.
/// Ordered from the fewest degrees of freedom to the most.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize,
)]
pub enum ModelLevel {
    /// Level 0: rigid discs (x, y, theta).
    Rigid,
    /// Level 1: + one volumetric strain (eps1 = eps2, alpha frozen).
    Volumetric,
    /// Level 3: the full SDEM grain (x, y, theta, eps1, eps2, alpha).
    #[default]
    Full,
}

impl ModelLevel {
    pub const ALL: [ModelLevel; 3] = [ModelLevel::Rigid, ModelLevel::Volumetric, ModelLevel::Full];

    /// 0, 1, 2 for Rigid, Volumetric, Full (an index, not the paper's level number).
    #[inline]
    pub fn index(self) -> usize {
        self as usize
    }
}

/// One grain. Angles in radians; strains are principal stretches minus one (semi-axes
/// `R (1 + eps_i)`), tension positive.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
// Fields in this order, with no padding: the grain pass moves blocks of records into lanes
// (`integration::grain_block`).
#[repr(C)]
pub struct Grain {
    /// Reference radius R.
    pub radius: f64,
    pub center: DVec2,
    pub velocity: DVec2,
    /// Rigid rotation theta.
    pub theta: f64,
    pub omega: f64,
    pub eps1: f64,
    pub eps1_rate: f64,
    pub eps2: f64,
    pub eps2_rate: f64,
    /// Orientation alpha of the principal strain axes relative to the grain (e1 is at theta + alpha).
    pub alpha: f64,
    pub alpha_rate: f64,
}

impl Grain {
    pub fn at_rest(center: DVec2, radius: f64) -> Self {
        Self {
            radius,
            center,
            ..Default::default()
        }
    }

    /// Every field, in the record's order: the radius, the centre, the velocity, theta, omega,
    /// eps1 and its rate, eps2 and its rate, alpha and its rate.
    pub fn to_array(&self) -> [f64; 13] {
        [
            self.radius,
            self.center.x,
            self.center.y,
            self.velocity.x,
            self.velocity.y,
            self.theta,
            self.omega,
            self.eps1,
            self.eps1_rate,
            self.eps2,
            self.eps2_rate,
            self.alpha,
            self.alpha_rate,
        ]
    }

    /// Reference area `pi R^2`.
    #[inline]
    pub fn reference_area(&self) -> f64 {
        PI * self.radius * self.radius
    }

    /// Mass `rho pi R^2` (conserved).
    #[inline]
    pub fn mass(&self, density: f64) -> f64 {
        density * self.reference_area()
    }

    /// `M_theta = m R^2 ((1+eps1)^2 + (1+eps2)^2) / 4`: the exact inertia of the ellipse.
    #[inline]
    pub fn rotational_inertia(&self, density: f64) -> f64 {
        self.rotational_inertia_of_mass(self.mass(density))
    }

    /// [`Grain::rotational_inertia`] from the grain's mass, where the step has it at hand.
    #[inline]
    pub fn rotational_inertia_of_mass(&self, mass: f64) -> f64 {
        let (a, b) = (1.0 + self.eps1, 1.0 + self.eps2);
        mass * self.radius * self.radius * (a * a + b * b) / 4.0
    }

    /// `M_eps1 = M_eps2 = m R^2 / 4`.
    #[inline]
    pub fn strain_inertia(&self, density: f64) -> f64 {
        self.strain_inertia_of_mass(self.mass(density))
    }

    #[inline]
    fn strain_inertia_of_mass(&self, mass: f64) -> f64 {
        mass * self.radius * self.radius / 4.0
    }

    /// `M_alpha = m R^2 (eps1 - eps2)^2 / 2`.
    #[inline]
    pub fn alpha_inertia(&self, density: f64) -> f64 {
        self.alpha_inertia_of_mass(self.mass(density))
    }

    #[inline]
    fn alpha_inertia_of_mass(&self, mass: f64) -> f64 {
        let d = self.eps1 - self.eps2;
        mass * self.radius * self.radius * d * d / 2.0
    }

    /// Ellipse area `pi R^2 (1+eps1)(1+eps2)`, before the contact caps are removed.
    #[inline]
    pub fn ellipse_area(&self) -> f64 {
        self.reference_area() * (1.0 + self.eps1) * (1.0 + self.eps2)
    }

    /// Direction of the principal axis e1, at angle theta + alpha: the rotation by theta of
    /// the unit vector at alpha ([`principal_direction`]), as the grain's frame gives it.
    #[inline]
    pub fn principal_direction(&self) -> DVec2 {
        DVec2::from(principal_direction(&self.affine_state()))
    }

    pub fn shape(&self) -> GrainShape {
        GrainShape::new(
            self.center,
            self.radius,
            self.theta,
            self.eps1,
            self.eps2,
            self.alpha,
        )
    }

    /// Velocity gradient `L = dA/dt A^-1` of the affine motion about the centre: a material
    /// point at x moves at `velocity + L (x - center)`. With `A = Q(theta) U`,
    /// `L = omega J + Q(theta) (dU/dt) U^-1 Q(theta)^T`, J the rotation by 90 degrees.
    pub fn velocity_gradient(&self) -> DMat2 {
        self.shape_and_velocity_gradient().1
    }

    /// [`Grain::shape`] and [`Grain::velocity_gradient`] together: the sines and cosines of
    /// theta and alpha are computed once (they were a tenth of the cost of a dense step).
    pub fn shape_and_velocity_gradient(&self) -> (GrainShape, DMat2) {
        let (shape, gradient, _) = self.shape_velocity_gradient_and_direction();
        (shape, gradient)
    }

    /// [`Grain::shape_and_velocity_gradient`] and [`Grain::principal_direction`], from the
    /// same sines and cosines.
    pub fn shape_velocity_gradient_and_direction(&self) -> (GrainShape, DMat2, DVec2) {
        let state = self.affine_state();
        let (map, gradient) = map_and_velocity_gradient(&state);
        let shape = GrainShape::from_map(
            self.center,
            map.to_glam(),
            self.radius,
            self.eps1,
            self.eps2,
        );
        (
            shape,
            gradient.to_glam(),
            DVec2::from(principal_direction(&state)),
        )
    }

    /// What [`map_and_velocity_gradient`] needs of this grain: the sines and cosines of theta
    /// and alpha, its strains, rates and radius.
    #[inline]
    pub fn affine_state(&self) -> AffineState<f64> {
        let (sin_theta, cos_theta) = angle::sin_cos(self.theta);
        let (sin_alpha, cos_alpha) = angle::sin_cos(self.alpha);
        AffineState {
            sin_theta,
            cos_theta,
            sin_alpha,
            cos_alpha,
            ..self.affine_state_without_angles()
        }
    }

    /// [`Grain::affine_state`] with zeros for the sines and cosines, for who computes them
    /// elsewhere.
    #[inline(always)]
    pub fn affine_state_without_angles(&self) -> AffineState<f64> {
        AffineState {
            eps1: self.eps1,
            eps2: self.eps2,
            eps1_rate: self.eps1_rate,
            eps2_rate: self.eps2_rate,
            alpha_rate: self.alpha_rate,
            omega: self.omega,
            radius: self.radius,
            ..Default::default()
        }
    }

    /// Kinetic energy of all six degrees of freedom, with the deformation DoF's masses scaled by
    /// `deformation_mass_scale` (1: the grain's own inertia).
    pub fn kinetic_energy(&self, density: f64, deformation_mass_scale: f64) -> f64 {
        self.kinetic_energy_of_mass(self.mass(density), deformation_mass_scale)
    }

    /// [`Grain::kinetic_energy`] from the grain's mass, where the step has it at hand.
    #[inline]
    pub fn kinetic_energy_of_mass(&self, mass: f64, deformation_mass_scale: f64) -> f64 {
        let rigid_body = 0.5 * mass * self.velocity.length_squared()
            + 0.5 * self.rotational_inertia_of_mass(mass) * self.omega * self.omega;
        // A grain whose deformation rates are zero (every rigid grain) would add +0 twice to a
        // sum that is >= +0: the same bits without the two terms.
        if self.eps1_rate == 0.0 && self.eps2_rate == 0.0 && self.alpha_rate == 0.0 {
            return rigid_body;
        }
        // The masses the step integrates: M_eps and M_alpha times the deformation mass scale.
        rigid_body
            + 0.5
                * (deformation_mass_scale * self.strain_inertia_of_mass(mass))
                * (self.eps1_rate * self.eps1_rate + self.eps2_rate * self.eps2_rate)
            + 0.5
                * (deformation_mass_scale * self.alpha_inertia_of_mass(mass))
                * self.alpha_rate
                * self.alpha_rate
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn velocity_gradient_matches_a_finite_difference_of_the_contour() {
        // Expectation: d/dt (A R u) = L (A R u) for every reference point u.
        let g = Grain {
            radius: 0.7,
            center: DVec2::ZERO,
            velocity: DVec2::ZERO,
            theta: 0.4,
            omega: 1.3,
            eps1: 0.2,
            eps1_rate: -0.5,
            eps2: -0.1,
            eps2_rate: 0.8,
            alpha: 1.1,
            alpha_rate: 2.0,
        };
        let h = 1e-6;
        let mut later = g;
        later.theta += h * g.omega;
        later.eps1 += h * g.eps1_rate;
        later.eps2 += h * g.eps2_rate;
        later.alpha += h * g.alpha_rate;
        let mut earlier = g;
        earlier.theta -= h * g.omega;
        earlier.eps1 -= h * g.eps1_rate;
        earlier.eps2 -= h * g.eps2_rate;
        earlier.alpha -= h * g.alpha_rate;
        let l = g.velocity_gradient();
        for k in 0..12 {
            let u = DVec2::from_angle(k as f64 * 0.5);
            let rate = (later.shape().map * u - earlier.shape().map * u) / (2.0 * h);
            let predicted = l * (g.shape().map * u);
            assert!((rate - predicted).length() < 1e-7, "{rate} vs {predicted}");
        }
    }

    #[test]
    fn rotational_inertia_is_that_of_the_ellipse() {
        // Expectation: I = m (a^2 + b^2) / 4 for an ellipse of semi-axes a, b.
        let g = Grain {
            radius: 2.0,
            eps1: 0.5,
            eps2: -0.25,
            ..Default::default()
        };
        let (a, b) = (3.0, 1.5);
        let m = g.mass(1.0);
        assert!((g.rotational_inertia(1.0) - m * (a * a + b * b) / 4.0).abs() < 1e-12);
    }
}
