//! Checkpoints of a run (`sdem run --checkpoint-every`, `sdem resume`): everything needed to
//! continue a run and reproduce, bit for bit, the uninterrupted one.
//!
//! File layout (all integers little-endian):
//!
//! | bytes | what |
//! | --- | --- |
//! | 8 | magic `SDEMCKPT` |
//! | 4 | format version (u32: [`SDEM_FORMAT_VERSION`] or [`FORMAT_VERSION`]) |
//! | 8 | payload length in bytes (u64) |
//! | 4 | CRC-32 (IEEE) of the payload (u32) |
//! | n | payload: RON text (UTF-8) |
//!
//! The payload of a version 1 file is the SDEM state ([`Stored`]). Version 2 tags the payload
//! with its solver: `Sdem((...))` (the same fields) or `Meshfree((...))` (a meshfree run's
//! state, [`super::meshfree_checkpoint::MeshfreeStored`]). SDEM checkpoints are still written
//! as version 1, byte for byte as before, so that older sdem resume them; meshfree checkpoints
//! are written as version 2, which older sdem refuse by their version. [`AnyCheckpoint`] reads
//! both solvers' files; [`Checkpoint`] is the SDEM one.
//!
//! Every f64 of the state (grains, walls, time, totals, runner state) is stored as its IEEE bit
//! pattern (u64), so the round trip is exact whatever the float printer does (-0.0, subnormals,
//! NaN payloads). The scenario is stored as ordinary RON (it is what a user would have written).
//!
//! The neighbour list, the per-pair search hints and the per-step work arrays are not stored:
//! the contact search is exact and the sums are taken in a fixed order, so results do not
//! depend on them.

use super::meshfree_checkpoint::{MeshfreeCheckpoint, MeshfreeStored};
use super::{Jamming, LoopState};
use crate::boundary::loading::LoadingProgram;
use crate::boundary::periodic::PeriodicBoundary;
use crate::boundary::walls::Wall;
use crate::grain::{Grain, GrainLevel, ModelLevel};
use crate::integration::{ContactHistory, KineticTotals, MAX_WALLS, StepTotals};
use crate::scenario::{LoadedSample, Scenario};
use glam::DVec2;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

pub const MAGIC: &[u8; 8] = b"SDEMCKPT";
/// The newest format version this sdem reads (and writes for meshfree runs).
pub const FORMAT_VERSION: u32 = 2;
/// The format version of SDEM checkpoints (unchanged since the first one).
pub const SDEM_FORMAT_VERSION: u32 = 1;
const HEADER_LEN: usize = 8 + 4 + 8 + 4;
/// The file name of the latest checkpoint in a run directory.
pub const FILE_NAME: &str = "checkpoint.bin";

#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("{path}: cannot read the checkpoint")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: not an sdem checkpoint (no SDEMCKPT magic)")]
    NotACheckpoint { path: String },
    #[error(
        "{path}: checkpoint format version {found}, this sdem reads versions 1 to {expected} only"
    )]
    Version {
        path: String,
        found: u32,
        expected: u32,
    },
    #[error("{path}: truncated checkpoint ({found} bytes, expected {expected})")]
    Truncated {
        path: String,
        found: u64,
        expected: u64,
    },
    #[error("{path}: corrupt checkpoint ({reason})")]
    Corrupt { path: String, reason: String },
    /// A checkpoint of another solver than the one asked for (read it with [`AnyCheckpoint`]).
    #[error("{path}: a checkpoint of a run with the {found} solver, not the {expected} solver")]
    OtherSolver {
        path: String,
        found: &'static str,
        expected: &'static str,
    },
}

/// An f64 stored as its bit pattern.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Bits(pub u64);

impl From<f64> for Bits {
    fn from(x: f64) -> Self {
        Bits(x.to_bits())
    }
}

impl From<Bits> for f64 {
    fn from(b: Bits) -> Self {
        f64::from_bits(b.0)
    }
}

fn v2(v: DVec2) -> [Bits; 2] {
    [v.x.into(), v.y.into()]
}

fn dv2(b: [Bits; 2]) -> DVec2 {
    DVec2::new(b[0].into(), b[1].into())
}

/// A grain: radius, x, y, vx, vy, theta, omega, eps1, eps1_rate, eps2, eps2_rate, alpha,
/// alpha_rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct GrainBits(pub [Bits; 13]);

