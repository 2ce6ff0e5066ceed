//! Scenario files (RON): what a run simulates, checked field by field before any work starts.
//!
//! A scenario names a sample (to generate, or to read from a file), the material, the model
//! level, the contact and deformation numerics, the time step, a loading program and the output
//! settings. Every section but `name`, `sample`, `material` and `loading` has defaults (the
//! paper's values).
//!
//! The parser accepts an optional field written plainly (`file: "grains.csv"`) or as
//! `Some(...)` (RON's `implicit_some` extension), so that adding optional fields keeps older
//! scenarios and checkpoints readable.

use crate::boundary::loading::{Phase, StopWhen, StrainRate};
use crate::boundary::walls::{Wall, box_walls};
use crate::contact::SecantLaw;
use crate::contact::friction::{COEFFICIENT_RANGE, FrictionSettings, is_coefficient};
use crate::grain::Grain;
use crate::grain::{AdaptiveSettings, Material, ModelLevel};
use crate::integration::Parameters;
use crate::integration::parameters::{
    Adaptive, Friction, ModeSettings, frictional_critical_time_step,
};
use crate::meshfree::shape::{ShapeFileError, StarShape, read_shape_file};
use crate::meshfree::{HyperelasticLaw, SolverSettings, TimeScheme};
use crate::sample::file::{BoxBounds, SampleFileError, check_packing, read_grains};
use crate::sample::{MAX_COUNT, RadiusDistribution, SampleError, SampleSpec};
use glam::DVec2;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Options of the RON parser for scenarios and checkpoints.
pub fn ron_options() -> ron::Options {
    ron::Options::default().with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    /// Seed of the sample generator.
    #[serde(default = "default_seed")]
    pub seed: u64,
    pub sample: SampleSettings,
    pub material: Material,
    #[serde(default)]
    pub model: Model,
    #[serde(default)]
    pub contact: ContactSettings,
    #[serde(default)]
    pub deformation: DeformationSettings,
    #[serde(default)]
    pub time_step: TimeStep,
    pub loading: Vec<Phase>,
    #[serde(default)]
    pub output: OutputSettings,
    /// Body force per unit mass, e.g. `(0.0, -9.81)`.
    #[serde(default, skip_serializing_if = "is_zero_origin")]
    pub gravity: (f64, f64),
    /// Fixed rigid walls at any angle besides the box's four (an inclined plane), walls only.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub planes: Vec<Plane>,
    /// What bounds the sample: walls (the default) or a periodic cell.
    #[serde(default, skip_serializing_if = "Boundary::is_walls")]
    pub boundary: Boundary,
}

fn default_seed() -> u64 {
    1
}

/// Most planes a scenario may add to the four box walls.
pub const MAX_PLANES: usize = crate::integration::MAX_WALLS - 4;

/// A fixed rigid wall: the line through `point` with `normal` pointing to the grains' side.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plane {
    pub point: (f64, f64),
    /// Need not be of unit length.
    pub normal: (f64, f64),
    /// Coulomb coefficient mu between the grains and this plane.
    #[serde(default)]
    pub friction: f64,
}

/// What bounds the sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Boundary {
    /// Four rigid frictionless walls on the sides of the sample's box.
    #[default]
    Walls,
    /// A periodic cell on the sample's box (SPEC §14), SDEM only: no walls; the loading phases
    /// deform the cell as they would move the walls (the grains follow the cell's affine
    /// deformation at every step, so `affine` is implied), and `Shear` shears it. Stresses are
    /// the cell's, from the contact forces. The cell must stay at least twice as wide as the
    /// largest grain diameter plus the neighbour skin.
    Periodic,
}

impl Boundary {
    pub fn is_walls(&self) -> bool {
        *self == Boundary::Walls
    }
}

/// The initial sample: generated (`count` grains with `radii`) or read from `file`, in the box
/// `[x0, x0 + box_width] x [y0, y0 + box_height]` with `(x0, y0) = origin`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SampleSettings {
    /// Number of grains to generate (with `file`: optional, must match the file).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count: Option<usize>,
    pub box_width: f64,
    pub box_height: f64,
    /// Lower left corner of the box (default (0, 0)).
    #[serde(default, skip_serializing_if = "is_zero_origin")]
    pub origin: (f64, f64),
    /// Radius distribution of a generated sample (not allowed with `file`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radii: Option<RadiusDistribution>,
    /// A CSV of grains (see [`crate::sample::file`]), relative to the scenario file's folder.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<PathBuf>,
    /// The grains' contours (meshfree model only; default: discs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shapes: Option<GrainShapes>,
    /// The grains of `file` once read ([`Scenario::load`], [`Scenario::load_sample`]; a
    /// checkpoint sets the radii of its grains). Not part of the scenario's text.
    #[serde(skip)]
    pub loaded: Option<Arc<LoadedSample>>,
    /// The grains of `shapes: File(...)` once read ([`Scenario::load`]).
    #[serde(skip)]
    pub loaded_shapes: Option<Arc<LoadedShapes>>,
}

fn is_zero_origin(o: &(f64, f64)) -> bool {
    o.0 == 0.0 && o.1 == 0.0
}

/// The grains of a sample file, as read and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedSample {
    /// The file as opened (the scenario's folder joined with `sample.file`).
    pub path: PathBuf,
    pub grains: Vec<Grain>,
}

impl LoadedSample {
    pub fn smallest_radius(&self) -> f64 {
        self.grains
            .iter()
            .map(|g| g.radius)
            .fold(f64::INFINITY, f64::min)
    }
}

/// What a user wrote is what compares: the grains read from the file are derived from it.
impl PartialEq for SampleSettings {
    fn eq(&self, other: &Self) -> bool {
        self.count == other.count
            && self.box_width.to_bits() == other.box_width.to_bits()
            && self.box_height.to_bits() == other.box_height.to_bits()
            && self.origin.0.to_bits() == other.origin.0.to_bits()
            && self.origin.1.to_bits() == other.origin.1.to_bits()
            && self.radii == other.radii
            && self.file == other.file
            && self.shapes == other.shapes
    }
}

impl SampleSettings {
    /// Corners of the box.
    pub fn bounds(&self) -> BoxBounds {
        BoxBounds {
            x0: self.origin.0,
            x1: self.origin.0 + self.box_width,
            y0: self.origin.1,
            y1: self.origin.1 + self.box_height,
        }
    }

    /// The generation spec of a generated sample (None with `file` or without count/radii).
    pub fn spec(&self) -> Option<SampleSpec> {
        match (self.file.is_none(), self.count, &self.radii) {
            (true, Some(count), Some(radii)) => Some(SampleSpec {
                count,
                box_width: self.box_width,
                box_height: self.box_height,
                radii: radii.clone(),
            }),
            _ => None,
        }
    }

    /// Number of grains: `count`, or the file's once read (0 if neither is known).
    pub fn grain_count(&self) -> usize {
        if let Some(l) = &self.loaded_shapes {
            return l.grains.len();
        }
        match (&self.loaded, self.count) {
            (Some(l), _) => l.grains.len(),
            (None, Some(n)) => n,
            (None, None) => 0,
        }
    }

