//! Initial samples: non-overlapping discs in a rectangular box (SPEC §8).
//!
//! A [`SampleSpec`] gives the number of grains, the box `[0, box_width] x [0, box_height]` and a
//! [`RadiusDistribution`]. [`generate`] draws the radii, then places the discs one by one, largest
//! first, at uniformly random positions fully inside the box, rejecting positions that overlap an
//! already placed disc (random sequential addition, RSA).
//!
//! # Units and conventions
//!
//! * All lengths (box sides, radii, positions, distribution parameters) are in the simulation's
//!   length unit: the same unit for the box and the radii, nothing is rescaled.
//! * Grains are discs of radius `r` centred at `(x, y)`; a placed disc satisfies
//!   `x - r >= 0`, `x + r <= box_width`, `y - r >= 0`, `y + r <= box_height`, and for two discs
//!   `dx*dx + dy*dy >= (ri + rj)^2` (they may touch, never overlap).
//! * Output order is the placement order: radii in non-increasing order.
//!
//! # Reproducibility
//!
//! The same spec and seed give a bitwise-identical `Vec` on every machine: the RNG is
//! `ChaCha8Rng::seed_from_u64(seed)` (a portable, value-stable stream), uniform variates are built
//! from the raw `u64` stream, and every transcendental function on the generation path (`ln`,
//! `exp`, `erfc`) is a portable pure-arithmetic implementation (`src/portable.rs`) rather than the
//! platform's C math library.
//!
//! # Example
//!
//! ```
//! use sdem::sample::{generate, packing_fraction, RadiusDistribution, SampleSpec};
//!
//! let spec = SampleSpec {
//!     count: 200,
//!     box_width: 1.0,
//!     box_height: 1.0,
//!     radii: RadiusDistribution::Uniform { min: 0.01, max: 0.03 },
//! };
//! let grains = generate(&spec, 42).unwrap();
//! assert_eq!(grains.len(), 200);
//! assert!(packing_fraction(&grains, 1.0, 1.0) < 0.55);
//! ```

pub mod file;
pub mod order;
mod placement;
mod radii;

use crate::portable as math;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Largest packing fraction (disc area / box area) that [`generate`] accepts for the requested
/// radii. Random sequential addition of equal discs in 2D jams near 0.547; beyond this the
/// placement cannot finish in bounded time.
pub const MAX_PACKING_FRACTION: f64 = 0.55;

/// Largest `count` accepted by [`SampleSpec::validate`] (memory and run-time guard).
pub const MAX_COUNT: usize = 100_000_000;

/// A truncated Gaussian whose interval holds less probability than this is rejected.
pub const MIN_TRUNCATION_MASS: f64 = 1e-9;

/// Attempts (random positions tried) allowed for one grain before [`generate`] gives up.
pub const MAX_ATTEMPTS_PER_GRAIN: u64 = placement::MAX_ATTEMPTS_PER_GRAIN;

/// Bound on the total number of attempts of one [`generate`] call:
/// `MAX_MEAN_ATTEMPTS_PER_GRAIN * count + MAX_ATTEMPTS_PER_GRAIN`, so that generation time is
/// O(count) even when the requested packing cannot be reached.
pub const MAX_MEAN_ATTEMPTS_PER_GRAIN: u64 = placement::MAX_MEAN_ATTEMPTS_PER_GRAIN;

/// Distribution of grain radii (lengths in the simulation unit).
///
/// In a RON scenario file, e.g. `Gaussian(mean: 0.012, std_dev: 0.002, min: 0.006, max: 0.018)`
/// or `Fractal(dimension: 2.0, min: 0.004, max: 0.038)`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub enum RadiusDistribution {
    /// Gaussian with the given mean and standard deviation, truncated to [min, max] (exact
    /// rejection sampling, C. P. Robert 1995, efficient also for intervals far in a tail).
    /// Requires `mean > 0`, `std_dev >= 0` (0 gives every grain the radius `mean`, which must
    /// then lie in [min, max]), `0 < min < max`, and a probability of [min, max] under
    /// N(mean, std_dev) of at least [`MIN_TRUNCATION_MASS`].
    Gaussian {
        /// Mean of the untruncated Gaussian.
        mean: f64,
        /// Standard deviation of the untruncated Gaussian.
        std_dev: f64,
        /// Smallest radius.
        min: f64,
        /// Largest radius.
        max: f64,
    },
    /// Fractal (power-law) distribution: number of grains larger than r ∝ r^-dimension,
    /// i.e. pdf ∝ r^-(dimension+1), truncated to [min, max]. Sampled by inverse CDF (exact, no
    /// rejection). Requires `dimension > 0` and `0 < min < max`.
    Fractal {
        /// Fractal dimension `d > 0` (2 for an Apollonian-like space-filling size distribution).
        dimension: f64,
        /// Smallest radius.
        min: f64,
        /// Largest radius.
        max: f64,
    },
    /// Radii uniformly distributed in [min, max], `0 < min < max`.
    Uniform {
        /// Smallest radius.
        min: f64,
        /// Largest radius.
        max: f64,
    },
    /// Every grain has the same radius (`radius > 0`).
    Monodisperse {
        /// The common radius.
        radius: f64,
    },
}