impl From<&Grain> for GrainBits {
    fn from(g: &Grain) -> Self {
        let b = |x: f64| Bits::from(x);
        GrainBits([
            b(g.radius),
            b(g.center.x),
            b(g.center.y),
            b(g.velocity.x),
            b(g.velocity.y),
            b(g.theta),
            b(g.omega),
            b(g.eps1),
            b(g.eps1_rate),
            b(g.eps2),
            b(g.eps2_rate),
            b(g.alpha),
            b(g.alpha_rate),
        ])
    }
}

impl From<&GrainBits> for Grain {
    fn from(g: &GrainBits) -> Self {
        let f = |k: usize| f64::from(g.0[k]);
        Grain {
            radius: f(0),
            center: DVec2::new(f(1), f(2)),
            velocity: DVec2::new(f(3), f(4)),
            theta: f(5),
            omega: f(6),
            eps1: f(7),
            eps1_rate: f(8),
            eps2: f(9),
            eps2_rate: f(10),
            alpha: f(11),
            alpha_rate: f(12),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WallBits {
    pub point: [Bits; 2],
    pub normal: [Bits; 2],
    pub velocity: [Bits; 2],
}

impl From<&Wall> for WallBits {
    fn from(w: &Wall) -> Self {
        WallBits {
            point: v2(w.point),
            normal: v2(w.normal),
            velocity: v2(w.velocity),
        }
    }
}

impl From<&WallBits> for Wall {
    fn from(w: &WallBits) -> Self {
        Wall {
            point: dv2(w.point),
            normal: dv2(w.normal),
            velocity: dv2(w.velocity),
        }
    }
}

/// The totals of the last step: the loading program reads the wall forces and the grain area
/// of the previous step before the next one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TotalsBits {
    pub wall_force: Vec<Bits>,
    pub grain_area: Bits,
    pub kinetic_energy: Bits,
    pub elastic_energy: Bits,
    pub contacts: u64,
    pub capped_contacts: u64,
    /// Grains at each level (zero in checkpoints of sdem before the adaptive level; a resumed
    /// run recounts them from the grains' levels).
    #[serde(default)]
    pub level_counts: [u64; 3],
    /// Periodic cell only (absent in a box): the cell's contact and kinetic stresses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cell_stresses: Option<[[Bits; 3]; 2]>,
}

impl TotalsBits {
    /// The totals and the kinetic figures of the last step.
    fn of(t: &StepTotals, kinetic: &KineticTotals) -> Self {
        TotalsBits {
            wall_force: t.wall_force.iter().map(|&f| f.into()).collect(),
            grain_area: t.grain_area.into(),
            kinetic_energy: kinetic.energy.into(),
            elastic_energy: t.elastic_energy.into(),
            contacts: t.contacts,
            capped_contacts: t.capped_contacts,
            level_counts: t.level_counts,
            cell_stresses: (t.cell_stress != [0.0; 3] || kinetic.stress != [0.0; 3]).then(|| {
                [
                    t.cell_stress.map(Bits::from),
                    kinetic.stress.map(Bits::from),
                ]
            }),
        }
    }

    fn to_kinetic(&self) -> KineticTotals {
        KineticTotals {
            energy: self.kinetic_energy.into(),
            stress: self.cell_stresses.map_or([0.0; 3], |s| s[1].map(f64::from)),
        }
    }

    fn to_totals(&self) -> Option<StepTotals> {
        if self.wall_force.len() != MAX_WALLS {
            return None;
        }
        let mut wall_force = [0.0; MAX_WALLS];
        for (w, b) in wall_force.iter_mut().zip(&self.wall_force) {
            *w = (*b).into();
        }
        Some(StepTotals {
            wall_force,
            grain_area: self.grain_area.into(),
            elastic_energy: self.elastic_energy.into(),
            contacts: self.contacts,
            capped_contacts: self.capped_contacts,
            level_counts: self.level_counts,
            cell_stress: self.cell_stresses.map_or([0.0; 3], |s| s[0].map(f64::from)),
            // Per-step figures of friction, recomputed by the next step.
            friction_dissipation: 0.0,
            sliding_contacts: 0,
            // A cycle's own figure, recomputed by the next step.
            fast_grains: 0,
        })
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct JammingBits {
    pub step: u64,
    pub phi: Bits,
    pub z: Bits,
    pub z_nr: Bits,
    pub p_c: Bits,
}

impl From<&Jamming> for JammingBits {
    fn from(j: &Jamming) -> Self {
        JammingBits {
            step: j.step,
            phi: j.phi.into(),
            z: j.z.into(),
            z_nr: j.z_nr.into(),
            p_c: j.p_c.into(),
        }
    }
}

impl From<&JammingBits> for Jamming {
    fn from(j: &JammingBits) -> Self {
        Jamming {
            step: j.step,
            phi: j.phi.into(),
            z: j.z.into(),
            z_nr: j.z_nr.into(),
            p_c: j.p_c.into(),
        }
    }
}

/// The loading program with its floats as bits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProgramBits {
    pub current: usize,
    pub phase_start_step: u64,
    pub phase_start_time: Bits,
    pub phase_start_size: [Bits; 2],
    pub rate: Bits,
    /// Shear phases of a periodic cell (absent otherwise): the shear rate of the last step and
    /// the cell's shear strain when the phase started.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shear: Option<[Bits; 2]>,
}

impl From<&LoadingProgram> for ProgramBits {
    fn from(p: &LoadingProgram) -> Self {
        ProgramBits {
            current: p.current,
            phase_start_step: p.phase_start_step,
            phase_start_time: p.phase_start_time.into(),
            phase_start_size: [p.phase_start_size.0.into(), p.phase_start_size.1.into()],
            rate: p.rate.into(),
            shear: (p.shear_rate != 0.0 || p.phase_start_shear_strain != 0.0)
                .then(|| [p.shear_rate.into(), p.phase_start_shear_strain.into()]),
        }
    }
}

impl ProgramBits {
    /// The program of the scenario's `phases` at this point; an error if the phase is not one
    /// of them.
    pub fn to_program(
        &self,
        phases: &[crate::boundary::loading::Phase],
    ) -> Result<LoadingProgram, String> {
        if self.current > phases.len() {
            return Err(format!(
                "loading phase {} of {}",
                self.current,
                phases.len()
            ));
        }
        Ok(LoadingProgram {
            phases: phases.to_vec(),
            current: self.current,
            phase_start_step: self.phase_start_step,
            phase_start_time: self.phase_start_time.into(),
            phase_start_size: (
                self.phase_start_size[0].into(),
                self.phase_start_size[1].into(),
            ),
            rate: self.rate.into(),
            shear_rate: self.shear.map_or(0.0, |s| s[0].into()),
            phase_start_shear_strain: self.shear.map_or(0.0, |s| s[1].into()),
        })
    }
}

/// Everything an SDEM run carries from one step to the next, besides the world: the run loop's
/// [`LoopState`] and the SDEM solver's last good grains and grain levels.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RunnerState {
    pub confirmed_jamming: Option<Jamming>,
    pub candidate: Option<Jamming>,
    pub max_loaded_inertial_number: f64,
    /// (phi, p_c) of the isotropic rows, for the eq. 69 comparison.
    pub isotropic_curve: Vec<(f64, f64)>,
    pub last_good_step: u64,
    /// Grains at `last_good_step` (reported after an instability).
    pub last_good: Vec<Grain>,
    /// Data rows of macro.csv written so far (header not counted).
    pub macro_rows: u64,
    /// Each grain's level at the checkpoint's step, with the adaptive model only (empty
    /// otherwise: every grain is at the scenario's level).
    pub levels: Vec<GrainLevel>,
}

impl RunnerState {
    /// The state of a run loop with the SDEM solver's part: its last good grains and (adaptive
    /// model only) each grain's level.
    pub fn new(state: &LoopState, last_good: Vec<Grain>, levels: Vec<GrainLevel>) -> Self {
        RunnerState {
            confirmed_jamming: state.confirmed_jamming,
            candidate: state.candidate,
            max_loaded_inertial_number: state.max_loaded_inertial_number,
            isotropic_curve: state.isotropic_curve.clone(),
            last_good_step: state.last_good_step,
            last_good,
            macro_rows: state.macro_rows,
            levels,
        }
    }

    /// The run loop's part.
    pub fn loop_state(&self) -> LoopState {
        LoopState {
            confirmed_jamming: self.confirmed_jamming,
            candidate: self.candidate,
            max_loaded_inertial_number: self.max_loaded_inertial_number,
            isotropic_curve: self.isotropic_curve.clone(),
            last_good_step: self.last_good_step,
            macro_rows: self.macro_rows,
        }
    }
}

/// A checkpoint as stored (see the module documentation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stored {
    /// The run's scenario: `resume` needs nothing else.
    pub scenario: Scenario,
    /// The run had ended when this was written (nothing left to resume).
    pub complete: bool,
    /// The run's `--checkpoint-every` (the default of `sdem resume`).
    pub checkpoint_every: u64,
    /// The run's wall-clock checkpoint interval in seconds, if any (absent in checkpoints
    /// written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checkpoint_seconds: Option<f64>,
    pub step: u64,
    pub time: Bits,
    pub grains: Vec<GrainBits>,
    pub walls: Vec<WallBits>,
    pub totals: TotalsBits,
    pub program: ProgramBits,
    pub confirmed_jamming: Option<JammingBits>,
    pub candidate: Option<JammingBits>,
    pub max_loaded_inertial_number: Bits,
    pub isotropic_curve: Vec<[Bits; 2]>,
    pub last_good_step: u64,
    pub last_good: Vec<GrainBits>,
    pub macro_rows: u64,
    /// Adaptive model only: each grain's (level index, steps at that level, steps its stress
    /// has asked for a higher level). Absent from the checkpoints of other runs, and of the
    /// sdem versions before the adaptive level.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub levels: Vec<[u32; 3]>,
    /// Periodic cell only: the tilt of h2, the shear rate and the shear strain (see
    /// [`PeriodicBoundary`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub periodic: Option<[Bits; 3]>,
    /// Frictional runs only: the tangential spring force of each closed contact (SPEC §13),
    /// grain pairs `(i, j, F_t)` and grain–wall contacts `(grain, wall, F_t)`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_history: Option<HistoryBits>,
}

/// The tangential history of the contacts, floats as bits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HistoryBits {
    pub pairs: Vec<(u32, u32, Bits)>,
    pub walls: Vec<(u32, u32, Bits)>,
    /// The energy friction has dissipated.
    pub dissipated: Bits,
}

