//! Checkpoints of meshfree runs ([`super::meshfree::Meshfree`]): the payload `Meshfree((...))`
//! of a version 2 checkpoint file (see [`super::checkpoint`] for the file layout).
//!
//! The grains' models (nodes, shape functions, integration meshes, mass and initial stiffness)
//! are not stored: [`super::meshfree::Meshfree::new`] rebuilds them, bit for bit, from the
//! scenario (and, for a scenario that reads its sample from a file, the sample's grains, which
//! are stored). What is stored is the dynamic state: step, time, displacements, velocities,
//! accelerations, contact multipliers and friction history (tangential tractions), the walls, the loading program and the run loop's
//! state, the last good state, and what the outputs of the next steps read from the last step:
//! its contact elements (wall forces, contacts, penetration), its energies and its counters.
//! Every f64 is stored as its bit pattern.
//!
//! Not stored: the contact elements' tangent stiffness (only Newton iterations use it, and
//! each step evaluates its own) and the sparse solver's symbolic analysis (rebuilt on the first
//! factorization; it depends on the matrix pattern only, so the results do not depend on it).

use super::checkpoint::{
    AnyCheckpoint, Bits, CheckpointError, FORMAT_VERSION, GrainBits, JammingBits, Payload,
    ProgramBits, WallBits, encode, read_file, write_encoded_atomic,
};
use super::meshfree::Meshfree;
use super::simulation::{RunRecord, Simulation};
use super::{Jamming, LoopState, RunError, RunOptions, RunSummary, io_error};
use crate::boundary::loading::LoadingProgram;
use crate::boundary::walls::Wall;
use crate::grain::Grain;
use crate::meshfree::assembly::{
    Assembly, AssemblyState, ContactElement, ContactKey, ContactMultipliers, ElementFriction,
    Evaluation, Master, StepStats,
};
use crate::meshfree::shape::{FourierMode, StarShape};
use crate::meshfree::solver::SolveStats;
use crate::output::MacroWriter;
use crate::scenario::{GrainShapes, LoadedSample, LoadedShapes, Scenario};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A meshfree run's checkpoint in memory.
#[derive(Debug, Clone)]
pub struct MeshfreeCheckpoint {
    pub scenario: Scenario,
    /// The run had ended when this was written (nothing left to resume).
    pub complete: bool,
    pub checkpoint_every: u64,
    pub checkpoint_seconds: Option<f64>,
    pub step: u64,
    pub state: AssemblyState,
    pub walls: Vec<Wall>,
    pub program: LoadingProgram,
    pub loop_state: LoopState,
    /// The solver's last good state and its step.
    pub last_good: (u64, AssemblyState),
    /// The last step's evaluation (its contact elements without their tangent stiffness).
    pub last: Evaluation,
    /// The last step's counters.
    pub stats: StepStats,
    /// The sparse tangent's contact pattern (it decides the factorization's pivots).
    pub contact_pattern: Vec<(usize, usize)>,
}

/// A contact key: slave grain, slave node, master kind (0: grain, 1: wall), master index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct KeyBits(pub [u32; 4]);

impl From<&ContactKey> for KeyBits {
    fn from(k: &ContactKey) -> Self {
        let (kind, index) = match k.master {
            Master::Grain(j) => (0, j),
            Master::Wall(w) => (1, w),
        };
        KeyBits([k.slave, k.node, kind, index])
    }
}

impl KeyBits {
    fn to_key(self) -> Result<ContactKey, String> {
        let [slave, node, kind, index] = self.0;
        let master = match kind {
            0 => Master::Grain(index),
            1 => Master::Wall(index),
            _ => return Err(format!("contact master kind {kind} (0: grain, 1: wall)")),
        };
        Ok(ContactKey {
            slave,
            node,
            master,
        })
    }
}

fn bits(x: &[f64]) -> Vec<Bits> {
    x.iter().map(|&x| x.into()).collect()
}

fn floats(b: &[Bits]) -> Vec<f64> {
    b.iter().map(|&b| b.into()).collect()
}

