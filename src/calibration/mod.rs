//! `sdem calibrate`: fits the secant contact law (a, b) to single-grain meshfree compressions
//! (SPEC §10).
//!
//! For every Poisson's ratio of the list, a meshfree disc of diameter 1 (E = 1, rho = 1) is
//! compressed quasi-statically by four frictionless walls of a square box, initially touching,
//! from side 1 down to `final_box_side`. At each load step the half side h, the force F on one
//! wall (mean of the four) and the contact length L_c (mean of the four) are recorded, and the
//! "virtual circle" through the ends of the contact segments gives
//! `delta_n = h - sqrt(h^2 + (L_c/2)^2)`. The law `F = E L_c |delta_n| / (a L_c + (b-1) delta_n)`
//! is fitted over all nu by least squares on the relative force error `F_model/F - 1`.
//!
//! Sign conventions of the outputs: `F` and `F_model` are magnitudes of the repulsive force per
//! unit thickness (compression positive); `dn` is negative (an overlap), as in SPEC §5.
//!
//! Both hyperelastic laws are run; the neo-Hookean fit is the result (`a`, `b`), the Saint
//! Venant–Kirchhoff fit is reported beside it.

pub mod assembly;
mod chart;
mod fit;

pub use assembly::{AssemblyCase, AssemblyOptions, AssemblyReport, run_assembly_calibration};
pub use fit::{SecantFit, fit_secant_law};

use std::path::PathBuf;
use std::time::{Duration, Instant};

use rayon::prelude::*;

use crate::meshfree::{
    DiscModel, Hyperelastic, HyperelasticLaw, MeshfreeError, Multipliers, NodeDensity, Problem,
    SolverSettings, Wall, contact_length,
};

/// Options of `sdem calibrate`.
#[derive(Debug, Clone)]
pub struct CalibrateOptions {
    /// Poisson's ratios to compress (each in [0, 0.5)).
    pub nus: Vec<f64>,
    /// Final side of the box (the disc has diameter 1); default 0.90.
    pub final_box_side: f64,
    /// Where `calibration.csv` and the chart go.
    pub out_dir: PathBuf,
    /// Number of equal load steps from side 1 to `final_box_side`.
    pub steps: usize,
    /// Boundary nodes of the disc (a multiple of 4); sets the nodal density.
    pub boundary_nodes: usize,
    /// Interior spacing grows to `(1 + grading)` times the boundary spacing at the centre.
    pub grading: f64,
    /// Laws to run. The first one gives the headline `a`, `b` (neo-Hookean by default).
    pub laws: Vec<HyperelasticLaw>,
    /// Newton / augmented-Lagrangian settings.
    pub solver: SolverSettings,
    /// Whether to write the SVG chart.
    pub chart: bool,
}

/// The densities shipped for the convergence study (boundary nodes; the default is the last).
pub const DENSITIES: [usize; 3] = [64, 80, 96];

impl Default for CalibrateOptions {
    fn default() -> Self {
        Self {
            nus: vec![0.0, 0.1, 0.2, 0.3, 0.4, 0.45, 0.49],
            final_box_side: 0.90,
            out_dir: PathBuf::from("."),
            steps: 20,
            boundary_nodes: DENSITIES[DENSITIES.len() - 1],
            grading: 3.0,
            laws: vec![
                HyperelasticLaw::NeoHookean,
                HyperelasticLaw::SaintVenantKirchhoff,
            ],
            solver: SolverSettings {
                k0: 20.0,
                alpha_k: 2.0,
                gap_tolerance: 1e-6,
                force_tolerance: 1e-11,
                max_newton: 40,
                max_augmentations: 40,
            },
            chart: true,
        }
    }
}

/// Failures of the calibration.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    #[error("invalid calibration option: {0}")]
    BadInput(String),
    #[error("meshfree setup failed: {0}")]
    Setup(#[source] MeshfreeError),
    #[error(
        "the compression of the {law} disc with nu = {nu} failed at box side {side:.5} \
         (load step {step}): {source}"
    )]
    Compression {
        law: &'static str,
        nu: f64,
        side: f64,
        step: usize,
        #[source]
        source: MeshfreeError,
    },
    #[error("the fit of (a, b) failed: {0}")]
    Fit(String),
    #[error("cannot write {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

