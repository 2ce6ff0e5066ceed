//! The meshfree multibody assembly ([`crate::meshfree::assembly`]) as a [`Simulation`] of the
//! run loop: a scenario with `model: Meshfree(...)` runs through the same loading programs,
//! measures and outputs as an SDEM scenario.
//!
//! Its `macro.csv` has the common columns (the level counts report every grain as `full`: the
//! grains are fully deformable) and four of its own: `newton_iterations`, `augmentations`,
//! `sub_steps` of the step, `max_penetration`, the deepest interpenetration at the end of
//! the step (a length), and `potential_energy` of gravity (`-m g . x_c` summed over grains, 0
//! without gravity). Its `grains.csv` has one row per grain: area centroid, current area,
//! the mean Cauchy stress tensor over the grain (tension positive), the mean stress
//! (compression positive) and the grain's contacts with other grains.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use rand::SeedableRng;

use super::simulation::{RunRecord, Simulation};
use super::{RunError, io_error};
use crate::boundary::loading::LoadState;
use crate::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP, Wall, box_size};
use crate::meshfree::assembly::{Assembly, AssemblyState, Evaluation, StepStats};
use crate::meshfree::friction::FrictionCoefficients;
use crate::meshfree::shape::{FourierParams, StarShape, place_nodes};
use crate::meshfree::{
    DiscNodes, GrainModel, Hyperelastic, IntegrationMesh, MeshfreeError, NodeDensity, NodeSet,
    TimeScheme, packing,
};
use crate::output::Measures;
use crate::output::frame::Frame;
use crate::output::mcap::{
    ContinueFrom, ContourLogInfo, FrameContour, McapSettings, TrajectoryWriter, WriteError,
};
use crate::output::measures::coordination_without_rattlers;
use crate::sample;
use crate::scenario::{GrainShapes, MeshfreeSettings, Scenario, TimeStep};

/// A grain of the initial sample: its contour about its centre, where the centre is, and the
/// rotation of the contour.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleGrain {
    pub shape: StarShape,
    pub centre: [f64; 2],
}

/// The grains of a meshfree scenario, placed in its box: the sample's discs, or sand-like
/// contours of the sample's radii placed anew without overlap.
pub fn sample_grains(scenario: &Scenario) -> Result<Vec<SampleGrain>, RunError> {
    let s = &scenario.sample;
    if let Some(GrainShapes::File(file)) = &s.shapes {
        let Some(loaded) = &s.loaded_shapes else {
            return Err(RunError::Setup(format!(
                "scenario {}: the shape file {} has not been read (Scenario::load reads it)",
                scenario.name,
                file.display()
            )));
        };
        return Ok(loaded
            .grains
            .iter()
            .map(|(centre, shape)| SampleGrain {
                shape: shape.clone(),
                centre: *centre,
            })
            .collect());
    }
    let (x0, y0) = s.origin;
    let discs: Vec<([f64; 2], f64)> = match (&s.loaded, s.spec()) {
        (Some(loaded), _) => loaded
            .grains
            .iter()
            .map(|g| ([g.center.x, g.center.y], g.radius))
            .collect(),
        (None, Some(spec)) => sample::generate(&spec, scenario.seed)?
            .iter()
            .map(|p| ([x0 + p.x, y0 + p.y], p.radius))
            .collect(),
        (None, None) => {
            return Err(RunError::Setup(format!(
                "scenario {}: sample.file has not been read (Scenario::load reads it)",
                scenario.name
            )));
        }
    };
    match s.shapes.as_ref().unwrap_or(&GrainShapes::Discs) {
        GrainShapes::File(_) => unreachable!("handled above"),
        GrainShapes::Discs => Ok(discs
            .into_iter()
            .map(|(centre, radius)| SampleGrain {
                shape: StarShape::Disc { radius },
                centre,
            })
            .collect()),
        GrainShapes::SandLike => {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(scenario.seed);
            let params = FourierParams::default();
            let shapes: Vec<StarShape> = discs
                .iter()
                .map(|&(_, r)| StarShape::random_fourier(r, &mut rng, &params))
                .collect();
            let b = s.bounds();
            let mean_radius = discs.iter().map(|d| d.1).sum::<f64>() / discs.len() as f64;
            let placed = packing::place_grains(
                &shapes,
                [b.x0, b.x1, b.y0, b.y1],
                0.02 * mean_radius,
                scenario.seed,
            )
            .map_err(|e| RunError::Setup(format!("sample.shapes: SandLike: {e}")))?;
            Ok(shapes
                .iter()
                .zip(placed)
                .map(|(shape, p)| SampleGrain {
                    shape: shape.rotated(p.rotation),
                    centre: p.centre,
                })
                .collect())
        }
    }
}

