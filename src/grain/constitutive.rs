//! Linear constitutive laws on finite principal strains (paper eq. 39–46, 65–68).
//!
//! Stress and strain are tension positive. `lost_fraction` is the area a grain loses to its
//! contacts, `sum_j S_j`, divided by its reference area `pi R^2`.

use crate::lanes::Real;
use serde::{Deserialize, Serialize};

/// Elastic, isotropic grain material.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Young's modulus E (> 0).
    pub young: f64,
    /// Poisson's ratio nu, in [0, 0.5]; exactly 0.5 selects the incompressible law of SPEC §6.
    pub poisson: f64,
    /// Mass density rho (> 0), mass per unit area in 2D.
    pub density: f64,
}

impl Material {
    pub fn shear_modulus(&self) -> f64 {
        self.young / (2.0 * (1.0 + self.poisson))
    }

    /// `kappa = E / (3 - 6 nu)` (paper eq. 46); infinite for nu = 0.5.
    pub fn bulk_modulus(&self) -> f64 {
        if self.is_incompressible() {
            f64::INFINITY
        } else {
            self.young / (3.0 - 6.0 * self.poisson)
        }
    }

    /// The moduli the grain laws below read (see [`Moduli`]).
    pub fn moduli(&self) -> Moduli {
        Moduli {
            shear: self.shear_modulus(),
            bulk: self.bulk_modulus(),
            incompressible: self.is_incompressible(),
        }
    }

    pub fn is_incompressible(&self) -> bool {
        self.poisson >= 0.5
    }

    /// Stiffness of the stiffest principal-strain mode: the largest eigenvalue of
    /// `d(sigma_1, sigma_2) / d(eps_1, eps_2) = [[mu + kappa, kappa - mu], [kappa - mu, mu + kappa]]`,
    /// i.e. `2 kappa` (volumetric mode, eps_1 = eps_2) or `2 mu` (deviatoric mode,
    /// eps_1 = -eps_2); `2 mu` when incompressible, where the volume is enforced by the
    /// correction, not by a stiffness. (The diagonal `mu + kappa` alone underestimates it by up
    /// to sqrt(2) as nu -> 0.5: the stability map found compressible runs unstable at 0.8 of
    /// that estimate, docs/speed_accuracy.md.)
    pub fn deformation_stiffness(&self) -> f64 {
        let deviatoric = 2.0 * self.shear_modulus();
        if self.is_incompressible() {
            deviatoric
        } else {
            deviatoric.max(2.0 * self.bulk_modulus())
        }
    }
}

/// A [`Material`]'s moduli, computed once: the grain pass reads them for every grain of a
/// step, and each is a division.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Moduli {
    /// Shear modulus mu, [`Material::shear_modulus`].
    pub shear: f64,
    /// Bulk modulus kappa, [`Material::bulk_modulus`] (infinite when incompressible).
    pub bulk: f64,
    /// [`Material::is_incompressible`].
    pub incompressible: bool,
}

// The laws below are written over `T: Real`, for one grain (`f64`) or lanes of grains side by
// side (the grain pass's blocks): the same formula, the same bits lane by lane.

/// Volumetric strain of eq. 41: `(1+eps1)(1+eps2) - lost_fraction - 1`.
#[inline(always)]
pub fn volumetric_strain<T: Real>(eps1: T, eps2: T, lost_fraction: T) -> T {
    let one = T::splat(1.0);
    (one + eps1) * (one + eps2) - lost_fraction - one
}

/// Principal grain stresses (sigma_1, sigma_2), along e1 and e2.
/// Compressible: `sigma_i = 2 mu eps_idev + kappa eps_V` (eq. 42–43 with eps1dev = -eps2dev);
/// incompressible: `sigma_i = 2 mu eps_idev` (eq. 65–66).
#[inline(always)]
pub fn principal_stress<T: Real>(moduli: &Moduli, eps1: T, eps2: T, lost_fraction: T) -> (T, T) {
    let mu = moduli.shear;
    let half_difference = T::splat(0.5) * (eps1 - eps2);
    let (dev1, dev2) = (
        T::splat(2.0 * mu) * half_difference,
        T::splat(-2.0 * mu) * half_difference,
    );
    if moduli.incompressible {
        (dev1, dev2)
    } else {
        let pressure_part = T::splat(moduli.bulk) * volumetric_strain(eps1, eps2, lost_fraction);
        (dev1 + pressure_part, dev2 + pressure_part)
    }
}

