//! Coulomb friction with tangential history (SPEC §13).
//!
//! Sign convention (the same as the normal law of [`super::law`]): the contact normal `n` points
//! from the first body i towards the second body j, the tangent is `t = perp(n) = (-n_y, n_x)`,
//! and the slip rate `w = (v_j(x_c) - v_i(x_c)) . t` is that of j relative to i at the contact
//! point. The tangential force `F_t` acts on i as `F_t t` and on j as `-F_t t`: a positive slip
//! rate drags i along `+t`, so friction raises `F_t`.
//!
//! The history is the force, not a displacement: the tangential stiffness follows the secant
//! normal stiffness, which changes with the contact length at every step, and a stored
//! displacement would change the force without any slip. In 2D the scalar `F_t` along `t` turns
//! with the contact by itself.

use serde::{Deserialize, Serialize};

/// Largest allowed tangential-to-normal stiffness ratio `r_t`.
pub const MAX_STIFFNESS_RATIO: f64 = 10.0;

/// What a Coulomb coefficient may be, for error messages.
pub const COEFFICIENT_RANGE: &str = "a finite number >= 0 (0: frictionless)";

/// Whether `mu` is a valid Coulomb coefficient.
pub fn is_coefficient(mu: f64) -> bool {
    mu.is_finite() && mu >= 0.0
}

/// Friction of a scenario: Coulomb coefficients and the tangential spring and dashpot.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FrictionSettings {
    /// Coulomb coefficient mu between grains (0: frictionless).
    pub grains: f64,
    /// Coulomb coefficient mu between the grains and the four box walls.
    pub walls: f64,
    /// Each box wall's own coefficient (left, right, bottom, top), in place of `walls`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub each_wall: Option<[f64; 4]>,
    /// `r_t = K_t / K_n`, the tangential stiffness over the secant normal stiffness, in (0, 10].
    pub stiffness_ratio: f64,
    /// gamma_t of the tangential dashpot `gamma_t sqrt(K_t m_eff)` (dimensionless, >= 0).
    pub damping: f64,
}

impl Default for FrictionSettings {
    fn default() -> Self {
        Self {
            grains: 0.0,
            walls: 0.0,
            each_wall: None,
            stiffness_ratio: 1.0,
            damping: 0.0,
        }
    }
}

impl FrictionSettings {
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// The coefficients of the four box walls (left, right, bottom, top).
    pub fn box_walls(&self) -> [f64; 4] {
        self.each_wall.unwrap_or([self.walls; 4])
    }

    /// The first field out of its range: (field, value, allowed range).
    pub fn check(&self) -> Result<(), (&'static str, f64, &'static str)> {
        if !is_coefficient(self.grains) {
            return Err(("grains", self.grains, COEFFICIENT_RANGE));
        }
        if !is_coefficient(self.walls) {
            return Err(("walls", self.walls, COEFFICIENT_RANGE));
        }
        if let Some(&mu) = self
            .each_wall
            .iter()
            .flatten()
            .find(|mu| !is_coefficient(**mu))
        {
            return Err(("each_wall", mu, COEFFICIENT_RANGE));
        }
        if !(self.stiffness_ratio > 0.0 && self.stiffness_ratio <= MAX_STIFFNESS_RATIO) {
            return Err(("stiffness_ratio", self.stiffness_ratio, "in (0, 10]"));
        }
        if !(self.damping.is_finite() && self.damping >= 0.0) {
            return Err(("damping", self.damping, "a finite number >= 0"));
        }
        Ok(())
    }
}

/// The tangential spring and dashpot of every frictional contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TangentialLaw {
    /// `r_t = K_t / K_n`.
    pub stiffness_ratio: f64,
    /// gamma_t of the dashpot.
    pub damping: f64,
}

impl From<&FrictionSettings> for TangentialLaw {
    fn from(s: &FrictionSettings) -> Self {
        Self {
            stiffness_ratio: s.stiffness_ratio,
            damping: s.damping,
        }
    }
}

/// One contact's tangential force over one step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TangentialResponse {
    /// Total tangential force on the first body along `t` (spring and dashpot), within the
    /// Coulomb limit.
    pub force: f64,
    /// The spring's force, carried to the next step (the contact's history).
    pub history: f64,
    /// Whether the contact slid (the Coulomb limit was reached).
    pub sliding: bool,
    /// Energy dissipated by Coulomb sliding over the step (>= 0): the Coulomb force times the
    /// slip that the spring did not take up. A contact sliding steadily dissipates exactly
    /// `mu |F_n| |w| dt`.
    pub dissipated: f64,
}

