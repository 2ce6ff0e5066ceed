//! A scenario from start to end: generate the sample, build the box, run the loading program,
//! write the measures.
//!
//! [`run_loop`] is the loop of every run, generic over the solver: it talks to it through
//! [`Simulation`] only, and its named steps (the methods of `steps::Run`) hold everything that
//! does not depend on the solver: wall driving, jamming detection, phase changes, stall and
//! stop conditions, outputs, checkpoints, progress. [`Sdem`] is the SDEM engine
//! ([`World`]) as a `Simulation`; [`run_scenario`] and [`resume_run`] start SDEM runs.

pub mod bench;
pub mod checkpoint;
pub mod meshfree;
pub mod meshfree_checkpoint;
mod progress;
pub mod sdem;
pub mod simulation;
mod steps;

pub use sdem::Sdem;
pub use simulation::{LastGood, RunRecord, Simulation, SolverStatistics};
pub use steps::LoopState;

use crate::boundary::loading::{LoadState, LoadingProgram};
use crate::boundary::periodic::PeriodicBoundary;
use crate::grain::Grain;
use crate::integration::{Instability, PhaseTimes, StepTotals, World};
use crate::output::MacroWriter;
use crate::output::Measures;
use crate::output::mcap::{ContinueFrom, Continued, McapSettings, TrajectoryWriter, WriteError};
use crate::sample::{self, SampleError};
use crate::scenario::{Boundary, Scenario};
use checkpoint::{AnyCheckpoint, Checkpoint, CheckpointError};
use glam::DVec2;
use meshfree_checkpoint::MeshfreeCheckpoint;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use steps::Run;

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Sample(#[from] SampleError),
    #[error("writing {path}")]
    Output {
        path: String,
        source: std::io::Error,
    },
    /// Writing a checkpoint failed (e.g. a full disk): the file written before, if any, is left
    /// as it was (checkpoints are written to a temporary file, then renamed over it).
    #[error(
        "writing the checkpoint {path} (the checkpoint written there before, if any, is left \
         intact: `sdem resume` continues from it)"
    )]
    CheckpointWrite {
        path: String,
        source: std::io::Error,
    },
    /// An instability of the SDEM step; `note` (empty, or a line starting with a newline) says which stress
    /// target the phase was heading for and the stress reached.
    #[error(
        "{instability}{note}\n  the last good state (step {last_good_step}) is in {state_file}"
    )]
    Unstable {
        instability: Instability,
        note: String,
        last_good_step: u64,
        state_file: String,
    },
    /// A step of a solver other than SDEM failed (see [`Simulation::failure_error`]), e.g. a
    /// Newton loop of the meshfree assembly that did not converge; the message has the shape of
    /// [`RunError::Unstable`]'s.
    #[error("{failure}{note}\n  the last good state (step {last_good_step}) is in {state_file}")]
    StepFailed {
        failure: Box<dyn std::error::Error + Send + Sync>,
        note: String,
        last_good_step: u64,
        state_file: String,
    },
    /// A phase with a stress target can no longer progress: the box collapsed or the grains
    /// fill it (phi >= [`PHI_LIMIT`]) before the target was reached.
    #[error(transparent)]
    TargetUnreachable(Box<TargetUnreachable>),
    /// The scenario cannot be run as given (e.g. its sample file was never read).
    #[error("{0}")]
    Setup(String),
    #[error("could not start {threads} threads: {message}")]
    Threads { threads: usize, message: String },
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    #[error("{0}")]
    Resume(String),
    #[error("stopped at step {step}; continue with `sdem resume {checkpoint}`")]
    Interrupted { step: u64, checkpoint: String },
}

