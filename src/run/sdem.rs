//! The SDEM world as a [`Simulation`] of the run loop.

use super::checkpoint::{Checkpoint, RunnerState};
use super::simulation::{LastGood, RunRecord, Simulation, SolverStatistics};
use super::{AdaptiveStats, RunError, open_log};
use crate::boundary::loading::LoadState;
use crate::boundary::walls::Wall;
use crate::grain::Grain;
use crate::integration::{Instability, World};
use crate::output::files::write_grain_rows;
use crate::output::frame::Frame;
use crate::output::mcap::{ContinueFrom, McapSettings, TrajectoryWriter, WriteError};
use crate::output::{Measures, write_grains_csv};
use crate::scenario::Scenario;
use std::path::Path;

/// The `macro.csv` columns of a periodic cell after the common ones (whose `sxx_c`, `syy_c`
/// are then the cell's contact stresses): the shear stress `sxy_c = -sigma_xy` (compression
/// positive convention: a positive shear rate gives `sxy_c < 0`), the shear strain
/// `∫ L_xy dt`, the cell's tilt `h2_x / h2_y` (within ±1/2 after remaps), and the kinetic part
/// of the stress, reported apart: `p_kin = -(sigma_kin_xx + sigma_kin_yy) / 2` and
/// `sxy_kin = -sigma_kin_xy`.
pub const PERIODIC_COLUMNS: &[&str] = &["sxy_c", "shear_strain", "cell_tilt", "p_kin", "sxy_kin"];

/// The `macro.csv` columns of a frictional run, after the periodic cell's if any: the contacts
/// sliding at the Coulomb limit in the row's step (grain–grain and grain–wall), and the energy
/// dissipated by sliding since the run started.
pub const FRICTION_COLUMNS: &[&str] = &["sliding_contacts", "friction_work"];

/// The columns of an SDEM run's `macro.csv` after the common ones.
pub fn extra_columns(scenario: &Scenario) -> Vec<&'static str> {
    let mut columns = Vec::new();
    if !scenario.boundary.is_walls() {
        columns.extend_from_slice(PERIODIC_COLUMNS);
    }
    if scenario.tangential_ratio() > 0.0 {
        columns.extend_from_slice(FRICTION_COLUMNS);
    }
    columns
}

/// The explicit SDEM engine ([`World`]) with what a run keeps beside it: the last good grains,
/// the constants of its measures and the adaptive-level statistics.
pub struct Sdem {
    pub world: World,
    /// The grains at the last output step (reported after a failure).
    last_good: Vec<Grain>,
    mean_diameter: f64,
    /// Incompressible grains keep their area pi R^2: their total is the area they need.
    conserved_area: Option<f64>,
    /// Counted over this process's steps only (a resumed run reports its continued part).
    adaptive: Option<AdaptiveStats>,
}

impl Sdem {
    /// A run of `scenario` from `world`, whose last good state is `last_good`.
    pub fn new(world: World, scenario: &Scenario, last_good: Vec<Grain>) -> Self {
        let mean_diameter = 2.0 * world.grains().iter().map(|g| g.radius).sum::<f64>()
            / world.grains().len() as f64;
        let adaptive = world.params.adaptive.map(|a| AdaptiveStats {
            dt_by_highest_level: a.dt,
            ..Default::default()
        });
        let conserved_area = scenario.material.is_incompressible().then(|| {
            world
                .grains()
                .iter()
                .map(Grain::reference_area)
                .sum::<f64>()
        });
        Self {
            world,
            last_good,
            mean_diameter,
            conserved_area,
            adaptive,
        }
    }
}

/// Index of the highest level with grains in it (0 when none).
fn highest_level(counts: &[u64; 3]) -> usize {
    (0..3).rev().find(|&k| counts[k] > 0).unwrap_or(0)
}

impl Simulation for Sdem {
    type Failure = Instability;

    fn step_count(&self) -> u64 {
        self.world.step
    }

    fn time(&self) -> f64 {
        self.world.time
    }

    fn dt(&self) -> f64 {
        self.world.params.dt
    }

    fn grain_count(&self) -> usize {
        self.world.grains().len()
    }

    fn walls(&self) -> &[Wall] {
        &self.world.walls
    }

    fn walls_mut(&mut self) -> &mut [Wall] {
        &mut self.world.walls
    }

    fn take_step(&mut self) -> Result<(), Instability> {
        let highest_before = highest_level(&self.world.totals.level_counts);
        let cycle = self.world.cycle_substep().is_some();
        self.world.step()?;
        if let Some(stats) = self.adaptive.as_mut() {
            stats.steps_by_highest_level[highest_before] += 1;
            stats.cycles += cycle as u64;
            stats.cycle_fast_grains += self.world.totals.fast_grains;
            for (sum, count) in stats
                .grain_steps_by_level
                .iter_mut()
                .zip(&self.world.totals.level_counts)
            {
                *sum += count;
            }
        }
        Ok(())
    }

