//! Many meshfree grains in contact (SPEC §10b): one displacement vector over all grains, a
//! block-sparse tangent (a block per grain, coupled by contact elements), the two-pass smoothed
//! node-to-segment element between grains ([`super::nts`]), node-to-wall elements against the
//! box walls, Newton loops nested in augmented-Lagrangian loops, and the Bathe composite or
//! trapezoidal dynamic schemes with sub-steps on non-convergence.
//!
//! Determinism: every grain's internal forces and tangent blocks are computed in parallel into
//! its own buffers, and every slave grain's contact elements likewise; they are gathered in a
//! fixed order (grains by index, then contact elements by slave grain, master, slave node), and
//! the sparse factorization is sequential. Results are bitwise identical whatever the number of
//! threads.
//!
//! Sign conventions: the residual is `f_int - f_ext - f_contact + M A + C V`; a contact's
//! pressure `T = <lambda - k g>` is positive in compression, its gap `g` negative when the
//! slave node is inside the master.
//!
//! Friction (SPEC §13, [`super::friction`]): an element against a master with a Coulomb
//! coefficient `mu > 0` carries a tangential traction from a return mapping. Its slip over a
//! (sub-)step is measured from where the slave node was at the last converged state (the
//! [`SlipOrigin`]); its tangential multiplier starts each step at the traction committed at the
//! end of the last one ([`AssemblyState::friction`]) and follows the augmentations as the
//! normal one does; the augmentations stop once sticking nodes have not slipped by more than
//! the gap tolerance either. Frictionless contacts take none of this: with every `mu = 0` the
//! results are those of the frictionless code, bit for bit.

use std::collections::BTreeMap;

use rayon::prelude::*;

use super::MeshfreeError;
use super::contact::wall_node_element;
use super::friction::{FrictionCoefficients, TangentialInput};
use super::model::{Dense, GrainModel};
use super::nts;
use super::solver::{
    DynamicTerms, SolveStats, SolverSettings, TimeScheme, finite_residual_norm, newton_update,
};
use super::sparse::{SparseSolver, TripletMatrix};

mod explicit;
pub use explicit::{EXPLICIT_SAFETY, ExplicitData};

/// A Newton step reuses the last factorization when the step before it shrank the residual
/// at least this much (the iterate is then close enough for the old tangent to contract too).
const REUSE_CONTRACTION: f64 = 0.1;

/// An augmentation that cannot be the last ends once the Newton correction is below this
/// fraction of the largest gap's excess over the tolerance: the gap is then known to exceed
/// it, and the next augmentation starts from the iterate.
const EARLY_AUGMENTATION_STEP: f64 = 0.05;

/// Full Newton steps in a row that do not lower the residual below [`STALL_CONTRACTION`] of
/// the lowest so far before the steps are shortened: Newton then cycles between two sides of
/// a kink of the residual (a frictional contact switching between stick and slip, or one
/// opening and closing), each linearisation sending the iterate to the other side.
const STALLED_STEPS_BEFORE_LINE_SEARCH: usize = 2;

/// A full Newton step that does not bring the residual below this fraction of the lowest
/// residual of its loop is stalled.
const STALL_CONTRACTION: f64 = 0.9;

/// Halvings of a stalled Newton step tried before the full step is kept.
const LINE_SEARCH_HALVINGS: usize = 8;

/// A shortened Newton step ([`Assembly::shorter_newton_step`]): its length as a fraction of
/// the full step, the iterate, its evaluation and residual norm.
struct ShorterStep {
    alpha: f64,
    u: Vec<f64>,
    eval: Evaluation,
    norm: f64,
}

/// How a Newton loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum NewtonEnd {
    /// The residual is below the force tolerance.
    Converged,
    /// Stopped early: a gap is known to exceed the tolerance, another augmentation follows.
    GapOpen,
}
use crate::boundary::walls::Wall;

/// What a slave node presses against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Master {
    /// The contour of another grain (node-to-segment element).
    Grain(u32),
    /// One of the box walls (node-to-wall element).
    Wall(u32),
}

/// One contact element: a boundary node of a slave grain against a master.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ContactKey {
    pub slave: u32,
    pub node: u32,
    pub master: Master,
}

/// Augmented-Lagrangian multipliers (contact pressures, > 0) of the active elements; also the
/// tangential multipliers (tractions) of the frictional ones.
pub type ContactMultipliers = BTreeMap<ContactKey, f64>;

/// Where the slave nodes were at the last converged state: the origin of the slip of a step.
#[derive(Debug, Clone, PartialEq)]
pub struct SlipOrigin {
    /// Each grain's contour nodes.
    pub contours: Vec<Vec<[f64; 2]>>,
    /// Each wall's point.
    pub wall_points: Vec<[f64; 2]>,
}

/// The friction state an evaluation reads: the tangential multipliers and the slip origin.
#[derive(Debug, Clone, Copy)]
pub struct FrictionInput<'a> {
    pub tractions: &'a ContactMultipliers,
    pub origin: &'a SlipOrigin,
}

/// Friction of an evaluated element.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ElementFriction {
    /// Tangential traction t (per unit length): the force on the slave node is
    /// `-t A_s tangent`, `tangent` the normal turned by +90°.
    pub traction: f64,
    /// Slip of the slave node over the step, along `tangent`.
    pub slip: f64,
    /// Whether the return mapping stuck.
    pub sticking: bool,
}

impl ElementFriction {
    /// The friction state of an element evaluated with `tangential` (None: frictionless).
    fn of<T>(tangential: Option<&T>, traction: f64, slip: f64, sticking: bool) -> Option<Self> {
        tangential.map(|_| Self {
            traction,
            slip,
            sticking,
        })
    }
}

/// An evaluated, active contact element.
#[derive(Debug, Clone)]
pub struct ContactElement {
    pub key: ContactKey,
    pub gap: f64,
    pub pressure: f64,
    pub tributary: f64,
    /// Unit normal of the force on the slave node.
    pub normal: [f64; 2],
    /// Friction, for an element against a master with `mu > 0`.
    pub friction: Option<ElementFriction>,
    /// Where the slave node is (current position).
    pub point: [f64; 2],
    /// Global DoF of the element's nodes (6 for a wall element, 14 for node-to-segment).
    pub dofs: Vec<usize>,
    /// Force on those DoF.
    pub force: Vec<f64>,
    /// `d force / d x`, row-major `dofs.len()` squared (empty without tangent).
    pub stiffness: Vec<f64>,
}

