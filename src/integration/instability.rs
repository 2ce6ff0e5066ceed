//! The failures the engine detects and stops on (SPEC §9).

use std::fmt;

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Instability {
    /// A degree of freedom became NaN or infinite.
    NonFinite { step: u64, grain: usize },
    /// A principal strain reached -1: the grain would invert.
    Inverted {
        step: u64,
        grain: usize,
        eps1: f64,
        eps2: f64,
    },
    /// The contact law left its domain: `a L_c + (b-1) delta_n` fell to its floor.
    ContactDomain {
        step: u64,
        grain: usize,
        /// The other grain, or None for a wall.
        other: Option<usize>,
        length: f64,
        normal_gap: f64,
    },
    /// One contour lies entirely inside another (or a grain entirely beyond a wall).
    Swallowed {
        step: u64,
        grain: usize,
        other: Option<usize>,
    },
    /// A grain moves faster than the elastic wave speed.
    Runaway { step: u64, grain: usize, speed: f64 },
    /// The periodic cell became narrower than twice the interaction range (largest grain
    /// diameter + neighbour skin): a grain could meet two images of another.
    CellTooNarrow { step: u64, width: f64, range: f64 },
}

fn other_name(other: &Option<usize>) -> String {
    match other {
        Some(j) => format!("grain {j}"),
        None => "a wall".to_string(),
    }
}

impl fmt::Display for Instability {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Instability::NonFinite { step, grain } => write!(
                f,
                "step {step}: grain {grain} has a non-finite degree of freedom (NaN or inf); \
                 the time step is probably above the critical one"
            ),
            Instability::Inverted {
                step,
                grain,
                eps1,
                eps2,
            } => write!(
                f,
                "step {step}: grain {grain} inverted (eps1 = {eps1:.4}, eps2 = {eps2:.4}, must stay > -1); \
                 reduce the time step or the loading rate"
            ),
            Instability::ContactDomain {
                step,
                grain,
                other,
                length,
                normal_gap,
            } => write!(
                f,
                "step {step}: the contact between grain {grain} and {} left the domain of the \
                 contact law (L_c = {length:.4e}, delta_n = {normal_gap:.4e}: a L_c + (b-1) delta_n \
                 is at or below its floor); set contact.on_domain_exit: Cap to continue with a capped law, \
                 or stop the compaction earlier",
                other_name(other)
            ),
            Instability::Swallowed { step, grain, other } => write!(
                f,
                "step {step}: grain {grain} and {} no longer cross (one contour swallowed by the other); \
                 reduce the time step or the loading rate",
                other_name(other)
            ),
            Instability::Runaway { step, grain, speed } => write!(
                f,
                "step {step}: grain {grain} moves at {speed:.3e}, faster than the elastic wave speed \
                 sqrt(E/rho): energy blow-up; reduce the time step"
            ),
            Instability::CellTooNarrow { step, width, range } => write!(
                f,
                "step {step}: the periodic cell is {width:.4e} wide across, under twice the \
                 interaction range {range:.4e} (largest grain diameter + neighbour skin): a grain \
                 would meet two images of another; use more grains or a larger cell, or compress \
                 less"
            ),
        }
    }
}

impl std::error::Error for Instability {}