impl TangentialLaw {
    /// The tangential force of a contact with history `history` (last step's spring force),
    /// secant normal stiffness `normal_stiffness`, total normal force `normal_force` (<= 0,
    /// repulsive), slip rate `slip_rate`, Coulomb coefficient `mu`, over a step `dt`.
    /// `effective_mass` scales the dashpot.
    ///
    /// `F_t <- F_t + K_t w dt` with `K_t = r_t K_n`; the total (with the dashpot) is bounded by
    /// `mu |F_n|`; on sliding the spring keeps what the bound leaves after the dashpot.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn response(
        &self,
        history: f64,
        normal_stiffness: f64,
        normal_force: f64,
        slip_rate: f64,
        mu: f64,
        effective_mass: f64,
        dt: f64,
    ) -> TangentialResponse {
        let stiffness = self.stiffness_ratio * normal_stiffness;
        let spring = history + stiffness * slip_rate * dt;
        let dashpot = if self.damping > 0.0 {
            self.damping * (stiffness * effective_mass).sqrt() * slip_rate
        } else {
            0.0
        };
        let total = spring + dashpot;
        let limit = mu * normal_force.abs();
        if total.abs() <= limit {
            return TangentialResponse {
                force: total,
                history: spring,
                sliding: false,
                dissipated: 0.0,
            };
        }
        let force = limit.copysign(total);
        let history = force - dashpot;
        // The slip the spring did not store is the sliding slip; the Coulomb force works on it.
        let sliding_slip = (spring - history) / stiffness;
        TangentialResponse {
            force,
            history,
            sliding: true,
            dissipated: limit * sliding_slip.abs(),
        }
    }

    /// The tangential stiffness `K_t` for a secant normal stiffness.
    pub fn stiffness(&self, normal_stiffness: f64) -> f64 {
        self.stiffness_ratio * normal_stiffness
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LAW: TangentialLaw = TangentialLaw {
        stiffness_ratio: 1.0,
        damping: 0.0,
    };

    #[test]
    fn sticking_contact_is_a_spring_of_stiffness_r_t_k_n() {
        // Expectation: below the Coulomb limit, F_t = K_t * (accumulated slip), K_t = r_t K_n.
        let law = TangentialLaw {
            stiffness_ratio: 0.5,
            damping: 0.0,
        };
        let (k_n, dt, w) = (100.0, 1e-3, 0.2);
        let mut history = 0.0;
        for _ in 0..10 {
            let r = law.response(history, k_n, -10.0, w, 0.5, 1.0, dt);
            assert!(!r.sliding);
            assert_eq!(r.dissipated, 0.0);
            history = r.history;
        }
        assert!((history - 0.5 * k_n * w * dt * 10.0).abs() < 1e-12);
    }

    #[test]
    fn steady_sliding_dissipates_mu_fn_slip() {
        // Expectation (SPEC §13): a contact sliding at w with the spring at its limit
        // dissipates exactly mu |F_n| |w| dt per step, whatever the direction of slip.
        for w in [0.3, -0.7] {
            let (mu, f_n, dt) = (0.4, -2.5_f64, 1e-3);
            let limit = mu * f_n.abs();
            let r = LAW.response(limit.copysign(w), 50.0, f_n, w, mu, 1.0, dt);
            assert!(r.sliding);
            assert_eq!(r.force, limit.copysign(w));
            assert!((r.dissipated - mu * f_n.abs() * w.abs() * dt).abs() < 1e-15);
        }
    }

    #[test]
    fn friction_follows_the_relative_motion() {
        // j moving along +t relative to i drags i along +t: F_t > 0 on i.
        let r = LAW.response(0.0, 10.0, -1.0, 1.0, 0.5, 1.0, 1e-3);
        assert!(r.force > 0.0);
        let r = LAW.response(0.0, 10.0, -1.0, -1.0, 0.5, 1.0, 1e-3);
        assert!(r.force < 0.0);
    }

    #[test]
    fn onset_of_sliding_dissipates_only_the_excess_slip() {
        // The spring takes up slip until the limit; the rest slides: from F_t = 0.8 limit, a
        // step of slip 0.5 limit / K_t stores 0.2 limit and slides 0.3 limit / K_t.
        let (k_n, mu, f_n, dt) = (10.0, 0.5, -4.0_f64, 1.0);
        let limit = mu * f_n.abs();
        let w = 0.5 * limit / k_n;
        let r = LAW.response(0.8 * limit, k_n, f_n, w, mu, 1.0, dt);
        assert!(r.sliding);
        assert_eq!(r.history, limit);
        assert!((r.dissipated - limit * 0.3 * limit / k_n).abs() < 1e-12);
    }

    #[test]
    fn the_dashpot_is_bounded_by_coulomb_too() {
        let law = TangentialLaw {
            stiffness_ratio: 1.0,
            damping: 10.0,
        };
        let r = law.response(0.0, 100.0, -1.0, 5.0, 0.3, 1.0, 1e-6);
        assert!(r.sliding);
        assert!((r.force - 0.3).abs() < 1e-15);
        // The spring keeps what the limit leaves after the dashpot.
        assert!((r.history + law.damping * 10.0 * 5.0 - 0.3).abs() < 1e-12);
    }

    #[test]
    fn frictionless_contact_has_no_tangential_force() {
        let r = LAW.response(0.0, 10.0, -1.0, 3.0, 0.0, 1.0, 1e-3);
        assert_eq!(r.force, 0.0);
        assert_eq!(r.history, 0.0);
    }

    #[test]
    fn bad_settings_name_their_field() {
        let bad = |f: fn(&mut FrictionSettings)| {
            let mut s = FrictionSettings::default();
            f(&mut s);
            s.check().unwrap_err().0
        };
        assert_eq!(bad(|s| s.grains = -0.1), "grains");
        assert_eq!(bad(|s| s.walls = f64::NAN), "walls");
        assert_eq!(bad(|s| s.stiffness_ratio = 0.0), "stiffness_ratio");
        assert_eq!(bad(|s| s.stiffness_ratio = 11.0), "stiffness_ratio");
        assert_eq!(bad(|s| s.damping = -1.0), "damping");
        assert!(FrictionSettings::default().check().is_ok());
    }
}
