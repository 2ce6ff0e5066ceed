//! Plane-strain hyperelastic laws for the total-Lagrangian meshfree solver (SPEC §10).
//!
//! Both laws take the in-plane deformation gradient F (2 x 2, `F[i][J]`) and return the energy
//! density W, the first Piola–Kirchhoff stress `P = F S` and the consistent tangent
//! `A_iJkL = dP_iJ / dF_kL = delta_ik S_JL + F_iI C_IJKL F_kK`, indexed `A[2i + J][2k + L]`.
//! Both reduce to linear plane-strain elasticity for small strains.

#![allow(clippy::needless_range_loop)] // index notation mirrors the tensor formulas

use super::MeshfreeError;
use crate::portable::ln;

/// Which hyperelastic law a meshfree grain follows.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
pub enum HyperelasticLaw {
    /// `W = mu/2 (tr C + 1 - 3) - mu ln J + lambda/2 (ln J)^2` (the default; `nu < 0.5`).
    #[default]
    NeoHookean,
    /// `S = lambda tr(E) I + 2 mu E` (the 2016 paper's law; softens in strong compression).
    SaintVenantKirchhoff,
}

impl HyperelasticLaw {
    pub fn name(self) -> &'static str {
        match self {
            Self::NeoHookean => "neo-Hookean",
            Self::SaintVenantKirchhoff => "Saint Venant-Kirchhoff",
        }
    }
}

/// A hyperelastic material: law, Young's modulus, Poisson's ratio, density.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hyperelastic {
    pub law: HyperelasticLaw,
    pub young: f64,
    pub poisson: f64,
    pub density: f64,
}

/// Stress response at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StressResponse {
    pub energy: f64,
    /// First Piola–Kirchhoff stress, `p[i][J]`.
    pub p: [[f64; 2]; 2],
    /// Second Piola–Kirchhoff stress `s[I][J]`.
    pub s: [[f64; 2]; 2],
    /// `dP/dF`, `a[2i + J][2k + L]`.
    pub a: [[f64; 4]; 4],
}

impl Hyperelastic {
    /// Checks `E > 0`, `rho > 0` and `-1 < nu < 0.5` (both laws here are compressible).
    pub fn new(
        law: HyperelasticLaw,
        young: f64,
        poisson: f64,
        density: f64,
    ) -> Result<Self, MeshfreeError> {
        if !(young.is_finite() && young > 0.0) {
            return Err(MeshfreeError::BadInput(format!(
                "Young's modulus must be positive, got {young}"
            )));
        }
        if !(density.is_finite() && density > 0.0) {
            return Err(MeshfreeError::BadInput(format!(
                "density must be positive, got {density}"
            )));
        }
        if !(poisson > -1.0 && poisson < 0.5) {
            return Err(MeshfreeError::BadInput(format!(
                "Poisson's ratio must be in (-1, 0.5) for the compressible meshfree solver, got \
                 {poisson} (nu = 0.5 needs a mixed formulation, which is not implemented)"
            )));
        }
        Ok(Self {
            law,
            young,
            poisson,
            density,
        })
    }

    pub fn mu(&self) -> f64 {
        self.young / (2.0 * (1.0 + self.poisson))
    }

    /// Plane-strain Lamé lambda.
    pub fn lambda(&self) -> f64 {
        self.young * self.poisson / ((1.0 + self.poisson) * (1.0 - 2.0 * self.poisson))
    }