impl CalibrationError {
    /// `map_err` for a failed write or directory creation at `path`.
    pub(crate) fn io(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> Self + '_ {
        move |source| CalibrationError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// One load step of one compression.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompressionStep {
    pub nu: f64,
    /// Half side of the box.
    pub h: f64,
    /// Force on one wall (magnitude, mean of the four walls).
    pub force: f64,
    /// Contact length on one wall (mean of the four walls).
    pub contact_length: f64,
    /// Normal gap from the virtual circle (<= 0).
    pub dn: f64,
    /// Active contact nodes on one wall (mean).
    pub active_nodes: f64,
    pub newton_iterations: usize,
    pub augmentations: usize,
}

/// Fit quality for one nu.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NuQuality {
    pub nu: f64,
    pub points: usize,
    /// RMS of `F_model/F - 1`.
    pub rms_relative_error: f64,
    /// Largest `|F_model/F - 1|`.
    pub max_relative_error: f64,
    /// Force on one wall at the final compression.
    pub final_force: f64,
}

/// The fit of one hyperelastic law.
#[derive(Debug, Clone, PartialEq)]
pub struct LawCalibration {
    pub law: HyperelasticLaw,
    pub fit: SecantFit,
    pub per_nu: Vec<NuQuality>,
    pub steps: Vec<CompressionStep>,
    /// Time spent in the compressions of this law (summed over threads).
    pub compute_time: Duration,
}

/// What `sdem calibrate` prints.
#[derive(Debug, Clone)]
pub struct CalibrationReport {
    /// Fitted `a` of the first law (neo-Hookean by default).
    pub a: f64,
    /// Fitted `b` of the first law.
    pub b: f64,
    pub laws: Vec<LawCalibration>,
    pub field_nodes: usize,
    pub gauss_points: usize,
    pub final_box_side: f64,
    pub wall_time: Duration,
    pub csv_path: PathBuf,
    pub chart_path: Option<PathBuf>,
}

impl std::fmt::Display for CalibrationReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "meshfree disc: {} field nodes, {} Gauss points; box side 1 -> {}",
            self.field_nodes, self.gauss_points, self.final_box_side
        )?;
        for (i, law) in self.laws.iter().enumerate() {
            writeln!(
                f,
                "{}{}: a = {:.4} b = {:.4}, RMS relative force error {:.2}% over {} points",
                law.law.name(),
                if i == 0 { " (default)" } else { "" },
                law.fit.a,
                law.fit.b,
                100.0 * law.fit.rms_relative_error,
                law.fit.points
            )?;
            for q in &law.per_nu {
                writeln!(
                    f,
                    "  nu = {:<5} F_final = {:.5}  RMS error {:>6.2}%  max error {:>6.2}%",
                    q.nu,
                    q.final_force,
                    100.0 * q.rms_relative_error,
                    100.0 * q.max_relative_error
                )?;
            }
        }
        writeln!(f, "paper (SDEM, fig. 7): a = 0.58 b = 2")?;
        writeln!(f, "wrote {}", self.csv_path.display())?;
        if let Some(p) = &self.chart_path {
            writeln!(f, "wrote {}", p.display())?;
        }
        writeln!(f, "time: {:.1} s", self.wall_time.as_secs_f64())?;
        write!(f, "a = {:.4} b = {:.4}", self.a, self.b)
    }
}

fn validate(options: &CalibrateOptions) -> Result<(), CalibrationError> {
    let bad = |m: String| Err(CalibrationError::BadInput(m));
    if options.nus.is_empty() {
        return bad("the list of Poisson's ratios is empty".into());
    }
    for &nu in &options.nus {
        if !(0.0..0.5).contains(&nu) {
            return bad(format!(
                "Poisson's ratio {nu} is outside [0, 0.5): the meshfree solver is compressible \
                 (nu = 0.5 would need a mixed formulation)"
            ));
        }
    }
    let s = options.final_box_side;
    if !(s > 0.5 && s < 1.0) {
        return bad(format!(
            "final box side {s} must be in (0.5, 1) (the disc has diameter 1; below ~0.886 the \
             box is smaller than the disc's area)"
        ));
    }
    if options.steps == 0 || options.steps > 10_000 {
        return bad(format!("steps must be in 1..=10000, got {}", options.steps));
    }
    if options.laws.is_empty() {
        return bad("no hyperelastic law to run".into());
    }
    let st = &options.solver;
    if !(st.k0 > 0.0 && st.alpha_k >= 1.0 && st.gap_tolerance > 0.0 && st.force_tolerance > 0.0) {
        return bad(format!("invalid solver settings {st:?}"));
    }
    Ok(())
}