impl RadiusDistribution {
    /// Largest radius the distribution can produce.
    pub fn max_radius(&self) -> f64 {
        match *self {
            Self::Gaussian { max, .. } | Self::Fractal { max, .. } | Self::Uniform { max, .. } => {
                max
            }
            Self::Monodisperse { radius } => radius,
        }
    }

    /// Smallest radius the distribution can produce (sets the critical time step).
    pub fn min_radius(&self) -> f64 {
        match *self {
            Self::Gaussian { min, .. } | Self::Fractal { min, .. } | Self::Uniform { min, .. } => {
                min
            }
            Self::Monodisperse { radius } => radius,
        }
    }

    /// Analytic mean radius `E[r]` (NaN for parameters that fail validation).
    pub fn mean_radius(&self) -> f64 {
        match *self {
            Self::Gaussian {
                mean,
                std_dev,
                min,
                max,
            } => truncated_gaussian_mean(mean, std_dev, min, max),
            Self::Fractal {
                dimension,
                min,
                max,
            } => fractal_mean(dimension, min, max),
            Self::Uniform { min, max } => 0.5 * (min + max),
            Self::Monodisperse { radius } => radius,
        }
    }

    /// Analytic mean squared radius `E[r^2]` (NaN for parameters that fail validation); the
    /// expected disc area is `pi * E[r^2]`.
    pub fn mean_squared_radius(&self) -> f64 {
        radii::second_moment(self)
    }
}

/// What to generate: `count` discs in the box `[0, box_width] x [0, box_height]`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SampleSpec {
    /// Number of grains, 1 ..= [`MAX_COUNT`].
    pub count: usize,
    /// Box width (x extent), finite and > 0; the box is `[0, box_width] x [0, box_height]`.
    pub box_width: f64,
    /// Box height (y extent), finite and > 0.
    pub box_height: f64,
    /// Radius distribution.
    pub radii: RadiusDistribution,
}

/// A placed disc: centre `(x, y)` and radius, in the simulation length unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacedGrain {
    /// Centre x coordinate, in `[radius, box_width - radius]`.
    pub x: f64,
    /// Centre y coordinate, in `[radius, box_height - radius]`.
    pub y: f64,
    /// Disc radius.
    pub radius: f64,
}

