//! A scenario from start to end: generate the sample, build the box, run the loading program,
//! write the measures.

pub mod bench;
pub mod checkpoint;

use crate::boundary::loading::{LoadState, LoadingProgram, Phase, StopWhen};
use crate::boundary::walls::{box_size, box_walls};
use crate::grain::Grain;
use crate::integration::{Instability, StepTotals, World};
use crate::output::mcap::{ContinueFrom, McapSettings, TrajectoryWriter};
use crate::output::reference::CantorReference;
use crate::output::{MacroWriter, Measures, write_grains_csv};
use crate::sample::{self, SampleError};
use crate::scenario::Scenario;
use checkpoint::{Checkpoint, CheckpointError, RunnerState};
use glam::DVec2;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Sample(#[from] SampleError),
    #[error("writing {path}")]
    Output {
        path: String,
        source: std::io::Error,
    },
    /// An instability; `note` (empty, or a line starting with a newline) says which stress
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
    pub critical_dt: f64,
    pub wall_seconds: f64,
    pub jamming: Option<Jamming>,
    pub last: Measures,
    /// Largest inertial number seen once p_c > 1e-4 E.
    pub max_loaded_inertial_number: f64,
    pub neighbor_builds: u64,
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

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> RunError + '_ {
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
        (None, Some(spec)) => sample::generate(&spec, scenario.seed)?
            .iter()
            .map(|p| {
                let center = if (x0, y0) == (0.0, 0.0) {
                    DVec2::new(p.x, p.y)
                } else {
                    DVec2::new(x0 + p.x, y0 + p.y)
                };
                Grain::at_rest(center, p.radius)
            })
            .collect(),
        (None, None) => {
            return Err(RunError::Setup(format!(
                "scenario {}: sample.file {:?} has not been read (Scenario::load reads it)",
                scenario.name,
                s.file.as_deref().unwrap_or(Path::new("")).display()
            )));
        }
    };
    let b = s.bounds();
    let walls = box_walls(b.x0, b.x1, b.y0, b.y1);
    Ok(World::new(scenario.parameters(), grains, walls))
}

/// Runs a scenario to the end of its loading program, writing `macro.csv`, `grains.csv` and
/// `summary.txt` in `options.out_dir`.
pub fn run_scenario(scenario: &Scenario, options: &RunOptions) -> Result<RunSummary, RunError> {
    let out = &options.out_dir;
    let world = build_world(scenario)?;
    std::fs::create_dir_all(out).map_err(io_error(out))?;
    let macro_path = out.join("macro.csv");
    let writer = MacroWriter::create(&macro_path).map_err(io_error(&macro_path))?;
    let program = LoadingProgram::new(scenario.loading.clone(), &world.walls);
    let runner = RunnerState {
        last_good: world.grains.clone(),
        ..Default::default()
    };
    run_loop(scenario, world, program, runner, writer, options, None)
}

/// Continues the run of a checkpoint (see [`checkpoint`]) in `options.out_dir`: `macro.csv`
/// there is cut back to the rows written up to the checkpoint's step, then appended to. When
/// the output directory has no `macro.csv` but `checkpoint_path`'s directory has one, it is
/// copied first.
///
/// An MCAP log (`options.mcap`) is continued when its file exists: the frames written up to the
/// checkpoint are read back from it (finished or left unfinished by a killed process) and the
/// run goes on after them in a temporary file that replaces it (see
/// [`TrajectoryWriter::continue_log`]), so that it ends up holding exactly the frames of the
/// uninterrupted run. When the file does not exist, a new log holds the continued part only.
pub fn resume_run(
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
    // A macro.csv of an sdem without the level columns is upgraded: every grain of a run
    // without the adaptive level is at the scenario's level.
    let fixed_levels = scenario.model.adaptive().is_none().then(|| {
        let mut counts = [0; 3];
        counts[scenario.model.level().index()] = c.grains.len() as u64;
        counts
    });
    let writer = MacroWriter::resume_upgrading(&macro_path, c.runner.macro_rows, fixed_levels)
        .map_err(|e| {
            RunError::Resume(format!(
                "{}: cannot continue it from the checkpoint's {} rows: {e}",
                macro_path.display(),
                c.runner.macro_rows
            ))
        })?;
    let mut world = World::new(scenario.parameters(), c.grains.clone(), c.walls.clone());
    world.time = c.time;
    world.step = c.step;
    world.totals = StepTotals {
        level_counts: world.totals.level_counts,
        ..c.totals
    };
    if scenario.model.adaptive().is_some() {
        world.set_levels(&c.runner.levels);
    }
    run_loop(
        scenario,
        world,
        c.program.clone(),
        c.runner.clone(),
        writer,
        options,
        Some(ContinueFrom {
            step: c.step,
            frames: c.runner.macro_rows,
        }),
    )
}

