//! Radius distributions: exact samplers and analytic moments.

use rand::Rng;

use super::math::{self, exprel, normal_mass, normal_pdf};
use super::{RadiusDistribution, SampleError};

/// Uniform `f64` in `[0, 1)` with 53 random bits, built from one `u64` with integer and exact
/// floating-point operations only (portable, unlike any platform-dependent conversion).
#[inline]
pub(crate) fn unit_f64<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    const SCALE: f64 = 1.0 / (1u64 << 53) as f64;
    (rng.next_u64() >> 11) as f64 * SCALE
}

/// Standard normal variate (Marsaglia polar method; the second variate of each pair is dropped
/// so that every draw is a pure function of the RNG stream).
fn standard_normal<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    loop {
        let u = 2.0 * unit_f64(rng) - 1.0;
        let v = 2.0 * unit_f64(rng) - 1.0;
        let s = u * u + v * v;
        if s > 0.0 && s < 1.0 {
            return u * (-2.0 * math::ln(s) / s).sqrt();
        }
    }
}

/// Upper bound on the proposals for one truncated-Gaussian radius. Every proposal scheme below
/// accepts with probability above ~0.3 for any interval that passed validation, so this bound is
/// never reached in practice; it only guarantees termination.
const MAX_PROPOSALS_PER_RADIUS: u32 = 1_000_000;

/// Which exact rejection scheme samples the standardized interval `[a, b]`.
#[derive(Debug, Clone, Copy)]
enum Scheme {
    /// `std_dev == 0`: every radius equals the mean.
    Constant,
    /// Interval contains 0 and is wide (`b - a >= sqrt(2 pi)`): plain normal draws, reject outside.
    Normal,
    /// Interval contains 0 and is narrow: uniform proposal, accept with `exp(-z^2/2)`.
    UniformAroundZero,
    /// `0 <= a`, short interval: uniform proposal, accept with `exp((a^2 - z^2)/2)`.
    UniformTail,
    /// `0 <= a`, long interval: Robert (1995) translated-exponential proposal with the optimal
    /// rate `lambda`, accept with `exp(-(z - lambda)^2/2)`, reject `z > b`.
    ExponentialTail { lambda: f64 },
}

/// Exact sampler of N(mean, std_dev) truncated to [min, max] (C. P. Robert, "Simulation of
/// truncated normal variables", Statistics and Computing 5, 1995). Intervals lying entirely
/// below the mean are mirrored to the upper tail.
#[derive(Debug, Clone, Copy)]
struct TruncatedGaussian {
    mean: f64,
    std_dev: f64,
    min: f64,
    max: f64,
    /// Standardized interval after mirroring (`a < b`, and `b > 0`).
    a: f64,
    b: f64,
    mirrored: bool,
    scheme: Scheme,
}

impl TruncatedGaussian {
    fn new(mean: f64, std_dev: f64, min: f64, max: f64) -> Self {
        if std_dev == 0.0 {
            return Self {
                mean,
                std_dev,
                min,
                max,
                a: 0.0,
                b: 0.0,
                mirrored: false,
                scheme: Scheme::Constant,
            };
        }
        let a0 = (min - mean) / std_dev;
        let b0 = (max - mean) / std_dev;
        let (a, b, mirrored) = if b0 <= 0.0 {
            (-b0, -a0, true)
        } else {
            (a0, b0, false)
        };
        let scheme = if a < 0.0 {
            if b - a >= (2.0 * std::f64::consts::PI).sqrt() {
                Scheme::Normal
            } else {
                Scheme::UniformAroundZero
            }
        } else if 0.5 * (b - a) * (b + a) <= 1.0 {
            Scheme::UniformTail
        } else {
            Scheme::ExponentialTail {
                lambda: 0.5 * (a + (a * a + 4.0).sqrt()),
            }
        };
        Self {
            mean,
            std_dev,
            min,
            max,
            a,
            b,
            mirrored,
            scheme,
        }
    }

    /// Standardized (and possibly mirrored) proposal that passed its acceptance test, if any.
    fn propose<R: Rng + ?Sized>(&self, rng: &mut R) -> Option<f64> {
        let (a, b) = (self.a, self.b);
        match self.scheme {
            Scheme::Constant => Some(0.0),
            Scheme::Normal => Some(standard_normal(rng)),
            Scheme::UniformAroundZero => {
                let z = a + unit_f64(rng) * (b - a);
                (unit_f64(rng) < math::exp(-0.5 * z * z)).then_some(z)
            }
            Scheme::UniformTail => {
                let z = a + unit_f64(rng) * (b - a);
                (unit_f64(rng) < math::exp(0.5 * (a - z) * (a + z))).then_some(z)
            }
            Scheme::ExponentialTail { lambda } => {
                // 1 - u lies in (0, 1], so the logarithm is finite.
                let z = a - math::ln(1.0 - unit_f64(rng)) / lambda;
                if z > b {
                    return None;
                }
                let d = z - lambda;
                (unit_f64(rng) < math::exp(-0.5 * d * d)).then_some(z)
            }
        }
    }

    fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> Option<f64> {
        if let Scheme::Constant = self.scheme {
            return Some(self.mean);
        }
        for _ in 0..MAX_PROPOSALS_PER_RADIUS {
            if let Some(z) = self.propose(rng) {
                let z = if self.mirrored { -z } else { z };
                let r = self.mean + self.std_dev * z;
                // Also guards against the last-bit rounding of `mean + std_dev * z`.
                if r >= self.min && r <= self.max {
                    return Some(r);
                }
            }
        }
        None
    }
}

/// Draws `count` radii (in draw order) from a distribution that passed validation.
pub(crate) fn draw_radii<R: Rng + ?Sized>(
    dist: &RadiusDistribution,
    count: usize,
    rng: &mut R,
) -> Result<Vec<f64>, SampleError> {
    let mut radii = Vec::with_capacity(count);
    match *dist {
        RadiusDistribution::Monodisperse { radius } => radii.resize(count, radius),
        RadiusDistribution::Uniform { min, max } => {
            for _ in 0..count {
                radii.push((min + unit_f64(rng) * (max - min)).min(max));
            }
        }
        RadiusDistribution::Fractal {
            dimension,
            min,
            max,
        } => {
            // Inverse CDF. With x = r/min, rho = max/min, q = rho^-d:
            //   F(r) = (1 - x^-d) / (1 - q)   =>   r = min * (1 - u (1 - q))^(-1/d).
            let log_rho = math::ln(max / min);
            let one_minus_q = dimension * log_rho * exprel(-dimension * log_rho);
            for _ in 0..count {
                let t = 1.0 - unit_f64(rng) * one_minus_q;
                let r = min * math::exp(-math::ln(t) / dimension);
                radii.push(r.clamp(min, max));
            }
        }
        RadiusDistribution::Gaussian {
            mean,
            std_dev,
            min,
            max,
        } => {
            let sampler = TruncatedGaussian::new(mean, std_dev, min, max);
            for _ in 0..count {
                match sampler.sample(rng) {
                    Some(r) => radii.push(r),
                    None => {
                        return Err(SampleError::EmptyTruncation {
                            mean,
                            std_dev,
                            min,
                            max,
                            mass: truncated_mass(mean, std_dev, min, max),
                        });
                    }
                }
            }
        }
    }
    Ok(radii)
}

/// Probability mass of [min, max] under N(mean, std_dev) (std_dev >= 0).
pub(crate) fn truncated_mass(mean: f64, std_dev: f64, min: f64, max: f64) -> f64 {
    if std_dev == 0.0 {
        return if min <= mean && mean <= max { 1.0 } else { 0.0 };
    }
    normal_mass((min - mean) / std_dev, (max - mean) / std_dev)
}

/// First and second raw moments (`E[r]`, `E[r^2]`) of the truncated Gaussian.
pub(crate) fn truncated_gaussian_moments(
    mean: f64,
    std_dev: f64,
    min: f64,
    max: f64,
) -> (f64, f64) {
    if std_dev == 0.0 {
        return if min <= mean && mean <= max {
            (mean, mean * mean)
        } else {
            (f64::NAN, f64::NAN)
        };
    }
    let a = (min - mean) / std_dev;
    let b = (max - mean) / std_dev;
    let z = normal_mass(a, b);
    if z.is_nan() || z <= 0.0 {
        return (f64::NAN, f64::NAN);
    }
    let (pa, pb) = (normal_pdf(a), normal_pdf(b));
    let shift = (pa - pb) / z;
    let m1 = mean + std_dev * shift;
    // `a * pa` with pa == 0 (far tail) must be 0, not NaN: a and b are finite here.
    let var = std_dev * std_dev * (1.0 + (a * pa - b * pb) / z - shift * shift);
    (m1, var.max(0.0) + m1 * m1)
}

/// `E[r^k]` of the fractal distribution (pdf ∝ r^-(d+1) on [min, max]):
/// `min^k * exprel((k - d) L) / exprel(-d L)` with `L = ln(max/min)`, exact for every d (d = k
/// included) and free of cancellation.
pub(crate) fn fractal_moment(k: f64, dimension: f64, min: f64, max: f64) -> f64 {
    let log_rho = math::ln(max / min);
    math::powf(min, k) * exprel((k - dimension) * log_rho) / exprel(-dimension * log_rho)
}

/// `E[r^2]` of any validated distribution.
pub(crate) fn second_moment(dist: &RadiusDistribution) -> f64 {
    match *dist {
        RadiusDistribution::Monodisperse { radius } => radius * radius,
        RadiusDistribution::Uniform { min, max } => (min * min + min * max + max * max) / 3.0,
        RadiusDistribution::Fractal {
            dimension,
            min,
            max,
        } => fractal_moment(2.0, dimension, min, max),
        RadiusDistribution::Gaussian {
            mean,
            std_dev,
            min,
            max,
        } => truncated_gaussian_moments(mean, std_dev, min, max).1,
    }
}