/// See [`RunError::TargetUnreachable`].
#[derive(Debug, thiserror::Error)]
#[error(
    "step {step}: {phase} cannot reach its target {target}: {reason}; the stress reached is \
     {reached}. Lower the target or stop the phase on another condition\n  the last good \
     state (step {last_good_step}) is in {state_file}"
)]
pub struct TargetUnreachable {
    pub step: u64,
    pub phase: String,
    pub target: String,
    pub reason: String,
    pub reached: String,
    pub last_good_step: u64,
    pub state_file: String,
}

/// Where the sample jammed (SPEC §7): the first state with p_c above p_jam.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jamming {
    pub step: u64,
    pub phi: f64,
    pub z: f64,
    pub z_nr: f64,
    pub p_c: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct RunSummary {
    pub grains: usize,
    pub steps: u64,
    pub dt: f64,
    /// The critical time step of the explicit integration (SDEM's, or the explicit meshfree
    /// scheme's); `None` for the implicit meshfree schemes.
    pub critical_dt: Option<f64>,
    pub wall_seconds: f64,
    pub jamming: Option<Jamming>,
    pub last: Measures,
    /// Largest inertial number seen once p_c > 1e-4 E.
    pub max_loaded_inertial_number: f64,
    pub neighbor_builds: u64,
    /// SDEM only: the neighbour list's skin at the end, as a multiple of the scenario's.
    pub neighbor_skin_widening: Option<f64>,
    /// SDEM only: the wall-clock seconds this process's steps spent in each pass of the step.
    pub phase_seconds: Option<PhaseTimes>,
    /// SDEM only: how this process's step sweeps shared their grain chunks among threads (a
    /// sample whose numbering makes many chunks wait takes the two passes one after the other).
    pub sweeps: Option<crate::integration::SweepTally>,
    /// For nu = 0.5: RMS relative error of p_c(phi) against eq. 69 with the run's own phi_0 and
    /// Z_0 (= z_nr at jamming), over phi in [phi_0 + 0.01, final phi], and the number of rows.
    pub eq69_rms_error: Option<(f64, usize)>,
    /// Wall-clock seconds spent writing the MCAP log (0 without one).
    pub mcap_seconds: f64,
    /// Checkpoints written by this process (the final one included).
    pub checkpoints_written: u64,
    /// The box at the end, `[x0, x1, y0, y1]`.
    pub final_box: [f64; 4],
    /// Adaptive model only: steps taken while the highest level present was Rigid,
    /// Volumetric, Full (each with its own time step), and the grain-steps at each level.
    pub adaptive: Option<AdaptiveStats>,
}

/// How an adaptive-level run spent its steps (see [`RunSummary::adaptive`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AdaptiveStats {
    /// Steps by the highest level present (which sets the time step).
    pub steps_by_highest_level: [u64; 3],
    /// Grain-steps at each level.
    pub grain_steps_by_level: [u64; 3],
    /// The time step for each highest level.
    pub dt_by_highest_level: [f64; 3],
    /// Steps that were multi-rate cycles (see [`crate::integration::World::step`]); each
    /// lasts twice the full level's time step and counts once in `steps_by_highest_level`.
    pub cycles: u64,
    /// Over those cycles, the grains that took their two substeps (the others took one).
    pub cycle_fast_grains: u64,
}

/// A phase with a stress target stops with [`RunError::TargetUnreachable`] once the packing
/// fraction reaches this: the grains fill the box and the stress cannot be raised further
/// without the contact law leaving its domain or grains inverting.
pub const PHI_LIMIT: f64 = 0.999;

