//! The seam between the run loop and a solver: [`Simulation`].

use super::{AdaptiveStats, LoopState, RunError};
use crate::boundary::loading::{LoadState, LoadingProgram};
use crate::boundary::walls::Wall;
use crate::integration::PhaseTimes;
use crate::output::Measures;
use crate::output::frame::Frame;
use crate::output::mcap::{ContinueFrom, McapSettings, TrajectoryWriter, WriteError};
use crate::scenario::Scenario;
use std::path::Path;

/// A solver as the run loop ([`super::run_loop`]) drives it: a box of grains between four
/// walls that the loading program moves, stepped in time, measured, and written out. (A
/// periodic cell is driven the same way: its four virtual walls carry the cell's size and
/// strain rates, see [`crate::boundary::periodic::PeriodicBoundary`]; a shear phase also sets
/// [`set_shear_rate`](Self::set_shear_rate).)
///
/// The loop owns everything that does not depend on how the grains are computed: the loading
/// program, jamming detection, stop conditions, the output cadence, checkpoint cadence,
/// interruption and progress reports. A solver answers the loop's questions about its state
/// and writes its own files. One call of each method per step at most: the trait sits at the
/// step level, the loop is generic over it (no dynamic dispatch), and nothing here should
/// allocate per step.
///
/// # What one step of the loop asks of a solver
///
/// 1. [`load_state`](Self::load_state): the wall stresses and packing fraction the loading
///    program reacts to; the program then sets the wall velocities through
///    [`walls_mut`](Self::walls_mut).
/// 2. [`take_step`](Self::take_step): advance by one time step, moving the walls by their
///    velocity × dt and counting the step ([`step_count`](Self::step_count),
///    [`time`](Self::time)). On failure the loop writes the last good state
///    ([`write_last_good`](Self::write_last_good)) and ends the run with
///    [`failure_error`](Self::failure_error).
/// 3. In an affine phase (told before the step by [`set_affine_carry`](Self::set_affine_carry))
///    the step itself has carried the grains with the box, from the box before the step to
///    the box after it.
/// 4. [`load_state`](Self::load_state) again, and [`coordination`](Self::coordination) when
///    the mean stress first rises above the jamming pressure.
/// 5. On output steps: [`measures`](Self::measures) (a `macro.csv` row, plus the solver's
///    [`EXTRA_COLUMNS`](Self::EXTRA_COLUMNS) from [`extra_columns`](Self::extra_columns)),
///    [`write_frame`](Self::write_frame) to the MCAP log when there is one, and
///    [`keep_last_good`](Self::keep_last_good): that state is the one reported after a failure.
/// 6. On checkpoint steps: [`write_checkpoint`](Self::write_checkpoint).
///
/// At the end: [`write_grains`](Self::write_grains) (`grains.csv`) and the summary figures
/// ([`grain_count`](Self::grain_count), [`dt`](Self::dt), [`statistics`](Self::statistics)).
///
/// # Implementing it for a new solver
///
/// Build the solver's state, then call [`super::run_loop`] with it, a fresh
/// [`LoadingProgram`] (or the checkpoint's), a [`LoopState`] (default, or the checkpoint's) and
/// a [`crate::output::MacroWriter`] created with the solver's `EXTRA_COLUMNS`. The walls are
/// [`Wall`]s in the order of [`crate::boundary::walls::box_walls`]: the loop reads the box from
/// them. Stresses are compression positive in [`LoadState`] and [`Measures`] (see
/// [`crate::output`]). A resumed run must continue bit for bit: whatever
/// [`write_checkpoint`](Self::write_checkpoint) leaves out must not change the results. The
/// methods with a default (affine remap, MCAP, extra columns, statistics) can be left out by a
/// solver that does not have them.
pub trait Simulation {
    /// Why a step failed (an instability of the explicit SDEM step, a Newton loop that did not
    /// converge...). Its message names the cause and, where it helps, the step and the grain.
    type Failure: std::error::Error + Send + Sync + 'static;

