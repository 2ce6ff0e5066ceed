//! Loading programs: a sequence of phases, each moving the box walls until a stop condition.
//!
//! Strain rates are positive in compression: a box side L shrinks as `dL/dt = -rate L`.

use super::walls::{BOTTOM, LEFT, RIGHT, TOP, Wall, box_size};
use glam::DVec2;
use serde::{Deserialize, Serialize};

/// How fast the walls move during a strain-driven phase.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum StrainRate {
    /// A fixed strain rate (1/time).
    Constant(f64),
    /// Quasi-static control (SPEC §7): while the packing fraction is below `fast_until_phi` the
    /// grains form a loose gas and the rate is `fast` (but never above the quasi-static rate
    /// while p_c exceeds 1e-4 E); after that the rate keeps the inertial
    /// number `I = rate d_mean sqrt(rho / p_c)` at `inertial_number`, with p_c floored at
    /// `1e-4 E` (below it the sample carries no load yet) and the rate capped at `max`.
    QuasiStatic {
        inertial_number: f64,
        max: f64,
        fast: f64,
        fast_until_phi: f64,
    },
}

/// When a phase ends (checked after every step).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum StopWhen {
    /// Packing fraction reaches this value.
    PackingFraction(f64),
    /// Mean wall stress p_c reaches this value (compression positive).
    MeanStress(f64),
    /// The sample jams: p_c exceeds the scenario's jamming threshold.
    Jammed,
    /// This many steps in the phase.
    Steps(u64),
    /// This much time in the phase.
    Time(f64),
    /// Engineering strain of the box in this phase, `1 - L/L0` (the width for oedometric
    /// loading, the width for isotropic loading too).
    Strain(f64),
    /// Vertical engineering strain of the box in this phase, `1 - H/H0` (uniaxial and biaxial
    /// loading).
    VerticalStrain(f64),
    /// Shear strain of a periodic cell in this phase, `∫ L_xy dt` (shear loading).
    ShearStrain(f64),
    /// The first of several conditions.
    Any(Vec<StopWhen>),
}

/// One phase of a loading program.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Phase {
    /// All four walls move inward at the same strain rate.
    Isotropic {
        rate: StrainRate,
        until: StopWhen,
        /// Affine compression: every step, the grain centres follow the box's homogeneous
        /// deformation (LAMMPS's `fix deform ... remap x`) instead of waiting for the walls to
        /// push them. The compaction is then uniform through the sample, with no dense layer
        /// building at the walls, whatever the box size; grain velocities stay the peculiar
        /// velocities (the affine motion is not added), so kinetic energy and dashpots see only
        /// the grains' own motion. Off by default.
        #[serde(default)]
        affine: bool,
    },
    /// The right wall moves left; the others stay (paper §5.2).
    Oedometric {
        rate: StrainRate,
        until: StopWhen,
        /// As for `Isotropic`, along x only.
        #[serde(default)]
        affine: bool,
    },
    /// Each axis is driven towards a target wall stress (compression positive): the box side
    /// changes at the relative rate `gain (s_c - target) / E`, capped at `max_rate`.
    /// Through the contact dashpot the wall stress responds at once to the wall's own velocity,
    /// so too high a gain makes the loop oscillate with period 2 steps; gains up to ~0.5 (with
    /// E = rho = 1, gamma = 1) are stable in the tests.
    Servo {
        sxx: f64,
        syy: f64,
        gain: f64,
        max_rate: f64,
        until: StopWhen,
    },
    /// The top wall moves down, the others stay: uniaxial compression (the meshfree paper's
    /// 100-grain example).
    Uniaxial { rate: StrainRate, until: StopWhen },
    /// Biaxial shear at constant area: the top and bottom walls move in at the strain rate, the
    /// left and right walls out at the same rate, so that `d(width height)/dt = 0` (the area
    /// drifts by `(rate dt)^2` per step at most).
    Biaxial { rate: StrainRate, until: StopWhen },
    /// Simple shear of a periodic cell at constant normal stress: the cell's velocity gradient
    /// has `L_xy = rate` (x velocity growing with y), and its height is servoed to the normal
    /// stress `syy` (compression positive) as a `Servo` phase servoes it: relative rate
    /// `gain (s_c - syy) / E`, capped at `max_rate`. The width stays. Periodic cells only.
    Shear {
        rate: f64,
        syy: f64,
        gain: f64,
        max_rate: f64,
        until: StopWhen,
    },
    /// Walls at rest.
    Relax { until: StopWhen },
}

impl Phase {
    pub fn name(&self) -> &'static str {
        match self {
            Phase::Isotropic { .. } => "isotropic",
            Phase::Oedometric { .. } => "oedometric",
            Phase::Servo { .. } => "servo",
            Phase::Uniaxial { .. } => "uniaxial",
            Phase::Biaxial { .. } => "biaxial",
            Phase::Shear { .. } => "shear",
            Phase::Relax { .. } => "relax",
        }
    }

    pub fn until(&self) -> &StopWhen {
        match self {
            Phase::Isotropic { until, .. }
            | Phase::Oedometric { until, .. }
            | Phase::Servo { until, .. }
            | Phase::Uniaxial { until, .. }
            | Phase::Biaxial { until, .. }
            | Phase::Shear { until, .. }
            | Phase::Relax { until } => until,
        }
    }
}