/// Strain energy per unit reference area: `mu (d1^2 + d2^2) + kappa/2 eps_V^2` (the deviatoric
/// part alone when incompressible).
#[inline(always)]
pub fn strain_energy_density<T: Real>(moduli: &Moduli, eps1: T, eps2: T, lost_fraction: T) -> T {
    let half_difference = T::splat(0.5) * (eps1 - eps2);
    let deviatoric = T::splat(2.0 * moduli.shear) * half_difference * half_difference;
    if moduli.incompressible {
        deviatoric
    } else {
        let ev = volumetric_strain(eps1, eps2, lost_fraction);
        deviatoric + T::splat(0.5 * moduli.bulk) * ev * ev
    }
}

/// The incompressibility correction of SPEC §6: keeps the deviatoric strains and returns the
/// principal strains `(d1 + e/2, d2 + e/2)` for which the grain's current area
/// `pi R^2 (1+eps1)(1+eps2) - sum S_j` equals its reference area `pi R^2`.
/// With d2 = -d1 the root of eq. 68 simplifies to `e = 2 sqrt(1 + lost_fraction + d1^2) - 2`.
#[inline(always)]
pub fn incompressible_strains<T: Real>(eps1: T, eps2: T, lost_fraction: T) -> (T, T) {
    let one = T::splat(1.0);
    let d1 = T::splat(0.5) * (eps1 - eps2);
    let half_add = (one + lost_fraction + d1 * d1).sqrt() - one;
    (d1 + half_add, -d1 + half_add)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deformation_stiffness_is_the_largest_eigenvalue_of_the_stress_jacobian() {
        // Expectation: the stiffest strain mode (which sets the critical time step) is the
        // largest eigenvalue of d(sigma_1, sigma_2)/d(eps_1, eps_2), here by central differences
        // of `principal_stress` at rest (for nu = 0.5 the volume is held by the correction, so
        // only the deviatoric response counts, as in `principal_stress`).
        for poisson in [0.0, 0.3, 0.45, 0.49, 0.499, 0.5] {
            let m = Material {
                young: 2.0,
                poisson,
                density: 1.0,
            };
            let h = 1e-7;
            let d = |e1: f64, e2: f64| principal_stress(&m.moduli(), e1, e2, 0.0);
            let column = |k: usize| {
                let (p, q) = if k == 0 {
                    (d(h, 0.0), d(-h, 0.0))
                } else {
                    (d(0.0, h), d(0.0, -h))
                };
                [(p.0 - q.0) / (2.0 * h), (p.1 - q.1) / (2.0 * h)]
            };
            let (c0, c1) = (column(0), column(1));
            let (a, b, c, dd) = (c0[0], c1[0], c0[1], c1[1]);
            let mean = 0.5 * (a + dd);
            let largest = mean + (0.25 * (a - dd) * (a - dd) + b * c).sqrt();
            let stiffness = m.deformation_stiffness();
            assert!(
                (stiffness - largest).abs() < 1e-6 * largest,
                "nu = {poisson}: {stiffness} vs {largest}"
            );
        }
    }

    #[test]
    fn incompressible_correction_restores_the_reference_area() {
        // Expectation (eq. 67): (1+eps1)(1+eps2) - lost = 1 after the correction, deviator kept.
        for (e1, e2, lost) in [
            (0.1, -0.2, 0.0),
            (0.3, 0.25, 0.07),
            (-0.4, 0.2, 0.15),
            (0.0, 0.0, 0.3),
        ] {
            let (a, b) = incompressible_strains(e1, e2, lost);
            assert!(((1.0 + a) * (1.0 + b) - lost - 1.0).abs() < 1e-14);
            assert!(((a - b) - (e1 - e2)).abs() < 1e-14);
        }
    }

    #[test]
    fn uniaxial_plane_stress_like_check_of_lame_relations() {
        // Expectation: for small strains, sigma_1 - sigma_2 = 2 mu (eps1 - eps2) / 2 * 2 and the
        // mean stress = kappa eps_V.
        let m = Material {
            young: 1.0,
            poisson: 0.3,
            density: 1.0,
        };
        let (s1, s2) = principal_stress(&m.moduli(), 1e-6, -2e-6, 0.0);
        assert!(((s1 - s2) - 2.0 * m.shear_modulus() * 3e-6).abs() < 1e-18);
        let ev = volumetric_strain(1e-6, -2e-6, 0.0);
        assert!((0.5 * (s1 + s2) - m.bulk_modulus() * ev).abs() < 1e-18);
    }
}