impl From<&ContactHistory> for HistoryBits {
    fn from(h: &ContactHistory) -> Self {
        HistoryBits {
            pairs: h
                .pairs
                .iter()
                .map(|&([i, j], f)| (i, j, f.into()))
                .collect(),
            walls: h.walls.iter().map(|&(g, w, f)| (g, w, f.into())).collect(),
            dissipated: h.dissipated.into(),
        }
    }
}

impl From<&HistoryBits> for ContactHistory {
    fn from(h: &HistoryBits) -> Self {
        ContactHistory {
            pairs: h
                .pairs
                .iter()
                .map(|&(i, j, f)| ([i, j], f.into()))
                .collect(),
            walls: h.walls.iter().map(|&(g, w, f)| (g, w, f.into())).collect(),
            dissipated: h.dissipated.into(),
        }
    }
}

/// A checkpoint in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkpoint {
    pub scenario: Scenario,
    pub complete: bool,
    pub checkpoint_every: u64,
    pub checkpoint_seconds: Option<f64>,
    pub step: u64,
    pub time: f64,
    pub grains: Vec<Grain>,
    pub walls: Vec<Wall>,
    pub totals: StepTotals,
    /// The grains' kinetic figures after the last step ([`crate::integration::World::kinetic`]).
    pub kinetic: KineticTotals,
    pub program: LoadingProgram,
    pub runner: RunnerState,
    /// The periodic cell's state beyond its virtual walls (None in a box).
    pub periodic: Option<PeriodicBoundary>,
    /// The tangential history of the frictional contacts (empty without friction).
    pub contact_history: ContactHistory,
}