/// The macroscopic state a loading program reacts to.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LoadState {
    pub phi: f64,
    pub sxx: f64,
    pub syy: f64,
    pub jammed: bool,
    /// Mean grain diameter, for the inertial number.
    pub mean_diameter: f64,
    pub density: f64,
    pub young: f64,
    /// Shear strain of a periodic cell since the start of the run (0 in a box).
    pub shear_strain: f64,
}

impl LoadState {
    pub fn mean_stress(&self) -> f64 {
        0.5 * (self.sxx + self.syy)
    }

    /// Inertial number `rate d sqrt(rho / p_c)` at a given strain rate (infinite with no load).
    pub fn inertial_number(&self, rate: f64) -> f64 {
        let p = self.mean_stress();
        if p > 0.0 {
            rate.abs() * self.mean_diameter * (self.density / p).sqrt()
        } else {
            f64::INFINITY
        }
    }
}

impl StrainRate {
    pub fn value(&self, state: &LoadState) -> f64 {
        match *self {
            StrainRate::Constant(rate) => rate,
            StrainRate::QuasiStatic {
                inertial_number,
                max,
                fast,
                fast_until_phi,
            } => {
                let loaded = 1e-4 * state.young;
                let p = state.mean_stress();
                let quasi_static = (inertial_number * (p.max(loaded) / state.density).sqrt()
                    / state.mean_diameter)
                    .min(max);
                if state.phi < fast_until_phi && !state.jammed {
                    // A fast gas compaction can lift p_c above 1e-4 E for a moment (a burst of
                    // collisions at the walls): the rate then drops to the quasi-static one, so
                    // the inertial number stays bounded whenever the sample carries load.
                    if p > loaded {
                        fast.min(quasi_static)
                    } else {
                        fast
                    }
                } else {
                    quasi_static
                }
            }
        }
    }
}

/// Progress through the phases of a program.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoadingProgram {
    pub phases: Vec<Phase>,
    pub current: usize,
    pub phase_start_step: u64,
    pub phase_start_time: f64,
    /// Box size when the phase started.
    pub phase_start_size: (f64, f64),
    /// Strain rate applied in the last step (a shear phase: its shear rate).
    pub rate: f64,
    /// Shear rate `L_xy` of a periodic cell for the next step (0 outside shear phases).
    #[serde(default)]
    pub shear_rate: f64,
    /// Shear strain of the cell when the phase started.
    #[serde(default)]
    pub phase_start_shear_strain: f64,
}

impl LoadingProgram {
    pub fn new(phases: Vec<Phase>, walls: &[Wall]) -> Self {
        Self {
            phases,
            current: 0,
            phase_start_step: 0,
            phase_start_time: 0.0,
            phase_start_size: box_size(walls),
            rate: 0.0,
            shear_rate: 0.0,
            phase_start_shear_strain: 0.0,
        }
    }

    /// Whether the current phase moves the grain centres with the box (see `Phase::Isotropic`).
    pub fn affine(&self) -> bool {
        matches!(
            self.phases.get(self.current),
            Some(Phase::Isotropic { affine: true, .. } | Phase::Oedometric { affine: true, .. })
        )
    }

    pub fn finished(&self) -> bool {
        self.current >= self.phases.len()
    }

    pub fn phase(&self) -> Option<&Phase> {
        self.phases.get(self.current)
    }

    /// Sets the velocities of the four box walls for the next step.
    pub fn drive(&mut self, walls: &mut [Wall], state: &LoadState) {
        for w in walls.iter_mut() {
            w.velocity = DVec2::ZERO;
        }
        let (width, height) = box_size(walls);
        self.rate = 0.0;
        self.shear_rate = 0.0;
        match self.phases.get(self.current) {
            Some(Phase::Isotropic { rate, .. }) => {
                let r = rate.value(state);
                self.rate = r;
                walls[LEFT].velocity.x = 0.5 * r * width;
                walls[RIGHT].velocity.x = -0.5 * r * width;
                walls[BOTTOM].velocity.y = 0.5 * r * height;
                walls[TOP].velocity.y = -0.5 * r * height;
            }
            Some(Phase::Oedometric { rate, .. }) => {
                let r = rate.value(state);
                self.rate = r;
                walls[RIGHT].velocity.x = -r * width;
            }
            Some(Phase::Servo {
                sxx,
                syy,
                gain,
                max_rate,
                ..
            }) => {
                let expand_x = (gain * (state.sxx - sxx) / state.young).clamp(-max_rate, *max_rate);
                let expand_y = (gain * (state.syy - syy) / state.young).clamp(-max_rate, *max_rate);
                self.rate = -0.5 * (expand_x + expand_y);
                walls[LEFT].velocity.x = -0.5 * expand_x * width;
                walls[RIGHT].velocity.x = 0.5 * expand_x * width;
                walls[BOTTOM].velocity.y = -0.5 * expand_y * height;
                walls[TOP].velocity.y = 0.5 * expand_y * height;
            }
            Some(Phase::Uniaxial { rate, .. }) => {
                let r = rate.value(state);
                self.rate = r;
                walls[TOP].velocity.y = -r * height;
            }
            Some(Phase::Biaxial { rate, .. }) => {
                let r = rate.value(state);
                self.rate = r;
                walls[BOTTOM].velocity.y = 0.5 * r * height;
                walls[TOP].velocity.y = -0.5 * r * height;
                walls[LEFT].velocity.x = -0.5 * r * width;
                walls[RIGHT].velocity.x = 0.5 * r * width;
            }
            Some(Phase::Shear {
                rate,
                syy,
                gain,
                max_rate,
                ..
            }) => {
                let expand_y = (gain * (state.syy - syy) / state.young).clamp(-max_rate, *max_rate);
                self.rate = *rate;
                self.shear_rate = *rate;
                walls[BOTTOM].velocity.y = -0.5 * expand_y * height;
                walls[TOP].velocity.y = 0.5 * expand_y * height;
            }
            Some(Phase::Relax { .. }) | None => {}
        }
    }

