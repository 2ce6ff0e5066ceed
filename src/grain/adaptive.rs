//! The adaptive model level (issue #6): each grain moves up and down the ladder of SPEC §1
//! (level 0 rigid, level 1 volumetric, level 3 full) by the stress its contacts put on it.
//!
//! Criterion, on the grain's Love–Weber stress σ (the stress of its contact forces, already
//! computed in the step), normalised by E, compression positive:
//! - mean stress `p = -(σxx + σyy) / 2`;
//! - deviatoric stress `τ = sqrt(((σxx - σyy) / 2)^2 + σxy^2)`.
//!
//! Going up: the stress asks for Full when `τ > full_up`, else for Volumetric when
//! `p > volumetric_up`; the grain goes up once the stress has asked for a higher level than its
//! own on more than `confirm` consecutive steps (to the level asked for at that step). A binary
//! collision in the loose gas lasts some 10–30 steps: it does not lift a grain, a sustained load
//! does. Going down needs both hysteresis and a dwell: once a grain has spent at least `dwell`
//! steps at its level, Full goes down when `τ < full_down` (to Volumetric if
//! `p >= volumetric_down`, else to Rigid) and Volumetric goes down to Rigid when
//! `p < volumetric_down`. With `down < up` a stress that hovers near a threshold cannot make a
//! grain flicker.
//!
//! Frozen degrees of freedom are held at their current values, not reset: a grain that steps
//! down keeps its shape (level 1 evolves the mean strain and holds the deviator `ε1 - ε2` and
//! α; level 0 holds both strains and α), and the rates of the frozen DoF are zeroed.

use super::state::ModelLevel;
use serde::{Deserialize, Serialize};

/// Thresholds of the adaptive level, all stresses as fractions of E.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdaptiveSettings {
    /// A rigid grain starts deforming (level 1) when its mean stress exceeds this.
    pub volumetric_up: f64,
    /// A volumetric grain goes back to rigid when its mean stress falls below this.
    pub volumetric_down: f64,
    /// A grain goes to the full model when its deviatoric stress exceeds this.
    pub full_up: f64,
    /// A full grain goes down when its deviatoric stress falls below this.
    pub full_down: f64,
    /// A grain goes up once the stress has asked for a higher level on more than this many
    /// consecutive steps.
    pub confirm: u32,
    /// Steps a grain stays at least at a level before it may step down.
    pub dwell: u32,
}

impl AdaptiveSettings {
    /// Levels that never change: no stress reaches a threshold up, and no grain outlasts its
    /// dwell to step down. For tests and benches that set each grain's level and keep it.
    pub const HELD: Self = Self {
        volumetric_up: f64::MAX,
        volumetric_down: 0.0,
        full_up: f64::MAX,
        full_down: 0.0,
        confirm: 0,
        dwell: u32::MAX,
    };
}

impl Default for AdaptiveSettings {
    /// The recommended setting for sample A (docs/speed_accuracy.md).
    fn default() -> Self {
        Self {
            volumetric_up: 1e-4,
            volumetric_down: 2e-5,
            full_up: 1e-4,
            full_down: 2e-5,
            confirm: 200,
            dwell: 1000,
        }
    }
}

/// The level of one grain and how long it has been there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GrainLevel {
    pub level: ModelLevel,
    /// Steps spent at `level` (saturating).
    pub steps: u32,
    /// Consecutive steps, up to now, in which the stress asked for a higher level.
    pub pending: u32,
}

impl GrainLevel {
    pub fn new(level: ModelLevel) -> Self {
        Self {
            level,
            steps: 0,
            pending: 0,
        }
    }
}

/// Mean and deviatoric parts `(p, τ)` of a stress `[xx, yy, xy]` (tension positive), `p`
/// compression positive.
#[inline]
pub fn stress_invariants(stress: [f64; 3]) -> (f64, f64) {
    let mean = -0.5 * (stress[0] + stress[1]);
    let half_difference = 0.5 * (stress[0] - stress[1]);
    let deviator = (half_difference * half_difference + stress[2] * stress[2]).sqrt();
    (mean, deviator)
}

impl AdaptiveSettings {
    /// The level of a grain for the next step, from its level now and the invariants `(p, τ)`
    /// of its contact stress divided by E.
    #[inline]
    pub fn next_level(&self, current: GrainLevel, mean: f64, deviator: f64) -> GrainLevel {
        let wanted = if deviator > self.full_up {
            ModelLevel::Full
        } else if mean > self.volumetric_up {
            ModelLevel::Volumetric
        } else {
            ModelLevel::Rigid
        };
        let mut level = current.level;
        let mut pending = 0;
        if wanted > level {
            pending = current.pending.saturating_add(1);
            if pending > self.confirm {
                level = wanted;
            }
        } else if current.steps >= self.dwell {
            let kept = if deviator >= self.full_down {
                ModelLevel::Full
            } else if mean >= self.volumetric_down {
                ModelLevel::Volumetric
            } else {
                ModelLevel::Rigid
            };
            level = level.min(kept);
        }
        if level == current.level {
            GrainLevel {
                level,
                steps: current.steps.saturating_add(1),
                pending,
            }
        } else {
            GrainLevel::new(level)
        }
    }