fn grains_bits(g: &[Grain]) -> Vec<GrainBits> {
    g.iter().map(GrainBits::from).collect()
}

fn grains_of(g: &[GrainBits]) -> Vec<Grain> {
    g.iter().map(Grain::from).collect()
}

impl Checkpoint {
    fn to_stored(&self) -> Stored {
        let p = &self.program;
        let r = &self.runner;
        Stored {
            scenario: self.scenario.clone(),
            complete: self.complete,
            checkpoint_every: self.checkpoint_every,
            checkpoint_seconds: self.checkpoint_seconds,
            step: self.step,
            time: self.time.into(),
            grains: grains_bits(&self.grains),
            walls: self.walls.iter().map(WallBits::from).collect(),
            totals: TotalsBits::of(&self.totals, &self.kinetic),
            program: p.into(),
            confirmed_jamming: r.confirmed_jamming.as_ref().map(JammingBits::from),
            candidate: r.candidate.as_ref().map(JammingBits::from),
            max_loaded_inertial_number: r.max_loaded_inertial_number.into(),
            isotropic_curve: r
                .isotropic_curve
                .iter()
                .map(|&(a, b)| [a.into(), b.into()])
                .collect(),
            last_good_step: r.last_good_step,
            last_good: grains_bits(&r.last_good),
            macro_rows: r.macro_rows,
            levels: r
                .levels
                .iter()
                .map(|l| [l.level.index() as u32, l.steps, l.pending])
                .collect(),
            periodic: self
                .periodic
                .map(|p| [p.tilt.into(), p.shear_rate.into(), p.shear_strain.into()]),
            contact_history: (!self.contact_history.is_empty())
                .then(|| HistoryBits::from(&self.contact_history)),
        }
    }