impl ContactElement {
    /// An element of `N` DoF: `[gap, pressure, tributary]`, `normal` and slave `point` as
    /// evaluated; its DoF those of `nodes` (each group: a grain's DoF offset and node
    /// indices, in the order of `force`); `stiffness` only when the tangent was asked for.
    fn new<const N: usize>(
        key: ContactKey,
        [gap, pressure, tributary]: [f64; 3],
        normal: [f64; 2],
        point: [f64; 2],
        nodes: &[(usize, &[usize])],
        force: &[f64; N],
        stiffness: Option<&[[f64; N]; N]>,
    ) -> Self {
        let mut dofs = Vec::with_capacity(N);
        for &(offset, group) in nodes {
            for &a in group {
                dofs.extend([offset + 2 * a, offset + 2 * a + 1]);
            }
        }
        debug_assert_eq!(dofs.len(), N);
        ContactElement {
            key,
            gap,
            pressure,
            tributary,
            normal,
            friction: None,
            point,
            dofs,
            force: force.to_vec(),
            stiffness: stiffness.map_or_else(Vec::new, |k| k.iter().flatten().copied().collect()),
        }
    }
}

/// Residual, contact elements and energies at one displacement.
#[derive(Debug, Clone, Default)]
pub struct Evaluation {
    pub residual: Vec<f64>,
    pub elements: Vec<ContactElement>,
    pub elastic_energy: f64,
    /// The largest magnitude among the terms summed into the residual, for a round-off floor
    /// on the Newton tolerance.
    pub force_scale: f64,
    /// Each grain's tangent blocks (internal, inertia, damping) on its pattern, when the
    /// evaluation was asked for the tangent (empty otherwise).
    pub grain_blocks: Vec<Vec<[f64; 4]>>,
    /// Energy dissipated by friction over the step that ended at this evaluation, all its
    /// sub-steps together (set by [`Assembly::step`]; 0 for a bare evaluation).
    pub dissipation: f64,
}

impl Evaluation {
    /// Deepest interpenetration among the active elements (a length, >= 0).
    pub fn max_penetration(&self) -> f64 {
        self.elements
            .iter()
            .map(|e| (-e.gap).max(0.0))
            .fold(0.0, f64::max)
    }

    /// Largest |g| over active elements.
    pub fn max_abs_gap(&self) -> f64 {
        self.elements
            .iter()
            .map(|e| e.gap.abs())
            .fold(0.0, f64::max)
    }

    /// The augmentation loop's stop test: the largest |g| over active elements and |slip|
    /// over sticking ones (the stick constraint: no slip over the step).
    pub fn constraint_violation(&self) -> f64 {
        self.elements
            .iter()
            .map(|e| match e.friction {
                Some(f) if f.sticking => e.gap.abs().max(f.slip.abs()),
                _ => e.gap.abs(),
            })
            .fold(0.0, f64::max)
    }

    /// The tangential multipliers of this evaluation: each frictional element's traction.
    pub fn tractions(&self) -> ContactMultipliers {
        self.elements
            .iter()
            .filter_map(|e| e.friction.map(|f| (e.key, f.traction)))
            .collect()
    }

    /// Energy dissipated by friction over the slips of this evaluation: `sum |t| A_s |slip|`
    /// over slipping elements (`|t| = mu p_N`: the work of the friction forces on the slips
    /// since the slip origin).
    pub fn friction_dissipation(&self) -> f64 {
        self.elements
            .iter()
            .filter_map(|e| {
                e.friction
                    .filter(|f| !f.sticking)
                    .map(|f| f.traction.abs() * e.tributary * f.slip.abs())
            })
            .sum()
    }

    /// Total force of the grains on wall `w` (a vector: minus the sum of the wall elements'
    /// forces on the grains).
    pub fn wall_force(&self, w: usize) -> [f64; 2] {
        let mut f = [0.0; 2];
        for e in &self.elements {
            if e.key.master == Master::Wall(w as u32) {
                let t = e.pressure * e.tributary;
                f[0] -= t * e.normal[0];
                f[1] -= t * e.normal[1];
                if let Some(fr) = e.friction {
                    // The grain receives -t A_s tangent, tangent = (-n_y, n_x).
                    let q = fr.traction * e.tributary;
                    f[0] += q * -e.normal[1];
                    f[1] += q * e.normal[0];
                }
            }
        }
        f
    }

    /// Sum of all contact forces (zero to round-off: momentum balance).
    pub fn grain_contact_force_sum(&self) -> ([f64; 2], f64) {
        let (mut s, mut mag) = ([0.0; 2], 0.0f64);
        for e in self
            .elements
            .iter()
            .filter(|e| matches!(e.key.master, Master::Grain(_)))
        {
            for (k, f) in e.force.iter().enumerate() {
                s[k % 2] += f;
                mag = mag.max(f.abs());
            }
        }
        (s, mag)
    }

    /// Grain–wall pairs `(grain, wall)` with at least one active element between them, sorted.
    pub fn wall_contacts(&self) -> Vec<(u32, u32)> {
        let mut pairs: Vec<(u32, u32)> = self
            .elements
            .iter()
            .filter_map(|e| match e.key.master {
                Master::Wall(w) => Some((e.key.slave, w)),
                Master::Grain(_) => None,
            })
            .collect();
        pairs.sort_unstable();
        pairs.dedup();
        pairs
    }

    /// Grain pairs `(i, j)`, `i < j`, with at least one active element between them (either
    /// pass), sorted.
    pub fn contact_pairs(&self) -> Vec<(u32, u32)> {
        let mut pairs: Vec<(u32, u32)> = self
            .elements
            .iter()
            .filter_map(|e| match e.key.master {
                Master::Grain(j) => Some((e.key.slave.min(j), e.key.slave.max(j))),
                Master::Wall(_) => None,
            })
            .collect();
        pairs.sort_unstable();
        pairs.dedup();
        pairs
    }
}

/// State of a dynamic run of an assembly.
#[derive(Debug, Clone, PartialEq)]
pub struct AssemblyState {
    pub time: f64,
    pub u: Vec<f64>,
    pub v: Vec<f64>,
    pub a: Vec<f64>,
    pub multipliers: ContactMultipliers,
    /// Tangential tractions of the frictional elements committed at the end of the last
    /// converged (sub-)step: the friction history.
    pub friction: ContactMultipliers,
}

/// Counters of one step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepStats {
    pub solve: SolveStats,
    /// Sub-steps taken (1 when the step converged at once).
    pub sub_steps: usize,
}

/// Grains, walls and solver settings.
#[derive(Debug)]
pub struct Assembly {
    pub grains: Vec<GrainModel>,
    /// First global DoF of each grain, and the total at the end.
    offsets: Vec<usize>,
    /// Box walls at their current positions (their `velocity` moves them during a step).
    pub walls: Vec<Wall>,
    pub gravity: [f64; 2],
    pub settings: SolverSettings,
    /// Coulomb coefficients (frictionless by default); set with [`Assembly::set_friction`].
    friction: FrictionCoefficients,
    /// Rayleigh damping `C = alpha M + beta K_i0`.
    pub rayleigh: (f64, f64),
    /// DoF held at their current value (quasi-static problems: rigid modes).
    pub fixed: Vec<usize>,
    /// Slave nodes farther than this from a master grain's bounding box are not tested.
    pub near_distance: f64,
    /// Smallest sub-step, as a fraction of the step (a power of 1/2).
    pub min_sub_step: f64,
    external: Vec<f64>,
    initial_stiffness: Vec<Vec<[f64; 4]>>,
    solver: SparseSolver,
    contact_pattern: ContactPattern,
    /// Lumped mass and critical step, once the explicit scheme is used.
    explicit: Option<ExplicitData>,
}

