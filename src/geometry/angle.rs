//! Sines, cosines and arc tangents that give the same bits on every machine.
//!
//! The platform's libm picks among variants of its functions at run time: glibc on x86-64 runs
//! `sin`, `cos`, `sincos` and `atan2` compiled with FMA where the processor has FMA, and without
//! it elsewhere, and the two differ in the last bit for some arguments. A run's bits then
//! depended on the processor: `sdem run scenarios/isotropic_A.ron` ended at p_c = 1.0288e-1,
//! and at 1.0238e-1 with glibc's FMA variants turned off
//! (`GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA`). The simulation calls these instead: the
//! `libm` crate's pure-Rust functions, the same operations on every machine (Rust never fuses
//! a multiply and an add on its own).

use crate::lanes::Lanes;
use glam::{DMat2, DVec2};

/// `(sin x, cos x)`.
#[inline]
pub fn sin_cos(x: f64) -> (f64, f64) {
    libm::sincos(x)
}

#[inline]
pub fn sin(x: f64) -> f64 {
    libm::sin(x)
}

#[inline]
pub fn cos(x: f64) -> f64 {
    libm::cos(x)
}

/// `(sin x, cos x)` of every lane: [`sin_cos`]'s bits, lane by lane, with no branch that
/// depends on a lane on the common path, so that the lanes are computed side by side in vector
/// registers (issue #16: the grain pass needs theta's and alpha's of every deforming grain).
///
/// The operations are `libm`'s (musl's `sincos`, from FreeBSD's msun): the reduction
/// `y = x - k pi/2` into `y0 + y1` with pi/2 split as `PIO2_1 + PIO2_1T`, the kernels `k_sin`
/// and `k_cos` on `[-pi/4, pi/4]`, and the quadrant `k mod 4`. `libm` picks `k` by ranges of
/// the high word of `|x|`: no reduction below pi/4, `k` = 1 to 4 up to 9 pi/4 (each range with
/// its own constants, equal to `k PIO2_1` and `k PIO2_1T`), `rint(x 2/pi)` beyond. Here the
/// ranges are comparisons of `|x|` with the same bounds, and a lane that `libm` may send down
/// another path (a second round of reduction, `|x|` from 2^20 pi/2, infinities and NaN) is
/// computed by `libm`'s `sincos` itself; under 2^-27 `libm` returns `(x, 1)`, and so do the
/// lanes. (Near pi/2, pi, 3 pi/2 and 2 pi libm's
/// ranges take its general reduction, whose `k` there is the range's and whose first round is
/// the same arithmetic: only its second round differs, and such lanes go to libm.)
#[inline(always)]
pub fn sin_cos_lanes<const N: usize>(x: &Lanes<N>) -> (Lanes<N>, Lanes<N>) {
    // libm's constants (rem_pio2.rs, k_sin.rs, k_cos.rs), by their bits.
    const TO_INT: f64 = 1.5 / f64::EPSILON;
    const INV_PIO2: f64 = f64::from_bits(0x3fe4_5f30_6dc9_c883);
    const PIO2_1: f64 = f64::from_bits(0x3ff9_21fb_5440_0000);
    const PIO2_1T: f64 = f64::from_bits(0x3dd0_b461_1a62_6331);
    const S1: f64 = f64::from_bits(0xbfc5_5555_5555_5549);
    const S2: f64 = f64::from_bits(0x3f81_1111_1110_f8a6);
    const S3: f64 = f64::from_bits(0xbf2a_01a0_19c1_61d5);
    const S4: f64 = f64::from_bits(0x3ec7_1de3_57b1_fe7d);
    const S5: f64 = f64::from_bits(0xbe5a_e5e6_8a2b_9ceb);
    const S6: f64 = f64::from_bits(0x3de5_d93a_5acf_d57c);
    const C1: f64 = f64::from_bits(0x3fa5_5555_5555_554c);
    const C2: f64 = f64::from_bits(0xbf56_c16c_16c1_5177);
    const C3: f64 = f64::from_bits(0x3efa_01a0_19cb_1590);
    const C4: f64 = f64::from_bits(0xbe92_7e4f_809c_52ad);
    const C5: f64 = f64::from_bits(0x3e21_ee9e_bdb4_b1c4);
    const C6: f64 = f64::from_bits(0xbda8_fae9_be88_38d4);
    // The smallest |x| whose high word is `high`: libm's `ix <= high` is `|x| < at(high + 1)`.
    const fn at(high: u64) -> f64 {
        f64::from_bits(high << 32)
    }
    const TINY: f64 = at(0x3e46_a09e);
    // Where the ranges with k = 1, 2, 3, 4 start, and where the last one ends.
    const K_STARTS: [f64; 4] = [
        at(0x3fe9_21fc),
        at(0x4002_d97d),
        at(0x400f_6a7b),
        at(0x4015_fdbd),
    ];
    const FIXED_END: f64 = at(0x401c_463c);
    const MEDIUM_END: f64 = at(0x4139_21fb);
    const EXPONENT: u64 = 0x7ff0_0000_0000_0000;
    // 2^-16: a power of two's exponent moved down by 16.
    const TWO_TO_MINUS_16: f64 = 1.0 / 65536.0;

    let (mut sin, mut cos) = (Lanes([0.0; N]), Lanes([0.0; N]));
    // 1 in the lanes that libm computes (a float, so that the test of all lanes is one vector
    // comparison).
    let mut elsewhere = Lanes([0.0; N]);
    for lane in 0..N {
        let x = x.0[lane];
        let magnitude = x.abs();
        let one_if = |condition: bool| if condition { 1.0 } else { 0.0 };
        let steps = one_if(magnitude >= K_STARTS[0])
            + one_if(magnitude >= K_STARTS[1])
            + one_if(magnitude >= K_STARTS[2])
            + one_if(magnitude >= K_STARTS[3]);
        let fixed = if x < 0.0 { -steps } else { steps };
        let rounded = (x * INV_PIO2 + TO_INT) - TO_INT;
        let k = if magnitude < FIXED_END {
            fixed
        } else {
            rounded
        };
        let head = x - k * PIO2_1;
        let tail = k * PIO2_1T;
        let y0 = head - tail;
        let y1 = (head - y0) - tail;
        // libm's second round of reduction, where y0's exponent is more than 16 under x's.
        let power_of_x = f64::from_bits(x.to_bits() & EXPONENT);
        let second_round = y0.abs() < power_of_x * TWO_TO_MINUS_16;
        // (A NaN is in no range.) Under 2^-27 libm returns (x, 1): a select below, not a
        // call, for a grain's alpha is exactly 0 until its strains part.
        let tiny = magnitude < TINY;
        let in_range = magnitude < MEDIUM_END;
        let off_path = !in_range | second_round;
        elsewhere.0[lane] = if off_path { 1.0 } else { 0.0 };

        let z = y0 * y0;
        let w = z * z;
        let r = S2 + z * (S3 + z * S4) + z * w * (S5 + z * S6);
        let v = z * y0;
        // Below pi/4 libm calls k_sin(x, 0, 0); after a reduction, k_sin(y0, y1, 1).
        let s = if steps == 0.0 {
            y0 + v * (S1 + z * r)
        } else {
            y0 - ((z * (0.5 * y1 - v * r) - y1) - v * S1)
        };
        let r = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6));
        let hz = 0.5 * z;
        let one_minus_hz = 1.0 - hz;
        let c = one_minus_hz + (((1.0 - one_minus_hz) - hz) + (z * r - y0 * y1));

        // The quadrant k mod 4 (k is a whole number under 2^20: these are exact).
        let quadrant = k - 4.0 * (k * 0.25).floor();
        let half = (quadrant * 0.5).floor();
        let odd = quadrant - 2.0 * half == 1.0;
        let (s, c) = if odd { (c, -s) } else { (s, c) };
        let (s, c) = if half == 1.0 { (-s, -c) } else { (s, c) };
        let (s, c) = if tiny { (x, 1.0) } else { (s, c) };
        sin.0[lane] = s;
        cos.0[lane] = c;
    }
    if elsewhere.0.iter().fold(0.0, |any, &e| any + e) != 0.0 {
        for lane in 0..N {
            if elsewhere.0[lane] != 0.0 {
                (sin.0[lane], cos.0[lane]) = sin_cos(x.0[lane]);
            }
        }
    }
    (sin, cos)
}

