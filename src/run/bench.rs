//! `sdem bench`: the throughput of the SDEM step on a dense packing (SPEC §12).
//!
//! The packing is a triangular lattice of spacing s = 0.024 (sample A's mean diameter) whose
//! grains have radii uniform in [1.01, 1.06] s/2: every grain overlaps its six neighbours by 1–6%
//! of a radius, as in a jammed packing a little above jamming (phi ~ 0.9 once the grains have
//! taken their contact flats). nu = 0.5, dbeta = 1°, walls at rest half a spacing away. The grains
//! are at the full SDEM level unless [`with_model`] says otherwise.

use crate::boundary::walls::box_walls;
use crate::contact::friction::FrictionSettings;
use crate::grain::{Grain, GrainLevel, Material, ModelLevel};
use crate::integration::parameters::{Friction, critical_time_step, frictional_critical_time_step};
use crate::integration::{Instability, Parameters, PhaseTimes, World};
use crate::sample::{RadiusDistribution, unit_random};
use glam::DVec2;
use rand::SeedableRng;
use std::time::Instant;

/// The lattice spacing s of the packing.
const SPACING: f64 = 0.024;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchResult {
    pub grains: usize,
    pub steps: u64,
    pub seconds: f64,
    pub contacts: u64,
    /// Candidate pairs of the neighbour list after the last step.
    pub candidate_pairs: usize,
    pub phi: f64,
    /// Neighbour-list builds during the timed steps.
    pub neighbor_builds: u64,
    /// The list's skin after the timed steps, as a multiple of the skin it was made with
    /// (see [`crate::geometry::broadphase::adapted_skin`]).
    pub skin_widening: f64,
    /// Seconds of the timed steps spent in each pass of the step.
    pub phases: PhaseTimes,
    /// The timed steps' sweeps: how their tasks shared the chunks.
    pub sweeps: crate::integration::SweepTally,
}

impl BenchResult {
    pub fn grain_steps_per_second(&self) -> f64 {
        self.grains as f64 * self.steps as f64 / self.seconds
    }
}

/// A dense packing of about `grains` grains (rounded to full lattice rows).
pub fn dense_packing(grains: usize, resolution_deg: f64) -> World {
    let spacing = SPACING;
    let columns = (grains as f64).sqrt().ceil().max(2.0) as usize;
    let rows = grains.div_ceil(columns).max(2);
    let row_height = spacing * 3f64.sqrt() / 2.0;
    let radius_range = RadiusDistribution::Uniform {
        min: 1.01 * 0.5 * spacing,
        max: 1.06 * 0.5 * spacing,
    };
    let radii =
        crate::sample::draw_radii(&radius_range, columns * rows, 7).expect("a valid distribution");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut jitter = || (unit_random(&mut rng) - 0.5) * 0.02 * spacing;
    let mut list = Vec::with_capacity(columns * rows);
    for r in 0..rows {
        for c in 0..columns {
            let x = spacing * (c as f64 + 0.5 * (r % 2) as f64 + 0.75) + jitter();
            let y = row_height * r as f64 + spacing * 0.75 + jitter();
            list.push(Grain::at_rest(DVec2::new(x, y), radii[r * columns + c]));
        }
    }
    let width = spacing * (columns as f64 + 1.0);
    let height = row_height * (rows - 1) as f64 + 1.5 * spacing;
    let material = Material {
        young: 1.0,
        poisson: 0.5,
        density: 1.0,
    };
    let mut params = Parameters::new(material, 0.0);
    params.resolution_deg = resolution_deg;
    params.dt = 0.4 * critical_time_step(&material, &params.law, 0.5 * spacing, params.level);
    World::new(params, list, box_walls(0.0, width, 0.0, height))
}

/// Puts every grain of a [`dense_packing`] at the model level `level` (a rigid disc, a disc with
/// one volumetric strain, or the full SDEM grain), with the time step at the same fraction of
/// that level's critical step. Discs (rigid or volumetric) take the closed-form circle contacts.
pub fn with_model(world: &mut World, level: ModelLevel) {
    let p = &mut world.params;
    p.level = level;
    p.dt = 0.4 * critical_time_step(&p.material, &p.law, 0.5 * SPACING, level);
    let levels = vec![GrainLevel::new(level); world.grains().len()];
    world.set_levels(&levels);
}

/// Makes every contact of a [`dense_packing`] frictional (grains and walls, `K_t = K_n`, no
/// tangential damping), with the time step at the same fraction of the frictional estimate.
pub fn with_friction(world: &mut World, mu: f64) {
    let settings = FrictionSettings {
        grains: mu,
        walls: mu,
        ..Default::default()
    };
    let p = &mut world.params;
    p.friction = Friction::new(&settings, &vec![mu; world.walls.len()]);
    p.dt = 0.4
        * frictional_critical_time_step(
            &p.material,
            &p.law,
            0.5 * SPACING,
            p.level,
            p.mode_settings(),
        );
}

/// Runs `steps` steps after `warmup` steps and times them.
pub fn run_bench(world: &mut World, warmup: u64, steps: u64) -> Result<BenchResult, Instability> {
    for _ in 0..warmup {
        world.step()?;
    }
    let builds_before = world.neighbors.builds;
    let phases_before = world.phase_times;
    let sweeps_before = world.sweep_tally;
    let start = Instant::now();
    for _ in 0..steps {
        world.step()?;
    }
    let seconds = start.elapsed().as_secs_f64();
    let (width, height) = crate::boundary::walls::box_size(&world.walls);
    Ok(BenchResult {
        grains: world.grains().len(),
        steps,
        seconds,
        contacts: world.totals.contacts,
        candidate_pairs: world.neighbors.pairs.len(),
        phi: world.totals.grain_area / (width * height),
        neighbor_builds: world.neighbors.builds - builds_before,
        skin_widening: world.neighbors.skin_widening(),
        phases: PhaseTimes {
            frames: world.phase_times.frames - phases_before.frames,
            neighbors: world.phase_times.neighbors - phases_before.neighbors,
            pairs: world.phase_times.pairs - phases_before.pairs,
            grains: world.phase_times.grains - phases_before.grains,
        },
        sweeps: world.sweep_tally.since(&sweeps_before),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_passes_account_for_the_timed_steps_and_no_more() {
        // Expectation: each pass is timed inside the step, so the four passes of the timed steps
        // are positive and sum to no more than the time the steps took (the warm-up excluded).
        let mut world = dense_packing(200, 1.0);
        let result = run_bench(&mut world, 3, 10).unwrap();
        let p = result.phases;
        for (name, seconds) in [
            ("frames", p.frames),
            ("neighbours", p.neighbors),
            ("pairs", p.pairs),
            ("grains", p.grains),
        ] {
            assert!(seconds > 0.0, "{name}: {seconds}");
        }
        assert!(
            p.total() <= result.seconds,
            "{p:?} against {}",
            result.seconds
        );
        assert!(
            world.phase_times.total() > p.total(),
            "the warm-up steps count in the world's own"
        );
    }
}