#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub out_dir: PathBuf,
    /// Print a progress line to stderr every this many seconds (None: silent).
    pub progress_seconds: Option<f64>,
    /// Also write the trajectory as an MCAP log (see [`crate::output::mcap`]).
    pub mcap: Option<McapSettings>,
    /// Also write the trajectory as VTK files for ParaView into this folder (see
    /// [`crate::output::vtk`]); a new run only (`sdem resume` does not continue them).
    pub vtk: Option<PathBuf>,
    /// Show a progress bar on stderr once the run has lasted a few seconds; drawn only when
    /// stderr is a terminal.
    pub progress_bar: bool,
    /// Keep the latest checkpoint in `out_dir/checkpoint.bin`, written every this many steps
    /// and at the end of the run (0: none). See [`checkpoint`].
    pub checkpoint_every: u64,
    /// Also (or instead) write the checkpoint after the first step that ends this many
    /// wall-clock seconds after the previous checkpoint or the start. Results do not depend on
    /// it.
    pub checkpoint_seconds: Option<f64>,
    /// Set (e.g. by a signal handler) to stop the run cleanly: a checkpoint is written after
    /// the current step and the run ends with [`RunError::Interrupted`].
    pub stop: Option<&'static AtomicBool>,
    /// Stop cleanly after this step, as on a signal (a checkpoint is written).
    pub stop_after_step: Option<u64>,
}

pub(crate) fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> RunError + '_ {
    move |source| RunError::Output {
        path: path.display().to_string(),
        source,
    }
}

/// Builds the world of a scenario: its sample (generated, or read from its file by
/// [`Scenario::load`]) at rest in its box.
pub fn build_world(scenario: &Scenario) -> Result<World, RunError> {
    let s = &scenario.sample;
    let (x0, y0) = s.origin;
    let grains = match (&s.loaded, s.spec()) {
        (Some(loaded), _) => loaded.grains.clone(),
        (None, Some(spec)) => {
            let placed = sample::generate(&spec, scenario.seed)?;
            // Numbered along a Hilbert curve, not in placement order: neighbours then sit close
            // in memory, which makes the step 2.5-3 times faster at 10^5 grains
            // (sample::order). A sample file keeps the numbering its author gave.
            let points: Vec<(f64, f64)> = placed.iter().map(|p| (p.x, p.y)).collect();
            sample::order::hilbert_order(&points, spec.box_width, spec.box_height)
                .into_iter()
                .map(|k| {
                    let p = &placed[k];
                    let center = if (x0, y0) == (0.0, 0.0) {
                        DVec2::new(p.x, p.y)
                    } else {
                        DVec2::new(x0 + p.x, y0 + p.y)
                    };
                    Grain::at_rest(center, p.radius)
                })
                .collect()
        }
        (None, None) => {
            return Err(RunError::Setup(format!(
                "scenario {}: sample.file {:?} has not been read (Scenario::load reads it)",
                scenario.name,
                s.file.as_deref().unwrap_or(Path::new("")).display()
            )));
        }
    };
    let walls = scenario.walls();
    // A plane cutting through the box must have the grains on its side.
    for (k, plane) in walls.iter().enumerate().skip(4) {
        if let Some((g, grain)) = grains
            .iter()
            .enumerate()
            .find(|(_, g)| plane.height(g.center) <= 0.0)
        {
            return Err(RunError::Setup(format!(
                "grain {g} (centre ({}, {}), radius {}) lies beyond planes[{}]: its centre is on \
                 the far side of the plane; place the sample on the side its normal points to",
                grain.center.x,
                grain.center.y,
                grain.radius,
                k - 4
            )));
        }
    }
    let world = World::new(scenario.parameters(), grains, walls);
    Ok(match scenario.boundary {
        Boundary::Walls => world,
        Boundary::Periodic => world.with_periodic(PeriodicBoundary::default()),
    })
}

/// A new `macro.csv` for an SDEM run: the common columns, and a periodic cell's and friction's
/// (see [`sdem::extra_columns`]).
fn sdem_macro_writer(scenario: &Scenario, path: &Path) -> std::io::Result<MacroWriter> {
    MacroWriter::create_with_columns(path, &sdem::extra_columns(scenario))
}