/// An [`AssemblyState`] with its floats as bits; the multipliers in key order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateBits {
    pub time: Bits,
    pub u: Vec<Bits>,
    pub v: Vec<Bits>,
    pub a: Vec<Bits>,
    pub multipliers: Vec<(KeyBits, Bits)>,
    /// The friction history (tangential tractions), in key order; absent in frictionless
    /// runs' checkpoints written before friction.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub friction: Vec<(KeyBits, Bits)>,
}

fn multipliers_bits(m: &ContactMultipliers) -> Vec<(KeyBits, Bits)> {
    m.iter().map(|(k, &p)| (k.into(), p.into())).collect()
}

fn multipliers_of(b: &[(KeyBits, Bits)], what: &str) -> Result<ContactMultipliers, String> {
    let mut m = ContactMultipliers::new();
    for &(k, p) in b {
        if m.insert(k.to_key()?, p.into()).is_some() {
            return Err(format!("{what} {:?} given twice", k.0));
        }
    }
    Ok(m)
}

impl From<&AssemblyState> for StateBits {
    fn from(s: &AssemblyState) -> Self {
        StateBits {
            time: s.time.into(),
            u: bits(&s.u),
            v: bits(&s.v),
            a: bits(&s.a),
            multipliers: multipliers_bits(&s.multipliers),
            friction: multipliers_bits(&s.friction),
        }
    }
}

impl StateBits {
    fn to_state(&self) -> Result<AssemblyState, String> {
        let (n, nv, na) = (self.u.len(), self.v.len(), self.a.len());
        if nv != n || na != n {
            return Err(format!(
                "{n} displacements, {nv} velocities and {na} accelerations"
            ));
        }
        Ok(AssemblyState {
            time: self.time.into(),
            u: floats(&self.u),
            v: floats(&self.v),
            a: floats(&self.a),
            multipliers: multipliers_of(&self.multipliers, "contact multiplier")?,
            friction: multipliers_of(&self.friction, "friction traction")?,
        })
    }
}

/// A [`ContactElement`] without its tangent stiffness.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ElementBits {
    pub key: KeyBits,
    pub gap: Bits,
    pub pressure: Bits,
    pub tributary: Bits,
    pub normal: [Bits; 2],
    pub point: [Bits; 2],
    pub dofs: Vec<u64>,
    pub force: Vec<Bits>,
    /// Friction (traction, slip, sticking) of a frictional element.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub friction: Option<(Bits, Bits, bool)>,
}

/// An [`Evaluation`] with its floats as bits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvaluationBits {
    pub residual: Vec<Bits>,
    pub elements: Vec<ElementBits>,
    pub elastic_energy: Bits,
    pub force_scale: Bits,
    /// Energy friction dissipated over the step (absent before friction).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dissipation: Option<Bits>,
}

impl From<&Evaluation> for EvaluationBits {
    fn from(e: &Evaluation) -> Self {
        EvaluationBits {
            residual: bits(&e.residual),
            elements: e
                .elements
                .iter()
                .map(|e| ElementBits {
                    key: (&e.key).into(),
                    gap: e.gap.into(),
                    pressure: e.pressure.into(),
                    tributary: e.tributary.into(),
                    normal: [e.normal[0].into(), e.normal[1].into()],
                    point: [e.point[0].into(), e.point[1].into()],
                    dofs: e.dofs.iter().map(|&d| d as u64).collect(),
                    force: bits(&e.force),
                    friction: e
                        .friction
                        .map(|f| (f.traction.into(), f.slip.into(), f.sticking)),
                })
                .collect(),
            elastic_energy: e.elastic_energy.into(),
            force_scale: e.force_scale.into(),
            dissipation: (e.dissipation != 0.0).then(|| e.dissipation.into()),
        }
    }
}