    /// The fields that do not need the file: box, origin, and which of count/radii/file.
    fn validate_fields(&self) -> Result<(), ScenarioError> {
        if !(self.origin.0.is_finite() && self.origin.1.is_finite()) {
            return Err(invalid(
                "sample.origin",
                format!("({}, {})", num(self.origin.0), num(self.origin.1)),
                "two finite numbers (x0, y0)",
            ));
        }
        match &self.file {
            Some(file) => {
                if self.radii.is_some() {
                    return Err(invalid(
                        "sample.radii",
                        "given together with sample.file",
                        "left out: a sample read from a file takes its radii from the file",
                    ));
                }
                if self.count == Some(0) {
                    return Err(SampleError::ZeroCount.into());
                }
                if file.as_os_str().is_empty() {
                    return Err(invalid(
                        "sample.file",
                        "\"\"",
                        "the path of a CSV of grains",
                    ));
                }
                positive("sample.box_width", self.box_width)?;
                positive("sample.box_height", self.box_height)?;
            }
            None if matches!(self.shapes, Some(GrainShapes::File(_))) => {
                if self.radii.is_some() {
                    return Err(invalid(
                        "sample.radii",
                        "given together with sample.shapes: File(...)",
                        "left out: the shape file gives the grains",
                    ));
                }
                if let Some(GrainShapes::File(f)) = &self.shapes
                    && f.as_os_str().is_empty()
                {
                    return Err(invalid(
                        "sample.shapes",
                        "File(\"\")",
                        "the path of a shape file",
                    ));
                }
                positive("sample.box_width", self.box_width)?;
                positive("sample.box_height", self.box_height)?;
            }
            None => {
                if self.count.is_none() {
                    return Err(invalid(
                        "sample.count",
                        "missing",
                        "a number of grains to generate (at least 1), unless sample.file gives \
                         the grains",
                    ));
                }
                if self.radii.is_none() {
                    return Err(invalid(
                        "sample.radii",
                        "missing",
                        "a radius distribution (Gaussian, Fractal, Uniform, Monodisperse), unless \
                         sample.file gives the grains",
                    ));
                }
            }
        }
        Ok(())
    }

    /// `count`, when given, must be the number of grains `n` read from `path`.
    fn check_count(&self, n: usize, path: &Path) -> Result<(), ScenarioError> {
        match self.count {
            Some(count) if count != n => Err(invalid(
                "sample.count",
                count,
                &format!(
                    "the number of grains in {} ({n}), or left out",
                    path.display()
                ),
            )),
            _ => Ok(()),
        }
    }

    fn validate(&self) -> Result<(), ScenarioError> {
        self.validate_fields()?;
        if self.file.is_some() && matches!(self.shapes, Some(GrainShapes::File(_))) {
            return Err(invalid(
                "sample.shapes",
                "File(...) together with sample.file",
                "one of them: the shape file gives both shapes and positions",
            ));
        }
        if let Some(GrainShapes::File(f)) = &self.shapes {
            let Some(loaded) = &self.loaded_shapes else {
                return Err(invalid(
                    "sample.shapes",
                    format!("File({:?})", f.display().to_string()),
                    "read before the scenario is used (Scenario::load reads it)",
                ));
            };
            let n = loaded.grains.len();
            self.check_count(n, &loaded.path)?;
            let b = self.bounds();
            for (k, (c, shape)) in loaded.grains.iter().enumerate() {
                let r = shape.max_radius();
                if c[0] - r < b.x0 || c[0] + r > b.x1 || c[1] - r < b.y0 || c[1] + r > b.y1 {
                    return Err(invalid(
                        "sample.shapes",
                        format!(
                            "grain {k} of {} (centroid ({}, {}), radius up to {})",
                            loaded.path.display(),
                            num(c[0]),
                            num(c[1]),
                            num(r)
                        ),
                        "inside the box [x0, x1] x [y0, y1] of the sample",
                    ));
                }
            }
            return Ok(());
        }
        if let Some(spec) = self.spec() {
            return Ok(spec.validate()?);
        }
        let file = self.file.as_deref().unwrap_or(Path::new(""));
        let Some(loaded) = &self.loaded else {
            return Err(invalid(
                "sample.file",
                format!("{:?}", file.display().to_string()),
                "read before the scenario is used (Scenario::load reads it; a scenario parsed \
                 from text needs Scenario::load_sample)",
            ));
        };
        let n = loaded.grains.len();
        if n > MAX_COUNT {
            return Err(SampleError::TooManyGrains {
                count: n,
                max: MAX_COUNT,
            }
            .into());
        }
        self.check_count(n, &loaded.path)?;
        Ok(())
    }
}

/// The model level of the grains (SPEC §1): one for all, or adaptive per grain (issue #6).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Model {
    /// Level 0: rigid discs (x, y, theta).
    Rigid,
    /// Level 1: + one volumetric strain (eps1 = eps2, alpha frozen).
    Volumetric,
    /// Level 3: all six degrees of freedom.
    #[default]
    Full,
    /// The meshfree multibody solver (SPEC §10, §10b): every grain resolved by field nodes,
    /// implicit dynamics. `Meshfree()` takes the defaults of [`MeshfreeSettings`].
    Meshfree(MeshfreeSettings),
    /// Each grain moves between the three by its contact stress (see
    /// [`crate::grain::adaptive`]); every field is optional, the defaults are those of
    /// [`AdaptiveSettings::default`]. `Adaptive()` takes them all.
    Adaptive {
        #[serde(default = "adaptive_default::volumetric_up")]
        volumetric_up: f64,
        #[serde(default = "adaptive_default::volumetric_down")]
        volumetric_down: f64,
        #[serde(default = "adaptive_default::full_up")]
        full_up: f64,
        #[serde(default = "adaptive_default::full_down")]
        full_down: f64,
        #[serde(default = "adaptive_default::confirm")]
        confirm: u32,
        #[serde(default = "adaptive_default::dwell")]
        dwell: u32,
        /// Multi-rate cycles: while some grains deform, the rigid grains out of their reach
        /// take one step of twice the deforming grains' (see
        /// [`crate::integration::Adaptive::multi_rate`]). Off by default.
        #[serde(default)]
        multi_rate: bool,
    },
}

mod adaptive_default {
    use crate::grain::AdaptiveSettings;
    pub fn volumetric_up() -> f64 {
        AdaptiveSettings::default().volumetric_up
    }
    pub fn volumetric_down() -> f64 {
        AdaptiveSettings::default().volumetric_down
    }
    pub fn full_up() -> f64 {
        AdaptiveSettings::default().full_up
    }
    pub fn full_down() -> f64 {
        AdaptiveSettings::default().full_down
    }
    pub fn confirm() -> u32 {
        AdaptiveSettings::default().confirm
    }
    pub fn dwell() -> u32 {
        AdaptiveSettings::default().dwell
    }
}

impl Model {
    /// The adaptive model with these thresholds.
    pub fn adaptive_with(s: AdaptiveSettings) -> Self {
        Model::Adaptive {
            volumetric_up: s.volumetric_up,
            volumetric_down: s.volumetric_down,
            full_up: s.full_up,
            full_down: s.full_down,
            confirm: s.confirm,
            dwell: s.dwell,
            multi_rate: false,
        }
    }

    /// Whether the adaptive model takes multi-rate cycles.
    pub fn multi_rate(&self) -> bool {
        matches!(
            self,
            Model::Adaptive {
                multi_rate: true,
                ..
            }
        )
    }

