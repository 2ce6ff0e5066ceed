//! Numerical and physical parameters of the time step, and the critical time step (SPEC §9).

use crate::contact::SecantLaw;
use crate::contact::friction::{FrictionSettings, TangentialLaw};
use crate::grain::{AdaptiveSettings, Material, ModelLevel};
use crate::integration::MAX_WALLS;
use glam::DVec2;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Parameters {
    pub material: Material,
    /// The model level of every grain; with `adaptive`, the highest level a grain may reach.
    pub level: ModelLevel,
    /// The adaptive level (issue #6): each grain picks its own level; `None`: all at `level`.
    pub adaptive: Option<Adaptive>,
    pub law: SecantLaw,
    /// Contour resolution dbeta, degrees; 0 for the exact ellipses ([`crate::geometry::Contours`]).
    pub resolution_deg: f64,
    /// gamma of the contact dashpot (eq. 61), dimensionless.
    pub contact_damping: f64,
    /// gamma of the deformation dashpots (eq. 62–64), 1/time.
    pub deformation_damping: f64,
    /// k_alpha of eq. 60.
    pub k_alpha: f64,
    /// Mass-scaling factor on M_alpha (1 = none), on top of `deformation_mass_scale`.
    pub alpha_mass_scale: f64,
    /// Mass-scaling factor on the generalized masses of the deformation DoF, M_eps and M_alpha
    /// (1 = none; for quasi-static runs): the strain responds `sqrt(s)` times slower and, with
    /// it, the contact mode that pushes the strain DoF, which sets the deformable levels'
    /// critical step (see [`stiffest_modes`]).
    pub deformation_mass_scale: f64,
    /// Time step.
    pub dt: f64,
    /// Verlet skin, as a fraction of the mean radius.
    pub skin_fraction: f64,
    /// Coulomb friction (SPEC §13); `None`: every contact is frictionless.
    pub friction: Option<Friction>,
    /// Body force per unit mass.
    pub gravity: DVec2,
}

/// Coulomb friction of a world's contacts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Friction {
    pub law: TangentialLaw,
    /// mu between grains.
    pub grains: f64,
    /// mu of each wall, in the order of the world's walls.
    pub walls: [f64; MAX_WALLS],
}

impl Friction {
    /// The friction of a scenario's settings, with `walls` the coefficient of each wall; `None`
    /// when every coefficient is zero.
    pub fn new(settings: &FrictionSettings, walls: &[f64]) -> Option<Self> {
        assert!(walls.len() <= MAX_WALLS, "at most {MAX_WALLS} walls");
        if settings.grains == 0.0 && walls.iter().all(|&mu| mu == 0.0) {
            return None;
        }
        let mut per_wall = [0.0; MAX_WALLS];
        per_wall[..walls.len()].copy_from_slice(walls);
        Some(Self {
            law: TangentialLaw::from(settings),
            grains: settings.grains,
            walls: per_wall,
        })
    }

    /// `r_t` of a world's contacts for the critical time step, 0 without friction.
    pub fn tangential_ratio(friction: &Option<Self>) -> f64 {
        friction.map_or(0.0, |f| f.law.stiffness_ratio)
    }
}

impl Parameters {
    /// Whether contacts between grains have friction: only then does a pair carry a tangential
    /// force (otherwise its tangential force is an exact +0).
    #[inline]
    pub fn frictional_pairs(&self) -> bool {
        self.friction.as_ref().is_some_and(|f| f.grains > 0.0)
    }

    /// Default numerics for a material: the paper's a = 0.58, b = 2, dbeta = 1 degree,
    /// gamma = 1 for contacts and deformation, k_alpha = 1e-3; `dt` must still be set.
    pub fn new(material: Material, dt: f64) -> Self {
        Self {
            material,
            level: ModelLevel::Full,
            adaptive: None,
            law: SecantLaw::new(material.young, 0.58, 2.0),
            resolution_deg: 1.0,
            contact_damping: 1.0,
            deformation_damping: 1.0,
            k_alpha: 1e-3,
            alpha_mass_scale: 1.0,
            deformation_mass_scale: 1.0,
            dt,
            skin_fraction: 0.2,
            friction: None,
            gravity: DVec2::ZERO,
        }
    }

    /// What, besides material, law, size and level, sets these parameters' critical step.
    pub fn mode_settings(&self) -> ModeSettings {
        ModeSettings {
            tangential_ratio: Friction::tangential_ratio(&self.friction),
            deformation_mass_scale: self.deformation_mass_scale,
        }
    }
}