impl EvaluationBits {
    fn to_evaluation(&self) -> Result<Evaluation, String> {
        let elements = self
            .elements
            .iter()
            .map(|e| {
                if e.force.len() != e.dofs.len() {
                    return Err(format!(
                        "a contact element with {} forces on {} DoF",
                        e.force.len(),
                        e.dofs.len()
                    ));
                }
                Ok(ContactElement {
                    key: e.key.to_key()?,
                    gap: e.gap.into(),
                    pressure: e.pressure.into(),
                    tributary: e.tributary.into(),
                    normal: [e.normal[0].into(), e.normal[1].into()],
                    point: [e.point[0].into(), e.point[1].into()],
                    dofs: e
                        .dofs
                        .iter()
                        .map(|&d| usize::try_from(d).map_err(|_| format!("DoF {d}")))
                        .collect::<Result<_, _>>()?,
                    force: floats(&e.force),
                    friction: e.friction.map(|(t, s, sticking)| ElementFriction {
                        traction: t.into(),
                        slip: s.into(),
                        sticking,
                    }),
                    stiffness: Vec::new(),
                })
            })
            .collect::<Result<_, String>>()?;
        Ok(Evaluation {
            residual: floats(&self.residual),
            elements,
            elastic_energy: self.elastic_energy.into(),
            force_scale: self.force_scale.into(),
            grain_blocks: Vec::new(),
            dissipation: self.dissipation.map_or(0.0, f64::from),
        })
    }
}

/// A grain of a shape file: its centre and contour, floats as bits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ShapeBits {
    Disc {
        centre: [Bits; 2],
        radius: Bits,
    },
    /// Modes as `(n, amplitude, phase)`.
    Fourier {
        centre: [Bits; 2],
        r0: Bits,
        modes: Vec<(u32, Bits, Bits)>,
    },
    Polygon {
        centre: [Bits; 2],
        vertices: Vec<[Bits; 2]>,
    },
}

impl From<&([f64; 2], StarShape)> for ShapeBits {
    fn from((c, shape): &([f64; 2], StarShape)) -> Self {
        let centre = c.map(Bits::from);
        match shape {
            StarShape::Disc { radius } => ShapeBits::Disc {
                centre,
                radius: (*radius).into(),
            },
            StarShape::Fourier { r0, modes } => ShapeBits::Fourier {
                centre,
                r0: (*r0).into(),
                modes: modes
                    .iter()
                    .map(|m| (m.n, m.amplitude.into(), m.phase.into()))
                    .collect(),
            },
            StarShape::Polygon { vertices } => ShapeBits::Polygon {
                centre,
                vertices: vertices.iter().map(|v| v.map(Bits::from)).collect(),
            },
        }
    }
}

impl ShapeBits {
    fn to_grain(&self) -> ([f64; 2], StarShape) {
        let point = |p: &[Bits; 2]| p.map(f64::from);
        match self {
            ShapeBits::Disc { centre, radius } => (
                point(centre),
                StarShape::Disc {
                    radius: (*radius).into(),
                },
            ),
            ShapeBits::Fourier { centre, r0, modes } => (
                point(centre),
                StarShape::Fourier {
                    r0: (*r0).into(),
                    modes: modes
                        .iter()
                        .map(|&(n, amplitude, phase)| FourierMode {
                            n,
                            amplitude: amplitude.into(),
                            phase: phase.into(),
                        })
                        .collect(),
                },
            ),
            ShapeBits::Polygon { centre, vertices } => (
                point(centre),
                StarShape::Polygon {
                    vertices: vertices.iter().map(point).collect(),
                },
            ),
        }
    }
}

/// [`StepStats`] with its floats as bits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StatsBits {
    pub newton_iterations: u64,
    /// Absent from checkpoints written before it was counted (read as 0).
    #[serde(default)]
    pub factorizations: u64,
    pub augmentations: u64,
    pub max_penetration: Bits,
    pub sub_steps: u64,
}

/// The run loop's [`LoopState`] with its floats as bits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoopBits {
    pub confirmed_jamming: Option<JammingBits>,
    pub candidate: Option<JammingBits>,
    pub max_loaded_inertial_number: Bits,
    pub isotropic_curve: Vec<[Bits; 2]>,
    pub last_good_step: u64,
    pub macro_rows: u64,
}