    /// Names of the solver's own `macro.csv` columns, after the common ones of
    /// [`Measures::HEADER`] (none by default: the SDEM `macro.csv` has only those).
    const EXTRA_COLUMNS: &'static [&'static str] = &[];

    /// Steps taken since the start of the run (a resumed run counts from its first start).
    fn step_count(&self) -> u64;

    /// Simulated time.
    fn time(&self) -> f64;

    /// The current time step (reported in the summary).
    fn dt(&self) -> f64;

    /// Number of grains.
    fn grain_count(&self) -> usize;

    /// The box walls, in the order of [`crate::boundary::walls::box_walls`].
    fn walls(&self) -> &[Wall];

    /// The walls, for the loading program to set their velocities before a step.
    fn walls_mut(&mut self) -> &mut [Wall];

    /// Advances by one time step: the grains, and the walls by velocity × dt.
    fn take_step(&mut self) -> Result<(), Self::Failure>;

    /// The run's error for a failed step; `last_good` says where the last good state was
    /// written. The default keeps the failure as it is in [`RunError::StepFailed`].
    fn failure_error(failure: Self::Failure, last_good: LastGood) -> RunError {
        RunError::StepFailed {
            failure: Box::new(failure),
            note: last_good.note,
            last_good_step: last_good.step,
            state_file: last_good.state_file,
        }
    }

    /// Whether the next step is in an affine phase: the step then moves the grains with the
    /// box, as the walls move over it (the affine part of the compression). The default
    /// ignores it (a solver whose grains follow the walls through contact only).
    fn set_affine_carry(&mut self, affine: bool) {
        let _ = affine;
    }

    /// The shear rate `L_xy` of a periodic cell for the next step, as the loading program set
    /// it. The default ignores it (a solver without a periodic cell: the scenario refuses
    /// shear phases there).
    fn set_shear_rate(&mut self, rate: f64) {
        let _ = rate;
    }

    /// What the loading program reacts to: packing fraction and wall stresses (compression
    /// positive) of the last step, and whether the sample has jammed.
    fn load_state(&self, jammed: bool) -> LoadState;

    /// The `macro.csv` row of the current state.
    fn measures(&self, phase: &str, strain_rate: f64) -> Measures;

    /// Coordination numbers `(z, z_nr, z_nr3)`: over all grains, without the rattlers (fewer
    /// than 2 contacts), and without the rattlers of the 3-contact rule (SPEC §7).
    fn coordination(&self) -> (f64, f64, f64);

    /// `(z, z_nr)` of [`coordination`](Self::coordination), all that a jamming candidate
    /// records: a loose gas makes candidates every few steps, and `z_nr3`'s rattler removal
    /// is the dearer part.
    fn coordination_without_z_nr3(&self) -> (f64, f64) {
        let (z, z_nr, _) = self.coordination();
        (z, z_nr)
    }

    /// Active grain–grain contacts (for progress reports).
    fn contacts(&self) -> u64;

    /// The total area the grains need when it cannot shrink (incompressible grains), so that
    /// a stress target is known to be out of reach once it fills the box. None by default.
    fn conserved_area(&self) -> Option<f64> {
        None
    }

    /// Appends the values of [`EXTRA_COLUMNS`](Self::EXTRA_COLUMNS) for the current step to
    /// `row`, each after a comma. Nothing by default.
    fn extra_columns(&self, row: &mut String) {
        let _ = row;
    }

    /// Remembers the current state as the last good one (the run reports it after a failure).
    fn keep_last_good(&mut self);

    /// Writes the last good state (as [`write_grains`](Self::write_grains) writes a state).
    fn write_last_good(&self, path: &Path) -> std::io::Result<()>;

    /// Writes `grains.csv` of the current state.
    fn write_grains(&self, path: &Path) -> std::io::Result<()>;

    /// Writes the checkpoint of the run at the current step, atomically, with the loop's
    /// part `run`: everything needed to continue the run bit for bit.
    fn write_checkpoint(&self, path: &Path, run: &RunRecord<'_>) -> std::io::Result<()>;

    /// Opens the MCAP trajectory log: a new one, or (`continue_from`) the log of a resumed run
    /// continued after the checkpoint's frames. The default refuses (a solver without MCAP
    /// frames).
    fn open_log(
        &self,
        settings: &McapSettings,
        scenario: &Scenario,
        continue_from: Option<ContinueFrom>,
    ) -> Result<TrajectoryWriter, RunError> {
        let _ = (scenario, continue_from);
        Err(RunError::Setup(format!(
            "{}: this solver does not write MCAP trajectory logs (run it without --mcap)",
            settings.path.display()
        )))
    }

    /// Logs the current state with its `macro.csv` row (called only once
    /// [`open_log`](Self::open_log) has opened the log).
    fn write_frame(&self, log: &mut TrajectoryWriter, row: &Measures) -> Result<(), WriteError> {
        let _ = (log, row);
        Err(WriteError::Io {
            path: String::new(),
            error: std::io::Error::new(
                std::io::ErrorKind::Unsupported,
                "this solver writes no MCAP frames",
            ),
        })
    }

    /// The current state as a frame of the neutral frame model, with its `macro.csv` row (for
    /// the VTK export of `sdem run --vtk`). The default refuses (a solver without frames).
    fn frame(&self, row: &Measures) -> Result<Frame, String> {
        let _ = row;
        Err("this solver writes no frames (run it without --vtk)".into())
    }

    /// Figures for the run summary.
    fn statistics(&self) -> SolverStatistics {
        SolverStatistics::default()
    }

    /// The critical time step of the solver's explicit integration, for the run summary
    /// (`None`: the solver is implicit and has none). By default SDEM's, from the scenario.
    fn critical_dt(&self, scenario: &Scenario) -> Option<f64> {
        Some(scenario.critical_time_step())
    }
}