    fn failure_error(instability: Instability, last_good: LastGood) -> RunError {
        RunError::Unstable {
            instability,
            note: last_good.note,
            last_good_step: last_good.step,
            state_file: last_good.state_file,
        }
    }

    /// The world's grain pass carries the grains with the box ([`World::affine_carry`]); in a
    /// periodic cell they follow the cell at every step already.
    fn set_affine_carry(&mut self, affine: bool) {
        self.world.affine_carry = affine;
    }

    fn set_shear_rate(&mut self, rate: f64) {
        if let Some(p) = self.world.periodic.as_mut() {
            p.shear_rate = rate;
        }
    }

    fn extra_columns(&self, row: &mut String) {
        use std::fmt::Write;
        if let Some(p) = &self.world.periodic {
            let t = &self.world.totals;
            let kinetic_stress = self.world.kinetic().stress;
            let height = crate::boundary::walls::box_size(&self.world.walls).1;
            let _ = write!(
                row,
                ",{:.9e},{:.9e},{:.9e},{:.9e},{:.9e}",
                -t.cell_stress[2],
                p.shear_strain,
                p.tilt / height,
                -0.5 * (kinetic_stress[0] + kinetic_stress[1]),
                -kinetic_stress[2]
            );
        }
        if self.world.params.friction.is_some() {
            let _ = write!(
                row,
                ",{},{:.9e}",
                self.world.totals.sliding_contacts, self.world.friction_work
            );
        }
    }

    fn load_state(&self, jammed: bool) -> LoadState {
        Measures::load_state(&self.world, jammed, self.mean_diameter)
    }

    fn measures(&self, phase: &str, strain_rate: f64) -> Measures {
        Measures::of(&self.world, phase, strain_rate, self.mean_diameter)
    }

    fn coordination(&self) -> (f64, f64, f64) {
        self.world.coordination()
    }

    fn coordination_without_z_nr3(&self) -> (f64, f64) {
        self.world.coordination_without_z_nr3()
    }

    fn contacts(&self) -> u64 {
        self.world.totals.contacts
    }

    fn conserved_area(&self) -> Option<f64> {
        self.conserved_area
    }

    fn keep_last_good(&mut self) {
        self.last_good.clear();
        self.last_good.extend_from_slice(self.world.grains());
    }

    /// The last good grains with the stresses of the current (failed) step, as sdem always
    /// wrote them.
    fn write_last_good(&self, path: &Path) -> std::io::Result<()> {
        write_grain_rows(path, &self.last_good, &self.world.grain_stress)
    }

    fn write_grains(&self, path: &Path) -> std::io::Result<()> {
        write_grains_csv(path, &self.world)
    }

    fn write_checkpoint(&self, path: &Path, run: &RunRecord<'_>) -> std::io::Result<()> {
        let world = &self.world;
        let levels = if run.scenario.model.adaptive().is_some() {
            world.levels().to_vec()
        } else {
            Vec::new()
        };
        Checkpoint {
            scenario: run.scenario.clone(),
            complete: run.complete,
            checkpoint_every: run.checkpoint_every,
            checkpoint_seconds: run.checkpoint_seconds,
            step: world.step,
            time: world.time,
            grains: world.grains().to_vec(),
            walls: world.walls.clone(),
            totals: world.totals,
            kinetic: world.kinetic(),
            program: run.program.clone(),
            runner: RunnerState::new(run.state, self.last_good.clone(), levels),
            periodic: world.periodic,
            contact_history: world.contact_history(),
        }
        .write_atomic(path)
    }

    fn open_log(
        &self,
        settings: &McapSettings,
        scenario: &Scenario,
        continue_from: Option<ContinueFrom>,
    ) -> Result<TrajectoryWriter, RunError> {
        open_log(
            settings,
            continue_from,
            || TrajectoryWriter::create(settings, scenario, &self.world),
            |from| TrajectoryWriter::continue_log(settings, scenario, &self.world, from),
        )
    }

    fn write_frame(&self, log: &mut TrajectoryWriter, row: &Measures) -> Result<(), WriteError> {
        log.write_frame(&self.world, row)
    }

    fn frame(&self, row: &Measures) -> Result<Frame, String> {
        Ok(Frame::of_world(&self.world, Some(row.clone())))
    }

    fn statistics(&self) -> SolverStatistics {
        SolverStatistics {
            neighbor_builds: self.world.neighbors.builds,
            neighbor_skin_widening: Some(self.world.neighbors.skin_widening()),
            phase_seconds: Some(self.world.phase_times),
            sweeps: Some(self.world.sweep_tally),
            adaptive: self.adaptive,
        }
    }
}