    fn from_stored(mut s: Stored) -> Result<Self, String> {
        let totals = s
            .totals
            .to_totals()
            .ok_or_else(|| format!("expected {MAX_WALLS} wall forces"))?;
        let kinetic = s.totals.to_kinetic();
        if s.walls.len() > MAX_WALLS {
            return Err(format!("{} walls (at most {MAX_WALLS})", s.walls.len()));
        }
        if let Some(count) = s.scenario.sample.count
            && s.grains.len() != count
        {
            return Err(format!(
                "{} grains, the scenario has {count}",
                s.grains.len(),
            ));
        }
        if let Some(file) = &s.scenario.sample.file {
            // The run goes on from the stored grains: the file is not read again, and only the
            // grains' radii (constant during a run) matter to the scenario, through the
            // critical time step.
            s.scenario.sample.loaded = Some(std::sync::Arc::new(LoadedSample {
                path: file.clone(),
                grains: grains_of(&s.grains),
            }));
        }
        if let Some(seconds) = s.checkpoint_seconds
            && !(seconds.is_finite() && seconds > 0.0)
        {
            return Err(format!("checkpoint interval of {seconds} s"));
        }
        if s.program.current > s.scenario.loading.len() {
            return Err(format!(
                "loading phase {} of {}",
                s.program.current,
                s.scenario.loading.len()
            ));
        }
        s.scenario
            .validate()
            .map_err(|e| format!("invalid scenario: {e}"))?;
        if s.periodic.is_some() == s.scenario.boundary.is_walls() {
            return Err(format!(
                "the scenario's boundary is {:?} but the state {} a periodic cell",
                s.scenario.boundary,
                if s.periodic.is_some() {
                    "has"
                } else {
                    "has no"
                }
            ));
        }
        let adaptive = s.scenario.model.adaptive().is_some();
        if adaptive && s.levels.len() != s.grains.len() {
            return Err(format!(
                "{} grain levels for {} grains of an adaptive-level run",
                s.levels.len(),
                s.grains.len()
            ));
        }
        if !adaptive && !s.levels.is_empty() {
            return Err("grain levels in a run without the adaptive level".into());
        }
        let levels = s
            .levels
            .iter()
            .map(
                |&[level, steps, pending]| match ModelLevel::ALL.get(level as usize) {
                    Some(&level) => Ok(GrainLevel {
                        level,
                        steps,
                        pending,
                    }),
                    None => Err(format!("grain level {level} (0, 1 or 2)")),
                },
            )
            .collect::<Result<Vec<_>, String>>()?;
        let program = s.program.to_program(&s.scenario.loading)?;
        let runner = RunnerState {
            confirmed_jamming: s.confirmed_jamming.as_ref().map(Jamming::from),
            candidate: s.candidate.as_ref().map(Jamming::from),
            max_loaded_inertial_number: s.max_loaded_inertial_number.into(),
            isotropic_curve: s
                .isotropic_curve
                .iter()
                .map(|&[a, b]| (a.into(), b.into()))
                .collect(),
            last_good_step: s.last_good_step,
            last_good: grains_of(&s.last_good),
            macro_rows: s.macro_rows,
            levels,
        };
        Ok(Checkpoint {
            complete: s.complete,
            checkpoint_every: s.checkpoint_every,
            checkpoint_seconds: s.checkpoint_seconds,
            step: s.step,
            time: s.time.into(),
            grains: grains_of(&s.grains),
            walls: s.walls.iter().map(Wall::from).collect(),
            totals,
            kinetic,
            program,
            runner,
            periodic: s
                .periodic
                .map(|[tilt, shear_rate, shear_strain]| PeriodicBoundary {
                    tilt: tilt.into(),
                    shear_rate: shear_rate.into(),
                    shear_strain: shear_strain.into(),
                }),
            contact_history: s
                .contact_history
                .as_ref()
                .map(ContactHistory::from)
                .unwrap_or_default(),
            scenario: s.scenario,
        })
    }