    /// The thresholds, for the adaptive model.
    pub fn adaptive(&self) -> Option<AdaptiveSettings> {
        match *self {
            Model::Adaptive {
                volumetric_up,
                volumetric_down,
                full_up,
                full_down,
                confirm,
                dwell,
                ..
            } => Some(AdaptiveSettings {
                volumetric_up,
                volumetric_down,
                full_up,
                full_down,
                confirm,
                dwell,
            }),
            _ => None,
        }
    }

    /// The level of every grain; for the adaptive model, the highest one a grain can reach.
    pub fn level(&self) -> ModelLevel {
        match self {
            Model::Rigid => ModelLevel::Rigid,
            Model::Volumetric => ModelLevel::Volumetric,
            Model::Full | Model::Adaptive { .. } | Model::Meshfree(_) => ModelLevel::Full,
        }
    }
}

impl From<ModelLevel> for Model {
    fn from(level: ModelLevel) -> Self {
        match level {
            ModelLevel::Rigid => Model::Rigid,
            ModelLevel::Volumetric => Model::Volumetric,
            ModelLevel::Full => Model::Full,
        }
    }
}

/// Settings of the meshfree multibody solver (SPEC §10, §10b). Lengths and stiffnesses are
/// relative to the sample's mean grain radius `R` and to `E`, so that one setting serves any
/// sample size.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MeshfreeSettings {
    /// Field nodes on each grain's contour (the nodal density: interior nodes follow at the
    /// contour's spacing, graded inward). For discs it is rounded up to a multiple of 4.
    pub boundary_nodes: usize,
    /// Interior spacing grows from the contour's to `(1 + grading)` times it at the centre.
    pub grading: f64,
    pub law: HyperelasticLaw,
    pub scheme: TimeScheme,
    /// Initial contact stiffness k0, in units of `E / R` (reset at each sub-step).
    pub k0: f64,
    /// Factor on the contact stiffness at each augmentation.
    pub alpha_k: f64,
    /// The augmentations stop when every active contact's |gap| is below this, in units of R.
    pub gap_tolerance: f64,
    /// Newton stops when every residual component is below this, in units of `E R`.
    pub force_tolerance: f64,
    pub max_newton: usize,
    pub max_augmentations: usize,
    /// Rayleigh damping `C = alpha M + beta K_i0`: alpha (1/time) and beta (time).
    pub rayleigh_alpha: f64,
    pub rayleigh_beta: f64,
    /// Smallest sub-step a step that does not converge is cut into (a fraction of dt).
    pub min_sub_step: f64,
}

impl Default for MeshfreeSettings {
    fn default() -> Self {
        Self {
            boundary_nodes: 32,
            grading: 1.0,
            law: HyperelasticLaw::NeoHookean,
            scheme: TimeScheme::Bathe,
            k0: 1.0,
            alpha_k: 2.0,
            gap_tolerance: 1e-5,
            force_tolerance: 1e-10,
            max_newton: 30,
            max_augmentations: 40,
            rayleigh_alpha: 0.0,
            rayleigh_beta: 0.0,
            min_sub_step: 1.0 / 16.0,
        }
    }
}

impl MeshfreeSettings {
    /// The solver's absolute settings for a sample of mean radius `mean_radius`.
    pub fn solver(&self, young: f64, mean_radius: f64) -> SolverSettings {
        SolverSettings {
            k0: self.k0 * young / mean_radius,
            alpha_k: self.alpha_k,
            gap_tolerance: self.gap_tolerance * mean_radius,
            force_tolerance: self.force_tolerance * young * mean_radius,
            max_newton: self.max_newton,
            max_augmentations: self.max_augmentations,
        }
    }
}

/// The contours of the grains (meshfree solver only; SDEM grains are discs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum GrainShapes {
    /// Discs of the sample's radii.
    Discs,
    /// "Sand-like" contours: random Fourier shape descriptors about each grain's radius
    /// (SPEC §10b), seeded by the scenario's seed.
    SandLike,
    /// Polygons read from a file (format: [`crate::meshfree::shape::read_shape_file`]), in
    /// the box's coordinates, relative to the scenario file's folder: they give the grains'
    /// shapes and positions (no `count`, `radii` or `file` then).
    File(PathBuf),
}

/// The grains of a shape file, as read and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedShapes {
    /// The file as opened.
    pub path: PathBuf,
    /// Each grain's centroid (in the file's coordinates) and contour about it.
    pub grains: Vec<([f64; 2], StarShape)>,
}

/// What to do when a contact leaves the domain of the secant law (SPEC §5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum DomainExitPolicy {
    /// Stop the run with a diagnostic.
    #[default]
    Stop,
    /// Hold the law's denominator at its floor and go on (reported in the output).
    Cap,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ContactSettings {
    /// Constant a of the secant law (paper: 0.58).
    pub a: f64,
    /// Constant b of the secant law (paper: 2).
    pub b: f64,
    /// Contour resolution dbeta in degrees (paper: 1); 0 for the exact ellipses, the polygons'
    /// limit as dbeta -> 0 ([`Contours::Exact`](crate::geometry::Contours)).
    pub resolution_deg: f64,
    /// gamma of the contact dashpot (eq. 61), dimensionless.
    pub damping: f64,
    pub on_domain_exit: DomainExitPolicy,
    /// Domain floor: the law is left when `a L_c + (b-1) delta_n <= floor a L_c`.
    pub domain_floor: f64,
    /// Verlet skin as a fraction of the mean radius: the neighbour list's skin at the start,
    /// which the list widens while it is rebuilt often and narrows back towards this value
    /// while it lasts (`crate::geometry::broadphase::adapted_skin`). The results are the same
    /// bits with any skin; only the speed depends on it.
    pub skin: f64,
    /// Coulomb friction (SPEC §13): frictionless unless set.
    #[serde(skip_serializing_if = "FrictionSettings::is_default")]
    pub friction: FrictionSettings,
}

