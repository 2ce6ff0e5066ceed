//! The a/b secant contact law.
//!
//! Sign convention: gaps `delta_n` are negative when the contours interpenetrate; the normal
//! force `F_n` is negative when repulsive, and acts as `F_n n` on grain i (`n` from i to j) and
//! `-F_n n` on grain j.

use crate::lanes::Real;

/// `F_n = E eps_n L_c = k_n delta_n`, `eps_n = delta_n / (a L_c + (b - 1) delta_n)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SecantLaw {
    /// Young's modulus of the grains.
    pub young: f64,
    pub a: f64,
    pub b: f64,
    /// When `a L_c + (b-1) delta_n` falls below `floor * a * L_c`, the law has left its domain.
    /// With `cap = true` the denominator is held at that floor (the force keeps growing, linearly
    /// in delta_n); otherwise the caller gets [`DomainExit`].
    pub floor: f64,
    pub cap: bool,
}

/// The contact is so deep that `a L_c + (b-1) delta_n <= floor a L_c` (SPEC §5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DomainExit {
    pub length: f64,
    pub normal_gap: f64,
}

/// Normal force and secant stiffness of one contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalResponse {
    /// Elastic normal force (<= 0, repulsive).
    pub force: f64,
    /// Secant stiffness `k_n = E L_c / (a L_c + (b-1) delta_n)` (> 0).
    pub stiffness: f64,
    /// Whether the denominator was held at its floor.
    pub capped: bool,
}

impl SecantLaw {
    pub fn new(young: f64, a: f64, b: f64) -> Self {
        Self {
            young,
            a,
            b,
            floor: 0.05,
            cap: false,
        }
    }

    /// Elastic response for a contact of length `length` and normal gap `normal_gap` (<= 0).
    #[inline]
    pub fn response(&self, length: f64, normal_gap: f64) -> Result<NormalResponse, DomainExit> {
        let (mut denominator, floor) = self.denominator(length, normal_gap);
        let mut capped = false;
        if !Self::in_domain(denominator, floor) {
            if !self.cap || !denominator.is_finite() {
                return Err(DomainExit { length, normal_gap });
            }
            denominator = floor;
            capped = true;
        }
        let stiffness = self.stiffness(length, denominator);
        Ok(NormalResponse {
            force: stiffness * normal_gap,
            stiffness,
            capped,
        })
    }

    /// The law's denominator `a L_c + (b-1) delta_n` and its floor `floor a L_c`, written once
    /// for one contact and for [lanes](crate::lanes) of contacts.
    #[inline(always)]
    pub fn denominator<T: Real>(&self, length: T, normal_gap: T) -> (T, T) {
        let nominal = T::splat(self.a) * length;
        let denominator = nominal + T::splat(self.b - 1.0) * normal_gap;
        (denominator, T::splat(self.floor) * nominal)
    }

    /// Whether a contact whose [`denominator`](Self::denominator) is `denominator` lies in the
    /// law's domain (above its floor); a NaN denominator does not.
    #[inline(always)]
    pub fn in_domain(denominator: f64, floor: f64) -> bool {
        denominator > floor
    }

    /// The secant stiffness `E L_c / denominator`; the force is `stiffness * delta_n`.
    #[inline(always)]
    pub fn stiffness<T: Real>(&self, length: T, denominator: T) -> T {
        T::splat(self.young) * length / denominator
    }

    /// Secant stiffness at vanishing overlap, `E / a`: the stiffest a shallow contact gets.
    pub fn initial_stiffness(&self) -> f64 {
        self.young / self.a
    }
}

/// Total normal force with the dashpot of eq. 61: `F = k_n delta_n + c ddelta_n/dt`,
/// `c = gamma sqrt(k_n m_eff)`, clamped to be repulsive only (`F <= 0`).
/// Written once for one contact and for [lanes](crate::lanes) of contacts.
#[inline(always)]
pub fn damped_normal_force<T: Real>(
    elastic: T,
    stiffness: T,
    effective_mass: T,
    damping_ratio: T,
    gap_rate: T,
) -> T {
    let dashpot = damping_ratio * (stiffness * effective_mass).sqrt();
    (elastic + dashpot * gap_rate).min(T::splat(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_overlap_limit_is_linear_with_stiffness_e_over_a() {
        // Expectation: for |delta_n| << a L_c, F_n -> (E/a) delta_n.
        let law = SecantLaw::new(2.0, 0.58, 2.0);
        let r = law.response(0.1, -1e-9).unwrap();
        assert!((r.stiffness - 2.0 / 0.58).abs() < 1e-6);
        assert!((r.force - (-1e-9 * 2.0 / 0.58)).abs() < 1e-15);
    }

    #[test]
    fn force_is_e_eps_n_lc() {
        let law = SecantLaw::new(1.0, 0.58, 2.0);
        let (lc, dn) = (0.2, -0.03);
        let eps_n = dn / (0.58 * lc + dn);
        let r = law.response(lc, dn).unwrap();
        assert!((r.force - eps_n * lc).abs() < 1e-15);
        assert!(r.force < 0.0);
    }

    #[test]
    fn domain_exit_is_reported_or_capped() {
        let mut law = SecantLaw::new(1.0, 0.58, 2.0);
        assert!(law.response(0.1, -0.06).is_err());
        law.cap = true;
        let r = law.response(0.1, -0.06).unwrap();
        assert!(r.capped && r.force.is_finite() && r.force < 0.0);
    }

    #[test]
    fn dashpot_resists_approach_and_never_attracts() {
        assert!(damped_normal_force(-1.0, 1.0, 1.0, 1.0, -0.5) < -1.0);
        assert_eq!(damped_normal_force(-1.0, 1.0, 1.0, 1.0, 5.0), 0.0);
    }
}