    /// The file's bytes (format version [`SDEM_FORMAT_VERSION`]).
    pub fn to_bytes(&self) -> Vec<u8> {
        encode(SDEM_FORMAT_VERSION, &self.to_stored())
    }

    /// Decodes a file's bytes; `path` only names the file in errors. Never panics. A meshfree
    /// run's checkpoint is refused with [`CheckpointError::OtherSolver`] (see [`AnyCheckpoint`]).
    pub fn from_bytes(bytes: &[u8], path: &str) -> Result<Self, CheckpointError> {
        match AnyCheckpoint::from_bytes(bytes, path)? {
            AnyCheckpoint::Sdem(c) => Ok(*c),
            other => Err(other.other_solver(path, "SDEM")),
        }
    }

    /// Decodes a version 1 payload (after the header checks). Never panics.
    pub fn decode_payload(payload: &[u8], path: &str) -> Result<Self, CheckpointError> {
        let text = payload_text(payload, path)?;
        let stored: Stored = crate::scenario::ron_options()
            .from_str(text)
            .map_err(|e| corrupt(path, format!("payload: {e}")))?;
        Self::from_stored(stored).map_err(|e| corrupt(path, e))
    }

    pub fn read(path: &Path) -> Result<Self, CheckpointError> {
        read_file(path, Self::from_bytes)
    }

    /// Writes atomically: `<path>.tmp`, fsync, rename over `path`, fsync of the directory.
    pub fn write_atomic(&self, path: &Path) -> std::io::Result<()> {
        write_encoded_atomic(path, SDEM_FORMAT_VERSION, &self.to_stored())
    }
}

/// A checkpoint of either solver, as `sdem resume` reads it.
#[derive(Debug, Clone)]
pub enum AnyCheckpoint {
    Sdem(Box<Checkpoint>),
    Meshfree(Box<MeshfreeCheckpoint>),
}

/// The payload of a version 2 file: the state, tagged by its solver.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum Payload {
    Sdem(Box<Stored>),
    Meshfree(Box<MeshfreeStored>),
}

impl AnyCheckpoint {
    /// Decodes a file's bytes (either version, either solver); `path` only names the file in
    /// errors. Never panics.
    pub fn from_bytes(bytes: &[u8], path: &str) -> Result<Self, CheckpointError> {
        let (version, payload) = unframe(bytes, path)?;
        if version == SDEM_FORMAT_VERSION {
            return Checkpoint::decode_payload(payload, path)
                .map(|c| AnyCheckpoint::Sdem(Box::new(c)));
        }
        let text = payload_text(payload, path)?;
        let tagged: Payload = crate::scenario::ron_options()
            .from_str(text)
            .map_err(|e| corrupt(path, format!("payload: {e}")))?;
        match tagged {
            Payload::Sdem(s) => {
                Checkpoint::from_stored(*s).map(|c| AnyCheckpoint::Sdem(Box::new(c)))
            }
            Payload::Meshfree(s) => {
                MeshfreeCheckpoint::from_stored(*s).map(|c| AnyCheckpoint::Meshfree(Box::new(c)))
            }
        }
        .map_err(|e| corrupt(path, e))
    }

    pub fn read(path: &Path) -> Result<Self, CheckpointError> {
        read_file(path, Self::from_bytes)
    }

    /// The error of a file that holds this checkpoint where one of solver `expected` was
    /// wanted.
    pub(crate) fn other_solver(&self, path: &str, expected: &'static str) -> CheckpointError {
        CheckpointError::OtherSolver {
            path: path.to_string(),
            found: match self {
                AnyCheckpoint::Sdem(_) => "SDEM",
                AnyCheckpoint::Meshfree(_) => "meshfree",
            },
            expected,
        }
    }

    /// The run's scenario.
    pub fn scenario(&self) -> &Scenario {
        match self {
            AnyCheckpoint::Sdem(c) => &c.scenario,
            AnyCheckpoint::Meshfree(c) => &c.scenario,
        }
    }

