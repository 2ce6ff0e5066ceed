//! The named steps of the run loop ([`super::run_loop`]), for any [`Simulation`].

use super::progress::Progress;
use super::simulation::{LastGood, RunRecord, Simulation};
use super::{
    Jamming, PHI_LIMIT, RunError, RunOptions, RunSummary, TargetUnreachable, checkpoint, io_error,
    log_outcome, write_summary,
};
use crate::boundary::loading::{LoadState, LoadingProgram, Phase, StopWhen};
use crate::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP, Wall, box_size};
use crate::output::mcap::{ContinueFrom, TrajectoryWriter, WriteError};
use crate::output::reference::CantorReference;
use crate::output::vtk::{VtkOptions, VtkWriter};
use crate::output::{MacroWriter, Measures};
use crate::scenario::Scenario;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::Instant;

/// What the run loop carries from one step to the next besides the solver and the loading
/// program (stored in checkpoints).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LoopState {
    pub confirmed_jamming: Option<Jamming>,
    /// A state with p_c above p_jam, confirmed once p_c has stayed there for `every` steps.
    pub candidate: Option<Jamming>,
    pub max_loaded_inertial_number: f64,
    /// (phi, p_c) of the isotropic rows, for the eq. 69 comparison.
    pub isotropic_curve: Vec<(f64, f64)>,
    /// The step of the solver's last good state (the last output step).
    pub last_good_step: u64,
    /// Data rows of macro.csv written so far (header not counted).
    pub macro_rows: u64,
}

impl LoopState {
    pub fn jammed(&self) -> bool {
        self.confirmed_jamming.is_some()
    }
}

/// The run loop's context: the scenario's constants, the output files, the clocks and the
/// progress report. Its methods are the steps of the loop.
pub(super) struct Run<'a> {
    scenario: &'a Scenario,
    options: &'a RunOptions,
    young: f64,
    /// The jamming pressure p_jam (absolute).
    p_jam: f64,
    /// A macro.csv row every this many steps.
    every: u64,
    macro_path: PathBuf,
    writer: MacroWriter,
    /// The solver's own columns of the current row (reused).
    extra: String,
    log: Option<TrajectoryWriter>,
    mcap_seconds: f64,
    vtk: Option<VtkWriter>,
    checkpoint_path: PathBuf,
    checkpoints_on: bool,
    checkpoints_written: u64,
    last_checkpoint: Instant,
    progress: Progress,
    started: Instant,
    /// The step the run (or the resumed part of it) started from: the progress lines' speed
    /// counts the steps since.
    first_step: u64,
    last_progress: Instant,
    last_row: Measures,
}

impl<'a> Run<'a> {
    /// Opens the MCAP log (if asked for) and starts the clocks.
    pub(super) fn start<S: Simulation>(
        scenario: &'a Scenario,
        sim: &S,
        writer: MacroWriter,
        options: &'a RunOptions,
        continue_from: Option<ContinueFrom>,
    ) -> Result<Self, RunError> {
        let out = &options.out_dir;
        let log = match &options.mcap {
            Some(settings) => Some(sim.open_log(settings, scenario, continue_from)?),
            None => None,
        };
        let vtk = match &options.vtk {
            Some(dir) => {
                let vtk = VtkWriter::create(dir, VtkOptions::default())
                    .map_err(|e| io_error(dir)(std::io::Error::other(e.to_string())))?;
                Some(vtk)
            }
            None => None,
        };
        let phases: Vec<&'static str> = scenario.loading.iter().map(|p| p.name()).collect();
        Ok(Self {
            scenario,
            options,
            young: scenario.material.young,
            p_jam: scenario.output.jamming_pressure * scenario.material.young,
            every: scenario.output.every,
            macro_path: out.join("macro.csv"),
            writer,
            extra: String::new(),
            log,
            mcap_seconds: 0.0,
            vtk,
            checkpoint_path: out.join(checkpoint::FILE_NAME),
            checkpoints_on: options.checkpoint_every > 0 || options.checkpoint_seconds.is_some(),
            checkpoints_written: 0,
            last_checkpoint: Instant::now(),
            progress: Progress::new(options.progress_bar, &phases),
            started: Instant::now(),
            first_step: sim.step_count(),
            last_progress: Instant::now(),
            last_row: sim.measures("start", 0.0),
        })
    }

