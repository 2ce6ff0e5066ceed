//! The analytic reference of incompressible-grain compaction (Cantor et al. 2020; SDEM paper
//! eq. 69; SPEC §8), compression positive:
//!
//! `p(phi) = -E (b phi / 2 pi) (Z0 + k (phi - phi0)^a) ln((phimax - phi) / (phimax - phi0))`

use std::f64::consts::PI;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CantorReference {
    pub phi0: f64,
    pub z0: f64,
    pub k: f64,
    pub a: f64,
    pub b: f64,
    pub phi_max: f64,
}

impl CantorReference {
    /// The paper's constants k = 5.1, a = 0.5, b = 0.12, phimax = 1 with a jamming point.
    pub fn new(phi0: f64, z0: f64) -> Self {
        Self {
            phi0,
            z0,
            k: 5.1,
            a: 0.5,
            b: 0.12,
            phi_max: 1.0,
        }
    }

    /// Mean stress (compression positive) at packing fraction `phi` (>= phi0).
    pub fn mean_stress(&self, phi: f64, young: f64) -> f64 {
        let excess = (phi - self.phi0).max(0.0);
        -young
            * (self.b * phi / (2.0 * PI))
            * (self.z0 + self.k * excess.powf(self.a))
            * ((self.phi_max - phi) / (self.phi_max - self.phi0)).ln()
    }

    /// Root-mean-square relative error of measured (phi, p) points against the reference, over
    /// the points with phi in `[phi_low, phi_high]`; `None` when no point falls there.
    pub fn rms_relative_error(
        &self,
        points: &[(f64, f64)],
        young: f64,
        phi_low: f64,
        phi_high: f64,
    ) -> Option<(f64, usize)> {
        let errors: Vec<f64> = points
            .iter()
            .filter(|(phi, _)| *phi >= phi_low && *phi <= phi_high)
            .map(|&(phi, p)| {
                let expected = self.mean_stress(phi, young);
                (p - expected) / expected
            })
            .collect();
        if errors.is_empty() {
            return None;
        }
        let mean_square = errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64;
        Some((mean_square.sqrt(), errors.len()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vanishes_at_jamming_and_grows_logarithmically_to_phimax() {
        let r = CantorReference::new(0.833, 4.2);
        assert_eq!(r.mean_stress(0.833, 1.0), 0.0);
        // Hand value: phi = 0.95, A: 0.12*0.95/2pi * (4.2 + 5.1 sqrt(0.117)) * -ln(0.05/0.167).
        let expected =
            0.12 * 0.95 / (2.0 * PI) * (4.2 + 5.1 * 0.117f64.sqrt()) * -(0.05f64 / 0.167).ln();
        assert!((r.mean_stress(0.95, 1.0) - expected).abs() < 1e-12);
        assert!(r.mean_stress(0.999, 1.0) > r.mean_stress(0.95, 1.0));
    }

    #[test]
    fn rms_of_the_reference_itself_is_zero() {
        let r = CantorReference::new(0.85, 4.0);
        let pts: Vec<(f64, f64)> = (0..20)
            .map(|k| 0.86 + 0.005 * k as f64)
            .map(|phi| (phi, r.mean_stress(phi, 2.0)))
            .collect();
        let (rms, n) = r.rms_relative_error(&pts, 2.0, 0.86, 0.95).unwrap();
        assert!(rms < 1e-14 && n == 19);
    }
}