/// Runs a scenario to the end of its loading program, writing `macro.csv`, `grains.csv` and
/// `summary.txt` in `options.out_dir`.
pub fn run_scenario(scenario: &Scenario, options: &RunOptions) -> Result<RunSummary, RunError> {
    if meshfree::settings_of(scenario).is_some() {
        return meshfree::run_meshfree(scenario, options);
    }
    let out = &options.out_dir;
    let world = build_world(scenario)?;
    std::fs::create_dir_all(out).map_err(io_error(out))?;
    let macro_path = out.join("macro.csv");
    let writer = sdem_macro_writer(scenario, &macro_path).map_err(io_error(&macro_path))?;
    let program = LoadingProgram::new(scenario.loading.clone(), &world.walls);
    let last_good = world.grains().to_vec();
    let sim = Sdem::new(world, scenario, last_good);
    run_loop(
        scenario,
        sim,
        program,
        LoopState::default(),
        writer,
        options,
        None,
    )
}

/// Continues the run of a checkpoint (see [`checkpoint`]), SDEM ([`Checkpoint`]), meshfree
/// ([`MeshfreeCheckpoint`]) or either ([`AnyCheckpoint`]), in `options.out_dir`: `macro.csv`
/// there is cut back to the rows written up to the checkpoint's step, then appended to. When
/// the output directory has no `macro.csv` but `checkpoint_path`'s directory has one, it is
/// copied first.
///
/// An MCAP log (`options.mcap`) is continued when its file exists: the frames written up to the
/// checkpoint are read back from it (finished or left unfinished by a killed process) and the
/// run goes on after them in a temporary file that replaces it (see
/// [`TrajectoryWriter::continue_log`], and [`TrajectoryWriter::continue_contours`] for the log
/// of a meshfree run), so that it ends up holding exactly the frames of the uninterrupted run.
/// When the file does not exist, a new log holds the continued part only.
pub fn resume_run<C: Resumable + ?Sized>(
    checkpoint: &C,
    checkpoint_path: &Path,
    options: &RunOptions,
) -> Result<RunSummary, RunError> {
    checkpoint.resume(checkpoint_path, options)
}

/// A checkpoint that [`resume_run`] continues.
pub trait Resumable {
    /// Continues the run (see [`resume_run`]).
    fn resume(&self, checkpoint_path: &Path, options: &RunOptions) -> Result<RunSummary, RunError>;
}

impl Resumable for Checkpoint {
    fn resume(&self, checkpoint_path: &Path, options: &RunOptions) -> Result<RunSummary, RunError> {
        resume_sdem(self, checkpoint_path, options)
    }
}

impl Resumable for MeshfreeCheckpoint {
    fn resume(&self, checkpoint_path: &Path, options: &RunOptions) -> Result<RunSummary, RunError> {
        meshfree_checkpoint::resume_meshfree(self, checkpoint_path, options)
    }
}

impl Resumable for AnyCheckpoint {
    fn resume(&self, checkpoint_path: &Path, options: &RunOptions) -> Result<RunSummary, RunError> {
        match self {
            AnyCheckpoint::Sdem(c) => c.resume(checkpoint_path, options),
            AnyCheckpoint::Meshfree(c) => c.resume(checkpoint_path, options),
        }
    }
}

/// The `macro.csv` a resumed run continues: the one in `out`, copied first from the
/// checkpoint's directory when `out` has none.
pub(crate) fn macro_to_continue(out: &Path, checkpoint_path: &Path) -> Result<PathBuf, RunError> {
    let macro_path = out.join("macro.csv");
    if !macro_path.exists() {
        let source = checkpoint_path
            .parent()
            .unwrap_or(Path::new("."))
            .join("macro.csv");
        if source.exists() {
            std::fs::copy(&source, &macro_path).map_err(io_error(&macro_path))?;
        }
    }
    Ok(macro_path)
}

