//! Least-squares fit of the secant law's (a, b) on the relative force error.

use super::CompressionStep;

/// Fitted parameters and the overall quality.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SecantFit {
    pub a: f64,
    pub b: f64,
    /// RMS of `F_model/F - 1` over the points used.
    pub rms_relative_error: f64,
    pub points: usize,
}

impl SecantFit {
    /// Magnitude of the model force `E L_c |dn| / (a L_c + (b-1) dn)` (dn <= 0); infinite
    /// outside the law's domain.
    pub fn model_force(&self, lc: f64, dn: f64, young: f64) -> f64 {
        model_force(self.a, self.b, lc, dn, young)
    }
}

fn model_force(a: f64, b: f64, lc: f64, dn: f64, young: f64) -> f64 {
    let d = a * lc + (b - 1.0) * dn;
    if d > 0.0 {
        -young * lc * dn / d
    } else {
        f64::INFINITY
    }
}

/// A step with a contact and a force can be fitted.
pub(crate) fn usable(s: &CompressionStep) -> bool {
    s.force > 0.0 && s.contact_length > 0.0 && s.dn < 0.0
}

/// Minimises `sum (F_model/F - 1)^2` over (a, b): a weighted linear least-squares start
/// (`a L_c + (b-1) dn = E L_c |dn| / F` weighted by `F / (E L_c |dn|)`), then Levenberg–Marquardt.
pub fn fit_secant_law(steps: &[CompressionStep], young: f64) -> Result<SecantFit, String> {
    let pts: Vec<(f64, f64, f64)> = steps
        .iter()
        .filter(|s| usable(s))
        .map(|s| (s.contact_length, s.dn, s.force))
        .collect();
    if pts.len() < 2 {
        return Err(format!(
            "only {} load steps with a contact: nothing to fit",
            pts.len()
        ));
    }
    // Linear start: y = a lc + c dn, c = b - 1, weights 1/y.
    let (mut s11, mut s12, mut s22, mut r1, mut r2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(lc, dn, f) in &pts {
        let y = -young * lc * dn / f;
        let w = 1.0 / (y * y);
        s11 += w * lc * lc;
        s12 += w * lc * dn;
        s22 += w * dn * dn;
        r1 += w * lc * y;
        r2 += w * dn * y;
    }
    let det = s11 * s22 - s12 * s12;
    let (mut a, mut c) = if det.abs() > 1e-300 {
        ((r1 * s22 - r2 * s12) / det, (s11 * r2 - s12 * r1) / det)
    } else {
        (r1 / s11, 0.0)
    };
    let cost = |a: f64, c: f64| -> f64 {
        pts.iter()
            .map(|&(lc, dn, f)| (model_force(a, c + 1.0, lc, dn, young) / f - 1.0).powi(2))
            .sum()
    };
    if !cost(a, c).is_finite() {
        a = a.abs().max(0.1);
        c = 0.0;
    }
    let mut mu = 1e-3;
    let mut current = cost(a, c);
    for _ in 0..200 {
        let (mut j11, mut j12, mut j22, mut g1, mut g2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(lc, dn, f) in &pts {
            let d = a * lc + c * dn;
            let fm = -young * lc * dn / d;
            let r = fm / f - 1.0;
            let da = -(fm / f) * lc / d;
            let dc = -(fm / f) * dn / d;
            j11 += da * da;
            j12 += da * dc;
            j22 += dc * dc;
            g1 += da * r;
            g2 += dc * r;
        }
        let mut improved = false;
        for _ in 0..30 {
            let (m11, m22) = (j11 * (1.0 + mu), j22 * (1.0 + mu));
            let det = m11 * m22 - j12 * j12;
            let step_a = -(m22 * g1 - j12 * g2) / det;
            let step_c = -(m11 * g2 - j12 * g1) / det;
            let trial = cost(a + step_a, c + step_c);
            if trial.is_finite() && trial < current {
                a += step_a;
                c += step_c;
                let done = current - trial < 1e-15 * current.max(1e-300);
                current = trial;
                mu = (mu * 0.3).max(1e-12);
                improved = !done;
                break;
            }
            mu *= 10.0;
        }
        if !improved {
            break;
        }
    }
    if !(a.is_finite() && c.is_finite() && current.is_finite()) {
        return Err("the least-squares fit diverged".into());
    }
    Ok(SecantFit {
        a,
        b: c + 1.0,
        rms_relative_error: (current / pts.len() as f64).sqrt(),
        points: pts.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_the_parameters_of_exact_data() {
        let (a, b) = (0.58, 2.0);
        let steps: Vec<CompressionStep> = (1..20)
            .map(|k| {
                let lc = 0.03 * k as f64;
                let dn = -0.4 * lc * lc;
                CompressionStep {
                    nu: 0.3,
                    h: 0.5,
                    force: model_force(a, b, lc, dn, 1.0),
                    contact_length: lc,
                    dn,
                    active_nodes: 3.0,
                    newton_iterations: 0,
                    augmentations: 0,
                }
            })
            .collect();
        let fit = fit_secant_law(&steps, 1.0).unwrap();
        assert!(
            (fit.a - a).abs() < 1e-8 && (fit.b - b).abs() < 1e-6,
            "{fit:?}"
        );
        assert!(fit.rms_relative_error < 1e-10);
    }
}