/// The node pairs that contact elements couple in the sparse tangent, kept from step to step
/// so that the triplets' index sequence (and with it the sparse solver's symbolic analysis)
/// stays the same while the contacts change within it. When an element needs a pair the
/// pattern lacks, the pattern takes the pairs of a window of [`PATTERN_WINDOW`] contour nodes
/// on either side of every node of every current element: a contact that slides by a few
/// nodes, or spreads to the neighbouring nodes, then stays inside it. Pairs of elements that
/// have opened stay with zero values; the pattern is rebuilt from the current elements alone
/// when these would need less than half of it.
///
/// The pattern decides the pivots of the factorization and hence the last bits of the
/// solution: it depends on the run's history, and checkpoints store it so that a resumed run
/// continues bit for bit.
#[derive(Debug, Default)]
struct ContactPattern {
    /// (x DoF of the row node, x DoF of the column node), sorted.
    pairs: Vec<(usize, usize)>,
    slot: std::collections::HashMap<(usize, usize), usize>,
}

/// Contour nodes on either side of an element's nodes that the contact pattern couples too.
const PATTERN_WINDOW: usize = 3;

impl ContactPattern {
    fn from_pairs(mut pairs: Vec<(usize, usize)>) -> Self {
        pairs.sort_unstable();
        pairs.dedup();
        let slot = pairs.iter().enumerate().map(|(k, &p)| (p, k)).collect();
        Self { pairs, slot }
    }

    /// The elements' stiffness (negated: the tangent of the residual) summed on the pattern,
    /// after extending it if it lacks a pair (see [`ContactPattern`]); `window` lists the x DoF
    /// of the contour nodes near an element's nodes. Blocks `[K_xx, K_yx, K_xy, K_yy]`.
    fn gather(
        &mut self,
        elements: &[ContactElement],
        window: impl Fn(&ContactElement) -> Vec<usize>,
    ) -> Vec<[f64; 4]> {
        fn node_pairs(
            e: &ContactElement,
        ) -> impl Iterator<Item = (usize, usize, (usize, usize))> + '_ {
            let nodes = e.dofs.len() / 2;
            let d = &e.dofs;
            (0..nodes).flat_map(move |p| (0..nodes).map(move |q| (p, q, (d[2 * p], d[2 * q]))))
        }
        let complete = elements
            .iter()
            .all(|e| node_pairs(e).all(|(_, _, key)| self.slot.contains_key(&key)));
        if !complete {
            let mut needed = Vec::new();
            for e in elements {
                let nodes = window(e);
                needed.extend(
                    nodes
                        .iter()
                        .flat_map(|&a| nodes.iter().map(move |&b| (a, b))),
                );
            }
            let needed = Self::from_pairs(needed);
            if 2 * needed.pairs.len() < self.pairs.len() {
                *self = needed;
            } else {
                let mut pairs = std::mem::take(&mut self.pairs);
                pairs.extend(needed.pairs);
                *self = Self::from_pairs(pairs);
            }
        }
        let mut values = vec![[0.0; 4]; self.pairs.len()];
        for e in elements {
            let n = e.dofs.len();
            for (p, q, key) in node_pairs(e) {
                let blk = &mut values[self.slot[&key]];
                blk[0] -= e.stiffness[(2 * p) * n + 2 * q];
                blk[1] -= e.stiffness[(2 * p + 1) * n + 2 * q];
                blk[2] -= e.stiffness[(2 * p) * n + 2 * q + 1];
                blk[3] -= e.stiffness[(2 * p + 1) * n + 2 * q + 1];
            }
        }
        values
    }
}

/// One grain's share of an evaluation.
struct GrainTerms {
    /// `f_int - f_ext` (+ inertia and damping) on the grain's DoF.
    residual: Vec<f64>,
    /// Tangent blocks on the grain's pattern (empty without tangent).
    blocks: Vec<[f64; 4]>,
    energy: f64,
    /// Largest magnitude of the terms summed into `residual`.
    scale: f64,
}

