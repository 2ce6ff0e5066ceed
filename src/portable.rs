//! Exponentials, logarithms, powers and hypotenuses that give the same bits on every machine.
//!
//! `f64::exp`, `f64::ln`, `f64::powf` and `f64::hypot` call the platform's C library, whose
//! results differ in the last bit from one library to another, and within glibc from one
//! processor to another (it runs FMA variants where the processor has FMA). These are the
//! `libm` crate's pure-Rust functions: the same operations everywhere, as the sines, cosines
//! and arc tangents of [`angle`](crate::geometry::angle).

#[inline]
pub fn exp(x: f64) -> f64 {
    libm::exp(x)
}

/// The natural logarithm.
#[inline]
pub fn ln(x: f64) -> f64 {
    libm::log(x)
}

/// `x` to the power `y`.
#[inline]
pub fn powf(x: f64, y: f64) -> f64 {
    libm::pow(x, y)
}

/// `sqrt(x^2 + y^2)` without undue overflow or underflow.
#[inline]
pub fn hypot(x: f64, y: f64) -> f64 {
    libm::hypot(x, y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_portable_functions_agree_with_the_platforms_to_an_ulp() {
        // Expectation: the same functions as the platform's, within an ulp (each is within
        // half an ulp or so of the exact value).
        let close =
            |a: f64, b: f64| (a - b).abs() <= 2.0 * f64::EPSILON * b.abs().max(f64::MIN_POSITIVE);
        for k in 0..2000 {
            let x = -20.0 + 0.02 * k as f64 + 1e-3;
            assert!(close(exp(x), x.exp()), "exp({x})");
            let y = 1e-3 + 0.05 * k as f64;
            assert!(close(ln(y), y.ln()), "ln({y})");
            assert!(close(powf(y, 2.0 / 3.0), y.powf(2.0 / 3.0)), "pow({y})");
            assert!(close(hypot(x, y), x.hypot(y)), "hypot({x}, {y})");
        }
    }
}