/// A meshfree checkpoint as stored (see the module documentation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshfreeStored {
    /// The run's scenario: `resume` needs nothing else.
    pub scenario: Scenario,
    pub complete: bool,
    pub checkpoint_every: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checkpoint_seconds: Option<Bits>,
    /// The grains of the sample file, as read at the start, when the scenario reads one (the
    /// grains' models are rebuilt from them; the file is not read again).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sample: Vec<GrainBits>,
    /// The grains of the shape file, as read at the start, when the scenario's shapes come
    /// from one (rebuilt from them; the file is not read again).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub shapes: Vec<ShapeBits>,
    pub step: u64,
    pub state: StateBits,
    pub walls: Vec<WallBits>,
    pub program: ProgramBits,
    pub run: LoopBits,
    pub last_good_step: u64,
    pub last_good: StateBits,
    pub last: EvaluationBits,
    pub stats: StatsBits,
    /// Absent from checkpoints written before the pattern was kept across steps.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub contact_pattern: Vec<[u64; 2]>,
}

fn u64_of(n: usize) -> u64 {
    n as u64
}

fn usize_of(n: u64, what: &str) -> Result<usize, String> {
    usize::try_from(n).map_err(|_| format!("{what} {n}"))
}

impl MeshfreeCheckpoint {
    /// The checkpoint of `sim` with the loop's part `run`.
    pub fn capture(sim: &Meshfree, run: &RunRecord<'_>) -> Self {
        MeshfreeCheckpoint {
            scenario: run.scenario.clone(),
            complete: run.complete,
            checkpoint_every: run.checkpoint_every,
            checkpoint_seconds: run.checkpoint_seconds,
            step: sim.step,
            state: sim.state.clone(),
            walls: sim.assembly.walls.clone(),
            program: run.program.clone(),
            loop_state: run.state.clone(),
            last_good: sim.last_good.clone(),
            last: sim.last.clone(),
            stats: sim.stats,
            contact_pattern: sim.assembly.contact_pattern().to_vec(),
        }
    }

    pub fn to_stored(&self) -> MeshfreeStored {
        let l = &self.loop_state;
        let s = &self.stats;
        let sample = match (&self.scenario.sample.file, &self.scenario.sample.loaded) {
            (Some(_), Some(loaded)) => loaded.grains.iter().map(GrainBits::from).collect(),
            _ => Vec::new(),
        };
        let shapes = match &self.scenario.sample.loaded_shapes {
            Some(loaded) => loaded.grains.iter().map(ShapeBits::from).collect(),
            None => Vec::new(),
        };
        MeshfreeStored {
            shapes,
            scenario: self.scenario.clone(),
            complete: self.complete,
            checkpoint_every: self.checkpoint_every,
            checkpoint_seconds: self.checkpoint_seconds.map(Bits::from),
            sample,
            step: self.step,
            state: (&self.state).into(),
            walls: self.walls.iter().map(WallBits::from).collect(),
            program: (&self.program).into(),
            run: LoopBits {
                confirmed_jamming: l.confirmed_jamming.as_ref().map(JammingBits::from),
                candidate: l.candidate.as_ref().map(JammingBits::from),
                max_loaded_inertial_number: l.max_loaded_inertial_number.into(),
                isotropic_curve: l
                    .isotropic_curve
                    .iter()
                    .map(|&(a, b)| [a.into(), b.into()])
                    .collect(),
                last_good_step: l.last_good_step,
                macro_rows: l.macro_rows,
            },
            last_good_step: self.last_good.0,
            last_good: (&self.last_good.1).into(),
            last: (&self.last).into(),
            stats: StatsBits {
                newton_iterations: u64_of(s.solve.newton_iterations),
                factorizations: u64_of(s.solve.factorizations),
                augmentations: u64_of(s.solve.augmentations),
                max_penetration: s.solve.max_penetration.into(),
                sub_steps: u64_of(s.sub_steps),
            },
            contact_pattern: self
                .contact_pattern
                .iter()
                .map(|&(a, b)| [u64_of(a), u64_of(b)])
                .collect(),
        }
    }