/// The x DoF of the contour nodes within [`PATTERN_WINDOW`] of the nodes among `dofs` (x and
/// y DoF of nodes, in pairs), sorted; interior nodes stand for themselves.
fn contour_window(grains: &[GrainModel], offsets: &[usize], dofs: &[usize]) -> Vec<usize> {
    let mut out = Vec::new();
    for &dof in dofs.iter().step_by(2) {
        let g = offsets.partition_point(|&o| o <= dof) - 1;
        let (off, nb) = (offsets[g], grains[g].nodes.boundary_count);
        let a = (dof - off) / 2;
        if a >= nb {
            out.push(dof);
            continue;
        }
        for d in 0..=2 * PATTERN_WINDOW {
            out.push(off + 2 * ((a + nb + d - PATTERN_WINDOW) % nb));
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// Current boundary positions of a grain.
fn contour(model: &GrainModel, u: &[f64]) -> Vec<[f64; 2]> {
    (0..model.nodes.boundary_count)
        .map(|s| model.position(u, s))
        .collect()
}

fn bounding_box(points: &[[f64; 2]]) -> [f64; 4] {
    points.iter().fold(
        [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ],
        |b, p| {
            [
                b[0].min(p[0]),
                b[1].min(p[1]),
                b[2].max(p[0]),
                b[3].max(p[1]),
            ]
        },
    )
}

impl Assembly {
    /// An assembly of grains (reference node positions in the global frame) in a box of walls.
    pub fn new(
        grains: Vec<GrainModel>,
        walls: Vec<Wall>,
        gravity: [f64; 2],
        rayleigh: (f64, f64),
        settings: SolverSettings,
    ) -> Result<Self, MeshfreeError> {
        if grains.is_empty() {
            return Err(MeshfreeError::BadInput("an assembly needs grains".into()));
        }
        let mut offsets = vec![0];
        for g in &grains {
            offsets.push(offsets.last().unwrap() + g.dofs());
        }
        let external = grains.iter().flat_map(|g| g.body_force(gravity)).collect();
        let initial_stiffness = if rayleigh.1 != 0.0 {
            grains
                .par_iter()
                .map(|g| {
                    let k = g.initial_stiffness()?;
                    let mut blocks = Vec::new();
                    g.pattern_blocks(&k, &mut blocks);
                    Ok(blocks)
                })
                .collect::<Result<Vec<_>, MeshfreeError>>()?
        } else {
            Vec::new()
        };
        let spacing = grains
            .iter()
            .map(|g| {
                let c = contour(g, &vec![0.0; g.dofs()]);
                let nb = c.len();
                (0..nb)
                    .map(|s| {
                        let (p, q) = (c[s], c[(s + 1) % nb]);
                        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
                    })
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max);
        Ok(Self {
            grains,
            offsets,
            walls,
            gravity,
            settings,
            friction: FrictionCoefficients::default(),
            rayleigh,
            fixed: Vec::new(),
            near_distance: 2.0 * spacing,
            min_sub_step: 1.0 / 16.0,
            external,
            initial_stiffness,
            solver: SparseSolver::new(),
            contact_pattern: ContactPattern::default(),
            explicit: None,
        })
    }

    pub fn dofs(&self) -> usize {
        *self.offsets.last().unwrap()
    }

    /// Sets the Coulomb coefficients of the contacts (refused: a negative or non-finite mu, a
    /// stiffness ratio outside (0, 10]).
    pub fn set_friction(&mut self, friction: FrictionCoefficients) -> Result<(), MeshfreeError> {
        friction
            .validate()
            .map_err(|e| MeshfreeError::BadInput(format!("friction: {e}")))?;
        self.friction = friction;
        Ok(())
    }

    pub fn friction(&self) -> &FrictionCoefficients {
        &self.friction
    }

    /// The slip origin of a step starting at `u` with the walls where they are now.
    pub fn slip_origin(&self, u: &[f64]) -> SlipOrigin {
        SlipOrigin {
            contours: (0..self.grains.len())
                .map(|g| contour(&self.grains[g], self.grain_slice(u, g)))
                .collect(),
            wall_points: self.walls.iter().map(|w| [w.point.x, w.point.y]).collect(),
        }
    }

    /// First global DoF of grain `g`.
    pub fn offset(&self, g: usize) -> usize {
        self.offsets[g]
    }

    /// The slice of a global vector that belongs to grain `g`.
    pub fn grain_slice<'v>(&self, v: &'v [f64], g: usize) -> &'v [f64] {
        &v[self.offsets[g]..self.offsets[g + 1]]
    }

    /// Sparse-solver counters: (symbolic analyses, numeric factorizations).
    pub fn factorizations(&self) -> (usize, usize) {
        (self.solver.symbolic_count(), self.solver.numeric_count())
    }

    /// Grain pairs whose bounding boxes, grown by `near_distance`, overlap: for each grain the
    /// sorted list of the others (sweep and prune along x).
    fn neighbours(&self, contours: &[Vec<[f64; 2]>]) -> Vec<Vec<u32>> {
        let d = self.near_distance;
        let boxes: Vec<[f64; 4]> = contours.iter().map(|c| bounding_box(c)).collect();
        let mut order: Vec<usize> = (0..boxes.len()).collect();
        order.sort_by(|&a, &b| boxes[a][0].total_cmp(&boxes[b][0]).then(a.cmp(&b)));
        let mut out = vec![Vec::new(); boxes.len()];
        for (k, &i) in order.iter().enumerate() {
            for &j in &order[k + 1..] {
                if boxes[j][0] > boxes[i][2] + d {
                    break;
                }
                if boxes[j][1] <= boxes[i][3] + d && boxes[i][1] <= boxes[j][3] + d {
                    out[i].push(j as u32);
                    out[j].push(i as u32);
                }
            }
        }
        for l in &mut out {
            l.sort_unstable();
        }
        out
    }

    /// Active contact elements of slave grain `i` (grain masters first, by index, then walls).
    #[allow(clippy::too_many_arguments)]
    fn slave_elements(
        &self,
        i: usize,
        contours: &[Vec<[f64; 2]>],
        masters: &[u32],
        multipliers: &ContactMultipliers,
        friction: Option<FrictionInput<'_>>,
        k: f64,
        with_tangent: bool,
    ) -> Vec<ContactElement> {
        let mut out = Vec::new();
        let slave = &contours[i];
        let nb = slave.len();
        let off_i = self.offsets[i];
        let lambda_of = |key: &ContactKey| multipliers.get(key).copied().unwrap_or(0.0);
        let d = self.near_distance;
        let grain_friction = friction.filter(|_| self.friction.grains > 0.0);
        for &j in masters {
            let j = j as usize;
            let master = &contours[j];
            let mb = master.len();
            let bb = bounding_box(master);
            let off_j = self.offsets[j];
            for s in 0..nb {
                let xs = slave[s];
                if xs[0] < bb[0] - d || xs[0] > bb[2] + d || xs[1] < bb[1] - d || xs[1] > bb[3] + d
                {
                    continue;
                }
                let closest = (0..mb)
                    .min_by(|&a, &b| dist2(master[a], xs).total_cmp(&dist2(master[b], xs)))
                    .unwrap();
                let Some((first, _)) = nts::master_segment(master, closest, xs) else {
                    continue;
                };
                let key = ContactKey {
                    slave: i as u32,
                    node: s as u32,
                    master: Master::Grain(j as u32),
                };
                let slave_nodes = [(s + nb - 1) % nb, s, (s + 1) % nb];
                let master_nodes = [
                    (first + mb - 1) % mb,
                    first,
                    (first + 1) % mb,
                    (first + 2) % mb,
                ];
                let x = [
                    slave[slave_nodes[0]],
                    slave[slave_nodes[1]],
                    slave[slave_nodes[2]],
                    master[master_nodes[0]],
                    master[master_nodes[1]],
                    master[master_nodes[2]],
                    master[master_nodes[3]],
                ];
                let tangential = grain_friction.and_then(|fr| {
                    let origin =
                        slip_origin_xi(&fr.origin.contours[j], fr.origin.contours[i][s], first)?;
                    Some(TangentialInput {
                        mu: self.friction.grains,
                        penalty: self.friction.stiffness_ratio * k,
                        lambda: fr.tractions.get(&key).copied().unwrap_or(0.0),
                        origin,
                    })
                });
                let Some(e) = nts::evaluate_frictional(
                    &x,
                    lambda_of(&key),
                    k,
                    tangential.as_ref(),
                    with_tangent,
                    0.0,
                ) else {
                    continue;
                };
                if e.pressure <= 0.0 {
                    continue;
                }
                let mut element = ContactElement::new(
                    key,
                    [e.gap, e.pressure, e.tributary],
                    e.normal,
                    xs,
                    &[(off_i, &slave_nodes), (off_j, &master_nodes)],
                    &e.force,
                    with_tangent.then_some(&e.stiffness),
                );
                element.friction =
                    ElementFriction::of(tangential.as_ref(), e.traction, e.slip, e.sticking);
                out.push(element);
            }
        }
        for (w, wall) in self.walls.iter().enumerate() {
            let (p, n) = ([wall.point.x, wall.point.y], [wall.normal.x, wall.normal.y]);
            let mu = self.friction.wall(w);
            let wall_friction = friction.filter(|_| mu > 0.0).map(|f| (mu, f));
            for s in 0..nb {
                let key = ContactKey {
                    slave: i as u32,
                    node: s as u32,
                    master: Master::Wall(w as u32),
                };
                let nodes = [(s + nb - 1) % nb, s, (s + 1) % nb];
                let x = nodes.map(|a| slave[a]);
                let tangential = wall_friction.map(|(mu, fr)| {
                    let (o, q) = (fr.origin.contours[i][s], fr.origin.wall_points[w]);
                    TangentialInput {
                        mu,
                        penalty: self.friction.stiffness_ratio * k,
                        lambda: fr.tractions.get(&key).copied().unwrap_or(0.0),
                        origin: (o[0] - q[0]) * -n[1] + (o[1] - q[1]) * n[0],
                    }
                });
                let e = wall_node_element(
                    &x,
                    p,
                    n,
                    lambda_of(&key),
                    k,
                    tangential.as_ref(),
                    with_tangent,
                );
                if e.pressure <= 0.0 {
                    continue;
                }
                let mut element = ContactElement::new(
                    key,
                    [e.gap, e.pressure, e.tributary],
                    n,
                    x[1],
                    &[(off_i, &nodes)],
                    &e.force,
                    with_tangent.then_some(&e.stiffness),
                );
                element.friction =
                    ElementFriction::of(tangential.as_ref(), e.traction, e.slip, e.sticking);
                out.push(element);
            }
        }
        out
    }

    /// Residual at displacement `u`, and with `with_tangent` the pieces of its Jacobian
    /// (grain blocks and contact elements' stiffness); frictionless contacts.
    pub fn evaluate(
        &self,
        u: &[f64],
        multipliers: &ContactMultipliers,
        k: f64,
        dynamic: Option<&DynamicTerms>,
        with_tangent: bool,
    ) -> Result<Evaluation, MeshfreeError> {
        self.evaluate_with(u, multipliers, None, k, dynamic, with_tangent)
    }

    /// [`Assembly::evaluate`] with the friction state of the step (`None`: frictionless).
    pub fn evaluate_with(
        &self,
        u: &[f64],
        multipliers: &ContactMultipliers,
        friction: Option<FrictionInput<'_>>,
        k: f64,
        dynamic: Option<&DynamicTerms>,
        with_tangent: bool,
    ) -> Result<Evaluation, MeshfreeError> {
        let (alpha, beta) = self.rayleigh;
        // Per grain: internal forces, dynamic terms, tangent blocks.
        let per_grain: Vec<GrainTerms> = (0..self.grains.len())
            .into_par_iter()
            .map(|g| {
                let model = &self.grains[g];
                let range = self.offsets[g]..self.offsets[g + 1];
                let ug = &u[range.clone()];
                let mut r: Vec<f64> = self.external[range.clone()].iter().map(|f| -f).collect();
                let mut dense = with_tangent.then(|| Dense::zeros(model.dofs()));
                let energy = model.internal(ug, &mut r, dense.as_mut())?;
                let mut scale = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let mut blocks = Vec::new();
                if let Some(d) = &dense {
                    model.pattern_blocks(d, &mut blocks);
                }
                if let Some(dt) = dynamic {
                    // M (A + alpha V) + beta K_i0 V, with A and V affine in u.
                    let acc: Vec<f64> = range
                        .clone()
                        .map(|i| {
                            dt.c_m * u[i] + dt.a_const[i] + alpha * (dt.c_v * u[i] + dt.v_const[i])
                        })
                        .collect();
                    let mut inertia = vec![0.0; model.dofs()];
                    model.pattern_mass_mul(&acc, &mut inertia);
                    if beta != 0.0 {
                        let k0 = &self.initial_stiffness[g];
                        for (&(a, b), blk) in model.pattern.pairs.iter().zip(k0) {
                            let (a, b) = (a as usize, b as usize);
                            let vb = [
                                dt.c_v * u[range.start + 2 * b] + dt.v_const[range.start + 2 * b],
                                dt.c_v * u[range.start + 2 * b + 1]
                                    + dt.v_const[range.start + 2 * b + 1],
                            ];
                            inertia[2 * a] += beta * (blk[0] * vb[0] + blk[2] * vb[1]);
                            inertia[2 * a + 1] += beta * (blk[1] * vb[0] + blk[3] * vb[1]);
                        }
                    }
                    for (ri, fi) in r.iter_mut().zip(&inertia) {
                        scale = scale.max(fi.abs());
                        *ri += fi;
                    }
                    if with_tangent {
                        let cm = dt.c_m + alpha * dt.c_v;
                        let k0 = self.initial_stiffness.get(g);
                        for (p, blk) in blocks.iter_mut().enumerate() {
                            let m = cm * model.pattern_mass[p];
                            blk[0] += m;
                            blk[3] += m;
                            if let Some(k0) = k0 {
                                for (b, k) in blk.iter_mut().zip(&k0[p]) {
                                    *b += beta * dt.c_v * k;
                                }
                            }
                        }
                    }
                }
                Ok(GrainTerms {
                    residual: r,
                    blocks,
                    energy,
                    scale,
                })
            })
            .collect::<Result<_, MeshfreeError>>()?;
        let contours: Vec<Vec<[f64; 2]>> = self
            .grains
            .iter()
            .enumerate()
            .map(|(g, m)| contour(m, self.grain_slice(u, g)))
            .collect();
        let neighbours = self.neighbours(&contours);
        let elements: Vec<ContactElement> = (0..self.grains.len())
            .into_par_iter()
            .map(|i| {
                self.slave_elements(
                    i,
                    &contours,
                    &neighbours[i],
                    multipliers,
                    friction,
                    k,
                    with_tangent,
                )
            })
            .collect::<Vec<_>>()
            .into_iter()
            .flatten()
            .collect();
        // Gather in a fixed order.
        let mut residual = Vec::with_capacity(self.dofs());
        let (mut elastic_energy, mut force_scale) = (0.0, 0.0f64);
        for t in &per_grain {
            residual.extend_from_slice(&t.residual);
            elastic_energy += t.energy;
            force_scale = force_scale.max(t.scale);
        }
        for e in &elements {
            for (&dof, f) in e.dofs.iter().zip(&e.force) {
                residual[dof] -= f;
                force_scale = force_scale.max(f.abs());
            }
        }
        for &i in &self.fixed {
            residual[i] = 0.0;
        }
        let grain_blocks = if with_tangent {
            per_grain.into_iter().map(|p| p.blocks).collect()
        } else {
            Vec::new()
        };
        Ok(Evaluation {
            residual,
            elements,
            elastic_energy,
            force_scale,
            grain_blocks,
            dissipation: 0.0,
        })
    }

    /// The Jacobian of an evaluation made with the tangent, as triplets: the grains' blocks,
    /// then the contact elements' 2 x 2 node blocks on the contact pattern (see
    /// [`ContactPattern`]), then 1 on the diagonal of the fixed DoF (their rows and columns
    /// are otherwise left out).
    fn fill_tangent(&mut self, eval: &Evaluation, t: &mut TripletMatrix) {
        let mut fixed = vec![false; self.dofs()];
        for &i in &self.fixed {
            fixed[i] = true;
        }
        t.clear();
        for (g, blocks) in eval.grain_blocks.iter().enumerate() {
            let off = self.offsets[g];
            for (&(a, b), blk) in self.grains[g].pattern.pairs.iter().zip(blocks) {
                let (ra, cb) = (off + 2 * a as usize, off + 2 * b as usize);
                for (q, (dr, dc)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
                    let (row, col) = (ra + dr, cb + dc);
                    if !fixed[row] && !fixed[col] {
                        t.push(row, col, blk[q]);
                    }
                }
            }
        }
        let (grains, offsets) = (&self.grains, &self.offsets);
        let values = self
            .contact_pattern
            .gather(&eval.elements, |e| contour_window(grains, offsets, &e.dofs));
        for (&(ra, cb), blk) in self.contact_pattern.pairs.iter().zip(&values) {
            for (q, (dr, dc)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
                let (row, col) = (ra + dr, cb + dc);
                if !fixed[row] && !fixed[col] {
                    t.push(row, col, blk[q]);
                }
            }
        }
        for &i in &self.fixed {
            t.push(i, i, 1.0);
        }
    }

    fn all_points_valid(&self, u: &[f64]) -> bool {
        (0..self.grains.len())
            .into_par_iter()
            .all(|g| self.grains[g].all_points_valid(self.grain_slice(u, g)))
    }

    /// Lumped mass and critical step, once the explicit scheme is in use.
    pub fn explicit_data(&self) -> Option<&ExplicitData> {
        self.explicit.as_ref()
    }

    /// The node pairs (x DoF, x DoF) the sparse tangent holds for contacts (see
    /// [`ContactPattern`]): part of the state a resumed run needs to continue bit for bit.
    pub fn contact_pattern(&self) -> &[(usize, usize)] {
        &self.contact_pattern.pairs
    }

    /// Sets the contact pattern (from a checkpoint); pairs outside the DoF or on a y DoF are
    /// refused.
    pub fn set_contact_pattern(&mut self, pairs: Vec<(usize, usize)>) -> Result<(), String> {
        let n = self.dofs();
        if let Some(p) = pairs
            .iter()
            .find(|&&(a, b)| a >= n || b >= n || a % 2 != 0 || b % 2 != 0)
        {
            return Err(format!("contact pattern pair {p:?} for {n} DoF"));
        }
        self.contact_pattern = ContactPattern::from_pairs(pairs);
        Ok(())
    }

    /// Newton iterations at fixed multipliers and contact stiffness, until the residual is
    /// below the force tolerance, or, with `open_gap_tolerance`, as soon as the iterate is
    /// known well enough to tell that a gap exceeds that tolerance (the last correction is
    /// below [`EARLY_AUGMENTATION_STEP`] of the excess): another augmentation follows anyway,
    /// and converging this one fully would be wasted (an inexact inner solve, which the next
    /// augmentation corrects; the last augmentation is always converged fully).
    ///
    /// A step reuses the last factorization (modified Newton) when the step before it shrank
    /// the residual by at least [`REUSE_CONTRACTION`]: near the solution the tangent hardly
    /// changes, and a residual with a solve costs a fraction of a tangent with its
    /// factorization. A modified step that does not reduce the residual is undone and redone
    /// with the tangent. The convergence test needs the residual only: the tangent is
    /// computed only when a full step follows. After [`STALLED_STEPS_BEFORE_LINE_SEARCH`] full
    /// steps in a row that leave the residual above [`STALL_CONTRACTION`] of the lowest so far
    /// (Newton cycling), the step is shortened until the residual falls
    /// ([`Assembly::shorter_newton_step`]); a Newton whose residual keeps falling never gets
    /// there.
    #[allow(clippy::too_many_arguments)]
    fn newton(
        &mut self,
        u: &mut Vec<f64>,
        multipliers: &ContactMultipliers,
        friction: Option<FrictionInput<'_>>,
        k: f64,
        dynamic: Option<&DynamicTerms>,
        open_gap_tolerance: Option<f64>,
        stats: &mut SolveStats,
    ) -> Result<(Evaluation, NewtonEnd), MeshfreeError> {
        let mut tangent = TripletMatrix::new(self.dofs());
        let mut eval = self.evaluate_with(u, multipliers, friction, k, dynamic, false)?;
        let mut norm = finite_residual_norm(&eval.residual)?;
        let mut previous_norm = f64::INFINITY;
        // Whether the solver holds a factorization of this loop's tangent.
        let mut factorized = false;
        // Largest component of the last correction applied (a length).
        let mut last_correction = f64::INFINITY;
        // The iterate before a modified step, to undo it if it fails.
        let mut before_modified: Option<(Vec<f64>, Evaluation, f64)> = None;
        // Full steps in a row that did not lower the residual well below the lowest so far.
        let mut stalled_steps = 0;
        let mut lowest_norm = norm;
        for _ in 0..self.settings.max_newton {
            if norm <= self.settings.force_tolerance + 1e-13 * eval.force_scale {
                return Ok((eval, NewtonEnd::Converged));
            }
            if let Some(tolerance) = open_gap_tolerance {
                let gap = eval.constraint_violation();
                if gap > tolerance && last_correction <= EARLY_AUGMENTATION_STEP * (gap - tolerance)
                {
                    return Ok((eval, NewtonEnd::GapOpen));
                }
            }
            let modified_failed = before_modified.is_some() && norm >= previous_norm;
            if modified_failed {
                let (u0, eval0, norm0) = before_modified.take().expect("checked above");
                *u = u0;
                eval = eval0;
                norm = norm0;
            }
            let reuse = factorized && !modified_failed && norm <= REUSE_CONTRACTION * previous_norm;
            stats.newton_iterations += 1;
            let mut du: Vec<f64>;
            if reuse {
                before_modified = Some((u.clone(), eval.clone(), norm));
                du = eval.residual.iter().map(|v| -v).collect();
                self.solver.solve_factored(&mut du)?;
            } else {
                before_modified = None;
                let with_tangent =
                    self.evaluate_with(u, multipliers, friction, k, dynamic, true)?;
                self.fill_tangent(&with_tangent, &mut tangent);
                du = with_tangent.residual.iter().map(|v| -v).collect();
                self.solver.solve(&tangent, &mut du)?;
                stats.factorizations += 1;
                factorized = true;
            }
            let start = (!reuse).then(|| u.clone());
            let mut applied = newton_update(u, &du, |trial| self.all_points_valid(trial))?;
            previous_norm = norm;
            eval = self.evaluate_with(u, multipliers, friction, k, dynamic, false)?;
            norm = finite_residual_norm(&eval.residual)?;
            if let Some(start) = start {
                stalled_steps = if norm < STALL_CONTRACTION * lowest_norm {
                    0
                } else {
                    stalled_steps + 1
                };
                lowest_norm = lowest_norm.min(norm);
                if stalled_steps >= STALLED_STEPS_BEFORE_LINE_SEARCH
                    && let Some(shorter) = self.shorter_newton_step(
                        &start,
                        &du,
                        applied,
                        previous_norm,
                        multipliers,
                        friction,
                        k,
                        dynamic,
                    )?
                {
                    *u = shorter.u;
                    eval = shorter.eval;
                    norm = shorter.norm;
                    applied = shorter.alpha;
                    stalled_steps = 0;
                }
            }
            last_correction = applied * du.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        }
        if norm <= self.settings.force_tolerance + 1e-13 * eval.force_scale {
            return Ok((eval, NewtonEnd::Converged));
        }
        Err(MeshfreeError::NotConverged(format!(
            "Newton did not converge in {} iterations (residual {norm:.3e} > {:.1e})",
            self.settings.max_newton, self.settings.force_tolerance
        )))
    }

    /// Backtracking along a full Newton step that left the residual no lower, after
    /// [`STALLED_STEPS_BEFORE_LINE_SEARCH`] such steps: `start + alpha du` for alpha =
    /// applied/2, applied/4, … ([`LINE_SEARCH_HALVINGS`] tries), the first valid one whose
    /// residual is below `norm_at_start`, with its evaluation and residual norm; `None` when
    /// none is (the full step is then kept, as without the search).
    #[allow(clippy::too_many_arguments)]
    fn shorter_newton_step(
        &self,
        start: &[f64],
        du: &[f64],
        applied: f64,
        norm_at_start: f64,
        multipliers: &ContactMultipliers,
        friction: Option<FrictionInput<'_>>,
        k: f64,
        dynamic: Option<&DynamicTerms>,
    ) -> Result<Option<ShorterStep>, MeshfreeError> {
        let mut alpha = applied;
        for _ in 0..LINE_SEARCH_HALVINGS {
            alpha *= 0.5;
            let trial: Vec<f64> = start.iter().zip(du).map(|(u, d)| u + alpha * d).collect();
            if !self.all_points_valid(&trial) {
                continue;
            }
            let eval = self.evaluate_with(&trial, multipliers, friction, k, dynamic, false)?;
            match finite_residual_norm(&eval.residual) {
                Ok(norm) if norm < norm_at_start => {
                    return Ok(Some(ShorterStep {
                        alpha,
                        u: trial,
                        eval,
                        norm,
                    }));
                }
                _ => {}
            }
        }
        Ok(None)
    }

    /// Newton loops nested in augmentation loops (k reset to k0, doubled at each
    /// augmentation); `u` and `multipliers` are updated in place. Frictionless contacts.
    pub fn solve(
        &mut self,
        u: &mut Vec<f64>,
        multipliers: &mut ContactMultipliers,
        dynamic: Option<&DynamicTerms>,
    ) -> Result<(Evaluation, SolveStats), MeshfreeError> {
        self.solve_with(u, multipliers, None, dynamic)
    }

    /// [`Assembly::solve`] with friction: `friction` holds the tangential multipliers (on
    /// entry the tractions committed at the last converged state, on return those of the
    /// solution) and the slip origin.
    pub fn solve_with(
        &mut self,
        u: &mut Vec<f64>,
        multipliers: &mut ContactMultipliers,
        mut friction: Option<(&mut ContactMultipliers, &SlipOrigin)>,
        dynamic: Option<&DynamicTerms>,
    ) -> Result<(Evaluation, SolveStats), MeshfreeError> {
        let s = self.settings;
        let mut k = s.k0;
        let mut stats = SolveStats::default();
        for augmentation in 0..s.max_augmentations {
            // The last allowed augmentation is converged fully whatever its gap.
            let open_gap = (augmentation + 1 < s.max_augmentations).then_some(s.gap_tolerance);
            let input = friction.as_ref().map(|(t, o)| FrictionInput {
                tractions: t,
                origin: o,
            });
            let (eval, end) =
                self.newton(u, multipliers, input, k, dynamic, open_gap, &mut stats)?;
            multipliers.clear();
            for e in &eval.elements {
                multipliers.insert(e.key, e.pressure);
            }
            if let Some((tractions, _)) = friction.as_mut() {
                **tractions = eval.tractions();
            }
            stats.augmentations += 1;
            stats.max_penetration = eval.max_penetration();
            if end == NewtonEnd::Converged && eval.constraint_violation() <= s.gap_tolerance {
                return Ok((eval, stats));
            }
            k *= s.alpha_k;
        }
        Err(MeshfreeError::NotConverged(format!(
            "the augmented Lagrangian did not reach the gap tolerance {:.1e} in {} augmentations \
             (max penetration {:.3e})",
            s.gap_tolerance, s.max_augmentations, stats.max_penetration
        )))
    }

    /// Grains at rest, undeformed; the acceleration is gravity's (the consistent mass
    /// reproduces a uniform field exactly).
    pub fn initial_state(&self) -> AssemblyState {
        let n = self.dofs();
        AssemblyState {
            time: 0.0,
            u: vec![0.0; n],
            v: vec![0.0; n],
            a: (0..n).map(|i| self.gravity[i % 2]).collect(),
            multipliers: ContactMultipliers::new(),
            friction: ContactMultipliers::new(),
        }
    }

    fn move_walls(&mut self, from: &[Wall], elapsed: f64) {
        for (w, f) in self.walls.iter_mut().zip(from) {
            w.point = f.point + f.velocity * elapsed;
        }
    }

    /// One step of `dt` (walls moving at their velocities), without sub-steps. `state` is
    /// written only on success; the walls are left where the failed solve had moved them.
    fn try_step(
        &mut self,
        state: &mut AssemblyState,
        dt: f64,
        scheme: TimeScheme,
    ) -> Result<(Evaluation, SolveStats), MeshfreeError> {
        let walls0 = self.walls.clone();
        let (u0, v0, a0) = (&state.u, &state.v, &state.a);
        let mut stats = SolveStats::default();
        let mid = match scheme {
            TimeScheme::Trapezoidal | TimeScheme::CentralDifference => dt,
            TimeScheme::Bathe => 0.5 * dt,
        };
        let mut multipliers = state.multipliers.clone();
        // Friction: the tractions committed at the end of each converged sub-step, the slip
        // measured from its start.
        let frictional = self.friction.any();
        let mut tractions = state.friction.clone();
        let origin0 = frictional.then(|| self.slip_origin(u0));
        self.move_walls(&walls0, mid);
        let terms = DynamicTerms::trapezoidal(mid, u0, v0, a0, None);
        let mut u1 = u0.clone();
        let (mut eval, s) = self.solve_with(
            &mut u1,
            &mut multipliers,
            origin0.as_ref().map(|o| (&mut tractions, o)),
            Some(&terms),
        )?;
        stats += s;
        let v1 = terms.velocity(&u1);
        let mut dissipation = eval.friction_dissipation();
        let (u, v, a) = match scheme {
            TimeScheme::Trapezoidal | TimeScheme::CentralDifference => {
                let a = terms.acceleration(&u1);
                (u1, v1, a)
            }
            TimeScheme::Bathe => {
                let origin1 = frictional.then(|| self.slip_origin(&u1));
                self.move_walls(&walls0, dt);
                let terms = DynamicTerms::backward_euler3(dt, u0, &u1, v0, &v1, None);
                let mut u2 = u1.clone();
                // k is reset at each sub-step (SPEC §10).
                let (e, s) = self.solve_with(
                    &mut u2,
                    &mut multipliers,
                    origin1.as_ref().map(|o| (&mut tractions, o)),
                    Some(&terms),
                )?;
                eval = e;
                dissipation += eval.friction_dissipation();
                stats += s;
                let (v, a) = (terms.velocity(&u2), terms.acceleration(&u2));
                (u2, v, a)
            }
        };
        state.u = u;
        state.v = v;
        state.a = a;
        state.multipliers = multipliers;
        state.friction = tractions;
        state.time += dt;
        eval.dissipation = dissipation;
        Ok((eval, stats))
    }

    /// Advances `state` by `dt`; a step that does not converge is retried as two half steps,
    /// down to `min_sub_step` of `dt`. On failure the state and walls are those of the start.
    pub fn step(
        &mut self,
        state: &mut AssemblyState,
        dt: f64,
        scheme: TimeScheme,
    ) -> Result<(Evaluation, StepStats), MeshfreeError> {
        let saved = (state.clone(), self.walls.clone());
        let result = match scheme {
            TimeScheme::CentralDifference => self.explicit_step(state, dt),
            TimeScheme::Bathe | TimeScheme::Trapezoidal => self.sub_steps(state, dt, 1.0, scheme),
        };
        match result {
            Ok(r) => Ok(r),
            Err(e) => {
                *state = saved.0;
                self.walls = saved.1;
                Err(e)
            }
        }
    }

    fn sub_steps(
        &mut self,
        state: &mut AssemblyState,
        dt: f64,
        fraction: f64,
        scheme: TimeScheme,
    ) -> Result<(Evaluation, StepStats), MeshfreeError> {
        let walls0 = self.walls.clone();
        match self.try_step(state, dt, scheme) {
            Ok((eval, solve)) => Ok((
                eval,
                StepStats {
                    solve,
                    sub_steps: 1,
                },
            )),
            Err(MeshfreeError::NotConverged(_) | MeshfreeError::Singular)
                if fraction * 0.5 >= self.min_sub_step =>
            {
                self.walls = walls0;
                let (first_eval, mut first) =
                    self.sub_steps(state, 0.5 * dt, 0.5 * fraction, scheme)?;
                let (mut eval, second) = self.sub_steps(state, 0.5 * dt, 0.5 * fraction, scheme)?;
                eval.dissipation += first_eval.dissipation;
                first.solve += second.solve;
                first.sub_steps += second.sub_steps;
                Ok((eval, first))
            }
            Err(e) => Err(e),
        }
    }

    /// A quasi-static solve at the walls' current positions (no inertia: rigid modes must be
    /// held by `fixed` DoF or by contacts).
    pub fn solve_static(
        &mut self,
        u: &mut Vec<f64>,
        multipliers: &mut ContactMultipliers,
    ) -> Result<(Evaluation, SolveStats), MeshfreeError> {
        self.solve(u, multipliers, None)
    }

    /// A quasi-static load step with friction: the slip measured from `u` on entry (the last
    /// converged state, walls where they were then: move them after calling
    /// [`Assembly::slip_origin`]), `tractions` committed on success.
    pub fn solve_static_with_friction(
        &mut self,
        u: &mut Vec<f64>,
        multipliers: &mut ContactMultipliers,
        tractions: &mut ContactMultipliers,
        origin: &SlipOrigin,
    ) -> Result<(Evaluation, SolveStats), MeshfreeError> {
        self.solve_with(u, multipliers, Some((tractions, origin)), None)
    }

    /// Potential energy of the body forces, `-f_ext . x` over the current node positions (for
    /// gravity, `-m g . x_c` summed over grains: the consistent body force reproduces it; the
    /// explicit scheme's lumped body force too).
    pub fn potential_energy(&self, u: &[f64]) -> f64 {
        if let Some(x) = &self.explicit {
            return -(0..u.len())
                .map(|i| x.lumped_mass[i] * self.gravity[i % 2] * (self.reference(i) + u[i]))
                .sum::<f64>();
        }
        let mut e = 0.0;
        for (g, model) in self.grains.iter().enumerate() {
            let off = self.offsets[g];
            for (a, x) in model.nodes.positions.iter().enumerate() {
                for i in 0..2 {
                    e -= self.external[off + 2 * a + i] * (x[i] + u[off + 2 * a + i]);
                }
            }
        }
        e
    }

    /// Reference coordinate of DoF `i` (x or y of its node).
    fn reference(&self, i: usize) -> f64 {
        let g = self.offsets.partition_point(|&o| o <= i) - 1;
        let local = i - self.offsets[g];
        self.grains[g].nodes.positions[local / 2][local % 2]
    }

    /// Kinetic energy `v^T M v / 2` (the lumped mass with the explicit scheme).
    pub fn kinetic_energy(&self, v: &[f64]) -> f64 {
        if let Some(x) = &self.explicit {
            return 0.5
                * v.iter()
                    .zip(&x.lumped_mass)
                    .map(|(v, m)| m * v * v)
                    .sum::<f64>();
        }
        let mut e = 0.0;
        for (g, model) in self.grains.iter().enumerate() {
            let vg = self.grain_slice(v, g);
            let mut mv = vec![0.0; vg.len()];
            model.pattern_mass_mul(vg, &mut mv);
            e += 0.5 * vg.iter().zip(&mv).map(|(a, b)| a * b).sum::<f64>();
        }
        e
    }
}

/// The slip origin of a node-to-segment element on master segment `first` (see
/// [`nts`]'s friction): where the slave node (at `slave` then) projected on the master's
/// contour `master` at the last converged state, as a parameter of segment `first`
/// (`ξ' - 2 j` for a projection at `ξ'` on the segment `j` segments back). `None` when the
/// projection fails (the element then has no friction in this evaluation).
fn slip_origin_xi(master: &[[f64; 2]], slave: [f64; 2], first: usize) -> Option<f64> {
    let mb = master.len();
    let closest =
        (0..mb).min_by(|&a, &b| dist2(master[a], slave).total_cmp(&dist2(master[b], slave)))?;
    let (then, xi) = nts::master_segment(master, closest, slave)?;
    // Segments from `then` to `first` along the contour, in (-mb/2, mb/2].
    let j = (first + mb - then) % mb;
    if 2 * j > mb {
        Some(xi + 2.0 * (mb - j) as f64)
    } else {
        Some(xi - 2.0 * j as f64)
    }
}

#[inline]
fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}
