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