/// The adaptive level: its thresholds and the time step for each highest level present.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Adaptive {
    pub settings: AdaptiveSettings,
    /// Time step while the highest level of any grain is Rigid, Volumetric, Full
    /// (indexed by [`ModelLevel::index`]). Rigid grains have no deformation coupling, so their
    /// critical step is sqrt(5) times larger (see [`stiffest_modes`]).
    pub dt: [f64; 3],
    /// Multi-rate cycles ([`World::step`](super::World::step)): while some grains deform and
    /// at least [`MULTI_RATE_MIN_RIGID_SHARE`] of them are rigid, the deforming grains (and the
    /// rigid grains that may meet them) take two steps of their level's while the other rigid
    /// grains take one of twice that.
    pub multi_rate: bool,
}

/// The share of rigid grains below which a multi-rate world takes plain steps: the cycle saves
/// work only on the grains that take one step of it, and costs a pass of roles.
pub const MULTI_RATE_MIN_RIGID_SHARE: f64 = 0.25;

impl Adaptive {
    /// `fraction` of the critical step of each level, for the smallest grain.
    pub fn fraction_of_critical(
        settings: AdaptiveSettings,
        fraction: f64,
        material: &Material,
        law: &SecantLaw,
        min_radius: f64,
        mode_settings: ModeSettings,
    ) -> Self {
        Self {
            settings,
            dt: ModelLevel::ALL.map(|level| {
                fraction
                    * frictional_critical_time_step(material, law, min_radius, level, mode_settings)
            }),
            multi_rate: false,
        }
    }
}

/// What, besides the material, the contact law and the grain's size and level, sets the
/// stiffest modes of a grain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModeSettings {
    /// `r_t` of the frictional contacts ([`Friction::tangential_ratio`]), 0 without friction.
    pub tangential_ratio: f64,
    /// [`Parameters::deformation_mass_scale`]: 1 = the physical inertia of the strain DoF.
    pub deformation_mass_scale: f64,
}

impl Default for ModeSettings {
    /// Frictionless contacts, no mass scaling.
    fn default() -> Self {
        Self {
            tangential_ratio: 0.0,
            deformation_mass_scale: 1.0,
        }
    }
}

/// Angular frequencies of the stiffest modes of a grain of radius `radius` (SPEC §9).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StiffestModes {
    /// Principal-strain mode: `(2/R) sqrt(K/(s rho))`, K the stiffest strain mode of
    /// [`Material::deformation_stiffness`] (`max(2 mu, 2 kappa)`; `2 mu` when incompressible),
    /// s the deformation mass scale.
    pub deformation: f64,
    /// Contact mode at the initial contact stiffness `k = E/a` in a dense packing:
    /// `sqrt(4 * coupling * 2k/m)`. Between two grains the mode is `sqrt(2k/m)` (m_eff = m/2);
    /// `coupling` = 1 + 4/s counts the push of a contact force on the strain DoF through the
    /// Love–Weber stress (generalized mass s m R^2/4 at lever arm R: 4/s times the translational
    /// response; 1 for rigid grains); the factor 4 is the stiffest lattice mode of a grain with
    /// six contacts, measured: the dense `sdem bench` packing goes unstable between 0.5 and 0.55
    /// of the single-contact estimate (tests/stability.rs).
    pub contact: f64,
    /// Tangential contact mode (friction, SPEC §13) at `K_t = r_t E/a`: the same lattice
    /// estimate with the tangential coupling 1 + 2 (translation, and rotation at lever arm R:
    /// `R^2 m / M_theta = 2` for a disc), + 4/s for the strain DoF of deformable grains. Measured
    /// on the dense `sdem bench` packing with mu = 0.5 and `r_t = 1`: unstable between 1.15 and
    /// 1.2 of the resulting estimate at the full level, between 1.4 and 1.6 at the rigid level
    /// (tests/stability.rs). Zero without friction.
    pub tangential: f64,
}

/// Whether a grain at `level` has strain DoF that contact forces drive through their own
/// inertia. A rigid grain has none; nor has a volumetric grain of an incompressible material:
/// it holds its deviator, and the volume correction (SPEC §6) sets its mean strain from its
/// lost area after every step, so no force accelerates a strain. Its stiffest modes are a rigid
/// grain's: on the dense `sdem bench` packing, all grains volumetric at nu = 0.5 run stable at
/// 0.8 of the rigid estimate and went unstable at 0.9 (rigid grains: 0.9 and 1.0; issue #16,
/// fourth session); tests/stability.rs checks 0.8 and 2.0.
pub fn has_dynamic_strains(material: &Material, level: ModelLevel) -> bool {
    match level {
        ModelLevel::Rigid => false,
        ModelLevel::Volumetric => !material.is_incompressible(),
        ModelLevel::Full => true,
    }
}