/// Compresses one disc and records every load step.
pub fn compress_disc(
    law: HyperelasticLaw,
    nu: f64,
    options: &CalibrateOptions,
) -> Result<Vec<CompressionStep>, CalibrationError> {
    let material = Hyperelastic::new(law, 1.0, nu, 1.0).map_err(CalibrationError::Setup)?;
    let density = NodeDensity {
        boundary_nodes: options.boundary_nodes,
        grading: options.grading,
    };
    let model = DiscModel::disc(0.5, density, material).map_err(CalibrationError::Setup)?;
    compress_model(&model, nu, options)
}

fn box_walls(h: f64) -> [Wall; 4] {
    [
        Wall::new([h, 0.0], [-1.0, 0.0]),
        Wall::new([0.0, h], [0.0, -1.0]),
        Wall::new([-h, 0.0], [1.0, 0.0]),
        Wall::new([0.0, -h], [0.0, 1.0]),
    ]
}

/// Quasi-static compression of a prepared model (radius 0.5) in a shrinking square box.
pub fn compress_model(
    model: &DiscModel,
    nu: f64,
    options: &CalibrateOptions,
) -> Result<Vec<CompressionStep>, CalibrationError> {
    let nb = model.nodes.boundary_count;
    // The tangential DoF of the nodes on the +x and +y axes: zero by symmetry, they remove the
    // rigid rotation that frictionless walls leave free.
    let fixed = [1, 2 * (nb / 4)];
    let external = vec![0.0; model.dofs()];
    let mut u = vec![0.0; model.dofs()];
    let mut mult = Multipliers::zeros(4, nb);
    let mut out = Vec::with_capacity(options.steps);
    let ds = (1.0 - options.final_box_side) / options.steps as f64;
    let mut side = 1.0;
    for step in 1..=options.steps {
        let target = 1.0 - ds * step as f64;
        // Sub-divide a load step that does not converge (up to 1/16).
        let mut sub = 1usize;
        loop {
            let (u_save, m_save, side_save) = (u.clone(), mult.clone(), side);
            let mut result = Ok((Vec::new(), 0, 0));
            for k in 1..=sub {
                let s = side_save + (target - side_save) * k as f64 / sub as f64;
                let walls = box_walls(0.5 * s);
                let problem = Problem {
                    model,
                    walls: &walls,
                    external: &external,
                    fixed: &fixed,
                    settings: options.solver,
                };
                match problem.solve(&mut u, &mut mult, None) {
                    Ok((states, stats)) => {
                        let (n0, a0) = match &result {
                            Ok((_, n, a)) => (*n, *a),
                            Err(_) => (0, 0),
                        };
                        result = Ok((
                            states,
                            n0 + stats.newton_iterations,
                            a0 + stats.augmentations,
                        ));
                    }
                    Err(e) => {
                        result = Err(e);
                        break;
                    }
                }
            }
            match result {
                Ok((states, newton, aug)) => {
                    side = target;
                    let h = 0.5 * side;
                    let walls = box_walls(h);
                    let force = states.iter().map(|s| s.force()).sum::<f64>() / 4.0;
                    let lc = walls
                        .iter()
                        .zip(&states)
                        .map(|(w, s)| contact_length(model, &u, w, s))
                        .sum::<f64>()
                        / 4.0;
                    let active = states
                        .iter()
                        .map(|s| s.pressure.iter().filter(|&&t| t > 0.0).count() as f64)
                        .sum::<f64>()
                        / 4.0;
                    let dn = h - (h * h + 0.25 * lc * lc).sqrt();
                    out.push(CompressionStep {
                        nu,
                        h,
                        force,
                        contact_length: lc,
                        dn,
                        active_nodes: active,
                        newton_iterations: newton,
                        augmentations: aug,
                    });
                    break;
                }
                Err(e) => {
                    u = u_save;
                    mult = m_save;
                    side = side_save;
                    if sub >= 16 {
                        return Err(CalibrationError::Compression {
                            law: model.material.law.name(),
                            nu,
                            side: target,
                            step,
                            source: e,
                        });
                    }
                    sub *= 2;
                }
            }
        }
    }
    Ok(out)
}