fn snapshot(
    scenario: &Scenario,
    world: &World,
    program: &LoadingProgram,
    runner: &RunnerState,
    complete: bool,
    options: &RunOptions,
) -> Checkpoint {
    let mut runner = runner.clone();
    if scenario.model.adaptive().is_some() {
        runner.levels = world.levels().to_vec();
    }
    Checkpoint {
        scenario: scenario.clone(),
        complete,
        checkpoint_every: options.checkpoint_every,
        checkpoint_seconds: options.checkpoint_seconds,
        step: world.step,
        time: world.time,
        grains: world.grains.clone(),
        walls: world.walls.clone(),
        totals: world.totals,
        program: program.clone(),
        runner,
    }
}

/// The run loop, from a fresh or a resumed state.
fn run_loop(
    scenario: &Scenario,
    mut world: World,
    mut program: LoadingProgram,
    mut r: RunnerState,
    mut writer: MacroWriter,
    options: &RunOptions,
    continue_from: Option<ContinueFrom>,
) -> Result<RunSummary, RunError> {
    let out = &options.out_dir;
    let mut log = match &options.mcap {
        Some(settings) => Some(open_log(settings, scenario, &world, continue_from)?),
        None => None,
    };
    let log_error = |e: crate::output::mcap::WriteError| {
        let path = options
            .mcap
            .as_ref()
            .map(|m| m.path.clone())
            .unwrap_or_default();
        io_error(&path)(e.into())
    };
    let checkpoint_path = out.join(checkpoint::FILE_NAME);
    let mut checkpoints_written = 0u64;
    let mut write_checkpoint = |c: Checkpoint| {
        checkpoints_written += 1;
        c.write_atomic(&checkpoint_path)
            .map_err(io_error(&checkpoint_path))
    };
    let checkpoints_on = options.checkpoint_every > 0 || options.checkpoint_seconds.is_some();
    let mut last_checkpoint = Instant::now();
    let mut mcap_seconds = 0.0;
    let mut progress = Progress::new(options.progress_bar, &program_phases(scenario));
    let started = Instant::now();
    let macro_path = out.join("macro.csv");
    let mean_diameter =
        2.0 * world.grains.iter().map(|g| g.radius).sum::<f64>() / world.grains.len() as f64;
    let young = scenario.material.young;
    let p_jam = scenario.output.jamming_pressure * young;
    let every = scenario.output.every;
    let mut last_progress = Instant::now();
    let mut last_row = Measures::of(&world, "start", 0.0, mean_diameter);
    // Counted over this process's steps only (a resumed run reports its continued part).
    let mut adaptive_stats = world.params.adaptive.map(|a| AdaptiveStats {
        dt_by_highest_level: a.dt,
        ..Default::default()
    });
    // Incompressible grains keep their area pi R^2: their total is the area they need.
    let conserved_area = scenario
        .material
        .is_incompressible()
        .then(|| world.grains.iter().map(Grain::reference_area).sum::<f64>());

    while !program.finished() {
        let state = Measures::load_state(&world, r.confirmed_jamming.is_some(), mean_diameter);
        program.drive(&mut world.walls, &state);
        let phase_name = program.phase().map(|p| p.name()).unwrap_or("end");
        let rate = program.rate;
        // Ends the run on a failure: the last good state to grains_last_good.csv, the MCAP log
        // finished with `status`; returns the state file's name.
        let mut fail = |world: &World,
                        r: &RunnerState,
                        log: &mut Option<TrajectoryWriter>,
                        status: &str,
                        detail: String|
         -> Result<String, RunError> {
            progress.finish();
            let state_file = out.join("grains_last_good.csv");
            let mut snapshot = world.clone();
            snapshot.grains.clone_from(&r.last_good);
            write_grains_csv(&state_file, &snapshot).map_err(io_error(&state_file))?;
            if let Some(log) = log.take() {
                let outcome: BTreeMap<String, String> = [
                    ("status", status.to_string()),
                    ("instability", detail),
                    ("last_good_step", r.last_good_step.to_string()),
                ]
                .into_iter()
                .map(|(k, v)| (k.to_string(), v))
                .collect();
                log.finish(outcome).map_err(log_error)?;
            }
            Ok(state_file.display().to_string())
        };
        // The box before the step, for an affine phase's remap of the grain centres.
        let box_before = program.affine().then(|| box_corners(&world.walls));
        let highest_before = highest_level(&world.totals.level_counts);
        if let Err(instability) = world.step() {
            let note = match program.phase().and_then(stress_target) {
                Some(target) => format!(
                    "\n  loading[{}] ({}) was heading for its target {target}; the stress reached \
                     is {}",
                    program.current,
                    phase_name,
                    stress_reached(&Measures::load_state(
                        &world,
                        r.confirmed_jamming.is_some(),
                        mean_diameter
                    ))
                ),
                None => String::new(),
            };
            let state_file = fail(
                &world,
                &r,
                &mut log,
                "unstable",
                format!("{instability}{note}"),
            )?;
            return Err(RunError::Unstable {
                instability,
                note,
                last_good_step: r.last_good_step,
                state_file,
            });
        }
        if let Some(stats) = adaptive_stats.as_mut() {
            stats.steps_by_highest_level[highest_before] += 1;
            for (sum, count) in stats
                .grain_steps_by_level
                .iter_mut()
                .zip(&world.totals.level_counts)
            {
                *sum += count;
            }
        }
        if let Some((lo, hi)) = box_before {
            let (to_lo, to_hi) = box_corners(&world.walls);
            world.remap_affine(lo, hi, to_lo, to_hi);
        }
        let state = Measures::load_state(&world, r.confirmed_jamming.is_some(), mean_diameter);
        let p_c = state.mean_stress();
        let mut write_row = world.step % every == 0;
        if p_c > 1e-4 * young {
            r.max_loaded_inertial_number = r
                .max_loaded_inertial_number
                .max(state.inertial_number(rate));
        }
        // Jamming (SPEC §7) is the first state with p_c > p_jam that carries on: a collision
        // in the loose gas can lift p_c over p_jam for a few steps, so a candidate is only
        // confirmed once p_c has stayed above p_jam for `every` steps.
        if r.confirmed_jamming.is_none() {
            match r.candidate {
                None if p_c > p_jam => {
                    let (z, z_nr) = world.coordination();
                    r.candidate = Some(Jamming {
                        step: world.step,
                        phi: state.phi,
                        z,
                        z_nr,
                        p_c,
                    });
                }
                Some(_) if p_c <= p_jam => r.candidate = None,
                Some(c) if world.step >= c.step + every => {
                    r.confirmed_jamming = r.candidate;
                    write_row = true;
                }
                _ => {}
            }
        }
        let jammed = r.confirmed_jamming.is_some();
        let state = crate::boundary::loading::LoadState { jammed, ..state };
        if program.advance(world.step, world.time, &world.walls, &state) {
            write_row = true;
        }
        if let Some(phase) = program.phase()
            && let Some(target) = stress_target(phase)
            && let Some(reason) = stalled(&world, &state, conserved_area)
        {
            let phase = format!("loading[{}] ({})", program.current, phase.name());
            let reached = stress_reached(&state);
            let detail = format!("{phase} cannot reach {target}: {reason}; reached {reached}");
            let state_file = fail(&world, &r, &mut log, "target unreachable", detail)?;
            return Err(RunError::TargetUnreachable(Box::new(TargetUnreachable {
                step: world.step,
                phase,
                target,
                reason,
                reached,
                last_good_step: r.last_good_step,
                state_file,
            })));
        }
        let limit_reached =
            scenario.output.max_steps > 0 && world.step >= scenario.output.max_steps;
        if write_row || program.finished() || limit_reached {
            last_row = Measures::of(&world, phase_name, rate, mean_diameter);
            if phase_name == "isotropic" {
                r.isotropic_curve.push((last_row.phi, last_row.p_c));
            }
            writer.write(&last_row).map_err(io_error(&macro_path))?;
            r.macro_rows += 1;
            if let Some(log) = log.as_mut() {
                let t = Instant::now();
                log.write_frame(&world, &last_row).map_err(log_error)?;
                mcap_seconds += t.elapsed().as_secs_f64();
            }
            r.last_good.clone_from(&world.grains);
            r.last_good_step = world.step;
        }
        let ending = limit_reached || program.finished();
        let stop_requested = options
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
            || options.stop_after_step == Some(world.step);
        if !ending
            && (stop_requested
                || (options.checkpoint_every > 0 && world.step % options.checkpoint_every == 0)
                || options
                    .checkpoint_seconds
                    .is_some_and(|s| last_checkpoint.elapsed().as_secs_f64() >= s))
        {
            if let Some(log) = log.as_mut() {
                let t = Instant::now();
                log.sync().map_err(log_error)?;
                mcap_seconds += t.elapsed().as_secs_f64();
            }
            write_checkpoint(snapshot(scenario, &world, &program, &r, false, options))?;
            last_checkpoint = Instant::now();
        }
        if stop_requested && !ending {
            progress.finish();
            if let Some(log) = log.take() {
                let outcome: BTreeMap<String, String> = [
                    ("status".to_string(), "interrupted".to_string()),
                    ("steps".to_string(), world.step.to_string()),
                ]
                .into_iter()
                .collect();
                log.finish(outcome).map_err(log_error)?;
            }
            return Err(RunError::Interrupted {
                step: world.step,
                checkpoint: checkpoint_path.display().to_string(),
            });
        }
        progress.update(&program, &world, state.phi, p_c, started);
        if let Some(seconds) = options.progress_seconds
            && last_progress.elapsed().as_secs_f64() >= seconds
        {
            last_progress = Instant::now();
            let elapsed = started.elapsed().as_secs_f64();
            progress.suspend(|| eprintln!(
                "step {:>9}  t {:.4e}  {:<10}  phi {:.4}  p_c {:.3e}  rate {:.2e}  contacts {}  {:.2e} grain-steps/s",
                world.step,
                world.time,
                phase_name,
                state.phi,
                p_c,
                rate,
                world.totals.contacts,
                world.step as f64 * world.grains.len() as f64 / elapsed
            ));
        }
        if limit_reached {
            break;
        }
    }
    progress.finish();
    if checkpoints_on {
        if let Some(log) = log.as_mut() {
            let t = Instant::now();
            log.sync().map_err(log_error)?;
            mcap_seconds += t.elapsed().as_secs_f64();
        }
        write_checkpoint(snapshot(scenario, &world, &program, &r, true, options))?;
    }
    let grains_path = out.join("grains.csv");
    write_grains_csv(&grains_path, &world).map_err(io_error(&grains_path))?;
    let jamming = r.confirmed_jamming;
    let eq69_rms_error = match jamming {
        Some(j) if scenario.material.is_incompressible() => {
            let reference = CantorReference::new(j.phi, j.z_nr);
            let phi_high = r.isotropic_curve.iter().map(|p| p.0).fold(0.0, f64::max);
            reference.rms_relative_error(&r.isotropic_curve, young, j.phi + 0.01, phi_high)
        }
        _ => None,
    };
    let mut summary = RunSummary {
        eq69_rms_error,
        grains: world.grains.len(),
        steps: world.step,
        dt: world.params.dt,
        critical_dt: scenario.critical_time_step(),
        wall_seconds: started.elapsed().as_secs_f64(),
        jamming,
        last: last_row,
        max_loaded_inertial_number: r.max_loaded_inertial_number,
        neighbor_builds: world.neighbors.builds,
        mcap_seconds,
        adaptive: adaptive_stats,
        checkpoints_written,
        final_box: {
            use crate::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP};
            let w = &world.walls;
            [
                w[LEFT].point.x,
                w[RIGHT].point.x,
                w[BOTTOM].point.y,
                w[TOP].point.y,
            ]
        },
    };
    if let Some(log) = log.take() {
        let t = Instant::now();
        log.finish(log_outcome(&summary)).map_err(log_error)?;
        summary.mcap_seconds += t.elapsed().as_secs_f64();
    }
    let summary_path = out.join("summary.txt");
    write_summary(&summary_path, scenario, &summary).map_err(io_error(&summary_path))?;
    Ok(summary)
}