/// The world of an SDEM checkpoint as it stood after its last step: grains, walls or cell,
/// time, step, totals, model levels and contact history (the loading program and the run
/// loop's state stay in the checkpoint). Errs when the contact history is inconsistent.
pub fn world_from_checkpoint(c: &Checkpoint) -> Result<World, String> {
    let scenario = &c.scenario;
    let mut world = World::new(scenario.parameters(), c.grains.clone(), c.walls.clone());
    // A checkpoint has the cell state exactly when its scenario has a periodic cell.
    world.periodic = c.periodic;
    world.time = c.time;
    world.step = c.step;
    world.totals = StepTotals {
        level_counts: world.totals.level_counts,
        ..c.totals
    };
    world.restore_kinetic(c.kinetic);
    if scenario.model.adaptive().is_some() {
        world.set_levels(&c.runner.levels);
    }
    world.restore_contact_history(&c.contact_history)?;
    Ok(world)
}

fn resume_sdem(
    checkpoint: &Checkpoint,
    checkpoint_path: &Path,
    options: &RunOptions,
) -> Result<RunSummary, RunError> {
    let c = checkpoint;
    if c.complete {
        return Err(RunError::Resume(format!(
            "{}: the run finished at step {}; there is nothing to resume",
            checkpoint_path.display(),
            c.step
        )));
    }
    let scenario = &c.scenario;
    let out = &options.out_dir;
    std::fs::create_dir_all(out).map_err(io_error(out))?;
    let macro_path = macro_to_continue(out, checkpoint_path)?;
    // A macro.csv of an sdem without the level columns is upgraded: every grain of a run
    // without the adaptive level is at the scenario's level.
    let fixed_levels = scenario.model.adaptive().is_none().then(|| {
        let mut counts = [0; 3];
        counts[scenario.model.level().index()] = c.grains.len() as u64;
        counts
    });
    let columns = sdem::extra_columns(scenario);
    let writer = if columns.is_empty() {
        MacroWriter::resume_upgrading(&macro_path, c.runner.macro_rows, fixed_levels)
    } else {
        MacroWriter::resume_with_columns(&macro_path, c.runner.macro_rows, &columns)
    }
    .map_err(|e| {
        RunError::Resume(format!(
            "{}: cannot continue it from the checkpoint's {} rows: {e}",
            macro_path.display(),
            c.runner.macro_rows
        ))
    })?;
    let world = world_from_checkpoint(c)
        .map_err(|e| RunError::Resume(format!("{}: {e}", checkpoint_path.display())))?;
    let sim = Sdem::new(world, scenario, c.runner.last_good.clone());
    run_loop(
        scenario,
        sim,
        c.program.clone(),
        c.runner.loop_state(),
        writer,
        options,
        Some(ContinueFrom {
            step: c.step,
            frames: c.runner.macro_rows,
        }),
    )
}

/// The run loop, from a fresh or a resumed state, for any solver (see [`Simulation`]): the
/// loading program drives the walls, the solver steps, the loop measures, detects jamming,
/// moves through the phases, writes the outputs and checkpoints, until the program ends.
pub fn run_loop<S: Simulation>(
    scenario: &Scenario,
    mut sim: S,
    mut program: LoadingProgram,
    mut state: LoopState,
    writer: MacroWriter,
    options: &RunOptions,
    continue_from: Option<ContinueFrom>,
) -> Result<RunSummary, RunError> {
    let mut run = Run::start(scenario, &sim, writer, options, continue_from)?;
    while !program.finished() {
        let (phase, rate) = run.drive_walls(&mut sim, &mut program, &state);
        run.step(&mut sim, &program, &state, phase)?;
        let load = run.measure(&sim, &mut state, rate);
        let mut write_row = run.row_due(&sim);
        write_row |= run.detect_jamming(&sim, &mut state, &load);
        let load = LoadState {
            jammed: state.jammed(),
            ..load
        };
        // Advance the phase when its stop condition is met (a row marks the change).
        write_row |= program.advance(sim.step_count(), sim.time(), sim.walls(), &load);
        run.check_stall(&sim, &program, &state, &load)?;
        let limit_reached = run.step_limit_reached(&sim);
        let ending = limit_reached || program.finished();
        if write_row || ending {
            run.record(&mut sim, &mut state, phase, rate)?;
        }
        run.checkpoint_or_stop(&sim, &program, &state, ending)?;
        run.report_progress(&sim, &program, &load, phase, rate);
        if limit_reached {
            break;
        }
    }
    run.finish(&sim, &program, &state)
}