    fn reached(
        &self,
        until: &StopWhen,
        step: u64,
        time: f64,
        walls: &[Wall],
        state: &LoadState,
    ) -> bool {
        match until {
            StopWhen::PackingFraction(phi) => state.phi >= *phi,
            StopWhen::MeanStress(p) => state.mean_stress() >= *p,
            StopWhen::Jammed => state.jammed,
            StopWhen::Steps(n) => step - self.phase_start_step >= *n,
            // Relative slack for the rounding of a time summed step by step (400 steps of 0.01
            // add up to 3.99999999999996, not 4).
            StopWhen::Time(t) => time - self.phase_start_time >= *t * (1.0 - 1e-12),
            StopWhen::Strain(e) => 1.0 - box_size(walls).0 / self.phase_start_size.0 >= *e,
            StopWhen::VerticalStrain(e) => 1.0 - box_size(walls).1 / self.phase_start_size.1 >= *e,
            StopWhen::ShearStrain(g) => {
                (state.shear_strain - self.phase_start_shear_strain).abs() >= *g
            }
            StopWhen::Any(list) => list
                .iter()
                .any(|u| self.reached(u, step, time, walls, state)),
        }
    }

    /// Moves to the next phase if the current one is done; returns true when a phase ended.
    pub fn advance(&mut self, step: u64, time: f64, walls: &[Wall], state: &LoadState) -> bool {
        let Some(phase) = self.phases.get(self.current) else {
            return false;
        };
        if self.reached(phase.until(), step, time, walls, state) {
            self.current += 1;
            self.phase_start_step = step;
            self.phase_start_time = time;
            self.phase_start_size = box_size(walls);
            self.phase_start_shear_strain = state.shear_strain;
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::boundary::walls::box_walls;

    #[test]
    fn isotropic_phase_shrinks_both_sides_at_the_strain_rate() {
        let mut walls = box_walls(0.0, 2.0, 0.0, 1.0);
        let mut program = LoadingProgram::new(
            vec![Phase::Isotropic {
                rate: StrainRate::Constant(0.1),
                until: StopWhen::Steps(10),
                affine: false,
            }],
            &walls,
        );
        program.drive(&mut walls, &LoadState::default());
        // dW/dt = -0.1 W = -0.2, dH/dt = -0.1
        assert!((walls[RIGHT].velocity.x - walls[LEFT].velocity.x + 0.2).abs() < 1e-15);
        assert!((walls[TOP].velocity.y - walls[BOTTOM].velocity.y + 0.1).abs() < 1e-15);
        assert!(!program.advance(5, 0.0, &walls, &LoadState::default()));
        assert!(program.advance(10, 0.0, &walls, &LoadState::default()));
        assert!(program.finished());
    }

    #[test]
    fn quasi_static_rate_keeps_the_inertial_number() {
        let rate = StrainRate::QuasiStatic {
            inertial_number: 1e-3,
            max: 1.0,
            fast: 0.5,
            fast_until_phi: 0.8,
        };
        let mut s = LoadState {
            phi: 0.85,
            sxx: 0.01,
            syy: 0.01,
            jammed: true,
            mean_diameter: 0.024,
            density: 1.0,
            young: 1.0,
            shear_strain: 0.0,
        };
        let r = rate.value(&s);
        assert!((s.inertial_number(r) - 1e-3).abs() < 1e-15);
        s.phi = 0.5;
        s.jammed = false;
        // A loaded gas (p_c = 0.01 > 1e-4 E) is held to the quasi-static rate ...
        assert!((s.inertial_number(rate.value(&s)) - 1e-3).abs() < 1e-15);
        // ... an unloaded one is compacted at `fast`.
        s.sxx = 1e-5;
        s.syy = 1e-5;
        assert_eq!(rate.value(&s), 0.5);
    }
}