    /// The step the checkpoint was written at.
    pub fn step(&self) -> u64 {
        match self {
            AnyCheckpoint::Sdem(c) => c.step,
            AnyCheckpoint::Meshfree(c) => c.step,
        }
    }

    /// The simulated time at that step.
    pub fn time(&self) -> f64 {
        match self {
            AnyCheckpoint::Sdem(c) => c.time,
            AnyCheckpoint::Meshfree(c) => c.state.time,
        }
    }

    /// The run's checkpoint intervals (steps, seconds): the defaults of `sdem resume`.
    pub fn checkpoint_interval(&self) -> (u64, Option<f64>) {
        match self {
            AnyCheckpoint::Sdem(c) => (c.checkpoint_every, c.checkpoint_seconds),
            AnyCheckpoint::Meshfree(c) => (c.checkpoint_every, c.checkpoint_seconds),
        }
    }
}

fn corrupt(path: &str, reason: String) -> CheckpointError {
    CheckpointError::Corrupt {
        path: path.to_string(),
        reason,
    }
}

fn payload_text<'p>(payload: &'p [u8], path: &str) -> Result<&'p str, CheckpointError> {
    std::str::from_utf8(payload).map_err(|e| corrupt(path, format!("not UTF-8: {e}")))
}

/// Reads the file at `path` and decodes its bytes with `decode` (a `from_bytes`, told the
/// path for its errors).
pub(crate) fn read_file<T>(
    path: &Path,
    decode: impl FnOnce(&[u8], &str) -> Result<T, CheckpointError>,
) -> Result<T, CheckpointError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| CheckpointError::Io {
        path: name.clone(),
        source,
    })?;
    decode(&bytes, &name)
}

/// The bytes of a file of format `version` whose payload is `stored` in RON.
pub(crate) fn encode(version: u32, stored: &impl Serialize) -> Vec<u8> {
    let payload = ron::Options::default()
        .to_string(stored)
        .expect("a checkpoint is always serializable");
    framed(version, payload.into_bytes())
}

/// Writes the file of format `version` whose payload is `stored` in RON to `path`, atomically
/// (see [`write_atomic`]), with the same bytes as [`encode`] but without holding them: the
/// payload streams to the file through its checksum, and the header's length and checksum are
/// written over their placeholders at the end. At 10⁵ grains the payload is some 30 MB of
/// text, which the run held twice (the text, and the file's bytes) on top of its own state.
pub(crate) fn write_encoded_atomic(
    path: &Path,
    version: u32,
    stored: &impl Serialize,
) -> std::io::Result<()> {
    use std::io::{Seek, SeekFrom};
    write_atomic(path, |file| {
        let mut out = std::io::BufWriter::new(file);
        out.write_all(MAGIC)?;
        out.write_all(&version.to_le_bytes())?;
        // Length and checksum, filled in once the payload is written.
        out.write_all(&[0; 12])?;
        let mut payload = Checksummed::new(&mut out);
        ron::Options::default()
            .to_io_writer(&mut payload, stored)
            .map_err(std::io::Error::other)?;
        let (length, crc) = payload.finish();
        let file = out.into_inner().map_err(|e| e.into_error())?;
        file.seek(SeekFrom::Start(MAGIC.len() as u64 + 4))?;
        file.write_all(&length.to_le_bytes())?;
        file.write_all(&crc.to_le_bytes())?;
        Ok(())
    })
}

/// A writer that passes bytes on and keeps their count and CRC-32 (as [`crc32`] of them all).
struct Checksummed<W> {
    inner: W,
    length: u64,
    crc: Crc32,
}

impl<W: Write> Checksummed<W> {
    fn new(inner: W) -> Self {
        Self {
            inner,
            length: 0,
            crc: Crc32::new(),
        }
    }

    /// The count and checksum of the bytes written.
    fn finish(self) -> (u64, u32) {
        (self.length, self.crc.value())
    }
}

impl<W: Write> Write for Checksummed<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.crc.update(&buf[..n]);
        self.length += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Header and payload: the bytes of a file.
fn framed(version: u32, payload: Vec<u8>) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&crc32(&payload).to_le_bytes());
    out.extend_from_slice(&payload);
    out
}