/// Opens the MCAP log of a run at `settings.path`: a new one (`create`), or for a resumed run
/// (`continue_from`) the existing log continued from the checkpoint (`continue_log`; a new one
/// holding the continued part when the file does not exist; both cases are reported on
/// stderr). Each solver gives its own ways to create and to continue its kind of log.
pub(crate) fn open_log(
    settings: &McapSettings,
    continue_from: Option<ContinueFrom>,
    create: impl FnOnce() -> Result<TrajectoryWriter, WriteError>,
    continue_log: impl FnOnce(ContinueFrom) -> Result<(TrajectoryWriter, Continued), WriteError>,
) -> Result<TrajectoryWriter, RunError> {
    let path = &settings.path;
    let created = |e: WriteError| io_error(path)(e.into());
    let Some(from) = continue_from else {
        return create().map_err(created);
    };
    if !path.exists() {
        eprintln!(
            "sdem: {} does not exist: a new MCAP log holds the continued part only (frames \
             after step {})",
            path.display(),
            from.step
        );
        return create().map_err(created);
    }
    let (log, c) = continue_log(from).map_err(|e| RunError::Resume(e.to_string()))?;
    eprintln!(
        "sdem: continuing the MCAP log {}: {} frames up to step {} kept, {} after it dropped \
         ({}); written to {} until it replaces the log",
        path.display(),
        c.kept_frames,
        from.step,
        c.dropped_frames,
        if c.was_finished {
            "the log was finished"
        } else {
            "the log was unfinished"
        },
        c.temporary.display()
    );
    Ok(log)
}

/// The `sdem.summary` metadata of a finished run (no wall-clock time: logs are deterministic).
pub(crate) fn log_outcome(s: &RunSummary) -> BTreeMap<String, String> {
    let mut m: BTreeMap<String, String> = BTreeMap::new();
    m.insert("status".into(), "complete".into());
    m.insert("steps".into(), s.steps.to_string());
    m.insert("dt".into(), format!("{:e}", s.dt));
    if let Some(j) = &s.jamming {
        m.insert("jamming_step".into(), j.step.to_string());
        m.insert("phi_0".into(), format!("{}", j.phi));
        m.insert("z_0".into(), format!("{}", j.z));
        m.insert("z_nr_0".into(), format!("{}", j.z_nr));
    }
    m.insert("final_phi".into(), format!("{}", s.last.phi));
    m.insert("final_p_c".into(), format!("{:e}", s.last.p_c));
    if let Some((rms, n)) = s.eq69_rms_error {
        m.insert("eq69_rms_relative_error".into(), format!("{rms}"));
        m.insert("eq69_points".into(), n.to_string());
    }
    m
}