/// Field nodes and integration mesh of one grain, in the global frame.
pub fn grain_model(
    grain: &SampleGrain,
    settings: &MeshfreeSettings,
    material: Hyperelastic,
) -> Result<GrainModel, MeshfreeError> {
    let (mut nodes, mesh_inside): (NodeSet, bool) = match grain.shape {
        StarShape::Disc { radius } => {
            let nb = settings.boundary_nodes.div_ceil(4) * 4;
            let density = NodeDensity {
                boundary_nodes: nb.max(8),
                grading: settings.grading,
            };
            (DiscNodes::disc(radius, density)?.into(), false)
        }
        ref shape => {
            let perimeter = {
                let o = shape.outline(1024);
                (0..o.len())
                    .map(|k| {
                        let (p, q) = (o[k], o[(k + 1) % o.len()]);
                        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
                    })
                    .sum::<f64>()
            };
            let spacing = perimeter / settings.boundary_nodes as f64;
            let n = place_nodes(shape, spacing, settings.grading)?;
            (
                NodeSet {
                    positions: n.positions,
                    boundary_count: n.boundary_count,
                },
                true,
            )
        }
    };
    for p in &mut nodes.positions {
        p[0] += grain.centre[0];
        p[1] += grain.centre[1];
    }
    if mesh_inside {
        let mesh = IntegrationMesh::inside_boundary(&nodes.positions, nodes.boundary_count)?;
        GrainModel::from_parts(nodes, mesh, material)
    } else {
        GrainModel::from_nodes(nodes, material)
    }
}

/// The meshfree assembly of a scenario with what a run keeps beside it.
pub struct Meshfree {
    pub assembly: Assembly,
    pub state: AssemblyState,
    pub(crate) scheme: TimeScheme,
    pub(crate) dt: f64,
    pub(crate) step: u64,
    /// Contacts, wall forces and energies at the end of the last step.
    pub(crate) last: Evaluation,
    pub(crate) stats: StepStats,
    pub(crate) last_good: (u64, AssemblyState),
    pub(crate) mean_diameter: f64,
    pub(crate) young: f64,
    pub(crate) density: f64,
}

/// A grain's current area, area centroid and mean Cauchy stress: the stress integral over the
/// current area, `(xx, yy, xy)`, tension positive; `mean_stress_c = -(xx + yy) / 2`,
/// compression positive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GrainMean {
    pub area: f64,
    pub centroid: [f64; 2],
    pub stress: [f64; 3],
    pub mean_stress_c: f64,
}

/// The settings of a meshfree scenario (None for an SDEM model).
pub fn settings_of(scenario: &Scenario) -> Option<MeshfreeSettings> {
    match scenario.model {
        crate::scenario::Model::Meshfree(s) => Some(s),
        _ => None,
    }
}