/// Why a sample could not be generated. Messages name the offending field (`sample.…`), its
/// value and what is allowed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SampleError {
    /// `count == 0`.
    #[error("sample.count must be at least 1 (got 0)")]
    ZeroCount,

    /// `count > MAX_COUNT`.
    #[error("sample.count = {count} is too large: at most {max} grains can be generated")]
    TooManyGrains {
        /// Requested count.
        count: usize,
        /// Largest accepted count.
        max: usize,
    },

    /// A length or parameter that must be finite and strictly positive is not.
    #[error("{field} must be a finite number > 0 (got {value})")]
    NotPositive {
        /// Field path, e.g. `sample.radii.min`.
        field: &'static str,
        /// Offending value.
        value: f64,
    },

    /// A parameter that must be finite and non-negative is not (`sample.radii.std_dev`).
    #[error("{field} must be a finite number >= 0 (got {value})")]
    Negative {
        /// Field path.
        field: &'static str,
        /// Offending value.
        value: f64,
    },

    /// `min >= max`.
    #[error(
        "sample.radii.min ({min}) must be smaller than sample.radii.max ({max}); \
         use Monodisperse(radius: ...) for equal radii"
    )]
    EmptyRadiusRange {
        /// Value of `sample.radii.min`.
        min: f64,
        /// Value of `sample.radii.max`.
        max: f64,
    },

    /// The truncation interval of a Gaussian holds practically no probability.
    #[error(
        "the Gaussian radius distribution (sample.radii: mean = {mean}, std_dev = {std_dev}) \
         has probability {mass:.3e} on [min, max] = [{min}, {max}], below the allowed 1e-9: \
         move sample.radii.min / sample.radii.max towards the mean or increase std_dev"
    )]
    EmptyTruncation {
        /// `sample.radii.mean`.
        mean: f64,
        /// `sample.radii.std_dev`.
        std_dev: f64,
        /// `sample.radii.min`.
        min: f64,
        /// `sample.radii.max`.
        max: f64,
        /// Probability of [min, max] under N(mean, std_dev).
        mass: f64,
    },

    /// The largest possible disc does not fit in the box.
    #[error(
        "the largest grain (radius {max_radius}, diameter {}) does not fit in the \
         {box_width} x {box_height} box: the diameter must be <= sample.box_width and \
         sample.box_height; reduce sample.radii.max (or radius) or enlarge the box",
        2.0 * max_radius
    )]
    GrainTooLarge {
        /// Largest radius of the distribution.
        max_radius: f64,
        /// `sample.box_width`.
        box_width: f64,
        /// `sample.box_height`.
        box_height: f64,
    },

    /// The requested discs cover too much of the box for random sequential addition.
    #[error(
        "sample too dense: {count} grains would cover a fraction {packing_fraction:.3} of the \
         box area, above the limit {limit} (random sequential addition jams near 0.547); \
         use a larger box (sample.box_width, sample.box_height) or fewer grains \
         (sample.count <= about {max_count} for this box)"
    )]
    TooDense {
        /// Requested `sample.count`.
        count: usize,
        /// Requested packing fraction (total disc area / box area; expected value in
        /// [`SampleSpec::validate`], actual drawn radii in [`generate`]).
        packing_fraction: f64,
        /// [`MAX_PACKING_FRACTION`].
        limit: f64,
        /// Largest count that would respect the limit (expected value).
        max_count: usize,
    },

    /// Random sequential addition could not place every grain within its attempt budget.
    #[error(
        "could only place {placed} of {requested} grains (requested packing fraction \
         {packing_fraction:.3}, reached {reached_packing_fraction:.3}) after {attempts} random \
         positions: the box is too crowded for random placement; use a larger box \
         (sample.box_width, sample.box_height) or fewer grains (sample.count)"
    )]
    PlacementFailed {
        /// Grains placed before giving up.
        placed: usize,
        /// `sample.count`.
        requested: usize,
        /// Packing fraction of all requested (drawn) discs.
        packing_fraction: f64,
        /// Packing fraction of the discs placed before giving up.
        reached_packing_fraction: f64,
        /// Total positions tried.
        attempts: u64,
    },
}

/// `value` must be finite and > 0.
fn positive(field: &'static str, value: f64) -> Result<(), SampleError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SampleError::NotPositive { field, value })
    }
}

/// `0 < min < max`, both finite.
fn radius_range(min: f64, max: f64) -> Result<(), SampleError> {
    positive("sample.radii.min", min)?;
    positive("sample.radii.max", max)?;
    if min >= max {
        return Err(SampleError::EmptyRadiusRange { min, max });
    }
    Ok(())
}