/// Where the last good state of a failed run is, for [`Simulation::failure_error`].
#[derive(Debug, Clone, PartialEq)]
pub struct LastGood {
    /// Empty, or a line starting with a newline: the stress target the phase was heading for
    /// and the stress reached.
    pub note: String,
    /// The step of the last good state.
    pub step: u64,
    /// The file it is in.
    pub state_file: String,
}

/// The loop's part of a checkpoint (see [`Simulation::write_checkpoint`]).
#[derive(Debug, Clone, Copy)]
pub struct RunRecord<'a> {
    pub scenario: &'a Scenario,
    /// The run has ended (nothing left to resume).
    pub complete: bool,
    /// The run's checkpoint intervals (the defaults of `sdem resume`).
    pub checkpoint_every: u64,
    pub checkpoint_seconds: Option<f64>,
    pub program: &'a LoadingProgram,
    pub state: &'a LoopState,
}

/// A solver's figures for the run summary.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SolverStatistics {
    /// Neighbour-list builds (0 for a solver without one).
    pub neighbor_builds: u64,
    /// SDEM only: the neighbour list's skin at the end, as a multiple of the scenario's
    /// (see [`crate::geometry::broadphase::adapted_skin`]).
    pub neighbor_skin_widening: Option<f64>,
    /// SDEM only: where this process's steps spent their wall-clock time.
    pub phase_seconds: Option<PhaseTimes>,
    /// SDEM only: how this process's step sweeps shared their grain chunks among threads.
    pub sweeps: Option<crate::integration::SweepTally>,
    /// Adaptive model level only: how the steps were spent.
    pub adaptive: Option<AdaptiveStats>,
}

#[cfg(test)]
mod tests {
    //! A toy solver through the run loop: the seam works for something other than SDEM.

    use super::*;
    use crate::boundary::walls::{box_size, box_walls};
    use crate::output::MacroWriter;
    use crate::run::{RunOptions, run_loop};
    use std::path::PathBuf;

    /// Grains of fixed total area in a box whose wall stress grows linearly past phi = 0.8;
    /// its step fails at `fail_at`. One extra column: the steps taken.
    struct Toy {
        walls: Vec<Wall>,
        area: f64,
        step: u64,
        dt: f64,
        fail_at: u64,
        last_good_step: u64,
    }

    #[derive(Debug, thiserror::Error)]
    #[error("step {0}: the toy solver gave up")]
    struct GaveUp(u64);

    impl Toy {
        fn phi(&self) -> f64 {
            let (w, h) = box_size(&self.walls);
            self.area / (w * h)
        }
    }

    impl Simulation for Toy {
        type Failure = GaveUp;
        const EXTRA_COLUMNS: &'static [&'static str] = &["toy_steps"];

        fn step_count(&self) -> u64 {
            self.step
        }
        fn time(&self) -> f64 {
            self.step as f64 * self.dt
        }
        fn dt(&self) -> f64 {
            self.dt
        }
        fn grain_count(&self) -> usize {
            1
        }
        fn walls(&self) -> &[Wall] {
            &self.walls
        }
        fn walls_mut(&mut self) -> &mut [Wall] {
            &mut self.walls
        }
        fn take_step(&mut self) -> Result<(), GaveUp> {
            self.step += 1;
            if self.step == self.fail_at {
                return Err(GaveUp(self.step));
            }
            for w in &mut self.walls {
                w.point += w.velocity * self.dt;
            }
            Ok(())
        }
        fn load_state(&self, jammed: bool) -> LoadState {
            let s = (self.phi() - 0.8).max(0.0);
            LoadState {
                phi: self.phi(),
                sxx: s,
                syy: s,
                jammed,
                mean_diameter: 0.1,
                density: 1.0,
                young: 1.0,
                shear_strain: 0.0,
            }
        }
        fn measures(&self, phase: &str, strain_rate: f64) -> Measures {
            let l = self.load_state(true);
            Measures {
                step: self.step,
                phase: phase.into(),
                phi: l.phi,
                p_c: l.mean_stress(),
                strain_rate,
                ..Default::default()
            }
        }
        fn coordination(&self) -> (f64, f64, f64) {
            (4.0, 4.0, 4.0)
        }
        fn contacts(&self) -> u64 {
            0
        }
        fn extra_columns(&self, row: &mut String) {
            row.push_str(&format!(",{}", self.step));
        }
        fn keep_last_good(&mut self) {
            self.last_good_step = self.step;
        }
        fn write_last_good(&self, path: &Path) -> std::io::Result<()> {
            std::fs::write(path, format!("step\n{}\n", self.last_good_step))
        }
        fn write_grains(&self, path: &Path) -> std::io::Result<()> {
            std::fs::write(path, "id\n0\n")
        }
        fn write_checkpoint(&self, path: &Path, run: &RunRecord<'_>) -> std::io::Result<()> {
            std::fs::write(path, format!("{} {}", self.step, run.state.macro_rows))
        }
    }

    const SCENARIO: &str = r#"