/// The angle of the point (x, y), in (-pi, pi].
#[inline]
pub fn atan2(y: f64, x: f64) -> f64 {
    libm::atan2(y, x)
}

/// The unit vector at `angle` (what glam's `DVec2::from_angle` builds).
#[inline]
pub fn unit_vector(angle: f64) -> DVec2 {
    let (s, c) = sin_cos(angle);
    DVec2::new(c, s)
}

/// The rotation by `angle` (what glam's `DMat2::from_angle` builds).
#[inline]
pub fn rotation_by(angle: f64) -> DMat2 {
    let (s, c) = sin_cos(angle);
    super::contour::rotation(s, c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn sin_cos_lanes_avx(x: &Lanes<4>) -> (Lanes<4>, Lanes<4>) {
        sin_cos_lanes(x)
    }

    #[test]
    fn sin_cos_lanes_gives_sin_cos_bits_in_every_lane() {
        // Expectation: libm's sincos, bit for bit, whatever the lane and its neighbours: over
        // the angles grains take, around every bound of libm's ranges and every multiple of
        // pi/4 (where the reduction cancels), and at the values libm treats apart.
        let mut values = vec![
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            -5e-324,
            1e-9,
            -1e-9,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MAX,
            1e300,
            -4e6,
        ];
        let mut unit = super::super::intersection::tests::unit_randoms(17);
        for scale in [1.0, 8.0, 30.0, 1e3, 1e6, 2e6] {
            for _ in 0..20_000 {
                values.push(scale * (2.0 * unit() - 1.0));
            }
        }
        let ulps =
            |x: f64| (-4..=4).map(move |d: i64| f64::from_bits((x.to_bits() as i64 + d) as u64));
        let bounds = [
            0x3e46_a09e_u64,
            0x3fe9_21fb,
            0x3fe9_21fc,
            0x4002_d97c,
            0x4002_d97d,
            0x400f_6a7a,
            0x400f_6a7b,
            0x4015_fdbc,
            0x4015_fdbd,
            0x401c_463b,
            0x401c_463c,
            0x4139_21fb,
            0x3ff9_21fb,
            0x4009_21fb,
            0x4012_d97c,
            0x4019_21fb,
        ];
        for high in bounds {
            for low in [0, 1, 0x5440_0000, 0xffff_ffff] {
                for x in ulps(f64::from_bits(high << 32 | low)) {
                    values.extend([x, -x]);
                }
            }
        }
        for m in 1..4000 {
            let x = m as f64 * std::f64::consts::FRAC_PI_4;
            values.extend(ulps(x).flat_map(|x| [x, -x]));
        }
        let check = |x: f64, (s, c): (f64, f64)| {
            let (expected_s, expected_c) = sin_cos(x);
            assert_eq!(
                (s.to_bits(), c.to_bits()),
                (expected_s.to_bits(), expected_c.to_bits()),
                "x = {x:e} ({:#018x})",
                x.to_bits()
            );
        };
        let check_lanes = |x: &Lanes<4>, (s, c): (Lanes<4>, Lanes<4>)| {
            for (lane, &x) in x.0.iter().enumerate() {
                check(x, (s.0[lane], c.0[lane]));
            }
        };
        for lanes in values.chunks_exact(4) {
            let x = Lanes([lanes[0], lanes[1], lanes[2], lanes[3]]);
            check_lanes(&x, sin_cos_lanes(&x));
            // The same lanes compiled for AVX, as the grain pass runs them where it can.
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx") {
                // SAFETY: the processor has AVX (tested just above).
                check_lanes(&x, unsafe { sin_cos_lanes_avx(&x) });
            }
        }
        for (k, &x) in values.iter().enumerate() {
            let (s, c) = sin_cos_lanes(&Lanes([x, values[(k * 7919) % values.len()]]));
            let (s, c) = (s.0, c.0);
            check(x, (s[0], c[0]));
            let (s, c) = sin_cos_lanes(&Lanes([x]));
            let (s, c) = (s.0, c.0);
            check(x, (s[0], c[0]));
        }
    }

    #[test]
    fn the_portable_functions_agree_with_the_platforms_to_an_ulp() {
        // Expectation: the same functions as the platform's (which are within an ulp of the
        // exact values), within an ulp or two, over the angles a grain takes.
        let close =
            |a: f64, b: f64| (a - b).abs() <= 2.0 * f64::EPSILON * a.abs().max(b.abs()).max(1e-300);
        for k in -4000..=4000 {
            let x = k as f64 * 0.00917 + 1e-3;
            let (s, c) = sin_cos(x);
            assert!(close(s, x.sin()) && close(c, x.cos()), "{x}");
            assert!(close(sin(x), x.sin()) && close(cos(x), x.cos()), "{x}");
            let (y, z) = (x.sin() * 3.0, x.cos() * 0.5);
            assert!(close(atan2(y, z), y.atan2(z)), "{x}");
            assert_eq!(unit_vector(x), DVec2::new(c, s));
            assert_eq!(rotation_by(x) * DVec2::X, DVec2::new(c, s));
        }
    }
}
