//! Elementary functions that give the same bits on every machine.
//!
//! `f64::ln`, `f64::exp` and friends in `std` call the platform's C math library, whose last-bit
//! rounding differs between platforms (glibc, musl, macOS, MSVC), and within glibc between
//! processors (it runs FMA variants where the processor has FMA). Sample generation promises
//! bitwise-identical output for the same spec and seed on every machine, and the meshfree solver
//! the same run on every machine, so the transcendental functions they call are computed here
//! with plain IEEE-754 arithmetic only (`+ - * /` and `sqrt`, which are correctly rounded
//! everywhere; Rust never fuses them into FMAs). Sines, cosines and arc tangents are in
//! [`angle`](crate::geometry::angle).
//!
//! `ln`, `exp` and `erfc` are ports of the FreeBSD msun / fdlibm routines (as carried by musl and
//! the `libm` crate); they are accurate to better than 1 ulp (`erfc`: a few ulp). `hypot` is the
//! `libm` crate's.
//!
//! ====================================================
//! Copyright (C) 1993, 2004 by Sun Microsystems, Inc. All rights reserved.
//!
//! Developed at SunPro, a Sun Microsystems, Inc. business.
//! Permission to use, copy, modify, and distribute this
//! software is freely granted, provided that this notice
//! is preserved.
//! ====================================================

// The constants are kept digit for digit as in fdlibm, so that they can be checked against it.
#![allow(clippy::excessive_precision)]

/// 1 / sqrt(2).
pub(crate) const FRAC_1_SQRT_2: f64 = std::f64::consts::FRAC_1_SQRT_2;
/// 1 / sqrt(2 pi).
pub(crate) const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

#[inline]
fn high_word(x: f64) -> u32 {
    (x.to_bits() >> 32) as u32
}

#[inline]
fn with_low_word_zero(x: f64) -> f64 {
    f64::from_bits(x.to_bits() & 0xffff_ffff_0000_0000)
}

/// `x * 2^n` (musl `scalbn`).
fn scalbn(x: f64, mut n: i32) -> f64 {
    let x1p1023 = f64::from_bits(0x7fe0_0000_0000_0000); // 2^1023
    let x1p53 = f64::from_bits(0x4340_0000_0000_0000); // 2^53
    let x1p_1022 = f64::from_bits(0x0010_0000_0000_0000); // 2^-1022
    let mut y = x;
    if n > 1023 {
        y *= x1p1023;
        n -= 1023;
        if n > 1023 {
            y *= x1p1023;
            n -= 1023;
            if n > 1023 {
                n = 1023;
            }
        }
    } else if n < -1022 {
        // keep the final n < -53 to avoid double rounding in the subnormal range
        y *= x1p_1022 * x1p53;
        n += 1022 - 53;
        if n < -1022 {
            y *= x1p_1022 * x1p53;
            n += 1022 - 53;
            if n < -1022 {
                n = -1022;
            }
        }
    }
    y * f64::from_bits(((0x3ff + n) as u64) << 52)
}

const LN2_HI: f64 = 6.931_471_803_691_238_164_90e-01; // 3fe62e42 fee00000
const LN2_LO: f64 = 1.908_214_929_270_587_700_02e-10; // 3dea39ef 35793c76

/// Natural logarithm (fdlibm `e_log.c`), error < 1 ulp.
pub(crate) fn ln(mut x: f64) -> f64 {
    const LG1: f64 = 6.666_666_666_666_735_130e-01;
    const LG2: f64 = 3.999_999_999_940_941_908e-01;
    const LG3: f64 = 2.857_142_874_366_239_149e-01;
    const LG4: f64 = 2.222_219_843_214_978_396e-01;
    const LG5: f64 = 1.818_357_216_161_805_012e-01;
    const LG6: f64 = 1.531_383_769_920_937_332e-01;
    const LG7: f64 = 1.479_819_860_511_658_591e-01;
    let x1p54 = f64::from_bits(0x4350_0000_0000_0000);

    let mut ui = x.to_bits();
    let mut hx = (ui >> 32) as u32;
    let mut k: i32 = 0;
    if hx < 0x0010_0000 || (hx >> 31) != 0 {
        if ui << 1 == 0 {
            return f64::NEG_INFINITY; // ln(+-0)
        }
        if hx >> 31 != 0 {
            return f64::NAN; // ln(negative)
        }
        // subnormal: scale up
        k -= 54;
        x *= x1p54;
        ui = x.to_bits();
        hx = (ui >> 32) as u32;
    } else if hx >= 0x7ff0_0000 {
        return x; // inf or nan
    } else if hx == 0x3ff0_0000 && ui << 32 == 0 {
        return 0.0;
    }

    // reduce x into [sqrt(2)/2, sqrt(2)]
    hx += 0x3ff0_0000 - 0x3fe6_a09e;
    k += ((hx >> 20) as i32) - 0x3ff;
    hx = (hx & 0x000f_ffff) + 0x3fe6_a09e;
    ui = ((hx as u64) << 32) | (ui & 0xffff_ffff);
    x = f64::from_bits(ui);

    let f = x - 1.0;
    let hfsq = 0.5 * f * f;
    let s = f / (2.0 + f);
    let z = s * s;
    let w = z * z;
    let t1 = w * (LG2 + w * (LG4 + w * LG6));
    let t2 = z * (LG1 + w * (LG3 + w * (LG5 + w * LG7)));
    let r = t2 + t1;
    let dk = k as f64;
    s * (hfsq + r) + dk * LN2_LO - hfsq + f + dk * LN2_HI
}

