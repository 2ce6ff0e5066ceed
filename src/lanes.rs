//! Kernels written once for one value and for four: the [`Real`] arithmetic they use, for `f64`
//! and for [`Lanes`], `N` independent `f64` lanes (issue #16).
//!
//! A formula written over `T: Real` gives, lane by lane, the same bits as over `f64`: every
//! operation here is a correctly rounded IEEE operation (`+ - * /`, `sqrt`) or a comparison
//! (`min`, `max`, `abs`), applied in the order the formula states; nothing fuses a multiply and
//! an add (Rust never contracts floating-point expressions). The compiler turns the lanes into
//! vector instructions where the target has them (SSE2 everywhere on x86-64, AVX where a caller
//! enables it at run time), which changes the speed, never the results.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// The arithmetic a lane kernel needs.
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// The same value in every lane.
    fn splat(value: f64) -> Self;
    fn sqrt(self) -> Self;
    /// As [`f64::max`] (a NaN takes the other operand), and `other` where the two are equal:
    /// `f64::max` leaves the sign of `max(-0, +0)` to the instructions the compiler picks, which
    /// differ between one lane and a vector of them.
    fn max(self, other: Self) -> Self;
    /// As [`f64::min`], and `other` where the two are equal (see [`Real::max`]).
    fn min(self, other: Self) -> Self;
    /// `then` where `self > than`, else `otherwise` (a NaN compares false), lane by lane.
    fn if_greater(self, than: Self, then: Self, otherwise: Self) -> Self;
}

/// [`Real::max`] of one lane: a select, the same in scalar and vector instructions.
#[inline(always)]
fn lane_max(a: f64, b: f64) -> f64 {
    if b.is_nan() || a > b { a } else { b }
}

/// [`Real::min`] of one lane.
#[inline(always)]
fn lane_min(a: f64, b: f64) -> f64 {
    if b.is_nan() || a < b { a } else { b }
}

impl Real for f64 {
    #[inline(always)]
    fn splat(value: f64) -> Self {
        value
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        lane_max(self, other)
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        lane_min(self, other)
    }
    #[inline(always)]
    fn if_greater(self, than: Self, then: Self, otherwise: Self) -> Self {
        if self > than { then } else { otherwise }
    }
}

/// `N` independent `f64` lanes, operated on lane by lane. Several vector registers' worth of
/// lanes (`N` = 8 or 16 with AVX's four) keep the processor busy through the long latencies of
/// division and square root: one register's four lanes would wait on each other's chain.
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C, align(32))]
pub struct Lanes<const N: usize>(pub [f64; N]);

impl<const N: usize> Default for Lanes<N> {
    fn default() -> Self {
        Lanes([0.0; N])
    }
}

impl<const N: usize> Lanes<N> {
    /// The lanes `f(0), f(1), ..., f(N - 1)`.
    #[inline(always)]
    pub fn from_fn(f: impl FnMut(usize) -> f64) -> Self {
        Lanes(std::array::from_fn(f))
    }

    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> Self {
        let mut out = self.0;
        for x in out.iter_mut() {
            *x = f(*x);
        }
        Lanes(out)
    }

    #[inline(always)]
    fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        let mut out = self.0;
        for (x, y) in out.iter_mut().zip(other.0) {
            *x = f(*x, y);
        }
        Lanes(out)
    }
}

macro_rules! lane_operator {
    ($trait:ident, $method:ident, $op:tt) => {
        impl<const N: usize> $trait for Lanes<N> {
            type Output = Self;
            #[inline(always)]
            fn $method(self, other: Self) -> Self {
                self.zip(other, |a, b| a $op b)
            }
        }
    };
}

lane_operator!(Add, add, +);
lane_operator!(Sub, sub, -);
lane_operator!(Mul, mul, *);
lane_operator!(Div, div, /);

impl<const N: usize> Neg for Lanes<N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.map(|a| -a)
    }
}

impl<const N: usize> Real for Lanes<N> {
    #[inline(always)]
    fn splat(value: f64) -> Self {
        Lanes([value; N])
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        self.map(f64::sqrt)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        self.zip(other, lane_max)
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        self.zip(other, lane_min)
    }
    #[inline(always)]
    fn if_greater(self, than: Self, then: Self, otherwise: Self) -> Self {
        Lanes(std::array::from_fn(|l| {
            if self.0[l] > than.0[l] {
                then.0[l]
            } else {
                otherwise.0[l]
            }
        }))
    }
}

/// Which vector instructions the kernels take where the processor has AVX-512, as the
/// environment variable `SDEM_SIMD` asks (`auto`, the default; `avx`; `avx512`). Every choice
/// gives the same bits (the kernels compute the same operations in the same order, only more
/// lanes at a time); it changes the speed only.
///
/// `auto` runs the eight-lane polygon kernel in AVX-512 everywhere, and the pair pass's loop and
/// its disc kernels (square roots and divisions in every lane) in AVX-512 except on Intel's
/// processors. Measured on an Ice Lake Xeon (issue #16, forty-first session): the pair loop and
/// disc kernels in AVX rather than AVX-512 ran rigid discs 1.09-1.12 times as fast on one
/// thread and 1.10-1.17 on two, the full level as fast (0.99); on an AMD Zen 5 their AVX-512
/// forms had been 2-5% faster each. The likely cause: Intel's server cores lower their clock
/// while they run heavy AVX-512 arithmetic (the "AVX-512 frequency licences" of Intel's
/// optimization manual), and divisions and square roots gain nothing per lane from the wider
/// registers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Simd {
    /// AVX-512 where it was measured to pay on this processor's maker.
    Auto,
    /// AVX at most (four lanes in 256-bit registers), never AVX-512.
    Avx,
    /// AVX-512 wherever a kernel has an AVX-512 form and the processor runs it.
    Avx512,
}