    /// Energy, stresses and tangent at the deformation gradient `f`. `None` if `det F <= 0`
    /// (the neo-Hookean law is undefined there; SVK is evaluated but flagged the same way, an
    /// inverted material point is never a valid state).
    pub fn response(&self, f: [[f64; 2]; 2]) -> Option<StressResponse> {
        let j = f[0][0] * f[1][1] - f[0][1] * f[1][0];
        if j.is_nan() || j <= 0.0 || !j.is_finite() {
            return None;
        }
        let mu = self.mu();
        let lambda = self.lambda();
        // Right Cauchy–Green tensor C = F^T F.
        let mut c = [[0.0; 2]; 2];
        for i in 0..2 {
            for k in 0..2 {
                c[i][k] = f[0][i] * f[0][k] + f[1][i] * f[1][k];
            }
        }
        let mut s = [[0.0; 2]; 2];
        let mut cc = [[[[0.0; 2]; 2]; 2]; 2]; // C_IJKL
        let energy;
        match self.law {
            HyperelasticLaw::NeoHookean => {
                let det_c = j * j;
                let ci = [
                    [c[1][1] / det_c, -c[0][1] / det_c],
                    [-c[1][0] / det_c, c[0][0] / det_c],
                ];
                let lnj = ln(j);
                energy = 0.5 * mu * (c[0][0] + c[1][1] - 2.0) - mu * lnj + 0.5 * lambda * lnj * lnj;
                let g = mu - lambda * lnj;
                for a in 0..2 {
                    for b in 0..2 {
                        let id = if a == b { 1.0 } else { 0.0 };
                        s[a][b] = mu * id - g * ci[a][b];
                        for k in 0..2 {
                            for l in 0..2 {
                                cc[a][b][k][l] = lambda * ci[a][b] * ci[k][l]
                                    + g * (ci[a][k] * ci[b][l] + ci[a][l] * ci[b][k]);
                            }
                        }
                    }
                }
            }
            HyperelasticLaw::SaintVenantKirchhoff => {
                let e = [
                    [0.5 * (c[0][0] - 1.0), 0.5 * c[0][1]],
                    [0.5 * c[1][0], 0.5 * (c[1][1] - 1.0)],
                ];
                let tr = e[0][0] + e[1][1];
                let mut ee = 0.0;
                for a in 0..2 {
                    for b in 0..2 {
                        ee += e[a][b] * e[a][b];
                    }
                }
                energy = 0.5 * lambda * tr * tr + mu * ee;
                for a in 0..2 {
                    for b in 0..2 {
                        let id = |x: usize, y: usize| if x == y { 1.0 } else { 0.0 };
                        s[a][b] = lambda * tr * id(a, b) + 2.0 * mu * e[a][b];
                        for k in 0..2 {
                            for l in 0..2 {
                                cc[a][b][k][l] = lambda * id(a, b) * id(k, l)
                                    + mu * (id(a, k) * id(b, l) + id(a, l) * id(b, k));
                            }
                        }
                    }
                }
            }
        }
        let mut p = [[0.0; 2]; 2];
        for i in 0..2 {
            for jj in 0..2 {
                p[i][jj] = f[i][0] * s[0][jj] + f[i][1] * s[1][jj];
            }
        }
        let mut a = [[0.0; 4]; 4];
        for i in 0..2 {
            for jj in 0..2 {
                for k in 0..2 {
                    for l in 0..2 {
                        let mut v = if i == k { s[jj][l] } else { 0.0 };
                        for ii in 0..2 {
                            for kk in 0..2 {
                                v += f[i][ii] * cc[ii][jj][kk][l] * f[k][kk];
                            }
                        }
                        a[2 * i + jj][2 * k + l] = v;
                    }
                }
            }
        }
        Some(StressResponse { energy, p, s, a })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_derivatives(law: HyperelasticLaw) {
        let m = Hyperelastic::new(law, 1.0, 0.3, 1.0).unwrap();
        let f = [[0.9, 0.12], [-0.05, 0.83]];
        let r = m.response(f).unwrap();
        let h = 1e-6;
        for q in 0..4 {
            let mut fp = f;
            let mut fm = f;
            fp[q / 2][q % 2] += h;
            fm[q / 2][q % 2] -= h;
            let rp = m.response(fp).unwrap();
            let rm = m.response(fm).unwrap();
            // P = dW/dF
            let dw = (rp.energy - rm.energy) / (2.0 * h);
            assert!((dw - r.p[q / 2][q % 2]).abs() < 1e-8, "{law:?} P");
            for pq in 0..4 {
                let da = (rp.p[pq / 2][pq % 2] - rm.p[pq / 2][pq % 2]) / (2.0 * h);
                assert!((da - r.a[pq][q]).abs() < 1e-7, "{law:?} A[{pq}][{q}]");
            }
        }
    }

    #[test]
    fn stresses_and_tangents_are_consistent_derivatives() {
        check_derivatives(HyperelasticLaw::NeoHookean);
        check_derivatives(HyperelasticLaw::SaintVenantKirchhoff);
    }

    #[test]
    fn small_strain_limit_is_linear_plane_strain() {
        for law in [
            HyperelasticLaw::NeoHookean,
            HyperelasticLaw::SaintVenantKirchhoff,
        ] {
            let m = Hyperelastic::new(law, 2.0, 0.25, 1.0).unwrap();
            let (exx, eyy, exy) = (1e-7, -3e-7, 2e-7);
            let f = [[1.0 + exx, exy], [exy, 1.0 + eyy]];
            let r = m.response(f).unwrap();
            let (l, mu) = (m.lambda(), m.mu());
            let sxx = l * (exx + eyy) + 2.0 * mu * exx;
            let syy = l * (exx + eyy) + 2.0 * mu * eyy;
            let sxy = 2.0 * mu * exy;
            assert!((r.p[0][0] - sxx).abs() < 1e-12);
            assert!((r.p[1][1] - syy).abs() < 1e-12);
            assert!((r.p[0][1] - sxy).abs() < 1e-12);
        }
    }

    #[test]
    fn incompressible_or_inverted_input_is_rejected() {
        assert!(Hyperelastic::new(HyperelasticLaw::NeoHookean, 1.0, 0.5, 1.0).is_err());
        let m = Hyperelastic::new(HyperelasticLaw::NeoHookean, 1.0, 0.3, 1.0).unwrap();
        assert!(m.response([[1.0, 0.0], [0.0, -0.1]]).is_none());
    }
}