/// Exponential (fdlibm `e_exp.c`), error < 1 ulp.
pub(crate) fn exp(mut x: f64) -> f64 {
    const INVLN2: f64 = std::f64::consts::LOG2_E; // 0x3ff71547 652b82fe
    const P1: f64 = 1.666_666_666_666_660_190_37e-01;
    const P2: f64 = -2.777_777_777_701_559_338_42e-03;
    const P3: f64 = 6.613_756_321_437_934_361_17e-05;
    const P4: f64 = -1.653_390_220_546_525_153_90e-06;
    const P5: f64 = 4.138_136_797_057_238_460_39e-08;

    let mut hx = high_word(x);
    let sign = (hx >> 31) as i32;
    hx &= 0x7fff_ffff;

    if hx >= 0x4086_232b {
        // |x| >= 708.39 or nan
        if x.is_nan() {
            return x;
        }
        if x > 709.782_712_893_383_973_096 {
            return f64::INFINITY;
        }
        if x < -745.133_219_101_941_108_42 {
            return 0.0;
        }
    }

    let hi: f64;
    let lo: f64;
    let k: i32;
    if hx > 0x3fd6_2e42 {
        // |x| > 0.5 ln2
        if hx >= 0x3ff0_a2b2 {
            // |x| >= 1.5 ln2
            let half = if sign == 0 { 0.5 } else { -0.5 };
            k = (INVLN2 * x + half) as i32;
        } else {
            k = 1 - sign - sign;
        }
        hi = x - k as f64 * LN2_HI; // exact
        lo = k as f64 * LN2_LO;
        x = hi - lo;
    } else if hx > 0x3e30_0000 {
        // |x| > 2^-28
        k = 0;
        hi = x;
        lo = 0.0;
    } else {
        return 1.0 + x;
    }

    let xx = x * x;
    let c = x - xx * (P1 + xx * (P2 + xx * (P3 + xx * (P4 + xx * P5))));
    let y = 1.0 + (x * c / (2.0 - c) - lo + hi);
    if k == 0 { y } else { scalbn(y, k) }
}

/// `(e^z - 1) / z`, accurate also for small `|z|` (equals 1 at z = 0).
pub(crate) fn exprel(z: f64) -> f64 {
    if z.abs() < 1e-2 {
        // Taylor series; the first omitted term z^6/5040 is < 3e-16 relative.
        1.0 + z
            * (1.0 / 2.0
                + z * (1.0 / 6.0 + z * (1.0 / 24.0 + z * (1.0 / 120.0 + z * (1.0 / 720.0)))))
    } else {
        (exp(z) - 1.0) / z
    }
}

/// `x^y` for `x > 0`, as `exp(y ln x)` (relative error about `|y ln x|` ulp).
pub(crate) fn powf(x: f64, y: f64) -> f64 {
    exp(y * ln(x))
}

/// `sqrt(x^2 + y^2)` without undue overflow or underflow (the `libm` crate's).
pub(crate) fn hypot(x: f64, y: f64) -> f64 {
    libm::hypot(x, y)
}