/// `SDEM_SIMD` holds a value other than `auto`, `avx` or `avx512`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("SDEM_SIMD={0:?}: expected auto, avx or avx512 (unset means auto)")]
pub struct UnknownSimd(pub String);

impl Simd {
    /// The choice that `SDEM_SIMD` holds (`auto` where it is unset or empty).
    pub fn from_env() -> Result<Self, UnknownSimd> {
        match std::env::var("SDEM_SIMD").as_deref() {
            Err(_) | Ok("") | Ok("auto") => Ok(Self::Auto),
            Ok("avx") => Ok(Self::Avx),
            Ok("avx512") => Ok(Self::Avx512),
            Ok(other) => Err(UnknownSimd(other.to_string())),
        }
    }

    /// This process's choice, read from `SDEM_SIMD` once (`auto` where it does not parse: the
    /// command line checks it first, with [`from_env`](Self::from_env)).
    pub fn chosen() -> Self {
        static CHOSEN: std::sync::OnceLock<Simd> = std::sync::OnceLock::new();
        *CHOSEN.get_or_init(|| Self::from_env().unwrap_or(Self::Auto))
    }

    /// Whether the pair pass's loop and its disc kernels run in AVX-512 on this processor.
    pub fn discs_in_avx512() -> bool {
        static DISCS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *DISCS.get_or_init(|| {
            has_avx512()
                && match Self::chosen() {
                    Self::Avx => false,
                    Self::Avx512 => true,
                    Self::Auto => !made_by_intel(),
                }
        })
    }

    /// Whether the eight-lane polygon kernel may run in AVX-512 (where the processor has it).
    pub fn polygons_in_avx512() -> bool {
        Self::chosen() != Self::Avx
    }

    /// What the kernels run in on this processor, for a run's report: the polygon kernel as
    /// the pair pass takes it ([`BlockKernel::best`]).
    ///
    /// [`BlockKernel::best`]: crate::geometry::intersection_lanes::BlockKernel::best
    pub fn describe() -> String {
        let Some(polygons) = crate::geometry::intersection_lanes::BlockKernel::best() else {
            return "no AVX: one pair at a time".to_string();
        };
        let discs = if Self::discs_in_avx512() {
            "AVX-512"
        } else {
            "AVX"
        };
        let chosen = match Self::chosen() {
            Self::Auto => "auto",
            Self::Avx => "avx",
            Self::Avx512 => "avx512",
        };
        format!(
            "pair loop and discs {discs}, polygons {} (SDEM_SIMD={chosen})",
            polygons.name()
        )
    }
}

fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::arch::is_x86_feature_detected!("avx512f");
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Whether the processor's maker is Intel (its CPUID vendor string).
fn made_by_intel() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        // SAFETY: CPUID leaf 0 exists on every x86-64 processor.
        #[allow(unused_unsafe)]
        let leaf = unsafe { std::arch::x86_64::__cpuid(0) };
        // "GenuineIntel" in EBX, EDX, ECX.
        [leaf.ebx, leaf.edx, leaf.ecx] == [0x756e_6547, 0x4965_6e69, 0x6c65_746e]
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Moving records into lanes and back with AVX registers.
#[cfg(target_arch = "x86_64")]
pub mod avx {
    use std::arch::x86_64::*;

    /// Rows to columns, four `f64`s each: `out[c][r] = rows[r][c]`. Four records of four words
    /// become four lanes of a field each, and back (eight shuffles).
    ///
    /// # Safety
    /// The processor must have AVX (call it from a function that enables it).
    #[inline(always)]
    pub unsafe fn transpose(rows: [__m256d; 4]) -> [__m256d; 4] {
        // SAFETY: the caller's processor has AVX.
        unsafe {
            let t0 = _mm256_unpacklo_pd(rows[0], rows[1]);
            let t1 = _mm256_unpackhi_pd(rows[0], rows[1]);
            let t2 = _mm256_unpacklo_pd(rows[2], rows[3]);
            let t3 = _mm256_unpackhi_pd(rows[2], rows[3]);
            [
                _mm256_permute2f128_pd(t0, t2, 0x20),
                _mm256_permute2f128_pd(t1, t3, 0x20),
                _mm256_permute2f128_pd(t0, t2, 0x31),
                _mm256_permute2f128_pd(t1, t3, 0x31),
            ]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_lane_gives_the_bits_of_its_scalar_operation() {
        // Expectation: the lanes are four scalar computations side by side, NaN and signed
        // zeros included (max and min of -0 and +0 too: lane 1).
        let a = [1.5, -0.0, f64::NAN, 3.0e-300];
        let b = [0.1, 0.0, 2.0, -7.25];
        let (x, y) = (Lanes(a), Lanes(b));
        let lanes = [
            (x + y).0,
            (x - y).0,
            (x * y).0,
            (x / y).0,
            (-x).0,
            x.sqrt().0,
            x.max(y).0,
            x.min(y).0,
            x.if_greater(y, x, y).0,
        ];
        for l in 0..4 {
            let scalar = [
                a[l] + b[l],
                a[l] - b[l],
                a[l] * b[l],
                a[l] / b[l],
                -a[l],
                a[l].sqrt(),
                Real::max(a[l], b[l]),
                Real::min(a[l], b[l]),
                Real::if_greater(a[l], b[l], a[l], b[l]),
            ];
            for (lane, one) in lanes.iter().zip(scalar) {
                // NaN payloads are not part of IEEE's results; a NaN must stay a NaN.
                let same = lane[l].to_bits() == one.to_bits() || (lane[l].is_nan() && one.is_nan());
                assert!(same, "lane {l}: {} against {one}", lane[l]);
            }
        }
    }
}