Scenario(
    name: "toy",
    sample: (count: 4, box_width: 1.0, box_height: 1.0,
             radii: Gaussian(mean: 0.1, std_dev: 0.0, min: 0.1, max: 0.1)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    loading: [ Isotropic(rate: Constant(1e-1), until: PackingFraction(0.9)) ],
    output: (every: 10, jamming_pressure: 1e-2),
)
"#;

    /// The toy run's output folder, removed when the test is done with it.
    struct Scratch(PathBuf);

    impl std::ops::Deref for Scratch {
        type Target = std::path::Path;
        fn deref(&self) -> &std::path::Path {
            &self.0
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            std::fs::remove_dir_all(&self.0).ok();
        }
    }

    fn run(
        name: &str,
        fail_at: u64,
        mcap: bool,
    ) -> (Result<crate::run::RunSummary, RunError>, Scratch) {
        let scenario = Scenario::parse(SCENARIO, "toy.ron").unwrap();
        let out = std::env::temp_dir().join(format!("sdem-toy-{}-{name}", std::process::id()));
        std::fs::remove_dir_all(&out).ok();
        std::fs::create_dir_all(&out).unwrap();
        let toy = Toy {
            walls: box_walls(0.0, 1.0, 0.0, 1.0),
            area: 0.5,
            step: 0,
            dt: 0.01,
            fail_at,
            last_good_step: 0,
        };
        let writer =
            MacroWriter::create_with_columns(&out.join("macro.csv"), Toy::EXTRA_COLUMNS).unwrap();
        let program = LoadingProgram::new(scenario.loading.clone(), &toy.walls);
        let options = RunOptions {
            out_dir: out.clone(),
            checkpoint_every: 100,
            mcap: mcap.then(|| McapSettings::new(out.join("toy.mcap"))),
            ..Default::default()
        };
        let result = run_loop(
            &scenario,
            toy,
            program,
            LoopState::default(),
            writer,
            &options,
            None,
        );
        (result, Scratch(out))
    }

    #[test]
    fn a_toy_solver_runs_to_the_end_of_its_program_with_its_own_columns() {
        let (result, out) = run("end", u64::MAX, false);
        let summary = result.unwrap();
        assert!(summary.last.phi >= 0.9, "{summary:?}");
        let jamming = summary.jamming.expect("p_c passes p_jam at phi = 0.81");
        assert!(jamming.phi > 0.81 && jamming.z == 4.0, "{jamming:?}");
        let text = std::fs::read_to_string(out.join("macro.csv")).unwrap();
        let mut lines = text.lines();
        assert_eq!(
            lines.next().unwrap(),
            format!("{},toy_steps", Measures::HEADER)
        );
        let last = lines.last().unwrap();
        assert!(last.ends_with(&format!(",{}", summary.steps)), "{last}");
        let checkpoint = std::fs::read_to_string(out.join("checkpoint.bin")).unwrap();
        assert!(checkpoint.starts_with(&format!("{} ", summary.steps)));
        assert!(out.join("grains.csv").exists() && out.join("summary.txt").exists());
    }

    #[test]
    fn a_failed_step_reports_the_last_good_state_in_the_shape_of_an_instability() {
        let (result, out) = run("fail", 25, false);
        let e = result.unwrap_err();
        let RunError::StepFailed {
            failure,
            last_good_step,
            ..
        } = &e
        else {
            panic!("{e:?}");
        };
        assert!(failure.downcast_ref::<GaveUp>().is_some());
        assert_eq!(*last_good_step, 20);
        let file = out.join("grains_last_good.csv");
        assert_eq!(
            e.to_string(),
            format!(
                "step 25: the toy solver gave up\n  the last good state (step 20) is in {}",
                file.display()
            )
        );
        assert_eq!(std::fs::read_to_string(file).unwrap(), "step\n20\n");
    }

    #[test]
    fn a_solver_without_mcap_frames_refuses_a_log() {
        let (result, _) = run("mcap", u64::MAX, true);
        let e = result.unwrap_err();
        assert!(matches!(e, RunError::Setup(_)), "{e:?}");
        assert!(e.to_string().contains("does not write MCAP"), "{e}");
    }
}