pub(crate) fn write_summary(
    path: &Path,
    scenario: &Scenario,
    s: &RunSummary,
) -> std::io::Result<()> {
    let mut f = std::fs::File::create(path)?;
    writeln!(f, "scenario = {}", scenario.name)?;
    writeln!(f, "grains = {}", s.grains)?;
    writeln!(f, "steps = {}", s.steps)?;
    writeln!(f, "dt = {:.6e}", s.dt)?;
    match s.critical_dt {
        Some(dt) => writeln!(f, "critical_dt = {dt:.6e}")?,
        None => writeln!(f, "critical_dt = none (implicit solver)")?,
    }
    writeln!(f, "wall_seconds = {:.3}", s.wall_seconds)?;
    writeln!(
        f,
        "grain_steps_per_second = {:.4e}",
        s.steps as f64 * s.grains as f64 / s.wall_seconds.max(1e-9)
    )?;
    if let Some(j) = &s.jamming {
        writeln!(f, "jamming_step = {}", j.step)?;
        writeln!(f, "phi_0 = {:.6}", j.phi)?;
        writeln!(f, "z_0 = {:.4}", j.z)?;
        writeln!(f, "z_nr_0 = {:.4}", j.z_nr)?;
    }
    writeln!(f, "final_phi = {:.6}", s.last.phi)?;
    writeln!(f, "final_p_c = {:.6e}", s.last.p_c)?;
    // The box as a scenario's sample section takes it, to start a run from grains.csv.
    let [x0, x1, y0, y1] = s.final_box;
    writeln!(
        f,
        "final_box = (origin: ({x0:?}, {y0:?}), box_width: {:?}, box_height: {:?})",
        x1 - x0,
        y1 - y0
    )?;
    writeln!(
        f,
        "max_loaded_inertial_number = {:.4e}",
        s.max_loaded_inertial_number
    )?;
    writeln!(f, "neighbor_builds = {}", s.neighbor_builds)?;
    if let Some(widening) = s.neighbor_skin_widening {
        writeln!(f, "neighbor_skin_widening = {widening:.3}")?;
    }
    if let Some(p) = &s.phase_seconds {
        // As LAMMPS's breakdown: which pass of the step a run's time went to.
        for (name, seconds) in [
            ("frames", p.frames),
            ("neighbor_list", p.neighbors),
            ("pairs", p.pairs),
            ("grains", p.grains),
        ] {
            writeln!(f, "pass_seconds_{name} = {seconds:.3}")?;
        }
    }
    if let Some(t) = &s.sweeps {
        writeln!(f, "sweeps = {}", t.sweeps)?;
        writeln!(f, "sweeps_in_two_passes = {}", t.two_passes)?;
        writeln!(
            f,
            "sweep_waiting_chunks_mean = {:.1} (of {})",
            t.mean_waiting_chunks(),
            t.chunks
        )?;
        writeln!(f, "sweep_runs = {}", t.runs)?;
        writeln!(f, "sweep_threads_busy = {:.3}", t.busy_share())?;
    }
    if s.mcap_seconds > 0.0 {
        writeln!(f, "mcap_write_seconds = {:.3}", s.mcap_seconds)?;
    }
    if let Some((rms, n)) = s.eq69_rms_error {
        writeln!(f, "eq69_rms_relative_error = {rms:.4}")?;
        writeln!(f, "eq69_points = {n}")?;
    }
    if let Some(a) = &s.adaptive {
        let total: u64 = a.grain_steps_by_level.iter().sum();
        for (k, name) in ["rigid", "volumetric", "full"].iter().enumerate() {
            writeln!(
                f,
                "adaptive_steps_highest_{name} = {}",
                a.steps_by_highest_level[k]
            )?;
            writeln!(
                f,
                "adaptive_dt_highest_{name} = {:.6e}",
                a.dt_by_highest_level[k]
            )?;
            writeln!(
                f,
                "adaptive_grain_step_fraction_{name} = {:.4}",
                a.grain_steps_by_level[k] as f64 / total.max(1) as f64
            )?;
        }
        if a.cycles > 0 {
            writeln!(f, "adaptive_multi_rate_cycles = {}", a.cycles)?;
            // The share of the cycles' grain-steps that took two substeps: the cycles' cost
            // against plain steps at the full level's step, whatever the machine.
            writeln!(
                f,
                "adaptive_multi_rate_fast_fraction = {:.4}",
                a.cycle_fast_grains as f64 / (a.cycles as f64 * s.grains as f64).max(1.0)
            )?;
        }
    }
    writeln!(
        f,
        "final_grains_rigid_volumetric_full = {},{},{}",
        s.last.levels[0], s.last.levels[1], s.last.levels[2]
    )?;
    Ok(())
}