    fn log_error(&self) -> impl FnOnce(WriteError) -> RunError + '_ {
        move |e| {
            let path = self
                .options
                .mcap
                .as_ref()
                .map(|m| m.path.clone())
                .unwrap_or_default();
            io_error(&path)(e.into())
        }
    }

    /// Makes the MCAP log durable before a checkpoint.
    fn sync_log(&mut self) -> Result<(), RunError> {
        if let Some(log) = self.log.as_mut() {
            let t = Instant::now();
            let synced = log.sync();
            self.mcap_seconds += t.elapsed().as_secs_f64();
            synced.map_err(self.log_error())?;
        }
        Ok(())
    }

    /// Finishes the MCAP log (if any) with the outcome `status` and its details.
    fn finish_log(&mut self, outcome: BTreeMap<String, String>) -> Result<(), RunError> {
        if let Some(log) = self.log.take() {
            log.finish(outcome).map_err(self.log_error())?;
        }
        Ok(())
    }

    fn write_checkpoint<S: Simulation>(
        &mut self,
        sim: &S,
        program: &LoadingProgram,
        state: &LoopState,
        complete: bool,
    ) -> Result<(), RunError> {
        self.checkpoints_written += 1;
        let record = RunRecord {
            scenario: self.scenario,
            complete,
            checkpoint_every: self.options.checkpoint_every,
            checkpoint_seconds: self.options.checkpoint_seconds,
            program,
            state,
        };
        sim.write_checkpoint(&self.checkpoint_path, &record)
            .map_err(|source| RunError::CheckpointWrite {
                path: self.checkpoint_path.display().to_string(),
                source,
            })
    }

    /// Ends the run on a failure: the last good state to `grains_last_good.csv`, the MCAP log
    /// finished with `status`; returns the state file's name.
    fn fail<S: Simulation>(
        &mut self,
        sim: &S,
        state: &LoopState,
        status: &str,
        detail: String,
    ) -> Result<String, RunError> {
        self.progress.finish();
        let state_file = self.options.out_dir.join("grains_last_good.csv");
        sim.write_last_good(&state_file)
            .map_err(io_error(&state_file))?;
        let outcome: BTreeMap<String, String> = [
            ("status", status.to_string()),
            ("instability", detail),
            ("last_good_step", state.last_good_step.to_string()),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        self.finish_log(outcome)?;
        Ok(state_file.display().to_string())
    }

    /// Drive the walls: the loading program sets their velocities from the state of the last
    /// step. Returns the phase's name and strain rate for this step.
    pub(super) fn drive_walls<S: Simulation>(
        &self,
        sim: &mut S,
        program: &mut LoadingProgram,
        state: &LoopState,
    ) -> (&'static str, f64) {
        let load = sim.load_state(state.jammed());
        program.drive(sim.walls_mut(), &load);
        sim.set_shear_rate(program.shear_rate);
        let phase = program.phase().map(|p| p.name()).unwrap_or("end");
        (phase, program.rate)
    }

    /// Step the solver (and, in an affine phase, carry the grains with the box). A failure
    /// ends the run with the last good state written.
    pub(super) fn step<S: Simulation>(
        &mut self,
        sim: &mut S,
        program: &LoadingProgram,
        state: &LoopState,
        phase_name: &str,
    ) -> Result<(), RunError> {
        sim.set_affine_carry(program.affine());
        if let Err(failure) = sim.take_step() {
            let note = match program.phase().and_then(stress_target) {
                Some(target) => format!(
                    "\n  loading[{}] ({}) was heading for its target {target}; the stress reached \
                     is {}",
                    program.current,
                    phase_name,
                    stress_reached(&sim.load_state(state.jammed()))
                ),
                None => String::new(),
            };
            let state_file = self.fail(sim, state, "unstable", format!("{failure}{note}"))?;
            return Err(S::failure_error(
                failure,
                LastGood {
                    note,
                    step: state.last_good_step,
                    state_file,
                },
            ));
        }
        Ok(())
    }

    /// Measure the state the program reacts to, and keep the largest inertial number seen
    /// under load (p_c > 1e-4 E).
    pub(super) fn measure<S: Simulation>(
        &self,
        sim: &S,
        state: &mut LoopState,
        rate: f64,
    ) -> LoadState {
        let load = sim.load_state(state.jammed());
        if load.mean_stress() > 1e-4 * self.young {
            state.max_loaded_inertial_number = state
                .max_loaded_inertial_number
                .max(load.inertial_number(rate));
        }
        load
    }

    /// Whether this step is one of the regular output steps.
    pub(super) fn row_due<S: Simulation>(&self, sim: &S) -> bool {
        sim.step_count().is_multiple_of(self.every)
    }

    /// Detect jamming (SPEC §7): the first state with p_c > p_jam that carries on. A collision
    /// in the loose gas can lift p_c over p_jam for a few steps, so a candidate is only
    /// confirmed once p_c has stayed above p_jam for `every` steps. Returns true when jamming
    /// is confirmed at this step (a row is written).
    pub(super) fn detect_jamming<S: Simulation>(
        &self,
        sim: &S,
        state: &mut LoopState,
        load: &LoadState,
    ) -> bool {
        if state.confirmed_jamming.is_some() {
            return false;
        }
        let p_c = load.mean_stress();
        let step = sim.step_count();
        match state.candidate {
            None if p_c > self.p_jam => {
                let (z, z_nr) = sim.coordination_without_z_nr3();
                state.candidate = Some(Jamming {
                    step,
                    phi: load.phi,
                    z,
                    z_nr,
                    p_c,
                });
            }
            Some(_) if p_c <= self.p_jam => state.candidate = None,
            Some(c) if step >= c.step + self.every => {
                state.confirmed_jamming = state.candidate;
                return true;
            }
            _ => {}
        }
        false
    }

    /// Check that a phase with a stress target can still reach it: the run ends with
    /// [`RunError::TargetUnreachable`] once the box has collapsed or the grains fill it.
    pub(super) fn check_stall<S: Simulation>(
        &mut self,
        sim: &S,
        program: &LoadingProgram,
        state: &LoopState,
        load: &LoadState,
    ) -> Result<(), RunError> {
        let Some(phase) = program.phase() else {
            return Ok(());
        };
        let Some(target) = stress_target(phase) else {
            return Ok(());
        };
        let Some(reason) = stalled(sim.walls(), load, sim.conserved_area()) else {
            return Ok(());
        };
        let phase = format!("loading[{}] ({})", program.current, phase.name());
        let reached = stress_reached(load);
        let detail = format!("{phase} cannot reach {target}: {reason}; reached {reached}");
        let state_file = self.fail(sim, state, "target unreachable", detail)?;
        Err(RunError::TargetUnreachable(Box::new(TargetUnreachable {
            step: sim.step_count(),
            phase,
            target,
            reason,
            reached,
            last_good_step: state.last_good_step,
            state_file,
        })))
    }

    /// Whether the scenario's step limit (`output.max_steps`) is reached.
    pub(super) fn step_limit_reached<S: Simulation>(&self, sim: &S) -> bool {
        let max = self.scenario.output.max_steps;
        max > 0 && sim.step_count() >= max
    }

    /// Record the state: a macro.csv row, an MCAP frame, and the last good state.
    pub(super) fn record<S: Simulation>(
        &mut self,
        sim: &mut S,
        state: &mut LoopState,
        phase_name: &str,
        rate: f64,
    ) -> Result<(), RunError> {
        self.last_row = sim.measures(phase_name, rate);
        if phase_name == "isotropic" {
            state
                .isotropic_curve
                .push((self.last_row.phi, self.last_row.p_c));
        }
        self.extra.clear();
        sim.extra_columns(&mut self.extra);
        self.writer
            .write_with(&self.last_row, &self.extra)
            .map_err(io_error(&self.macro_path))?;
        state.macro_rows += 1;
        if let Some(log) = self.log.as_mut() {
            let t = Instant::now();
            let written = sim.write_frame(log, &self.last_row);
            self.mcap_seconds += t.elapsed().as_secs_f64();
            written.map_err(self.log_error())?;
        }
        if let Some(vtk) = self.vtk.as_mut() {
            let dir = self.options.vtk.clone().unwrap_or_default();
            let vtk_error = |e: String| io_error(&dir)(std::io::Error::other(e));
            let frame = sim.frame(&self.last_row).map_err(vtk_error)?;
            vtk.write_frame(&frame)
                .map_err(|e| vtk_error(e.to_string()))?;
        }
        sim.keep_last_good();
        state.last_good_step = sim.step_count();
        Ok(())
    }

    /// Checkpoint when due (every `checkpoint_every` steps or `checkpoint_seconds` seconds),
    /// or when a stop was asked for: then the run ends with [`RunError::Interrupted`]. Nothing
    /// on the run's last step (`ending`): [`Run::finish`] writes the final checkpoint.
    pub(super) fn checkpoint_or_stop<S: Simulation>(
        &mut self,
        sim: &S,
        program: &LoadingProgram,
        state: &LoopState,
        ending: bool,
    ) -> Result<(), RunError> {
        if ending {
            return Ok(());
        }
        let options = self.options;
        let step = sim.step_count();
        let stop_requested = options
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
            || options.stop_after_step == Some(step);
        if stop_requested
            || (options.checkpoint_every > 0 && step.is_multiple_of(options.checkpoint_every))
            || options
                .checkpoint_seconds
                .is_some_and(|s| self.last_checkpoint.elapsed().as_secs_f64() >= s)
        {
            self.sync_log()?;
            self.write_checkpoint(sim, program, state, false)?;
            self.last_checkpoint = Instant::now();
        }
        if stop_requested {
            self.progress.finish();
            self.finish_log(
                [
                    ("status".to_string(), "interrupted".to_string()),
                    ("steps".to_string(), step.to_string()),
                ]
                .into_iter()
                .collect(),
            )?;
            return Err(RunError::Interrupted {
                step,
                checkpoint: self.checkpoint_path.display().to_string(),
            });
        }
        Ok(())
    }

    /// Report progress: the progress bar, and a line every `progress_seconds`.
    pub(super) fn report_progress<S: Simulation>(
        &mut self,
        sim: &S,
        program: &LoadingProgram,
        load: &LoadState,
        phase_name: &str,
        rate: f64,
    ) {
        let p_c = load.mean_stress();
        self.progress
            .update(program, sim, load, self.started, self.first_step);
        if let Some(seconds) = self.options.progress_seconds
            && self.last_progress.elapsed().as_secs_f64() >= seconds
        {
            self.last_progress = Instant::now();
            let elapsed = self.started.elapsed().as_secs_f64();
            self.progress.suspend(|| eprintln!(
                "step {:>9}  t {:.4e}  {:<10}  phi {:.4}  p_c {:.3e}  rate {:.2e}  contacts {}  {:.2e} grain-steps/s",
                sim.step_count(),
                sim.time(),
                phase_name,
                load.phi,
                p_c,
                rate,
                sim.contacts(),
                (sim.step_count() - self.first_step) as f64 * sim.grain_count() as f64 / elapsed
            ));
        }
    }

    /// Finish the run: the final checkpoint (when checkpoints are on), `grains.csv`, the
    /// summary (`summary.txt`, and the MCAP log's).
    pub(super) fn finish<S: Simulation>(
        mut self,
        sim: &S,
        program: &LoadingProgram,
        state: &LoopState,
    ) -> Result<RunSummary, RunError> {
        self.progress.finish();
        if self.checkpoints_on {
            self.sync_log()?;
            self.write_checkpoint(sim, program, state, true)?;
        }
        let out = &self.options.out_dir;
        let grains_path = out.join("grains.csv");
        sim.write_grains(&grains_path)
            .map_err(io_error(&grains_path))?;
        let scenario = self.scenario;
        let jamming = state.confirmed_jamming;
        let eq69_rms_error = match jamming {
            Some(j) if scenario.material.is_incompressible() => {
                let reference = CantorReference::new(j.phi, j.z_nr);
                let phi_high = state
                    .isotropic_curve
                    .iter()
                    .map(|p| p.0)
                    .fold(0.0, f64::max);
                reference.rms_relative_error(
                    &state.isotropic_curve,
                    self.young,
                    j.phi + 0.01,
                    phi_high,
                )
            }
            _ => None,
        };
        let statistics = sim.statistics();
        let w = sim.walls();
        let mut summary = RunSummary {
            eq69_rms_error,
            grains: sim.grain_count(),
            steps: sim.step_count(),
            dt: sim.dt(),
            critical_dt: sim.critical_dt(scenario),
            wall_seconds: self.started.elapsed().as_secs_f64(),
            jamming,
            last: std::mem::take(&mut self.last_row),
            max_loaded_inertial_number: state.max_loaded_inertial_number,
            neighbor_builds: statistics.neighbor_builds,
            neighbor_skin_widening: statistics.neighbor_skin_widening,
            phase_seconds: statistics.phase_seconds,
            sweeps: statistics.sweeps,
            mcap_seconds: self.mcap_seconds,
            adaptive: statistics.adaptive,
            checkpoints_written: self.checkpoints_written,
            final_box: [
                w[LEFT].point.x,
                w[RIGHT].point.x,
                w[BOTTOM].point.y,
                w[TOP].point.y,
            ],
        };
        if let Some(log) = self.log.take() {
            let t = Instant::now();
            log.finish(log_outcome(&summary))
                .map_err(self.log_error())?;
            summary.mcap_seconds += t.elapsed().as_secs_f64();
        }
        let summary_path = out.join("summary.txt");
        write_summary(&summary_path, scenario, &summary).map_err(io_error(&summary_path))?;
        Ok(summary)
    }
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
fn stalled(walls: &[Wall], state: &LoadState, conserved_area: Option<f64>) -> Option<String> {
    let (width, height) = box_size(walls);
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