    /// Checks the thresholds; returns the offending field and why.
    pub fn check(&self) -> Result<(), (&'static str, f64, &'static str)> {
        for (name, value) in [
            ("volumetric_up", self.volumetric_up),
            ("volumetric_down", self.volumetric_down),
            ("full_up", self.full_up),
            ("full_down", self.full_down),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err((name, value, "a finite stress / E >= 0"));
            }
        }
        if self.volumetric_down > self.volumetric_up {
            return Err((
                "volumetric_down",
                self.volumetric_down,
                "<= volumetric_up (hysteresis)",
            ));
        }
        if self.full_down > self.full_up {
            return Err(("full_down", self.full_down, "<= full_up (hysteresis)"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invariants_of_a_uniaxial_compression() {
        // Expectation: sigma = diag(-2, 0): p = 1, tau = 1.
        let (p, t) = stress_invariants([-2.0, 0.0, 0.0]);
        assert_eq!((p, t), (1.0, 1.0));
        // Pure shear: p = 0, tau = |xy|.
        let (p, t) = stress_invariants([0.0, 0.0, -0.5]);
        assert_eq!((p, t), (0.0, 0.5));
    }

    #[test]
    fn up_is_immediate_down_waits_for_the_dwell_and_the_lower_threshold() {
        let s = AdaptiveSettings {
            volumetric_up: 1.0,
            volumetric_down: 0.5,
            full_up: 2.0,
            full_down: 1.0,
            confirm: 0,
            dwell: 3,
        };
        let rigid = GrainLevel::new(ModelLevel::Rigid);
        assert_eq!(s.next_level(rigid, 0.9, 0.0).level, ModelLevel::Rigid);
        assert_eq!(s.next_level(rigid, 1.1, 0.0).level, ModelLevel::Volumetric);
        assert_eq!(s.next_level(rigid, 2.5, 2.1).level, ModelLevel::Full);
        // Between the thresholds a full grain stays full, whatever the dwell.
        let full = GrainLevel {
            level: ModelLevel::Full,
            steps: 100,
            pending: 0,
        };
        assert_eq!(
            s.next_level(full, 1.5, 1.5),
            GrainLevel {
                level: ModelLevel::Full,
                steps: 101,
                pending: 0
            }
        );
        // Below full_down: to volumetric while p >= volumetric_down, else to rigid.
        assert_eq!(s.next_level(full, 0.6, 0.3).level, ModelLevel::Volumetric);
        assert_eq!(s.next_level(full, 0.4, 0.3).level, ModelLevel::Rigid);
        // Not before the dwell.
        let young = GrainLevel {
            level: ModelLevel::Full,
            steps: 2,
            pending: 0,
        };
        assert_eq!(s.next_level(young, 0.0, 0.0).level, ModelLevel::Full);
        // A volumetric grain under a deviator between the full thresholds stays volumetric.
        let vol = GrainLevel {
            level: ModelLevel::Volumetric,
            steps: 10,
            pending: 0,
        };
        assert_eq!(s.next_level(vol, 1.5, 1.5).level, ModelLevel::Volumetric);
        assert_eq!(s.next_level(vol, 0.6, 0.0).level, ModelLevel::Volumetric);
        assert_eq!(
            s.next_level(vol, 0.4, 0.0),
            GrainLevel::new(ModelLevel::Rigid)
        );
    }

    #[test]
    fn going_up_waits_for_a_sustained_stress() {
        // Expectation: with confirm = 3 the stress must ask for more on 4 consecutive steps; a
        // shorter burst (a collision) leaves the grain where it is and resets the count.
        let s = AdaptiveSettings {
            confirm: 3,
            ..Default::default()
        };
        let high = 10.0 * s.full_up;
        let mut g = GrainLevel::new(ModelLevel::Rigid);
        for _ in 0..3 {
            g = s.next_level(g, high, high);
            assert_eq!(g.level, ModelLevel::Rigid);
        }
        g = s.next_level(g, 0.0, 0.0);
        assert_eq!((g.level, g.pending), (ModelLevel::Rigid, 0));
        for k in 0..4 {
            g = s.next_level(g, high, high);
            assert_eq!(g.level == ModelLevel::Full, k == 3, "step {k}");
        }
        assert_eq!(g, GrainLevel::new(ModelLevel::Full));
    }

    #[test]
    fn thresholds_must_leave_a_hysteresis_band() {
        let mut s = AdaptiveSettings::default();
        assert!(s.check().is_ok());
        s.full_down = 2.0 * s.full_up;
        assert_eq!(s.check().unwrap_err().0, "full_down");
        s = AdaptiveSettings {
            volumetric_up: f64::NAN,
            ..Default::default()
        };
        assert_eq!(s.check().unwrap_err().0, "volumetric_up");
    }
}