impl SampleSpec {
    /// Checks every field; returns the first problem. Called by [`generate`].
    ///
    /// Order of the checks: count, box sides, distribution parameters (finite and positive,
    /// `min < max`, Gaussian truncation mass), largest disc fits in the box, expected packing
    /// fraction `count * pi * E[r^2] / (w h)` at most [`MAX_PACKING_FRACTION`].
    pub fn validate(&self) -> Result<(), SampleError> {
        if self.count == 0 {
            return Err(SampleError::ZeroCount);
        }
        if self.count > MAX_COUNT {
            return Err(SampleError::TooManyGrains {
                count: self.count,
                max: MAX_COUNT,
            });
        }
        positive("sample.box_width", self.box_width)?;
        positive("sample.box_height", self.box_height)?;

        match self.radii {
            RadiusDistribution::Gaussian {
                mean,
                std_dev,
                min,
                max,
            } => {
                positive("sample.radii.mean", mean)?;
                if !(std_dev.is_finite() && std_dev >= 0.0) {
                    return Err(SampleError::Negative {
                        field: "sample.radii.std_dev",
                        value: std_dev,
                    });
                }
                radius_range(min, max)?;
                let mass = radii::truncated_mass(mean, std_dev, min, max);
                if mass.is_nan() || mass < MIN_TRUNCATION_MASS {
                    return Err(SampleError::EmptyTruncation {
                        mean,
                        std_dev,
                        min,
                        max,
                        mass,
                    });
                }
            }
            RadiusDistribution::Fractal {
                dimension,
                min,
                max,
            } => {
                positive("sample.radii.dimension", dimension)?;
                radius_range(min, max)?;
            }
            RadiusDistribution::Uniform { min, max } => radius_range(min, max)?,
            RadiusDistribution::Monodisperse { radius } => positive("sample.radii.radius", radius)?,
        }

        let max_radius = self.radii.max_radius();
        if 2.0 * max_radius > self.box_width || 2.0 * max_radius > self.box_height {
            return Err(SampleError::GrainTooLarge {
                max_radius,
                box_width: self.box_width,
                box_height: self.box_height,
            });
        }

        let mean_area = std::f64::consts::PI * self.radii.mean_squared_radius();
        let box_area = self.box_width * self.box_height;
        let fraction = self.count as f64 * mean_area / box_area;
        if fraction.is_nan() || fraction > MAX_PACKING_FRACTION {
            return Err(self.too_dense(fraction));
        }
        Ok(())
    }

    fn too_dense(&self, packing_fraction: f64) -> SampleError {
        let mean_area = std::f64::consts::PI * self.radii.mean_squared_radius();
        let max_count = MAX_PACKING_FRACTION * self.box_width * self.box_height / mean_area;
        SampleError::TooDense {
            count: self.count,
            packing_fraction,
            limit: MAX_PACKING_FRACTION,
            max_count: if max_count.is_finite() {
                max_count.floor() as usize
            } else {
                0
            },
        }
    }
}

/// Draws `count` radii from the distribution with a ChaCha8 RNG seeded by `seed`
/// (`rand_chacha::ChaCha8Rng::seed_from_u64`), then places them one by one, largest first,
/// at uniformly random positions fully inside the box, rejecting any position that overlaps an
/// already placed disc (random sequential addition), using a uniform cell grid (cell side at
/// least 2 * max radius) so that each trial is O(1). Same spec + seed => bitwise-identical
/// output on every machine.
///
/// The result has `spec.count` grains in placement order (non-increasing radius).
///
/// Errors: any [`SampleSpec::validate`] error; [`SampleError::TooDense`] if the radii actually
/// drawn cover more than [`MAX_PACKING_FRACTION`] of the box; [`SampleError::PlacementFailed`]
/// if a grain finds no free position in [`MAX_ATTEMPTS_PER_GRAIN`] tries or the whole run
/// exceeds `MAX_MEAN_ATTEMPTS_PER_GRAIN * count + MAX_ATTEMPTS_PER_GRAIN` tries.
pub fn generate(spec: &SampleSpec, seed: u64) -> Result<Vec<PlacedGrain>, SampleError> {
    spec.validate()?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut radii = radii::draw_radii(&spec.radii, spec.count, &mut rng)?;
    // Largest first; ties are equal values, so the order is fully determined.
    radii.sort_unstable_by(|a, b| b.total_cmp(a));

    let box_area = spec.box_width * spec.box_height;
    let disc_area = |rs: &mut dyn Iterator<Item = f64>| -> f64 {
        rs.map(|r| std::f64::consts::PI * r * r).sum::<f64>()
    };
    let fraction = disc_area(&mut radii.iter().copied()) / box_area;
    if fraction.is_nan() || fraction > MAX_PACKING_FRACTION {
        return Err(spec.too_dense(fraction));
    }

    placement::place(&radii, spec.box_width, spec.box_height, &mut rng).map_err(|failure| {
        SampleError::PlacementFailed {
            placed: failure.placed,
            requested: spec.count,
            packing_fraction: fraction,
            reached_packing_fraction: disc_area(&mut radii[..failure.placed].iter().copied())
                / box_area,
            attempts: failure.attempts,
        }
    })
}