/// Runs the compressions for every law and nu (in parallel over rayon's pool; each solve is
/// sequential, so results do not depend on the thread count), fits (a, b), writes
/// `out_dir/calibration.csv` (first law), `out_dir/calibration_<law>.csv` (others) and the chart
/// `out_dir/calibration.svg`.
pub fn run_calibration(options: &CalibrateOptions) -> Result<CalibrationReport, CalibrationError> {
    validate(options)?;
    let start = Instant::now();
    // Set up one model to report its size and surface setup errors before the parallel part.
    let probe = DiscModel::disc(
        0.5,
        NodeDensity {
            boundary_nodes: options.boundary_nodes,
            grading: options.grading,
        },
        Hyperelastic::new(options.laws[0], 1.0, options.nus[0], 1.0)
            .map_err(CalibrationError::Setup)?,
    )
    .map_err(CalibrationError::Setup)?;
    let jobs: Vec<(usize, f64)> = (0..options.laws.len())
        .flat_map(|l| options.nus.iter().map(move |&nu| (l, nu)))
        .collect();
    let results: Vec<Result<(Vec<CompressionStep>, Duration), CalibrationError>> = jobs
        .par_iter()
        .map(|&(l, nu)| {
            let t = Instant::now();
            let mut model = probe.clone();
            model.material = Hyperelastic::new(options.laws[l], 1.0, nu, 1.0)
                .map_err(CalibrationError::Setup)?;
            compress_model(&model, nu, options).map(|s| (s, t.elapsed()))
        })
        .collect();
    let mut per_law: Vec<(Vec<CompressionStep>, Duration)> =
        vec![(Vec::new(), Duration::ZERO); options.laws.len()];
    for (&(l, _), r) in jobs.iter().zip(results) {
        let (steps, t) = r?;
        per_law[l].0.extend(steps);
        per_law[l].1 += t;
    }
    let mut laws = Vec::new();
    for (l, (steps, time)) in per_law.into_iter().enumerate() {
        let fit = fit_secant_law(&steps, 1.0).map_err(CalibrationError::Fit)?;
        let per_nu = options
            .nus
            .iter()
            .map(|&nu| {
                let errs: Vec<f64> = steps
                    .iter()
                    .filter(|s| s.nu == nu && fit::usable(s))
                    .map(|s| fit.model_force(s.contact_length, s.dn, 1.0) / s.force - 1.0)
                    .collect();
                let n = errs.len().max(1) as f64;
                NuQuality {
                    nu,
                    points: errs.len(),
                    rms_relative_error: (errs.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
                    max_relative_error: errs.iter().fold(0.0f64, |m, e| m.max(e.abs())),
                    final_force: steps.iter().rfind(|s| s.nu == nu).map_or(0.0, |s| s.force),
                }
            })
            .collect();
        laws.push(LawCalibration {
            law: options.laws[l],
            fit,
            per_nu,
            steps,
            compute_time: time,
        });
    }
    std::fs::create_dir_all(&options.out_dir).map_err(CalibrationError::io(&options.out_dir))?;
    let mut csv_path = PathBuf::new();
    for (i, law) in laws.iter().enumerate() {
        let name = if i == 0 {
            "calibration.csv".to_string()
        } else {
            format!("calibration_{}.csv", file_tag(law.law))
        };
        let path = options.out_dir.join(name);
        write_csv(&path, law)?;
        if i == 0 {
            csv_path = path;
        }
    }
    let chart_path = if options.chart {
        let path = options.out_dir.join("calibration.svg");
        std::fs::write(&path, chart::svg(&laws, options.final_box_side))
            .map_err(CalibrationError::io(&path))?;
        Some(path)
    } else {
        None
    };
    Ok(CalibrationReport {
        a: laws[0].fit.a,
        b: laws[0].fit.b,
        field_nodes: probe.node_count(),
        gauss_points: probe.gauss_count(),
        final_box_side: options.final_box_side,
        laws,
        wall_time: start.elapsed(),
        csv_path,
        chart_path,
    })
}

fn file_tag(law: HyperelasticLaw) -> &'static str {
    match law {
        HyperelasticLaw::NeoHookean => "neohookean",
        HyperelasticLaw::SaintVenantKirchhoff => "svk",
    }
}

fn write_csv(path: &std::path::Path, law: &LawCalibration) -> Result<(), CalibrationError> {
    let mut s = String::from("nu,h,F,Lc,dn,F_model\n");
    for st in &law.steps {
        // A step without contact has no model force: the field is left empty.
        let fm = if fit::usable(st) {
            format!("{:.8e}", law.fit.model_force(st.contact_length, st.dn, 1.0))
        } else {
            String::new()
        };
        s.push_str(&format!(
            "{},{:.8},{:.8e},{:.8e},{:.8e},{fm}\n",
            st.nu, st.h, st.force, st.contact_length, st.dn
        ));
    }
    std::fs::write(path, s).map_err(CalibrationError::io(path))
}