    /// The checkpoint of a stored one, or why it cannot be one (checks that do not need the
    /// grains' models; [`Self::check_fits`] does the others).
    pub fn from_stored(mut s: MeshfreeStored) -> Result<Self, String> {
        if super::meshfree::settings_of(&s.scenario).is_none() {
            return Err("a meshfree checkpoint of a scenario without the Meshfree model".into());
        }
        match (&s.scenario.sample.file, s.sample.is_empty()) {
            (Some(file), false) => {
                s.scenario.sample.loaded = Some(std::sync::Arc::new(LoadedSample {
                    path: file.clone(),
                    grains: s.sample.iter().map(Grain::from).collect(),
                }));
            }
            (Some(_), true) => return Err("no sample grains for a sample file".into()),
            (None, false) => return Err("sample grains without a sample file".into()),
            (None, true) => {}
        }
        match (&s.scenario.sample.shapes, s.shapes.is_empty()) {
            (Some(GrainShapes::File(file)), false) => {
                s.scenario.sample.loaded_shapes = Some(std::sync::Arc::new(LoadedShapes {
                    path: file.clone(),
                    grains: s.shapes.iter().map(ShapeBits::to_grain).collect(),
                }));
            }
            (Some(GrainShapes::File(_)), true) => {
                return Err("no grain shapes for a shape file".into());
            }
            (_, false) => return Err("grain shapes without a shape file".into()),
            (_, true) => {}
        }
        if let Some(seconds) = s.checkpoint_seconds.map(f64::from)
            && !(seconds.is_finite() && seconds > 0.0)
        {
            return Err(format!("checkpoint interval of {seconds} s"));
        }
        let program = s.program.to_program(&s.scenario.loading)?;
        s.scenario
            .validate()
            .map_err(|e| format!("invalid scenario: {e}"))?;
        let r = &s.run;
        let loop_state = LoopState {
            confirmed_jamming: r.confirmed_jamming.as_ref().map(Jamming::from),
            candidate: r.candidate.as_ref().map(Jamming::from),
            max_loaded_inertial_number: r.max_loaded_inertial_number.into(),
            isotropic_curve: r
                .isotropic_curve
                .iter()
                .map(|&[a, b]| (a.into(), b.into()))
                .collect(),
            last_good_step: r.last_good_step,
            macro_rows: r.macro_rows,
        };
        let state = s.state.to_state().map_err(|e| format!("state: {e}"))?;
        let last_good = s
            .last_good
            .to_state()
            .map_err(|e| format!("last good state: {e}"))?;
        if last_good.u.len() != state.u.len() {
            return Err(format!(
                "{} DoF in the last good state, {} in the state",
                last_good.u.len(),
                state.u.len()
            ));
        }
        let last = s
            .last
            .to_evaluation()
            .map_err(|e| format!("last step: {e}"))?;
        let t = &s.stats;
        let stats = StepStats {
            solve: SolveStats {
                newton_iterations: usize_of(t.newton_iterations, "Newton iterations")?,
                factorizations: usize_of(t.factorizations, "factorizations")?,
                augmentations: usize_of(t.augmentations, "augmentations")?,
                max_penetration: t.max_penetration.into(),
            },
            sub_steps: usize_of(t.sub_steps, "sub-steps")?,
        };
        Ok(MeshfreeCheckpoint {
            complete: s.complete,
            checkpoint_every: s.checkpoint_every,
            checkpoint_seconds: s.checkpoint_seconds.map(f64::from),
            step: s.step,
            state,
            walls: s.walls.iter().map(Wall::from).collect(),
            program,
            loop_state,
            last_good: (s.last_good_step, last_good),
            last,
            stats,
            contact_pattern: s
                .contact_pattern
                .iter()
                .map(|&[a, b]| Ok((usize_of(a, "pattern DoF")?, usize_of(b, "pattern DoF")?)))
                .collect::<Result<_, String>>()?,
            scenario: s.scenario,
        })
    }