/// Packing fraction of discs in the box: `sum(pi r^2) / (box_width * box_height)`.
pub fn packing_fraction(grains: &[PlacedGrain], box_width: f64, box_height: f64) -> f64 {
    let area: f64 = grains
        .iter()
        .map(|g| std::f64::consts::PI * g.radius * g.radius)
        .sum();
    area / (box_width * box_height)
}

/// Mean of N(mean, std_dev) truncated to [min, max]:
/// `mean + std_dev * (phi(alpha) - phi(beta)) / (Phi(beta) - Phi(alpha))`, with
/// `alpha = (min - mean) / std_dev`, `beta = (max - mean) / std_dev`. `std_dev == 0` gives `mean`
/// if it lies in [min, max]. Returns NaN if [min, max] has zero probability (in `f64`).
pub fn truncated_gaussian_mean(mean: f64, std_dev: f64, min: f64, max: f64) -> f64 {
    radii::truncated_gaussian_moments(mean, std_dev, min, max).0
}

/// Mean of the fractal distribution with pdf ∝ r^-(dimension+1) on [min, max]:
/// `d / (min^-d - max^-d) * (min^(1-d) - max^(1-d)) / (d - 1)` (and its limit
/// `ln(max/min) / (1/min - 1/max)` at d = 1), evaluated without cancellation.
pub fn fractal_mean(dimension: f64, min: f64, max: f64) -> f64 {
    radii::fractal_moment(1.0, dimension, min, max)
}

/// Draws `count` radii from a distribution (validated first) with a ChaCha8 RNG seeded by
/// `seed`, in draw order: the radii of a sample without its placement.
pub fn draw_radii(
    radii: &RadiusDistribution,
    count: usize,
    seed: u64,
) -> Result<Vec<f64>, SampleError> {
    use rand::SeedableRng;
    SampleSpec {
        count,
        box_width: f64::MAX,
        box_height: f64::MAX,
        radii: radii.clone(),
    }
    .validate()?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    radii::draw_radii(radii, count, &mut rng)
}

/// A uniform number in [0, 1) from a portable bit recipe (for jitter and the like).
pub fn unit_random(rng: &mut rand_chacha::ChaCha8Rng) -> f64 {
    radii::unit_f64(rng)
}

#[cfg(test)]
mod tests {
    use super::math;

    /// The portable functions agree with the platform's to within 1-2 ulp (they are not
    /// required to be bitwise equal to it).
    #[test]
    fn portable_math_matches_std() {
        let ulps = |a: f64, b: f64| (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs();
        let mut x = 1e-300_f64;
        while x < 1e300 {
            assert!(ulps(math::ln(x), x.ln()) <= 1, "ln({x})");
            x *= 1.37;
        }
        let mut x = -740.0_f64;
        while x < 709.0 {
            assert!(ulps(math::exp(x), x.exp()) <= 1, "exp({x})");
            x += 0.0137;
        }
        for i in 0..4000 {
            let x = -6.0 + i as f64 * 0.0083;
            let reference = 1.0 - erf_series(x);
            if x.abs() < 2.0 {
                assert!((math::erfc(x) - reference).abs() < 1e-14, "erfc({x})");
            }
        }
        // Far-tail values (Abramowitz & Stegun / high-precision references).
        let rel = |a: f64, b: f64| ((a - b) / b).abs();
        assert!(rel(math::erfc(3.0), 2.209_049_699_858_544e-5) < 1e-14);
        assert!(rel(math::erfc(5.0), 1.537_459_794_428_035e-12) < 1e-14);
        assert!(rel(math::erfc(10.0), 2.088_487_583_762_545e-45) < 1e-13);
        assert_eq!(math::erfc(0.0), 1.0);
        assert!(rel(math::erfc(-1.0), 1.842_700_792_949_715) < 1e-15);
    }

    /// erf by its Taylor series (accurate for |x| < 2).
    fn erf_series(x: f64) -> f64 {
        let mut term = x;
        let mut sum = x;
        let mut n = 0.0;
        while term.abs() > 1e-18 * sum.abs().max(1e-300) {
            n += 1.0;
            term *= -x * x / n;
            sum += term / (2.0 * n + 1.0);
        }
        sum * 2.0 / std::f64::consts::PI.sqrt()
    }
}
