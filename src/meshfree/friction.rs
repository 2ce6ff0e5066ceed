//! Coulomb friction of the meshfree contact elements (SPEC §13, "Meshfree"): the one place of
//! the law, a scalar return mapping on the tangential traction (2D: the tangent space is a
//! line).
//!
//! Each element carries a tangential traction `t` per unit length (like the normal pressure
//! `p_N`), positive when it resists a slip of the slave node in the `+tangent` direction: the
//! force on the slave node is `-t A_s tangent`. Over one (sub-)step the slip is
//! `Δg_T = g_T - g_T,n`, measured from where the slave node was at the last converged state.
//!
//! * Trial traction `t* = λ_T + ε_T Δg_T` (λ_T: the augmented-Lagrangian tangential multiplier,
//!   starting each step at the traction committed at the end of the last one).
//! * Stick, `|t*| <= mu p_N`: `t = t*`, `dt/dΔg_T = ε_T`.
//! * Slip, `|t*| > mu p_N`: `t = mu p_N sign(t*)`, `dt/dΔg_T = 0`, `dt/dp_N = mu sign(t*)`:
//!   the element's tangent is not symmetric.
//!
//! The cone radius `p_N` is the current normal pressure `<λ_N - k g>`, not the last
//! augmentation's multiplier (a frozen radius makes the augmentation loop alternate between two
//! states; FRICTION.md). `ε_T = r_t k`, `k` the current normal penalty.
//!
//! In the stick state the augmentations enforce `Δg_T = 0` (Uzawa on the stick constraint:
//! `λ_T <- t`); in the slip state `Δg_T` is the physical slip of the step.

use crate::contact::friction::MAX_STIFFNESS_RATIO;

/// Coulomb coefficients of an assembly's contacts and the tangential penalty ratio.
#[derive(Debug, Clone, PartialEq)]
pub struct FrictionCoefficients {
    /// Grain–grain friction coefficient.
    pub grains: f64,
    /// Friction coefficient of each wall (walls beyond the list are frictionless).
    pub walls: Vec<f64>,
    /// Tangential penalty over normal penalty, `ε_T = r_t k`, in (0, 10].
    pub stiffness_ratio: f64,
}

impl Default for FrictionCoefficients {
    fn default() -> Self {
        Self {
            grains: 0.0,
            walls: Vec::new(),
            stiffness_ratio: 1.0,
        }
    }
}

impl FrictionCoefficients {
    /// Checks the coefficients: each mu finite and >= 0, the ratio in (0, 10].
    pub fn validate(&self) -> Result<(), String> {
        let bad_mu = |mu: f64| !(mu.is_finite() && mu >= 0.0);
        if bad_mu(self.grains) {
            return Err(format!(
                "grain friction coefficient {}: must be finite and >= 0",
                self.grains
            ));
        }
        if let Some((w, mu)) = self.walls.iter().enumerate().find(|(_, m)| bad_mu(**m)) {
            return Err(format!(
                "friction coefficient {mu} of wall {w}: must be finite and >= 0"
            ));
        }
        let r = self.stiffness_ratio;
        if !(r > 0.0 && r <= MAX_STIFFNESS_RATIO) {
            return Err(format!(
                "friction stiffness_ratio {r}: must lie in (0, {MAX_STIFFNESS_RATIO}]"
            ));
        }
        Ok(())
    }

    /// Friction coefficient of wall `w` (0 beyond the list).
    pub fn wall(&self, w: usize) -> f64 {
        self.walls.get(w).copied().unwrap_or(0.0)
    }

    /// Whether any contact has friction.
    pub fn any(&self) -> bool {
        self.grains > 0.0 || self.walls.iter().any(|&m| m > 0.0)
    }
}

/// What an element needs for its friction: the coefficient, the tangential penalty, the
/// multiplier and where the slave node's slip is measured from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TangentialInput {
    /// Coulomb coefficient (> 0; a frictionless contact takes no `TangentialInput`).
    pub mu: f64,
    /// Tangential penalty `ε_T`.
    pub penalty: f64,
    /// Tangential multiplier `λ_T` (a traction per unit length).
    pub lambda: f64,
    /// Slip coordinate `g_T,n` at the last converged state (the origin of this step's slip).
    pub origin: f64,
}

/// Result of the return mapping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coulomb {
    /// Tangential traction `t` (per unit length; resists slip along `+tangent`).
    pub traction: f64,
    /// `dt / dΔg_T`: `ε_T` when sticking, 0 when slipping.
    pub d_slip: f64,
    /// `dt / dp_N`: 0 when sticking, `mu sign(t*)` when slipping.
    pub d_pressure: f64,
    pub sticking: bool,
}

/// The return mapping for a slip `slip = Δg_T` of the step under the normal pressure
/// `pressure` (>= 0).
pub fn return_map(input: &TangentialInput, slip: f64, pressure: f64) -> Coulomb {
    let trial = input.lambda + input.penalty * slip;
    let radius = input.mu * pressure;
    if trial.abs() <= radius {
        Coulomb {
            traction: trial,
            d_slip: input.penalty,
            d_pressure: 0.0,
            sticking: true,
        }
    } else {
        let sign = trial.signum();
        Coulomb {
            traction: radius * sign,
            d_slip: 0.0,
            d_pressure: input.mu * sign,
            sticking: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input(lambda: f64) -> TangentialInput {
        TangentialInput {
            mu: 0.5,
            penalty: 10.0,
            lambda,
            origin: 0.0,
        }
    }

    #[test]
    fn stick_inside_the_cone_slip_on_it() {
        // mu p = 0.5 x 2 = 1: a trial of 0.2 + 10 x 0.05 = 0.7 sticks, 0.2 + 10 x 0.1 = 1.2
        // slips at +1, -0.2 - 10 x 0.1 = -1.2 at -1.
        let c = return_map(&input(0.2), 0.05, 2.0);
        assert!(c.sticking);
        assert!((c.traction - 0.7).abs() < 1e-15);
        assert_eq!((c.d_slip, c.d_pressure), (10.0, 0.0));
        let c = return_map(&input(0.2), 0.1, 2.0);
        assert!(!c.sticking);
        assert_eq!((c.traction, c.d_slip, c.d_pressure), (1.0, 0.0, 0.5));
        let c = return_map(&input(-0.2), -0.1, 2.0);
        assert_eq!((c.traction, c.d_slip, c.d_pressure), (-1.0, 0.0, -0.5));
    }

    #[test]
    fn bad_coefficients_are_refused() {
        let ok = FrictionCoefficients {
            grains: 0.3,
            walls: vec![0.0, 0.6],
            stiffness_ratio: 1.0,
        };
        assert!(ok.validate().is_ok());
        for bad in [
            FrictionCoefficients {
                grains: -0.1,
                ..ok.clone()
            },
            FrictionCoefficients {
                walls: vec![f64::NAN],
                ..ok.clone()
            },
            FrictionCoefficients {
                stiffness_ratio: 0.0,
                ..ok.clone()
            },
            FrictionCoefficients {
                stiffness_ratio: 11.0,
                ..ok.clone()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?} accepted");
        }
    }
}