/// Complementary error function (fdlibm `s_erf.c`), relative error of a few ulp over the
/// whole range (including the far tail, where it underflows gracefully to 0 beyond x ~ 27).
pub(crate) fn erfc(x: f64) -> f64 {
    const ERX: f64 = 8.450_629_115_104_675_292_97e-01;
    const PP0: f64 = 1.283_791_670_955_125_585_61e-01;
    const PP1: f64 = -3.250_421_072_470_014_993_70e-01;
    const PP2: f64 = -2.848_174_957_559_851_047_66e-02;
    const PP3: f64 = -5.770_270_296_489_441_591_57e-03;
    const PP4: f64 = -2.376_301_665_665_016_260_84e-05;
    const QQ1: f64 = 3.979_172_239_591_553_528_19e-01;
    const QQ2: f64 = 6.502_224_998_876_729_444_85e-02;
    const QQ3: f64 = 5.081_306_281_875_765_627_76e-03;
    const QQ4: f64 = 1.324_947_380_043_216_445_26e-04;
    const QQ5: f64 = -3.960_228_278_775_368_123_20e-06;
    const PA0: f64 = -2.362_118_560_752_659_440_77e-03;
    const PA1: f64 = 4.148_561_186_837_483_316_66e-01;
    const PA2: f64 = -3.722_078_760_357_013_238_47e-01;
    const PA3: f64 = 3.183_466_199_011_617_536_74e-01;
    const PA4: f64 = -1.108_946_942_823_966_774_76e-01;
    const PA5: f64 = 3.547_830_432_561_823_593_71e-02;
    const PA6: f64 = -2.166_375_594_868_790_843_00e-03;
    const QA1: f64 = 1.064_208_804_008_442_282_86e-01;
    const QA2: f64 = 5.403_979_177_021_710_489_37e-01;
    const QA3: f64 = 7.182_865_441_419_626_628_68e-02;
    const QA4: f64 = 1.261_712_198_087_616_421_12e-01;
    const QA5: f64 = 1.363_708_391_202_905_073_62e-02;
    const QA6: f64 = 1.198_449_984_679_910_741_70e-02;
    const RA0: f64 = -9.864_944_034_847_148_227_05e-03;
    const RA1: f64 = -6.938_585_727_071_817_643_72e-01;
    const RA2: f64 = -1.055_862_622_532_329_098_14e+01;
    const RA3: f64 = -6.237_533_245_032_600_603_96e+01;
    const RA4: f64 = -1.623_966_694_625_734_703_55e+02;
    const RA5: f64 = -1.846_050_929_067_110_359_94e+02;
    const RA6: f64 = -8.128_743_550_630_659_342_46e+01;
    const RA7: f64 = -9.814_329_344_169_145_485_92e+00;
    const SA1: f64 = 1.965_127_166_743_925_712_92e+01;
    const SA2: f64 = 1.376_577_541_435_190_426_00e+02;
    const SA3: f64 = 4.345_658_774_752_292_288_21e+02;
    const SA4: f64 = 6.453_872_717_332_678_803_36e+02;
    const SA5: f64 = 4.290_081_400_275_678_333_86e+02;
    const SA6: f64 = 1.086_350_055_417_794_351_34e+02;
    const SA7: f64 = 6.570_249_770_319_281_701_35e+00;
    const SA8: f64 = -6.042_441_521_485_809_874_38e-02;
    const RB0: f64 = -9.864_942_924_700_099_285_97e-03;
    const RB1: f64 = -7.992_832_376_805_230_065_74e-01;
    const RB2: f64 = -1.775_795_491_775_475_198_89e+01;
    const RB3: f64 = -1.606_363_848_558_219_160_62e+02;
    const RB4: f64 = -6.375_664_433_683_896_277_22e+02;
    const RB5: f64 = -1.025_095_131_611_077_249_54e+03;
    const RB6: f64 = -4.835_191_916_086_513_970_19e+02;
    const SB1: f64 = 3.033_806_074_348_245_829_24e+01;
    const SB2: f64 = 3.257_925_129_965_739_188_26e+02;
    const SB3: f64 = 1.536_729_586_084_436_959_94e+03;
    const SB4: f64 = 3.199_858_219_508_595_539_08e+03;
    const SB5: f64 = 2.553_050_406_433_164_425_83e+03;
    const SB6: f64 = 4.745_285_412_069_553_672_15e+02;
    const SB7: f64 = -2.244_095_244_658_581_833_62e+01;

    let mut ix = high_word(x);
    let negative = (ix >> 31) != 0;
    ix &= 0x7fff_ffff;
    if ix >= 0x7ff0_0000 {
        // erfc(nan) = nan, erfc(+inf) = 0, erfc(-inf) = 2
        if x.is_nan() {
            return x;
        }
        return if negative { 2.0 } else { 0.0 };
    }
    if ix < 0x3feb_0000 {
        // |x| < 0.84375
        if ix < 0x3c70_0000 {
            return 1.0 - x;
        }
        let z = x * x;
        let r = PP0 + z * (PP1 + z * (PP2 + z * (PP3 + z * PP4)));
        let s = 1.0 + z * (QQ1 + z * (QQ2 + z * (QQ3 + z * (QQ4 + z * QQ5))));
        let y = r / s;
        if negative || ix < 0x3fd0_0000 {
            return 1.0 - (x + x * y);
        }
        return 0.5 - (x - 0.5 + x * y);
    }
    if ix >= 0x403c_0000 {
        // |x| >= 28
        return if negative { 2.0 } else { 0.0 };
    }
    let tail = if ix < 0x3ff4_0000 {
        // 0.84375 <= |x| < 1.25
        let s = x.abs() - 1.0;
        let p = PA0 + s * (PA1 + s * (PA2 + s * (PA3 + s * (PA4 + s * (PA5 + s * PA6)))));
        let q = 1.0 + s * (QA1 + s * (QA2 + s * (QA3 + s * (QA4 + s * (QA5 + s * QA6)))));
        1.0 - ERX - p / q
    } else {
        let ax = x.abs();
        let s = 1.0 / (ax * ax);
        let (r, big_s) = if ix < 0x4006_db6d {
            // |x| < 1/0.35
            (
                RA0 + s
                    * (RA1 + s * (RA2 + s * (RA3 + s * (RA4 + s * (RA5 + s * (RA6 + s * RA7)))))),
                1.0 + s
                    * (SA1
                        + s * (SA2
                            + s * (SA3 + s * (SA4 + s * (SA5 + s * (SA6 + s * (SA7 + s * SA8))))))),
            )
        } else {
            (
                RB0 + s * (RB1 + s * (RB2 + s * (RB3 + s * (RB4 + s * (RB5 + s * RB6))))),
                1.0 + s
                    * (SB1 + s * (SB2 + s * (SB3 + s * (SB4 + s * (SB5 + s * (SB6 + s * SB7)))))),
            )
        };
        let z = with_low_word_zero(ax);
        exp(-z * z - 0.5625) * exp((z - ax) * (z + ax) + r / big_s) / ax
    };
    if negative { 2.0 - tail } else { tail }
}