pub fn stiffest_modes(
    material: &Material,
    law: &SecantLaw,
    radius: f64,
    level: ModelLevel,
    settings: ModeSettings,
) -> StiffestModes {
    let mass = material.density * std::f64::consts::PI * radius * radius;
    let dynamic_strains = has_dynamic_strains(material, level);
    // Response of the strain DoF to a contact force, relative to the translational one.
    let strain_coupling = if dynamic_strains {
        4.0 / settings.deformation_mass_scale
    } else {
        0.0
    };
    let coupling = 1.0 + strain_coupling;
    let contact = (4.0 * law.initial_stiffness() * 2.0 / mass * coupling).sqrt();
    let tangential_coupling = 3.0 + strain_coupling;
    let tangential = (4.0 * settings.tangential_ratio * law.initial_stiffness() * 2.0 / mass
        * tangential_coupling)
        .sqrt();
    let deformation = if dynamic_strains {
        2.0 / radius
            * (material.deformation_stiffness()
                / (material.density * settings.deformation_mass_scale))
                .sqrt()
    } else {
        0.0
    };
    StiffestModes {
        deformation,
        contact,
        tangential,
    }
}

/// Critical time step of symplectic Euler, `2 / omega_max`, for the smallest grain.
///
/// For incompressible grains `omega_max` is the larger of the two modes: the contact mode's
/// coupling factor already counts the strain DoF's inertia, and the volume is held by the
/// correction, not by a stiffness. A compressible grain's volumetric stiffness `2 kappa` acts on
/// the same strain DoF that the contacts push, so the two stiffnesses add:
/// `omega_max^2 = omega_c^2 + omega_eps^2`. The stability map (tools/stability_map.py,
/// docs/speed_accuracy.md) found compressible runs (nu = 0.3 to 0.499) unstable at 1.0, and for
/// nu >= 0.45 at 0.8, of the larger-mode estimate, at the point where contacts and volumetric
/// strain couple; the summed estimate places every observed limit between 1.0 and 1.25 of it.
pub fn critical_time_step(
    material: &Material,
    law: &SecantLaw,
    min_radius: f64,
    level: ModelLevel,
) -> f64 {
    frictional_critical_time_step(material, law, min_radius, level, ModeSettings::default())
}

/// [`critical_time_step`] with frictional contacts of tangential stiffness ratio `r_t`
/// (0: frictionless) and a deformation mass scale: the tangential mode is a mode of its own, so
/// the stiffer of the normal and tangential contact modes counts.
pub fn frictional_critical_time_step(
    material: &Material,
    law: &SecantLaw,
    min_radius: f64,
    level: ModelLevel,
    settings: ModeSettings,
) -> f64 {
    let modes = stiffest_modes(material, law, min_radius, level, settings);
    let contact = modes.contact.max(modes.tangential);
    let omega_max = if material.is_incompressible() || level == ModelLevel::Rigid {
        modes.deformation.max(contact)
    } else {
        (modes.deformation * modes.deformation + contact * contact).sqrt()
    };
    2.0 / omega_max
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material(poisson: f64) -> Material {
        Material {
            young: 1.0,
            poisson,
            density: 1.0,
        }
    }

    fn step(poisson: f64, level: ModelLevel, tangential_ratio: f64, mass_scale: f64) -> f64 {
        let m = material(poisson);
        let modes = ModeSettings {
            tangential_ratio,
            deformation_mass_scale: mass_scale,
        };
        frictional_critical_time_step(&m, &SecantLaw::new(m.young, 0.58, 2.0), 0.01, level, modes)
    }

    #[test]
    fn the_mass_scale_moves_the_deformable_step_towards_the_rigid_one() {
        // Expectation: coupling 1 + 4/s, so the step is sqrt(5 / (1 + 4/s)) times the unscaled
        // one, tends to the rigid step as s grows, and leaves rigid grains alone.
        for (s, gain) in [(1.0, 1.0), (4.0, 2.5_f64.sqrt()), (16.0, 2.0)] {
            let ratio = step(0.5, ModelLevel::Full, 0.0, s) / step(0.5, ModelLevel::Full, 0.0, 1.0);
            assert!((ratio - gain).abs() < 1e-12, "s = {s}: {ratio}");
        }
        let rigid = step(0.5, ModelLevel::Rigid, 0.0, 1.0);
        assert_eq!(step(0.5, ModelLevel::Rigid, 0.0, 9.0), rigid);
        let heavy = step(0.5, ModelLevel::Volumetric, 0.0, 1e12);
        assert!((heavy / rigid - 1.0).abs() < 1e-9, "{heavy} vs {rigid}");
        // Friction: the tangential coupling 3 + 4/s, 7 unscaled.
        let frictional = |s| step(0.5, ModelLevel::Full, 1.0, s);
        let ratio = frictional(4.0) / frictional(1.0);
        assert!((ratio - (7.0_f64 / 4.0).sqrt()).abs() < 1e-12, "{ratio}");
        // Compressible grains: the strain mode's stiffness is divided by s too, so the summed
        // estimate scales like the contact mode alone when both are scaled to infinity.
        let soft = step(0.3, ModelLevel::Full, 0.0, 1e12);
        assert!((soft / step(0.3, ModelLevel::Rigid, 0.0, 1.0) - 1.0).abs() < 1e-9);
    }
}