impl Default for ContactSettings {
    fn default() -> Self {
        Self {
            a: 0.58,
            b: 2.0,
            resolution_deg: 1.0,
            damping: 1.0,
            on_domain_exit: DomainExitPolicy::Stop,
            domain_floor: 0.05,
            skin: 0.2,
            friction: FrictionSettings::default(),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DeformationSettings {
    /// gamma of the deformation dashpots (eq. 62–64), 1/time (paper: 1 with E = rho = 1).
    pub damping: f64,
    /// k_alpha of eq. 60.
    pub k_alpha: f64,
    /// Mass scaling of M_alpha (1 = none; only licit for quasi-static runs), on top of
    /// `mass_scale`.
    pub alpha_mass_scale: f64,
    /// Mass scaling of the deformation DoF, M_eps and M_alpha (1 = none; only licit for
    /// quasi-static runs): the strains respond sqrt(mass_scale) times slower, and the deformable
    /// levels' critical step grows towards the rigid one (sqrt((1 + 4) / (1 + 4 / mass_scale))
    /// times longer; docs/performance.md).
    pub mass_scale: f64,
}

impl Default for DeformationSettings {
    fn default() -> Self {
        Self {
            damping: 1.0,
            k_alpha: 1e-3,
            alpha_mass_scale: 1.0,
            mass_scale: 1.0,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum TimeStep {
    /// A fraction of the critical time step estimated for the smallest grain (SPEC §9).
    FractionOfCritical(f64),
    /// A fixed time step.
    Fixed(f64),
}

impl Default for TimeStep {
    fn default() -> Self {
        TimeStep::FractionOfCritical(0.4)
    }
}

/// How often a run writes its checkpoint (see `docs/checkpoints.md`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum CheckpointInterval {
    /// After every step that is a multiple of this.
    EverySteps(u64),
    /// After the first step that ends at least this many wall-clock seconds after the last
    /// checkpoint (or the start). Results do not depend on when checkpoints are written.
    EverySeconds(f64),
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutputSettings {
    /// A row of macro.csv every this many steps (and at every phase end and at jamming).
    pub every: u64,
    /// Jamming threshold p_jam as a fraction of E (SPEC §7).
    pub jamming_pressure: f64,
    /// Hard limit on the number of steps (0 = none).
    pub max_steps: u64,
    /// Keep the latest checkpoint in `OUT/checkpoint.bin` (the command line's
    /// `--checkpoint-every` / `--checkpoint-every-seconds` override it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub checkpoint: Option<CheckpointInterval>,
}

impl Default for OutputSettings {
    fn default() -> Self {
        Self {
            every: 1000,
            jamming_pressure: 1e-5,
            max_steps: 0,
            checkpoint: None,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file could not be read. The reason is the error's `source`, not repeated in its
    /// message (anyhow prints the chain: `{:#}` as `...: reason`).
    #[error("cannot read scenario {path}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    /// Malformed RON, an unknown or missing field, a value of the wrong type.
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        path: String,
        /// 1-based line of the offending token.
        line: usize,
        /// 1-based column (in characters) of the offending token.
        column: usize,
        /// The parser's message, followed by the offending line with a caret under `column`.
        message: String,
    },
    #[error("scenario field `{field}` = {value}: must be {allowed}")]
    Invalid {
        field: String,
        value: String,
        allowed: String,
    },
    #[error(transparent)]
    Sample(#[from] SampleError),
    #[error(transparent)]
    SampleFile(#[from] SampleFileError),
    #[error(transparent)]
    ShapeFile(#[from] ShapeFileError),
}

fn invalid(field: &str, value: impl std::fmt::Display, allowed: &str) -> ScenarioError {
    ScenarioError::Invalid {
        field: field.to_string(),
        value: value.to_string(),
        allowed: allowed.to_string(),
    }
}

/// A number as a user wrote it: plain for ordinary magnitudes, in exponent form (`1e-200`)
/// where the plain form would run to dozens of digits.
fn num(x: f64) -> String {
    if x == 0.0 || !x.is_finite() || (1e-5..1e16).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// A number to four decimals, without trailing zeros (`19`, `0.4375`).
fn short(x: f64) -> String {
    let text = format!("{x:.4}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

/// `value` must be finite and strictly positive.
fn positive(field: &str, value: f64) -> Result<(), ScenarioError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(invalid(field, num(value), "a finite number > 0"))
    }
}

fn non_negative(field: &str, value: f64) -> Result<(), ScenarioError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(invalid(field, num(value), "a finite number >= 0"))
    }
}

impl Scenario {
    /// Reads and validates a scenario file; returns it with the warnings it deserves.
    pub fn load(path: &Path) -> Result<(Scenario, Vec<String>), ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Io {
            path: path.display().to_string(),
            source,
        })?;
        let mut scenario = Self::parse(&text, &path.display().to_string())?;
        let base = path.parent().unwrap_or(Path::new(""));
        if scenario.sample.file.is_some() {
            scenario.load_sample(base)?;
        }
        if let Some(GrainShapes::File(file)) = &scenario.sample.shapes {
            let path = base.join(file);
            let grains = read_shape_file(&path)?;
            scenario.sample.loaded_shapes = Some(Arc::new(LoadedShapes { path, grains }));
        }
        let warnings = scenario.validate()?;
        Ok((scenario, warnings))
    }

    /// Reads and checks the grains of `sample.file` (a path relative to `base`, the scenario
    /// file's folder, unless absolute) against the box, each other and the contact law (see
    /// [`crate::sample::file`]); keeps them in `sample.loaded`. Does nothing for a generated
    /// sample. The settings the check needs (contact law, contour resolution) are validated
    /// first.
    pub fn load_sample(&mut self, base: &Path) -> Result<(), ScenarioError> {
        let Some(file) = &self.sample.file else {
            return Ok(());
        };
        self.validate_settings()?;
        self.sample.validate_fields()?;
        let path = base.join(file);
        let sample = read_grains(&path)?;
        check_packing(
            &path.display().to_string(),
            &sample,
            self.sample.bounds(),
            &self.secant_law(),
            self.contact.resolution_deg,
        )?;
        self.sample.loaded = Some(Arc::new(LoadedSample {
            path,
            grains: sample.grains,
        }));
        Ok(())
    }

    /// Parses RON text; errors carry the line and column of the offending token and quote its
    /// line.
    pub fn parse(text: &str, path: &str) -> Result<Scenario, ScenarioError> {
        ron_options().from_str::<Scenario>(text).map_err(|e| {
            let (line, column) = token_start(text, e.span.start, e.span.end);
            ScenarioError::Parse {
                path: path.to_string(),
                line,
                column,
                message: format!("{}{}", e.code, excerpt(text, line, column)),
            }
        })
    }

    /// Checks every field; returns warnings for legal but suspicious choices. A sample read
    /// from a file must have been read ([`Scenario::load_sample`]).
    pub fn validate(&self) -> Result<Vec<String>, ScenarioError> {
        self.sample.validate()?;
        let mut warnings = self.validate_settings()?;
        self.validate_time_step(&mut warnings)?;
        // SDEM's step reads grains by number (the meshfree solver's nodes are its own).
        if !matches!(self.model, Model::Meshfree(_))
            && let Some(loaded) = &self.sample.loaded
        {
            let scattered = crate::sample::order::numbering_warning("sample.file", &loaded.grains);
            if scattered.is_none() {
                warnings.extend(crate::sample::order::threads_wait_warning(
                    "sample.file",
                    &loaded.grains,
                    self.contact.skin * self.mean_radius(),
                ));
            }
            warnings.extend(scattered);
        }
        Ok(warnings)
    }

    /// What only one solver accepts: the meshfree settings and shapes (meshfree), an affine
    /// phase or a critical-fraction time step (SDEM).
    fn validate_solver_choice(&self, warnings: &mut Vec<String>) -> Result<(), ScenarioError> {
        let Model::Meshfree(s) = self.model else {
            if let Some(shapes) = &self.sample.shapes
                && *shapes != GrainShapes::Discs
            {
                return Err(invalid(
                    "sample.shapes",
                    format!("{shapes:?}"),
                    "Discs, or left out: SDEM grains are discs (model: Meshfree(...) resolves \
                     grains of any shape)",
                ));
            }
            return Ok(());
        };
        let friction = &self.contact.friction;
        if friction.damping != 0.0 {
            return Err(invalid(
                "contact.friction.damping",
                num(friction.damping),
                "0 for model: Meshfree (its frictional contacts have no tangential dashpot)",
            ));
        }
        if self.material.poisson >= 0.5 {
            return Err(invalid(
                "material.poisson",
                num(self.material.poisson),
                "below 0.5 for model: Meshfree (its hyperelastic laws are compressible; \
                 nu <= 0.45 is free of volumetric locking at the usual nodal densities)",
            ));
        }
        if self.material.poisson > 0.45 {
            warnings.push(format!(
                "material.poisson = {}: watch for volumetric locking of the meshfree grains \
                 (check convergence in model.Meshfree.boundary_nodes)",
                self.material.poisson
            ));
        }
        let f = "model.Meshfree";
        if s.boundary_nodes < 8 {
            return Err(invalid(
                &format!("{f}.boundary_nodes"),
                s.boundary_nodes,
                "at least 8 (a grain needs 21 field nodes for its 20-neighbour supports)",
            ));
        }
        non_negative(&format!("{f}.grading"), s.grading)?;
        positive(&format!("{f}.k0"), s.k0)?;
        if !(s.alpha_k.is_finite() && s.alpha_k >= 1.0) {
            return Err(invalid(&format!("{f}.alpha_k"), num(s.alpha_k), ">= 1"));
        }
        positive(&format!("{f}.gap_tolerance"), s.gap_tolerance)?;
        positive(&format!("{f}.force_tolerance"), s.force_tolerance)?;
        if s.max_newton == 0 || s.max_augmentations == 0 {
            return Err(invalid(
                &format!("{f}.max_newton / max_augmentations"),
                format!("{} / {}", s.max_newton, s.max_augmentations),
                "at least 1 each",
            ));
        }
        non_negative(&format!("{f}.rayleigh_alpha"), s.rayleigh_alpha)?;
        non_negative(&format!("{f}.rayleigh_beta"), s.rayleigh_beta)?;
        if !(s.min_sub_step > 0.0 && s.min_sub_step <= 1.0) {
            return Err(invalid(
                &format!("{f}.min_sub_step"),
                num(s.min_sub_step),
                "in (0, 1]",
            ));
        }
        if !matches!(self.time_step, TimeStep::Fixed(_)) {
            return Err(invalid(
                "time_step",
                format!("{:?}", self.time_step),
                "Fixed(dt) for model: Meshfree (an implicit solver has no critical step)",
            ));
        }
        for (k, phase) in self.loading.iter().enumerate() {
            if matches!(
                phase,
                Phase::Isotropic { affine: true, .. } | Phase::Oedometric { affine: true, .. }
            ) {
                return Err(invalid(
                    &format!("loading[{k}].affine"),
                    "true",
                    "false for model: Meshfree (its grains follow the walls through contact)",
                ));
            }
        }
        Ok(())
    }

    /// Every check that needs neither the sample nor the time step.
    fn validate_settings(&self) -> Result<Vec<String>, ScenarioError> {
        let mut warnings = Vec::new();
        if self.name.trim().is_empty()
            || self.name == "."
            || self.name == ".."
            || self.name.contains(['/', '\\'])
            || self.name.chars().any(char::is_control)
        {
            return Err(invalid(
                "name",
                format!("{:?}", self.name),
                "a non-empty name without path separators (it names the default output folder \
                 out/<name>)",
            ));
        }
        let m = &self.material;
        positive("material.young", m.young)?;
        positive("material.density", m.density)?;
        if !(m.poisson.is_finite() && (0.0..=0.5).contains(&m.poisson)) {
            return Err(invalid(
                "material.poisson",
                num(m.poisson),
                "in [0, 0.5] (0.5 = incompressible)",
            ));
        }
        if !m.is_incompressible() && m.poisson > 0.49 {
            warnings.push(format!(
                "material.poisson = {}: the bulk modulus is {:.1} E and the critical time step shrinks \
                 with it; nu = 0.5 uses the incompressible law, which has no such cost",
                m.poisson,
                m.bulk_modulus() / m.young
            ));
        }
        if let Some(a) = self.model.adaptive() {
            a.check().map_err(|(field, value, allowed)| {
                invalid(&format!("model.Adaptive.{field}"), num(value), allowed)
            })?;
        }
        if !(self.gravity.0.is_finite() && self.gravity.1.is_finite()) {
            return Err(invalid(
                "gravity",
                format!("({}, {})", num(self.gravity.0), num(self.gravity.1)),
                "two finite numbers",
            ));
        }
        self.validate_solver_choice(&mut warnings)?;
        self.validate_boundary(&mut warnings)?;
        self.validate_friction()?;
        self.validate_multi_rate()?;
        let c = &self.contact;
        positive("contact.a", c.a)?;
        positive("contact.b", c.b)?;
        if !(c.resolution_deg.is_finite() && c.resolution_deg >= 0.0 && c.resolution_deg <= 45.0) {
            return Err(invalid(
                "contact.resolution_deg",
                num(c.resolution_deg),
                "in (0, 45] degrees, or 0 for the exact ellipses",
            ));
        }
        non_negative("contact.damping", c.damping)?;
        if !(c.domain_floor.is_finite() && c.domain_floor > 0.0 && c.domain_floor < 1.0) {
            return Err(invalid(
                "contact.domain_floor",
                num(c.domain_floor),
                "in (0, 1)",
            ));
        }
        non_negative("contact.skin", c.skin)?;
        let d = &self.deformation;
        non_negative("deformation.damping", d.damping)?;
        non_negative("deformation.k_alpha", d.k_alpha)?;
        positive("deformation.alpha_mass_scale", d.alpha_mass_scale)?;
        if !(d.mass_scale.is_finite() && d.mass_scale >= 1.0) {
            return Err(invalid(
                "deformation.mass_scale",
                num(d.mass_scale),
                "a finite factor >= 1 (1 = the grains' own inertia)",
            ));
        }
        if c.damping == 0.0 {
            warnings.push("contact.damping = 0: nothing dissipates energy at contacts; a compaction will not be quasi-static".into());
        }
        if d.mass_scale > 1.0 {
            warnings.push(format!(
                "deformation.mass_scale = {}: the grains' strains answer a load {:.2} times \
                 slower than their own inertia allows; for quasi-static runs only, and p_c just \
                 above jamming moves (about -5% at phi = 0.86 with 4; docs/speed_accuracy.md)",
                d.mass_scale,
                d.mass_scale.sqrt()
            ));
        }
        if self.loading.is_empty() {
            return Err(invalid("loading", "[]", "a list of at least one phase"));
        }
        for (k, phase) in self.loading.iter().enumerate() {
            let field = format!("loading[{k}]");
            match phase {
                Phase::Isotropic { rate, until, .. }
                | Phase::Oedometric { rate, until, .. }
                | Phase::Uniaxial { rate, until }
                | Phase::Biaxial { rate, until } => {
                    validate_rate(&format!("{field}.rate"), rate, &mut warnings)?;
                    validate_until(&format!("{field}.until"), until)?;
                }
                Phase::Servo {
                    sxx,
                    syy,
                    gain,
                    max_rate,
                    until,
                } => {
                    compressive_target(&format!("{field}.sxx"), *sxx)?;
                    compressive_target(&format!("{field}.syy"), *syy)?;
                    positive(&format!("{field}.gain"), *gain)?;
                    if *gain > 1.0 {
                        warnings.push(format!(
                            "{field}.gain = {gain}: the contact dashpot feeds the wall velocity back into \
                             the wall stress; gains above ~1 can make the servo oscillate (0.5 is stable)"
                        ));
                    }
                    positive(&format!("{field}.max_rate"), *max_rate)?;
                    validate_until(&format!("{field}.until"), until)?;
                    // The servo holds p_c at the mean of its targets: a phase that can only end
                    // on a higher mean stress would never end.
                    let held = 0.5 * (sxx + syy);
                    let mut stresses = Vec::new();
                    stress_conditions(&format!("{field}.until"), until, &mut stresses);
                    if only_stress_conditions(until)
                        && let Some((f, p)) = stresses.iter().find(|(_, p)| *p > held)
                    {
                        return Err(invalid(
                            f,
                            format!("MeanStress({})", num(*p)),
                            &format!(
                                "at most the mean stress the servo holds, (sxx + syy)/2 = {}, or \
                                 combined with a condition that can end the phase (Any([.., Steps(n)])): \
                                 the phase would never end",
                                num(held)
                            ),
                        ));
                    }
                }
                Phase::Shear {
                    rate,
                    syy,
                    gain,
                    max_rate,
                    until,
                } => {
                    if !(rate.is_finite() && *rate != 0.0) {
                        return Err(invalid(
                            &format!("{field}.rate"),
                            num(*rate),
                            "a finite, non-zero shear rate (1/time; negative shears the other way)",
                        ));
                    }
                    compressive_target(&format!("{field}.syy"), *syy)?;
                    if !(gain.is_finite() && *gain > 0.0) {
                        return Err(invalid(
                            &format!("{field}.gain"),
                            num(*gain),
                            "a positive servo gain: the normal stress syy is stress-controlled, \
                             and without a gain the cell height would never respond (0.5 is stable)",
                        ));
                    }
                    positive(&format!("{field}.max_rate"), *max_rate)?;
                    validate_until(&format!("{field}.until"), until)?;
                    self.shear_rate_warning(&field, *rate, *syy, &mut warnings);
                }
                Phase::Relax { until } => {
                    validate_until(&format!("{field}.until"), until)?;
                    if only_stress_conditions(until) {
                        warnings.push(format!(
                            "{field}: a Relax phase that ends only on MeanStress: the walls stand \
                             still and p_c only relaxes, so it ends at once or never"
                        ));
                    }
                }
            }
            let mut targets = Vec::new();
            if let Phase::Servo { sxx, syy, .. } = phase {
                targets.push((format!("{field}.sxx"), *sxx));
                targets.push((format!("{field}.syy"), *syy));
            }
            stress_conditions(&format!("{field}.until"), phase.until(), &mut targets);
            for (f, target) in targets {
                self.stress_target_warning(&f, target, &mut warnings);
            }
        }
        if self.output.every == 0 {
            return Err(invalid("output.every", 0, "at least 1 step"));
        }
        positive("output.jamming_pressure", self.output.jamming_pressure)?;
        match self.output.checkpoint {
            Some(CheckpointInterval::EverySteps(0)) => {
                return Err(invalid(
                    "output.checkpoint",
                    "EverySteps(0)",
                    "EverySteps(n) with n >= 1, or EverySeconds(s) with s > 0",
                ));
            }
            Some(CheckpointInterval::EverySeconds(s)) => {
                positive("output.checkpoint.EverySeconds", s)?;
            }
            _ => {}
        }
        Ok(warnings)
    }

    /// Multi-rate cycles hold the forces between the grains that take one step of a cycle and
    /// those that take two: a frictional contact's spring and a periodic cell's images and
    /// stress would need their own substeps, which are not written.
    fn validate_multi_rate(&self) -> Result<(), ScenarioError> {
        if !self.model.multi_rate() {
            return Ok(());
        }
        if self.friction().is_some() {
            return Err(invalid(
                "model.Adaptive.multi_rate",
                "true",
                "false with friction (contact.friction): multi-rate cycles are frictionless",
            ));
        }
        if !self.boundary.is_walls() {
            return Err(invalid(
                "model.Adaptive.multi_rate",
                "true",
                "false in a periodic cell (boundary: Periodic): multi-rate cycles need walls",
            ));
        }
        Ok(())
    }

    /// Friction coefficients and the tangential spring; the planes.
    fn validate_friction(&self) -> Result<(), ScenarioError> {
        self.contact
            .friction
            .check()
            .map_err(|(field, value, allowed)| {
                invalid(&format!("contact.friction.{field}"), num(value), allowed)
            })?;
        if self.planes.len() > MAX_PLANES {
            return Err(invalid(
                "planes",
                format!("{} planes", self.planes.len()),
                &format!("at most {MAX_PLANES} (besides the four box walls)"),
            ));
        }
        if !self.planes.is_empty() && !self.boundary.is_walls() {
            return Err(invalid(
                "planes",
                format!("{} planes", self.planes.len()),
                "none in a periodic cell (boundary: Periodic has no walls)",
            ));
        }
        for (k, plane) in self.planes.iter().enumerate() {
            let (x, y) = plane.point;
            if !(x.is_finite() && y.is_finite()) {
                return Err(invalid(
                    &format!("planes[{k}].point"),
                    format!("({}, {})", num(x), num(y)),
                    "two finite numbers",
                ));
            }
            let (nx, ny) = plane.normal;
            let length = libm::hypot(nx, ny);
            if !(length.is_finite() && length > 0.0) {
                return Err(invalid(
                    &format!("planes[{k}].normal"),
                    format!("({}, {})", num(nx), num(ny)),
                    "a finite vector of non-zero length, pointing to the grains' side",
                ));
            }
            if !is_coefficient(plane.friction) {
                return Err(invalid(
                    &format!("planes[{k}].friction"),
                    num(plane.friction),
                    COEFFICIENT_RANGE,
                ));
            }
        }
        Ok(())
    }

    /// The walls of a run: the sample box's four (in the order of
    /// [`crate::boundary::walls::box_walls`]), then the planes.
    pub fn walls(&self) -> Vec<Wall> {
        let b = self.sample.bounds();
        let mut walls = box_walls(b.x0, b.x1, b.y0, b.y1);
        walls.extend(self.planes.iter().map(|p| {
            Wall::new(
                DVec2::new(p.point.0, p.point.1),
                DVec2::new(p.normal.0, p.normal.1),
            )
        }));
        walls
    }

    /// Coulomb coefficient of each wall: the four box walls' (`contact.friction.walls`, or
    /// `each_wall`), then the planes'.
    pub fn wall_friction(&self) -> Vec<f64> {
        let mut mu = self.contact.friction.box_walls().to_vec();
        mu.extend(self.planes.iter().map(|p| p.friction));
        mu
    }

    /// The friction of the run's contacts (`None` when every coefficient is zero).
    pub fn friction(&self) -> Option<Friction> {
        Friction::new(&self.contact.friction, &self.wall_friction())
    }

    /// `r_t` of the scenario's frictional contacts, 0 when every contact is frictionless (it
    /// enters the critical time step).
    pub fn tangential_ratio(&self) -> f64 {
        Friction::tangential_ratio(&self.friction())
    }

    /// Friction's tangential ratio and the deformation mass scale, for the critical step.
    pub fn mode_settings(&self) -> ModeSettings {
        ModeSettings {
            tangential_ratio: self.tangential_ratio(),
            deformation_mass_scale: self.deformation.mass_scale,
        }
    }

    /// The periodic cell's checks: SDEM only; a cell at least twice the interaction range wide;
    /// shear phases and shear-strain stops only in a periodic cell.
    fn validate_boundary(&self, warnings: &mut Vec<String>) -> Result<(), ScenarioError> {
        let _ = warnings;
        if self.boundary.is_walls() {
            for (k, phase) in self.loading.iter().enumerate() {
                if matches!(phase, Phase::Shear { .. }) {
                    return Err(invalid(
                        &format!("loading[{k}]"),
                        "Shear(..)",
                        "a phase of a periodic cell (boundary: Periodic): walls cannot shear",
                    ));
                }
                if has_shear_strain(phase.until()) {
                    return Err(invalid(
                        &format!("loading[{k}].until"),
                        "ShearStrain(..)",
                        "a stop condition of a periodic cell (boundary: Periodic)",
                    ));
                }
            }
            return Ok(());
        }
        if matches!(self.model, Model::Meshfree(_)) {
            return Err(invalid(
                "boundary",
                "Periodic",
                "Walls for model: Meshfree (its periodic cell is not written yet)",
            ));
        }
        let Some(range) = self.interaction_range() else {
            return Ok(());
        };
        let narrowest = self.sample.box_width.min(self.sample.box_height);
        if narrowest < 2.0 * range {
            return Err(invalid(
                "sample.box_width / box_height",
                format!(
                    "{} x {}",
                    num(self.sample.box_width),
                    num(self.sample.box_height)
                ),
                &format!(
                    "at least {} on each side in a periodic cell: twice the largest grain \
                     diameter plus the neighbour skin ({}), so that a grain meets one image of \
                     another at most; the cell must stay that wide as it is compressed",
                    num(2.0 * range),
                    num(range)
                ),
            ));
        }
        Ok(())
    }

    /// The interaction range of the neighbour search, largest grain diameter + skin (None while
    /// the sample file is not read): a periodic cell must stay twice as wide.
    pub fn interaction_range(&self) -> Option<f64> {
        let largest = match (&self.sample.loaded, &self.sample.radii) {
            (Some(l), _) => l.grains.iter().map(|g| g.radius).fold(0.0, f64::max),
            (None, Some(r)) => r.max_radius(),
            (None, None) => return None,
        };
        Some(2.0 * largest + self.contact.skin * self.mean_radius())
    }

    /// The mean grain radius: the distribution's, or the file's grains' (NaN while unknown).
    pub fn mean_radius(&self) -> f64 {
        match (&self.sample.loaded, &self.sample.radii) {
            (Some(l), _) => {
                l.grains.iter().map(|g| g.radius).sum::<f64>() / l.grains.len().max(1) as f64
            }
            (None, Some(r)) => r.mean_radius(),
            (None, None) => f64::NAN,
        }
    }

    /// Warns when a shear phase is not quasi-static: the inertial number
    /// `|rate| d_mean sqrt(rho / syy)` at its normal stress above 1e-3 (SPEC §7).
    fn shear_rate_warning(&self, field: &str, rate: f64, syy: f64, warnings: &mut Vec<String>) {
        let d = 2.0 * self.mean_radius();
        let inertial = rate.abs() * d * (self.material.density / syy).sqrt();
        if inertial > 1e-3 {
            warnings.push(format!(
                "{field}.rate = {rate}: the inertial number |rate| d_mean sqrt(rho / syy) is \
                 {inertial:.2e}, above the quasi-static limit 1e-3: the shear stress will \
                 include inertial (rate-dependent) stress; use |rate| <= {:.2e} for a \
                 quasi-static test",
                1e-3 / (d * (self.material.density / syy).sqrt())
            ));
        }
    }

    /// The largest mean stress the contact law can carry before it leaves its domain (None when
    /// it cannot leave it: `Cap`, or b <= 1). A grain's mean Love–Weber stress is
    /// `sum(F_k r_k) / (2 A)`; with `r_k ~ R`, `A ~ pi R^2` and the contact lengths adding up to at
    /// most the perimeter `2 pi R`, and `|F| / L_c = E |eps_n|` below
    /// `E (1 - floor) / ((b - 1) floor)` inside the domain, p_c stays below that bound.
    pub fn law_stress_limit(&self) -> Option<f64> {
        let c = &self.contact;
        (c.on_domain_exit == DomainExitPolicy::Stop && c.b > 1.0)
            .then(|| self.material.young * (1.0 - c.domain_floor) / ((c.b - 1.0) * c.domain_floor))
    }

    fn stress_target_warning(&self, field: &str, target: f64, warnings: &mut Vec<String>) {
        let young = self.material.young;
        if let Some(limit) = self.law_stress_limit()
            && target >= limit
        {
            warnings.push(format!(
                "{field} = {}: above the largest mean stress the contact law can carry, about \
                 E (1 - domain_floor) / ((b - 1) domain_floor) = {}: contacts will leave the law's \
                 domain first and the run will stop there",
                num(target),
                short(limit)
            ));
        } else if target >= STRESS_WARNING_FRACTION * young {
            warnings.push(format!(
                "{field} = {}: {:.2} x E, of the order of the grains' Young's modulus: grains \
                 strain by tens of percent and the packing fraction approaches 1 long before; the \
                 run stops with an error if the phase can no longer progress",
                num(target),
                target / young
            ));
        }
    }

    /// The time step against its critical estimate (which needs the smallest radius).
    fn validate_time_step(&self, warnings: &mut Vec<String>) -> Result<(), ScenarioError> {
        if let (Model::Meshfree(_), TimeStep::Fixed(dt)) = (self.model, self.time_step) {
            return positive("time_step.Fixed", dt);
        }
        let m = &self.material;
        let critical = self.critical_time_step();
        match self.time_step {
            TimeStep::FractionOfCritical(f) => {
                positive("time_step.FractionOfCritical", f)?;
                if f > 1.0 {
                    warnings.push(format!(
                        "time_step = {f} x the critical estimate {critical:.3e}: expect an instability"
                    ));
                }
            }
            TimeStep::Fixed(dt) => {
                positive("time_step.Fixed", dt)?;
                if dt > critical {
                    warnings.push(format!(
                        "time_step = {dt:.3e} is above the critical estimate {critical:.3e} \
                         (smallest grain, stiffest contact): expect an instability"
                    ));
                }
            }
        }
        // Extreme but individually legal values (tiny radii, huge E / rho) can make the
        // critical estimate, and with it the time step, 0 or non-finite.
        let dt = self.time_step_value();
        if !(dt.is_finite() && dt > 0.0) {
            return Err(invalid(
                "time_step",
                format!("{:?} (dt = {})", self.time_step, num(dt)),
                &format!(
                    "a time step that is finite and > 0; the critical estimate is {} for the \
                     smallest radius {} with material.young = {} and material.density = {}: \
                     rescale the material or sample.radii",
                    num(critical),
                    num(self.smallest_radius()),
                    num(m.young),
                    num(m.density)
                ),
            ));
        }
        Ok(())
    }

    pub fn critical_time_step(&self) -> f64 {
        frictional_critical_time_step(
            &self.material,
            &self.secant_law(),
            self.smallest_radius(),
            self.model.level(),
            self.mode_settings(),
        )
    }

    /// The critical time step while every grain is rigid (the adaptive model's largest step).
    pub fn rigid_critical_time_step(&self) -> f64 {
        frictional_critical_time_step(
            &self.material,
            &self.secant_law(),
            self.smallest_radius(),
            ModelLevel::Rigid,
            self.mode_settings(),
        )
    }

    /// The smallest grain radius, which sets the critical time step: the distribution's lower
    /// bound for a generated sample, the smallest radius of the file's grains otherwise (NaN
    /// while the file is not read).
    pub fn smallest_radius(&self) -> f64 {
        match (&self.sample.loaded, &self.sample.radii) {
            (Some(l), _) => l.smallest_radius(),
            (None, Some(r)) => r.min_radius(),
            (None, None) => f64::NAN,
        }
    }

    pub fn time_step_value(&self) -> f64 {
        match self.time_step {
            TimeStep::FractionOfCritical(f) => f * self.critical_time_step(),
            TimeStep::Fixed(dt) => dt,
        }
    }

    pub fn secant_law(&self) -> SecantLaw {
        SecantLaw {
            young: self.material.young,
            a: self.contact.a,
            b: self.contact.b,
            floor: self.contact.domain_floor,
            cap: self.contact.on_domain_exit == DomainExitPolicy::Cap,
        }
    }

    /// The engine parameters this scenario asks for.
    pub fn parameters(&self) -> Parameters {
        let adaptive = self.model.adaptive().map(|settings| Adaptive {
            multi_rate: self.model.multi_rate(),
            ..match self.time_step {
                TimeStep::FractionOfCritical(f) => Adaptive::fraction_of_critical(
                    settings,
                    f,
                    &self.material,
                    &self.secant_law(),
                    self.smallest_radius(),
                    self.mode_settings(),
                ),
                TimeStep::Fixed(dt) => Adaptive {
                    settings,
                    dt: [dt; 3],
                    multi_rate: false,
                },
            }
        });
        Parameters {
            material: self.material,
            level: self.model.level(),
            adaptive,
            law: self.secant_law(),
            resolution_deg: self.contact.resolution_deg,
            contact_damping: self.contact.damping,
            deformation_damping: self.deformation.damping,
            k_alpha: self.deformation.k_alpha,
            alpha_mass_scale: self.deformation.alpha_mass_scale,
            deformation_mass_scale: self.deformation.mass_scale,
            dt: self.time_step_value(),
            skin_fraction: self.contact.skin,
            friction: self.friction(),
            gravity: DVec2::new(self.gravity.0, self.gravity.1),
        }
    }
}

/// Position of the offending token: ron's span may start on the blank before it.
fn token_start(
    text: &str,
    start: ron::error::Position,
    end: ron::error::Position,
) -> (usize, usize) {
    let (line, mut column) = (start.line, start.col);
    if let Some(src) = text.lines().nth(line.saturating_sub(1)) {
        let chars: Vec<char> = src.chars().collect();
        while (line, column) < (end.line, end.col)
            && matches!(chars.get(column.saturating_sub(1)), Some(' ' | '\t'))
        {
            column += 1;
        }
    }
    (line, column)
}

/// The source line `line` (1-based) and a caret under `column`, for a parse error; long lines
/// are cut to a window around the column.
fn excerpt(text: &str, line: usize, column: usize) -> String {
    const WIDTH: usize = 100;
    let Some(src) = text.lines().nth(line.saturating_sub(1)) else {
        return String::new();
    };
    let chars: Vec<char> = src.chars().collect();
    let caret = column.saturating_sub(1).min(chars.len());
    let (from, to) = if chars.len() <= WIDTH {
        (0, chars.len())
    } else {
        let from = caret.saturating_sub(WIDTH / 2).min(chars.len() - WIDTH);
        (from, from + WIDTH)
    };
    let head = if from > 0 { "..." } else { "" };
    let tail = if to < chars.len() { "..." } else { "" };
    let shown: String = chars[from..to].iter().collect();
    let pad: String = std::iter::repeat_n(' ', head.len())
        .chain(
            chars[from..caret]
                .iter()
                .map(|&c| if c == '\t' { '\t' } else { ' ' }),
        )
        .collect();
    let number = line.to_string();
    let gutter = " ".repeat(number.len());
    format!("\n {number} | {head}{shown}{tail}\n {gutter} | {pad}^")
}

fn validate_rate(
    field: &str,
    rate: &StrainRate,
    warnings: &mut Vec<String>,
) -> Result<(), ScenarioError> {
    match rate {
        StrainRate::Constant(r) => {
            if !r.is_finite() {
                return Err(invalid(field, num(*r), "a finite strain rate"));
            }
            if *r <= 0.0 {
                warnings.push(format!(
                    "{field} = Constant({r}): the box does not shrink; a phase that waits for a \
                     packing fraction, a stress or jamming may never end (set output.max_steps)"
                ));
            }
        }
        StrainRate::QuasiStatic {
            inertial_number,
            max,
            fast,
            fast_until_phi,
        } => {
            positive(&format!("{field}.inertial_number"), *inertial_number)?;
            positive(&format!("{field}.max"), *max)?;
            positive(&format!("{field}.fast"), *fast)?;
            if !(fast_until_phi.is_finite() && *fast_until_phi >= 0.0 && *fast_until_phi <= 1.0) {
                return Err(invalid(
                    &format!("{field}.fast_until_phi"),
                    num(*fast_until_phi),
                    "in [0, 1]",
                ));
            }
            if *inertial_number > 1e-3 {
                warnings.push(format!(
                    "{field}.inertial_number = {inertial_number}: above 1e-3 the compaction is not quasi-static (SPEC §7)"
                ));
            }
        }
    }
    Ok(())
}

/// A stress target at or above this fraction of E gets a warning.
pub const STRESS_WARNING_FRACTION: f64 = 0.5;

/// A target wall stress (compression positive): finite and > 0.
fn compressive_target(field: &str, value: f64) -> Result<(), ScenarioError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            field,
            num(value),
            "a finite compressive stress > 0 (compression positive): frictionless grains carry \
             no tension, and a zero target would open the box without end",
        ))
    }
}

/// The `MeanStress` conditions of a stop condition, with their field names.
fn stress_conditions(field: &str, until: &StopWhen, out: &mut Vec<(String, f64)>) {
    match until {
        StopWhen::MeanStress(p) => out.push((field.to_string(), *p)),
        StopWhen::Any(list) => {
            for (k, u) in list.iter().enumerate() {
                stress_conditions(&format!("{field}[{k}]"), u, out);
            }
        }
        _ => {}
    }
}

/// Whether a stop condition names a shear strain (only a periodic cell shears).
fn has_shear_strain(until: &StopWhen) -> bool {
    match until {
        StopWhen::ShearStrain(_) => true,
        StopWhen::Any(list) => list.iter().any(has_shear_strain),
        _ => false,
    }
}

/// Whether a stop condition can only be met by a mean stress.
fn only_stress_conditions(until: &StopWhen) -> bool {
    match until {
        StopWhen::MeanStress(_) => true,
        StopWhen::Any(list) => list.iter().all(only_stress_conditions),
        _ => false,
    }
}

fn validate_until(field: &str, until: &StopWhen) -> Result<(), ScenarioError> {
    match until {
        StopWhen::PackingFraction(phi) => {
            if !(phi.is_finite() && *phi > 0.0 && *phi < 1.0) {
                return Err(invalid(field, num(*phi), "a packing fraction in (0, 1)"));
            }
        }
        StopWhen::MeanStress(p) => compressive_target(field, *p)?,
        StopWhen::Time(t) => positive(field, *t)?,
        StopWhen::Strain(e) | StopWhen::VerticalStrain(e) => {
            if !(e.is_finite() && *e > 0.0 && *e < 1.0) {
                return Err(invalid(field, num(*e), "a strain in (0, 1)"));
            }
        }
        StopWhen::ShearStrain(g) => positive(field, *g)?,
        StopWhen::Steps(_) | StopWhen::Jammed => {}
        StopWhen::Any(list) => {
            if list.is_empty() {
                return Err(invalid(field, "Any([])", "at least one condition"));
            }
            for (k, u) in list.iter().enumerate() {
                validate_until(&format!("{field}[{k}]"), u)?;
            }
        }
    }
    Ok(())
}