/// Opens the MCAP log of a run: a new one, or for a resumed run (`continue_from`) the existing
/// log continued from the checkpoint (a new one holding the continued part when the file does
/// not exist; both cases are reported on stderr).
fn open_log(
    settings: &McapSettings,
    scenario: &Scenario,
    world: &World,
    continue_from: Option<ContinueFrom>,
) -> Result<TrajectoryWriter, RunError> {
    let path = &settings.path;
    let created = |e: crate::output::mcap::WriteError| io_error(path)(e.into());
    let Some(from) = continue_from else {
        return TrajectoryWriter::create(settings, scenario, world).map_err(created);
    };
    if !path.exists() {
        eprintln!(
            "sdem: {} does not exist: a new MCAP log holds the continued part only (frames \
             after step {})",
            path.display(),
            from.step
        );
        return TrajectoryWriter::create(settings, scenario, world).map_err(created);
    }
    let (log, c) = TrajectoryWriter::continue_log(settings, scenario, world, from)
        .map_err(|e| RunError::Resume(e.to_string()))?;
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
fn log_outcome(s: &RunSummary) -> BTreeMap<String, String> {
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

/// The stress target of a phase, for messages (None when it has none): a servo's wall
/// stresses, and any `MeanStress` stop condition.
fn stress_target(phase: &Phase) -> Option<String> {
    let mut parts = Vec::new();
    if let Phase::Servo { sxx, syy, .. } = phase {
        parts.push(format!("sxx_c = {sxx}, syy_c = {syy}"));
    }
    fn mean_stresses(until: &StopWhen, parts: &mut Vec<String>) {
        match until {
            StopWhen::MeanStress(p) => parts.push(format!("p_c = {p}")),
            StopWhen::Any(list) => list.iter().for_each(|u| mean_stresses(u, parts)),
            _ => {}
        }
    }
    mean_stresses(phase.until(), &mut parts);
    (!parts.is_empty()).then(|| format!("{} (compression positive)", parts.join(" or ")))
}

fn stress_reached(state: &LoadState) -> String {
    format!(
        "sxx_c = {:.4e}, syy_c = {:.4e}, p_c = {:.4e} at phi = {:.5}",
        state.sxx,
        state.syy,
        state.mean_stress(),
        state.phi
    )
}

/// Why a phase can no longer raise the stress, if it cannot: the box collapsed, or the grains
/// fill it: the packing fraction, or for incompressible grains (whose areas stay pi R^2) their
/// total area over the box area, at [`PHI_LIMIT`] or above.
fn stalled(world: &World, state: &LoadState, conserved_area: Option<f64>) -> Option<String> {
    let (width, height) = box_size(&world.walls);
    if !(width > 0.0 && height > 0.0) {
        return Some(format!(
            "the box has collapsed (width {width:.4e}, height {height:.4e})"
        ));
    }
    let filled = conserved_area.map_or(0.0, |a| a / (width * height));
    if state.phi >= PHI_LIMIT || filled >= PHI_LIMIT {
        return Some(format!(
            "the grains fill the box (phi = {:.5}, grain area / box area = {:.5}; the limit is \
             {PHI_LIMIT})",
            state.phi,
            if conserved_area.is_some() {
                filled
            } else {
                state.phi
            }
        ));
    }
    None
}

/// Index of the highest level with grains in it (0 when none).
fn highest_level(counts: &[u64; 3]) -> usize {
    (0..3).rev().find(|&k| counts[k] > 0).unwrap_or(0)
}

fn program_phases(scenario: &Scenario) -> Vec<&'static str> {
    scenario.loading.iter().map(|p| p.name()).collect()
}

/// Fraction of a stop condition reached, when it can be told.
fn stop_fraction(
    until: &StopWhen,
    program: &LoadingProgram,
    world: &World,
    phi: f64,
    p_c: f64,
    phi_start: f64,
) -> Option<f64> {
    let f = match until {
        StopWhen::PackingFraction(target) => {
            let span = target - phi_start;
            (span.abs() > 1e-12).then(|| (phi - phi_start) / span)?
        }
        StopWhen::MeanStress(target) => (*target > 0.0).then(|| p_c / target)?,
        StopWhen::Jammed => return None,
        StopWhen::Steps(n) => (world.step - program.phase_start_step) as f64 / (*n).max(1) as f64,
        StopWhen::Time(t) => (world.time - program.phase_start_time) / t.max(f64::MIN_POSITIVE),
        StopWhen::Strain(e) => {
            let (w0, _) = program.phase_start_size;
            let (w, _) = crate::boundary::walls::box_size(&world.walls);
            (1.0 - w / w0) / e
        }
        StopWhen::Any(list) => {
            return list
                .iter()
                .filter_map(|u| stop_fraction(u, program, world, phi, p_c, phi_start))
                .fold(None, |acc: Option<f64>, f| {
                    Some(acc.map_or(f, |a| a.max(f)))
                });
        }
    };
    f.is_finite().then_some(f.clamp(0.0, 1.0))
}

/// The progress bar of a run: appears after [`Progress::DELAY`], redrawn at most 10 times a
/// second, hidden when stderr is not a terminal (indicatif's stderr target).
struct Progress {
    enabled: bool,
    bar: Option<ProgressBar>,
    phases: Vec<&'static str>,
    phase_seen: Option<usize>,
    phi_start: f64,
    known: bool,
    last_draw: Option<Instant>,
}

impl Progress {
    const DELAY: Duration = Duration::from_secs(3);
    const PERIOD: Duration = Duration::from_millis(100);

    fn new(enabled: bool, phases: &[&'static str]) -> Self {
        Self {
            enabled,
            bar: None,
            phases: phases.to_vec(),
            phase_seen: None,
            phi_start: 0.0,
            known: false,
            last_draw: None,
        }
    }

    fn bar_style() -> ProgressStyle {
        ProgressStyle::with_template(
            "{prefix} [{elapsed_precise}] {bar:30.cyan/blue} {percent:>3}%  {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ")
    }

    fn spinner_style() -> ProgressStyle {
        ProgressStyle::with_template("{prefix} [{elapsed_precise}] {spinner}  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner())
    }

    fn update(
        &mut self,
        program: &LoadingProgram,
        world: &World,
        phi: f64,
        p_c: f64,
        started: Instant,
    ) {
        if !self.enabled {
            return;
        }
        if self.phase_seen != Some(program.current) {
            self.phase_seen = Some(program.current);
            self.phi_start = phi;
        }
        let now = Instant::now();
        if self.bar.is_none() {
            if now.duration_since(started) < Self::DELAY {
                return;
            }
            let bar = ProgressBar::with_draw_target(Some(1000), ProgressDrawTarget::stderr())
                .with_style(Self::spinner_style());
            bar.set_elapsed(now.duration_since(started));
            self.bar = Some(bar);
        }
        if self
            .last_draw
            .is_some_and(|t| now.duration_since(t) < Self::PERIOD)
        {
            return;
        }
        self.last_draw = Some(now);
        let Some(bar) = &self.bar else { return };
        let fraction = program
            .phase()
            .and_then(|p| stop_fraction(p.until(), program, world, phi, p_c, self.phi_start));
        if fraction.is_some() != self.known {
            self.known = fraction.is_some();
            bar.set_style(if self.known {
                Self::bar_style()
            } else {
                Self::spinner_style()
            });
        }
        bar.set_prefix(format!(
            "{} {}/{}",
            program.phase().map_or("end", |p| p.name()),
            (program.current + 1).min(self.phases.len()),
            self.phases.len()
        ));
        if let Some(f) = fraction {
            bar.set_position((f * 1000.0) as u64);
        } else {
            bar.tick();
        }
        let elapsed = now.duration_since(started).as_secs_f64().max(1e-9);
        bar.set_message(format!(
            "step {}  φ {:.4}  p_c {:.3e}  contacts {}  {:.2e} grain-steps/s",
            world.step,
            phi,
            p_c,
            world.totals.contacts,
            world.step as f64 * world.grains.len() as f64 / elapsed
        ));
    }

    fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        match &self.bar {
            Some(bar) => bar.suspend(f),
            None => f(),
        }
    }

    fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}

fn write_summary(path: &Path, scenario: &Scenario, s: &RunSummary) -> std::io::Result<()> {
    let mut f = std::fs::File::create(path)?;
    writeln!(f, "scenario = {}", scenario.name)?;
    writeln!(f, "grains = {}", s.grains)?;
    writeln!(f, "steps = {}", s.steps)?;
    writeln!(f, "dt = {:.6e}", s.dt)?;
    writeln!(f, "critical_dt = {:.6e}", s.critical_dt)?;
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
    }
    writeln!(
        f,
        "final_grains_rigid_volumetric_full = {},{},{}",
        s.last.levels[0], s.last.levels[1], s.last.levels[2]
    )?;
    Ok(())
}

/// Lower-left and upper-right corners of the box made by the four walls.
fn box_corners(walls: &[crate::boundary::walls::Wall]) -> (glam::DVec2, glam::DVec2) {
    use crate::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP};
    (
        glam::DVec2::new(walls[LEFT].point.x, walls[BOTTOM].point.y),
        glam::DVec2::new(walls[RIGHT].point.x, walls[TOP].point.y),
    )
}