impl Meshfree {
    /// Builds the grains, the box and the solver of a meshfree scenario, at rest.
    pub fn new(scenario: &Scenario) -> Result<Self, RunError> {
        let settings = settings_of(scenario).ok_or_else(|| {
            RunError::Setup(format!("scenario {}: not a meshfree model", scenario.name))
        })?;
        let m = &scenario.material;
        let material = Hyperelastic::new(settings.law, m.young, m.poisson, m.density)
            .map_err(|e| RunError::Setup(format!("material: {e}")))?;
        let grains = sample_grains(scenario)?;
        let models = grains
            .iter()
            .enumerate()
            .map(|(k, g)| {
                grain_model(g, &settings, material)
                    .map_err(|e| RunError::Setup(format!("meshfree grain {k}: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mean_radius = grains
            .iter()
            .map(|g| (g.shape.area() / std::f64::consts::PI).sqrt())
            .sum::<f64>()
            / grains.len() as f64;
        // The box's four walls, then the scenario's planes.
        let walls = scenario.walls();
        let mut assembly = Assembly::new(
            models,
            walls,
            [scenario.gravity.0, scenario.gravity.1],
            (settings.rayleigh_alpha, settings.rayleigh_beta),
            settings.solver(m.young, mean_radius),
        )
        .map_err(|e| RunError::Setup(format!("meshfree assembly: {e}")))?;
        assembly.min_sub_step = settings.min_sub_step;
        let friction = &scenario.contact.friction;
        assembly
            .set_friction(FrictionCoefficients {
                grains: friction.grains,
                walls: scenario.wall_friction(),
                stiffness_ratio: friction.stiffness_ratio,
            })
            .map_err(|e| RunError::Setup(format!("contact: {e}")))?;
        if settings.scheme == TimeScheme::CentralDifference {
            assembly
                .use_explicit()
                .map_err(|e| RunError::Setup(format!("model: {e}")))?;
        }
        let dt = match scenario.time_step {
            TimeStep::Fixed(dt) => dt,
            TimeStep::FractionOfCritical(_) => {
                return Err(RunError::Setup(
                    "time_step: give the meshfree solver a Fixed(dt) (the explicit scheme \
                     sub-steps it below its critical step by itself)"
                        .into(),
                ));
            }
        };
        let state = assembly.initial_state();
        // Any positive stiffness makes a penetrating node an active element.
        let probe = assembly
            .evaluate(&state.u, &state.multipliers, 1.0, None, false)
            .map_err(|e| RunError::Setup(format!("meshfree initial state: {e}")))?;
        if let Some(e) = probe.elements.iter().find(|e| e.gap < 0.0) {
            return Err(RunError::Setup(format!(
                "meshfree grains overlap at the start: node {} of grain {} is {:.3e} inside {:?}",
                e.key.node, e.key.slave, -e.gap, e.key.master
            )));
        }
        let last = assembly
            .evaluate(&state.u, &state.multipliers, 0.0, None, false)
            .map_err(|e| RunError::Setup(format!("meshfree initial state: {e}")))?;
        Ok(Self {
            assembly,
            last_good: (0, state.clone()),
            state,
            scheme: settings.scheme,
            dt,
            step: 0,
            last,
            stats: StepStats::default(),
            mean_diameter: 2.0 * mean_radius,
            young: m.young,
            density: m.density,
        })
    }

    /// Compressive force of the grains on each wall (>= 0).
    fn wall_forces(&self) -> [f64; 4] {
        let walls = &self.assembly.walls;
        std::array::from_fn(|w| {
            let f = self.last.wall_force(w);
            -(f[0] * walls[w].normal.x + f[1] * walls[w].normal.y)
        })
    }

    fn grain_areas(&self, u: &[f64]) -> Vec<(f64, [f64; 2])> {
        (0..self.assembly.grains.len())
            .map(|g| self.assembly.grains[g].contour_area_centroid(self.assembly.grain_slice(u, g)))
            .collect()
    }

    /// Packing fraction, wall stresses (compression positive) and box size.
    fn box_state(&self) -> (f64, f64, f64, f64, f64) {
        let (width, height) = box_size(&self.assembly.walls);
        let f = self.wall_forces();
        let area: f64 = self.grain_areas(&self.state.u).iter().map(|a| a.0).sum();
        (
            area / (width * height),
            0.5 * (f[LEFT] + f[RIGHT]) / height,
            0.5 * (f[BOTTOM] + f[TOP]) / width,
            width,
            height,
        )
    }

    /// Contacts of each grain with other grains.
    fn contacts_per_grain(&self) -> Vec<u32> {
        let mut c = vec![0; self.assembly.grains.len()];
        for (i, j) in self.last.contact_pairs() {
            c[i as usize] += 1;
            c[j as usize] += 1;
        }
        c
    }

    /// Current area, area centroid and mean stress of grain `g` in the displacements `u` (as
    /// `grains.csv` and the MCAP frames report them).
    pub fn grain_mean(&self, u: &[f64], g: usize) -> Result<GrainMean, MeshfreeError> {
        let model = &self.assembly.grains[g];
        let u = self.assembly.grain_slice(u, g);
        let (area, centroid) = model.contour_area_centroid(u);
        let s = model.stress_integral(u)?;
        let stress = [
            s[0][0] / area,
            s[1][1] / area,
            0.5 * (s[0][1] + s[1][0]) / area,
        ];
        Ok(GrainMean {
            area,
            centroid,
            stress,
            mean_stress_c: -0.5 * (stress[0] + stress[1]),
        })
    }

    /// The grains of the current state as MCAP contours: boundary nodes (counter-clockwise)
    /// and mean stress.
    pub fn frame_contours(&self) -> Result<Vec<FrameContour>, MeshfreeError> {
        (0..self.assembly.grains.len())
            .map(|g| {
                let model = &self.assembly.grains[g];
                let u = self.assembly.grain_slice(&self.state.u, g);
                let m = self.grain_mean(&self.state.u, g)?;
                Ok(FrameContour {
                    grain: g as u32,
                    stress: m.stress,
                    mean_stress_c: m.mean_stress_c,
                    points: (0..model.nodes.boundary_count)
                        .map(|s| glam::DVec2::from(model.position(u, s)))
                        .collect(),
                })
            })
            .collect()
    }

    fn write_state(&self, path: &Path, state: &AssemblyState) -> std::io::Result<()> {
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        writeln!(
            out,
            "id,x,y,area,stress_xx,stress_yy,stress_xy,mean_stress_c,contacts"
        )?;
        for (g, contacts) in self.contacts_per_grain().into_iter().enumerate() {
            let m = self
                .grain_mean(&state.u, g)
                .map_err(|e| std::io::Error::other(format!("grain {g}: {e}")))?;
            let [sxx, syy, sxy] = m.stress;
            writeln!(
                out,
                "{g},{:.12e},{:.12e},{:.12e},{sxx:.9e},{syy:.9e},{sxy:.9e},{:.9e},{}",
                m.centroid[0], m.centroid[1], m.area, m.mean_stress_c, contacts
            )?;
        }
        out.flush()
    }
}

impl Simulation for Meshfree {
    type Failure = MeshfreeError;
    const EXTRA_COLUMNS: &'static [&'static str] = &[
        "newton_iterations",
        "factorizations",
        "augmentations",
        "sub_steps",
        "max_penetration",
        "potential_energy",
    ];

    fn step_count(&self) -> u64 {
        self.step
    }

    fn critical_dt(&self, _scenario: &Scenario) -> Option<f64> {
        self.assembly.explicit_data().map(|x| x.critical_step)
    }

    fn time(&self) -> f64 {
        self.state.time
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    fn grain_count(&self) -> usize {
        self.assembly.grains.len()
    }

    fn walls(&self) -> &[Wall] {
        &self.assembly.walls
    }

    fn walls_mut(&mut self) -> &mut [Wall] {
        &mut self.assembly.walls
    }

    fn take_step(&mut self) -> Result<(), MeshfreeError> {
        let (eval, stats) = self.assembly.step(&mut self.state, self.dt, self.scheme)?;
        self.last = eval;
        self.stats = stats;
        self.step += 1;
        Ok(())
    }

    fn load_state(&self, jammed: bool) -> LoadState {
        let (phi, sxx, syy, _, _) = self.box_state();
        LoadState {
            phi,
            sxx,
            syy,
            jammed,
            mean_diameter: self.mean_diameter,
            density: self.density,
            young: self.young,
            shear_strain: 0.0,
        }
    }

    fn measures(&self, phase: &str, strain_rate: f64) -> Measures {
        let (phi, sxx_c, syy_c, box_width, box_height) = self.box_state();
        let (z, z_nr, z_nr3) = self.coordination();
        let state = self.load_state(true);
        Measures {
            step: self.step,
            time: self.state.time,
            phase: phase.to_string(),
            phi,
            sxx_c,
            syy_c,
            p_c: 0.5 * (sxx_c + syy_c),
            q_c: 0.5 * (sxx_c - syy_c),
            z,
            z_nr,
            z_nr3,
            kinetic_energy: self.assembly.kinetic_energy(&self.state.v),
            elastic_energy: self.last.elastic_energy,
            inertial_number: state.inertial_number(strain_rate),
            strain_rate,
            box_width,
            box_height,
            contacts: self.contacts(),
            capped_contacts: 0,
            levels: [0, 0, self.assembly.grains.len() as u64],
        }
    }

    fn coordination(&self) -> (f64, f64, f64) {
        let pairs = self.last.contact_pairs();
        let n = self.assembly.grains.len().max(1) as f64;
        let per_grain = self.contacts_per_grain();
        let carrying = |g: u32| per_grain[g as usize] >= 2;
        let grains_nr = per_grain.iter().filter(|&&c| c >= 2).count();
        let contacts_nr = pairs
            .iter()
            .filter(|(i, j)| carrying(*i) && carrying(*j))
            .count();
        let z_nr = if grains_nr > 0 {
            2.0 * contacts_nr as f64 / grains_nr as f64
        } else {
            0.0
        };
        let mut wall_contacts = vec![0u32; self.assembly.grains.len()];
        for (g, _) in self.last.wall_contacts() {
            wall_contacts[g as usize] += 1;
        }
        let z_nr3 = coordination_without_rattlers(&wall_contacts, &pairs, 3);
        (2.0 * pairs.len() as f64 / n, z_nr, z_nr3)
    }

    fn contacts(&self) -> u64 {
        self.last.contact_pairs().len() as u64
    }

    fn extra_columns(&self, row: &mut String) {
        let s = &self.stats;
        let _ = write!(
            row,
            ",{},{},{},{},{:.6e},{:.9e}",
            s.solve.newton_iterations,
            s.solve.factorizations,
            s.solve.augmentations,
            s.sub_steps,
            self.last.max_penetration(),
            self.assembly.potential_energy(&self.state.u)
        );
    }

    fn keep_last_good(&mut self) {
        self.last_good = (self.step, self.state.clone());
    }

    fn write_last_good(&self, path: &Path) -> std::io::Result<()> {
        self.write_state(path, &self.last_good.1)
    }

    fn write_grains(&self, path: &Path) -> std::io::Result<()> {
        self.write_state(path, &self.state)
    }

    fn open_log(
        &self,
        settings: &McapSettings,
        scenario: &Scenario,
        continue_from: Option<ContinueFrom>,
    ) -> Result<TrajectoryWriter, RunError> {
        let info = ContourLogInfo {
            grains: self.assembly.grains.len(),
            boundary_nodes: self
                .assembly
                .grains
                .iter()
                .map(|m| m.nodes.boundary_count)
                .sum(),
            dt: self.dt,
        };
        super::open_log(
            settings,
            continue_from,
            || TrajectoryWriter::create_contours(settings, scenario, &info),
            |from| TrajectoryWriter::continue_contours(settings, scenario, &info, from),
        )
    }

    fn write_frame(&self, log: &mut TrajectoryWriter, row: &Measures) -> Result<(), WriteError> {
        let contours = self.frame_contours().map_err(|e| WriteError::Io {
            path: String::new(),
            error: std::io::Error::other(format!("meshfree contours at step {}: {e}", self.step)),
        })?;
        log.write_contour_frame(
            self.step,
            self.state.time,
            &contours,
            &self.assembly.walls,
            row,
        )
    }

    fn frame(&self, row: &Measures) -> Result<Frame, String> {
        let contours = self
            .frame_contours()
            .map_err(|e| format!("meshfree contours at step {}: {e}", self.step))?;
        Ok(Frame::of_contours(
            (self.step, self.state.time),
            contours,
            &self.assembly.walls,
            Some(row.clone()),
        ))
    }

    fn write_checkpoint(&self, path: &Path, run: &RunRecord<'_>) -> std::io::Result<()> {
        super::meshfree_checkpoint::MeshfreeCheckpoint::capture(self, run).write_atomic(path)
    }
}

/// Runs a meshfree scenario from its start.
pub fn run_meshfree(
    scenario: &Scenario,
    options: &super::RunOptions,
) -> Result<super::RunSummary, RunError> {
    let out = &options.out_dir;
    let sim = Meshfree::new(scenario)?;
    std::fs::create_dir_all(out).map_err(io_error(out))?;
    let macro_path = out.join("macro.csv");
    let writer =
        crate::output::MacroWriter::create_with_columns(&macro_path, Meshfree::EXTRA_COLUMNS)
            .map_err(io_error(&macro_path))?;
    let program = crate::boundary::loading::LoadingProgram::new(
        scenario.loading.clone(),
        &sim.assembly.walls,
    );
    super::run_loop(
        scenario,
        sim,
        program,
        super::LoopState::default(),
        writer,
        options,
        None,
    )
}

impl Meshfree {
    /// The run of a checkpoint at its step: the grains' models rebuilt from the scenario (as
    /// [`Meshfree::new`] builds them), the dynamic state and the last step's evaluation and
    /// counters the checkpoint's. A state that does not fit the rebuilt grains (a damaged
    /// checkpoint) is a [`RunError::Resume`] saying why.
    pub(crate) fn restore(
        c: &super::meshfree_checkpoint::MeshfreeCheckpoint,
    ) -> Result<Self, RunError> {
        let mut sim = Self::new(&c.scenario)?;
        c.check_fits(&sim.assembly).map_err(RunError::Resume)?;
        sim.assembly.walls = c.walls.clone();
        sim.assembly
            .set_contact_pattern(c.contact_pattern.clone())
            .map_err(RunError::Resume)?;
        sim.state = c.state.clone();
        sim.step = c.step;
        sim.last = c.last.clone();
        sim.stats = c.stats;
        sim.last_good = c.last_good.clone();
        Ok(sim)
    }
}