/// Checks a file's header (magic, version, length, checksum): its version and payload.
fn unframe<'b>(bytes: &'b [u8], path: &str) -> Result<(u32, &'b [u8]), CheckpointError> {
    let path = path.to_string();
    if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
        return Err(CheckpointError::NotACheckpoint { path });
    }
    if bytes.len() < HEADER_LEN {
        return Err(CheckpointError::Truncated {
            path,
            found: bytes.len() as u64,
            expected: HEADER_LEN as u64,
        });
    }
    let u32_at = |k: usize| u32::from_le_bytes(bytes[k..k + 4].try_into().unwrap_or([0; 4]));
    let version = u32_at(8);
    if version == 0 || version > FORMAT_VERSION {
        return Err(CheckpointError::Version {
            path,
            found: version,
            expected: FORMAT_VERSION,
        });
    }
    let length = u64::from_le_bytes(bytes[12..20].try_into().unwrap_or([0; 8]));
    let crc = u32_at(20);
    let expected = (HEADER_LEN as u64).saturating_add(length);
    let found = bytes.len() as u64;
    if found < expected {
        return Err(CheckpointError::Truncated {
            path,
            found,
            expected,
        });
    }
    if found > expected {
        return Err(CheckpointError::Corrupt {
            path,
            reason: format!("{} trailing bytes", found - expected),
        });
    }
    let payload = &bytes[HEADER_LEN..];
    if crc32(payload) != crc {
        return Err(CheckpointError::Corrupt {
            path,
            reason: "checksum mismatch".into(),
        });
    }
    Ok((version, payload))
}

/// Writes to `path` atomically what `write` writes to the file: `<path>.tmp`, fsync, rename
/// over `path`, fsync of the directory (a failed write leaves what `path` held; `sdem
/// sort-sample` writes its file this way too, which may be the file it read).
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let tmp = tmp_path(path);
    let written = std::fs::File::create(&tmp).and_then(|mut f| {
        write(&mut f)?;
        f.sync_all()
    });
    if let Err(e) = written {
        // A full disk (or a file size limit): the previous checkpoint at `path` is untouched;
        // the partial temporary file goes.
        std::fs::remove_file(&tmp).ok();
        return Err(e);
    }
    std::fs::rename(&tmp, path)?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    // Directory fsync makes the rename durable; not every platform allows opening one.
    if let Ok(d) = std::fs::File::open(&dir) {
        d.sync_all().ok();
    }
    Ok(())
}

fn tmp_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".tmp");
    PathBuf::from(name)
}

/// CRC-32 (IEEE 802.3, reflected, polynomial 0xEDB88320).
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = Crc32::new();
    crc.update(data);
    crc.value()
}

/// A CRC-32 (as [`crc32`]) computed over bytes given piece by piece.
struct Crc32 {
    state: u32,
    table: &'static [u32; 256],
}

impl Crc32 {
    fn new() -> Self {
        Self {
            state: !0u32,
            table: crc32_table(),
        }
    }

    fn update(&mut self, data: &[u8]) {
        let mut crc = self.state;
        for &b in data {
            crc = self.table[((crc ^ b as u32) & 0xff) as usize] ^ (crc >> 8);
        }
        self.state = crc;
    }

    fn value(&self) -> u32 {
        !self.state
    }
}

fn crc32_table() -> &'static [u32; 256] {
    static TABLE: std::sync::OnceLock<[u32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [0u32; 256];
        for (i, e) in t.iter_mut().enumerate() {
            let mut c = i as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
            *e = c;
        }
        t
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        // Piece by piece, the same value.
        let mut crc = Crc32::new();
        for piece in [&b"1234"[..], b"", b"56789"] {
            crc.update(piece);
        }
        assert_eq!(crc.value(), 0xCBF4_3926);
    }

    #[test]
    fn a_streamed_file_has_the_bytes_of_the_encoded_one() {
        // Expectation: write_encoded_atomic is encode's bytes, header included, whatever
        // size the buffered writer splits the payload into (here larger than its buffer).
        let stored: Vec<(u64, String)> = (0..5000).map(|k| (k * k, format!("grain {k}"))).collect();
        let dir = std::env::temp_dir().join(format!("sdem-stream-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("c.bin");
        write_encoded_atomic(&path, 7, &stored).unwrap();
        let written = std::fs::read(&path).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert!(written.len() > 8192 + HEADER_LEN);
        assert_eq!(written, encode(7, &stored));
    }
}