    /// Whether the stored state fits the scenario's assembly (rebuilt from the scenario): the
    /// number of walls and DoF, and the contact keys and DoF of the multipliers and elements.
    pub fn check_fits(&self, assembly: &Assembly) -> Result<(), String> {
        let (grains, walls, dofs) = (assembly.grains.len(), assembly.walls.len(), assembly.dofs());
        if self.walls.len() != walls {
            return Err(format!("{} walls, the box has {walls}", self.walls.len()));
        }
        for (what, s) in [
            ("state", &self.state),
            ("last good state", &self.last_good.1),
        ] {
            if s.u.len() != dofs {
                return Err(format!(
                    "{what}: {} displacements for the {dofs} DoF of the scenario's grains",
                    s.u.len()
                ));
            }
        }
        let key_ok = |k: &ContactKey| -> Result<(), String> {
            let bad = || {
                Err(format!(
                    "contact {k:?} for {grains} grains and {walls} walls"
                ))
            };
            let Some(slave) = assembly.grains.get(k.slave as usize) else {
                return bad();
            };
            let master_ok = match k.master {
                Master::Grain(j) => (j as usize) < grains && j != k.slave,
                Master::Wall(w) => (w as usize) < walls,
            };
            if (k.node as usize) < slave.nodes.boundary_count && master_ok {
                Ok(())
            } else {
                bad()
            }
        };
        for s in [&self.state, &self.last_good.1] {
            s.multipliers.keys().try_for_each(key_ok)?;
            s.friction.keys().try_for_each(key_ok)?;
        }
        let l = &self.last;
        if !l.residual.is_empty() && l.residual.len() != dofs {
            return Err(format!(
                "a residual of {} values for {dofs} DoF",
                l.residual.len()
            ));
        }
        for e in &l.elements {
            key_ok(&e.key)?;
            if let Some(d) = e.dofs.iter().find(|&&d| d >= dofs) {
                return Err(format!("contact element on DoF {d} of {dofs}"));
            }
        }
        Ok(())
    }

    /// The file's bytes (format version [`FORMAT_VERSION`], payload `Meshfree((...))`).
    pub fn to_bytes(&self) -> Vec<u8> {
        encode(
            FORMAT_VERSION,
            &Payload::Meshfree(Box::new(self.to_stored())),
        )
    }

    /// Decodes a file's bytes; refuses an SDEM checkpoint. Never panics.
    pub fn from_bytes(bytes: &[u8], path: &str) -> Result<Self, CheckpointError> {
        match AnyCheckpoint::from_bytes(bytes, path)? {
            AnyCheckpoint::Meshfree(c) => Ok(*c),
            other => Err(other.other_solver(path, "meshfree")),
        }
    }

    pub fn read(path: &Path) -> Result<Self, CheckpointError> {
        read_file(path, Self::from_bytes)
    }

    /// Writes atomically (see [`super::checkpoint::Checkpoint::write_atomic`]).
    pub fn write_atomic(&self, path: &Path) -> std::io::Result<()> {
        write_encoded_atomic(
            path,
            FORMAT_VERSION,
            &Payload::Meshfree(Box::new(self.to_stored())),
        )
    }
}

/// Continues the meshfree run of a checkpoint in `options.out_dir` (as
/// [`super::resume_run`] does an SDEM run's): `macro.csv` cut back to the checkpoint's rows
/// and appended to.
pub fn resume_meshfree(
    c: &MeshfreeCheckpoint,
    checkpoint_path: &Path,
    options: &RunOptions,
) -> Result<RunSummary, RunError> {
    if c.complete {
        return Err(RunError::Resume(format!(
            "{}: the run finished at step {}; there is nothing to resume",
            checkpoint_path.display(),
            c.step
        )));
    }
    // `restore` says why the state does not fit the scenario's grains as a `Resume` error.
    let sim = Meshfree::restore(c).map_err(|e| match e {
        RunError::Resume(reason) => RunError::Checkpoint(CheckpointError::Corrupt {
            path: checkpoint_path.display().to_string(),
            reason,
        }),
        e => e,
    })?;
    let out = &options.out_dir;
    std::fs::create_dir_all(out).map_err(io_error(out))?;
    let macro_path = super::macro_to_continue(out, checkpoint_path)?;
    let rows = c.loop_state.macro_rows;
    let writer = MacroWriter::resume_with_columns(&macro_path, rows, Meshfree::EXTRA_COLUMNS)
        .map_err(|e| {
            RunError::Resume(format!(
                "{}: cannot continue it from the checkpoint's {rows} rows: {e}",
                macro_path.display()
            ))
        })?;
    super::run_loop(
        &c.scenario,
        sim,
        c.program.clone(),
        c.loop_state.clone(),
        writer,
        options,
        Some(crate::output::mcap::ContinueFrom {
            step: c.step,
            frames: rows,
        }),
    )
}