/// Standard normal density phi(z).
pub(crate) fn normal_pdf(z: f64) -> f64 {
    FRAC_1_SQRT_2PI * exp(-0.5 * z * z)
}

/// Probability mass of the standard normal distribution on [a, b] (a <= b), computed from the
/// tail on the side where the interval lies so that far-tail intervals keep full relative
/// accuracy (no `1 - 1` cancellation).
pub(crate) fn normal_mass(a: f64, b: f64) -> f64 {
    if a >= 0.0 {
        // upper tail: Q(a) - Q(b), Q(t) = erfc(t / sqrt 2) / 2
        0.5 * (erfc(a * FRAC_1_SQRT_2) - erfc(b * FRAC_1_SQRT_2))
    } else if b <= 0.0 {
        0.5 * (erfc(-b * FRAC_1_SQRT_2) - erfc(-a * FRAC_1_SQRT_2))
    } else {
        1.0 - 0.5 * (erfc(-a * FRAC_1_SQRT_2) + erfc(b * FRAC_1_SQRT_2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hypot_and_powf_agree_with_the_platforms() {
        // Expectation: the platform's functions (within half an ulp or so of the exact values),
        // to an ulp or two for `hypot`, and to powf's own bound of about |y ln x| ulp.
        for k in 0..2000 {
            let (x, y) = (-20.0 + 0.02 * k as f64 + 1e-3, 1e-3 + 0.05 * k as f64);
            let h = x.hypot(y);
            assert!(
                (hypot(x, y) - h).abs() <= 2.0 * f64::EPSILON * h,
                "hypot({x}, {y})"
            );
            for e in [2.0 / 3.0, 1.5, -0.7] {
                let p = y.powf(e);
                let bound = (2.0 + (e * y.ln()).abs()) * f64::EPSILON * p;
                assert!((powf(y, e) - p).abs() <= bound, "powf({y}, {e})");
            }
        }
    }
}
