//! The explicit SDEM time step (SPEC §4): contact forces, Love–Weber stress, grain stress,
//! symplectic Euler on the six degrees of freedom, incompressibility correction.
//!
//! One step is three parallel passes (four in a periodic cell), each deterministic whatever the
//! thread count:
//! 1. per grain: its shape and velocity field (`frames`);
//! 2. per candidate pair: contact geometry and force, written to the pair's own slot
//!    ([`pairs`]: circles eight pairs at a time);
//! 3. per grain: sum of its contacts in pair order (plus its wall contacts), stresses, update
//!    (`grain_pass.rs`); in a periodic cell (SPEC §14) each updated grain is then carried by
//!    the cell's affine deformation over the step and wrapped back into the cell, and the
//!    neighbour list follows the wraps (`World::follow_cell`).
//!
//! In a periodic cell a pair `[i, j]` meets the image of j at `x_j + H n` (its image vector n in
//! the neighbour list); its relative velocity adds the affine field's `L d` (d the branch vector),
//! since grain velocities are relative to that field; its force enters the cell stress
//! `(1/A) sum sym(f_i ⊗ d)`.
//!
//! Sums over grains (wall forces, areas, energies) are taken per fixed-size chunk and the chunk
//! sums added in order; sums over contacts, per chunk of the pairs whose first grains form one
//! such chunk, so that they depend neither on the thread count nor on when the neighbour list
//! was built. What only outputs read and the step's end state determines (the grains' kinetic
//! energy and kinetic stress) is summed when asked ([`World::kinetic`]), in the same chunks.

mod grain_block;
mod grain_pass;
pub mod instability;
pub mod pairs;
pub mod parameters;
mod sweep;

pub use instability::Instability;
pub use parameters::Parameters;
pub use sweep::{SweepPlan, SweepTally, sweep_plan_of};

use crate::boundary::periodic::{CellMotion, PeriodicBoundary, PeriodicCell, symmetric_dyad};
use crate::boundary::walls::{Wall, box_corners, box_corners_after};
use crate::geometry::affine::{AffineState, Mat2, map_and_velocity_gradient, principal_direction};
use crate::geometry::angle;
use crate::geometry::broadphase::{NeighborList, clear_with_room};
use crate::geometry::contour::QUARTER_TURN;
use crate::geometry::intersection_lanes::LaneShape;
use crate::geometry::{Contours, GrainShape, PairHint};
use crate::grain::{Grain, GrainLevel, ModelLevel};
use crate::lanes::{Lanes, Real};
use crate::output::measures::coordination_without_rattlers;
use glam::{DMat2, DVec2};
use grain_pass::{CycleHalf, GrainChunk, GrainPass};
use parameters::MULTI_RATE_MIN_RIGID_SHARE;
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::time::Instant;

/// Grains per chunk of the parallel passes: fixed, so that every reduction is the same sum in
/// the same order for any number of threads. The pair pass's chunks follow them (see
/// [`pair_chunk_ends`]).
pub const GRAIN_CHUNK: usize = 256;
/// Pairs per chunk of the passes over the pair list that sum nothing (the rebuild's merge).
pub const PAIR_CHUNK: usize = 512;
/// Largest number of walls a world may have.
pub const MAX_WALLS: usize = 8;

/// What a grain's neighbours need from it during one step.
///
/// Two cache lines, aligned: the first holds all that a circle's contacts read (centre, radius,
/// mass, velocity, spin, dilation rate), so that the passes load one line per circle where
/// they loaded three from the 152 bytes this was (issue #16: those loads were the run's
/// largest cost). A circle's frame writes only that line; the second, the shape map and
/// velocity gradient of a grain that is not a circle, is rebuilt from the radius, spin and
/// dilation rate when a circle needs it.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
pub struct Frame {
    pub center: DVec2,
    /// Radius of a circle about the centre that contains the whole contour (see
    /// [`GrainShape::bounding_radius`]); a circle's radius.
    pub bounding_radius: f64,
    pub mass: f64,
    pub velocity: DVec2,
    /// Spin omega (read for circles only: their velocity gradient is `omega J + d I`).
    pub omega: f64,
    /// Where the grain is an exact circle of radius `bounding_radius` ([`Frame::is_circle`]:
    /// a grain below the full level whose strains are equal), the rate `d` at which it
    /// dilates (its radius grows at `d` times itself: zero at the rigid level); NaN where it
    /// is not a circle ([`Frame::circle`]). A circle's contacts with walls and with other
    /// circles take the closed forms of [`circle`](crate::geometry::circle) instead of the
    /// contour polygon (issue #16). One word for the flag and the rate, so that a circle's
    /// contacts still read one line.
    circle_dilation: f64,
    /// `A R` (see [`GrainShape::map`]); not written for a circle.
    map: DMat2,
    /// Velocity gradient of the grain's affine motion (see [`Grain::velocity_gradient`]); not
    /// written for a circle.
    velocity_gradient: DMat2,
}

// What `Frame::lane_shape` reads: the centre and bounding radius at a block's offsets.
const _: () = assert!(
    std::mem::offset_of!(Frame, center) == 0
        && std::mem::offset_of!(Frame, bounding_radius) == 16
        && std::mem::offset_of!(Frame, mass) == 24
);

/// [`Frame::circle_dilation`] of a frame that is not a circle.
const NOT_A_CIRCLE: f64 = f64::NAN;

impl Default for Frame {
    /// A frame of zeros that is not a circle.
    fn default() -> Self {
        Frame {
            center: DVec2::ZERO,
            bounding_radius: 0.0,
            mass: 0.0,
            velocity: DVec2::ZERO,
            omega: 0.0,
            circle_dilation: NOT_A_CIRCLE,
            map: DMat2::ZERO,
            velocity_gradient: DMat2::ZERO,
        }
    }
}

impl Frame {
    /// The frame of a grain at its current state.
    #[inline]
    pub fn of_grain(grain: &Grain, density: f64) -> Self {
        Self::of_grain_and_direction(grain, density).0
    }

    /// [`Frame::of_grain`] and the grain's [principal direction](Grain::principal_direction),
    /// from the same sines and cosines.
    #[inline]
    pub fn of_grain_and_direction(grain: &Grain, density: f64) -> (Self, DVec2) {
        let (shape, gradient, direction) = grain.shape_velocity_gradient_and_direction();
        (Self::full(grain, density, shape.map, gradient), direction)
    }

    /// The frame of a grain that is not a circle, given its map and velocity gradient.
    #[inline(always)]
    fn full(grain: &Grain, density: f64, map: DMat2, velocity_gradient: DMat2) -> Self {
        Frame {
            center: grain.center,
            bounding_radius: GrainShape::bounding_radius_of(grain.radius, grain.eps1, grain.eps2),
            mass: grain.mass(density),
            velocity: grain.velocity,
            omega: grain.omega,
            circle_dilation: NOT_A_CIRCLE,
            map,
            velocity_gradient,
        }
    }

    /// Writes [`Frame::of_grain_and_direction`] of the grains `block` into `frames` and
    /// `directions` (the same indices), the sines and cosines of their angles, their maps,
    /// velocity gradients and principal directions computed side by side in lanes (with AVX
    /// where the processor has it, chosen at run time): the same bits, grain by grain. These
    /// were some 400 instructions a grain-step at the full level, and `libm`'s branches on the
    /// angles of grains that have turned (issue #16).
    #[inline]
    pub fn write_full_block(
        frames: &mut [Frame],
        directions: &mut [DVec2],
        grains: &[Grain],
        block: [usize; FRAME_LANES],
        density: f64,
    ) {
        let mut angles = BlockAngles::default();
        let mut states = AffineState::<FrameLanes>::default();
        for (l, &k) in block.iter().enumerate() {
            let grain = &grains[k];
            (angles.theta.0[l], angles.alpha.0[l]) = (grain.theta, grain.alpha);
            states.set_lane(l, &grain.affine_state_without_angles());
        }
        let (maps, gradients, principal) = affine_lanes_dispatch(&angles, &states);
        for (l, &k) in block.iter().enumerate() {
            frames[k] = Frame::full(&grains[k], density, maps.lane(l), gradients.lane(l));
            directions[k] = DVec2::new(principal[0].0[l], principal[1].0[l]);
        }
    }
}

/// Grains a block of [`Frame::write_full_block`] holds.
pub const FRAME_LANES: usize = 4;

type FrameLanes = Lanes<FRAME_LANES>;
/// A block's maps, velocity gradients and principal directions.
type AffineLanes = (Mat2<FrameLanes>, Mat2<FrameLanes>, [FrameLanes; 2]);

/// The angles theta and alpha of a block's grains.
#[derive(Default)]
struct BlockAngles {
    theta: FrameLanes,
    alpha: FrameLanes,
}

/// [`map_and_velocity_gradient`] of a block, the sines and cosines of its angles computed in
/// lanes too ([`angle::sin_cos_lanes`]).
#[inline(always)]
fn affine_lanes(angles: &BlockAngles, states: &AffineState<FrameLanes>) -> AffineLanes {
    let (sin_theta, cos_theta) = angle::sin_cos_lanes(&angles.theta);
    let (sin_alpha, cos_alpha) = angle::sin_cos_lanes(&angles.alpha);
    let state = AffineState {
        sin_theta,
        cos_theta,
        sin_alpha,
        cos_alpha,
        ..*states
    };
    let (map, gradient) = map_and_velocity_gradient(&state);
    (map, gradient, principal_direction(&state))
}

/// [`affine_lanes`], with AVX where the processor has it. Out of line, so that the lanes are
/// loaded from memory as vectors: inlined into the gather, the compiler vectorised the
/// matrices along their own entries instead of across the grains (190 instructions a grain
/// for the matrices, against 37 out of line).
#[inline(never)]
fn affine_lanes_dispatch(angles: &BlockAngles, states: &AffineState<FrameLanes>) -> AffineLanes {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the processor has AVX (tested just above).
        return unsafe { affine_lanes_avx(angles, states) };
    }
    affine_lanes(angles, states)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline(never)]
fn affine_lanes_avx(angles: &BlockAngles, states: &AffineState<FrameLanes>) -> AffineLanes {
    affine_lanes(angles, states)
}

impl Frame {
    /// Writes the frame of `grain` at `level`: a circle where the grain is one (see
    /// [`Frame::circle`]), else its full frame, and then its principal direction to
    /// `direction` (left as it was beside a circle, which is never at the full level, the one
    /// level that reads it).
    #[inline]
    pub fn write(&mut self, direction: &mut DVec2, grain: &Grain, level: ModelLevel, density: f64) {
        if Self::is_circle(grain, level) {
            self.write_circle(grain, level, density);
        } else {
            (*self, *direction) = Frame::of_grain_and_direction(grain, density);
        }
    }

    /// Whether the frame of `grain` at `level` is a circle: a rigid or volumetric grain whose
    /// strains are equal (a disc, or one held or evolving at a volumetric strain: the
    /// volumetric level moves both strains by the same rate, so they stay equal).
    #[inline(always)]
    pub fn is_circle(grain: &Grain, level: ModelLevel) -> bool {
        level != ModelLevel::Full && grain.eps1 == grain.eps2
    }

    /// Whether this frame is a circle (see [`Frame::is_circle`]).
    #[inline(always)]
    pub fn circle(&self) -> bool {
        !self.circle_dilation.is_nan()
    }

    /// The rate at which a circle's radius `R (1 + eps)` grows, relative to itself:
    /// `eps_rate / (1 + eps)`, the diagonal of the grain's velocity gradient
    /// ([`Grain::velocity_gradient`] for equal strains); zero at the rigid level, whose rates
    /// are held at zero.
    #[inline(always)]
    pub fn circle_dilation_rate(grain: &Grain, level: ModelLevel) -> f64 {
        if level == ModelLevel::Rigid {
            0.0
        } else {
            grain.eps1_rate / (1.0 + grain.eps1)
        }
    }

    /// The frame of a grain at `level` that is a circle ([`Frame::is_circle`]): a circle of
    /// radius `R (1 + eps)`. Only the first line is written (see [`Frame`]).
    #[inline]
    pub fn write_circle(&mut self, grain: &Grain, level: ModelLevel, density: f64) {
        self.center = grain.center;
        self.bounding_radius = grain.radius * (1.0 + grain.eps1);
        self.mass = grain.mass(density);
        self.velocity = grain.velocity;
        self.omega = grain.omega;
        self.circle_dilation = Self::circle_dilation_rate(grain, level);
    }

    /// The contour polygon's shape. A circle's polygon, needed only where it meets a grain
    /// that is not a circle, is laid unrotated (node k at the angle `k dbeta` whatever theta):
    /// an inscribed polygon of a circle has no material orientation to follow, and so the
    /// frame needs no sine or cosine.
    #[inline]
    pub fn shape(&self) -> GrainShape {
        if self.circle() {
            let radius = self.bounding_radius;
            GrainShape {
                center: self.center,
                map: DMat2::from_diagonal(DVec2::splat(radius)),
                bounding_radius: radius,
                circle: true,
            }
        } else {
            GrainShape {
                center: self.center,
                map: self.map,
                bounding_radius: self.bounding_radius,
                circle: false,
            }
        }
    }

    /// The shape as a block of polygon contacts reads it, in place; a grain that is not a
    /// circle (a circle's map is not kept).
    #[inline(always)]
    pub fn lane_shape(&self) -> LaneShape<'_> {
        debug_assert!(!self.circle());
        // SAFETY: the frame is `repr(C)`, its first four fields four f64s (the centre is a
        // `repr(C)` `DVec2`): checked at compile time (the assertion before `impl Frame`).
        let center_and_radius = unsafe { &*(self as *const Frame).cast::<[f64; 4]>() };
        LaneShape {
            center_and_radius,
            map: self.map.as_ref(),
        }
    }

    /// Velocity gradient of the grain's affine motion: for a circle the rotation and dilation
    /// `omega J + d I` ([`circle_velocity_gradient`]).
    #[inline]
    pub fn velocity_gradient(&self) -> DMat2 {
        if self.circle() {
            let [x_axis, y_axis] = circle_velocity_gradient(self.omega, self.circle_dilation);
            DMat2::from_cols(DVec2::from(x_axis), DVec2::from(y_axis))
        } else {
            self.velocity_gradient
        }
    }

    /// Velocity of the material point of this grain at x.
    #[inline]
    pub fn velocity_at(&self, x: DVec2) -> DVec2 {
        self.velocity + self.velocity_gradient() * (x - self.center)
    }
}

/// The velocity gradient `omega J + d I` of a circle that spins at `omega` and dilates at `d`
/// ([`Frame::circle_dilation_rate`]), by columns: off the diagonal `QUARTER_TURN`'s entries
/// times omega, on it d (J's diagonal is zero). For a circle's frame
/// ([`Frame::velocity_gradient`]) and its [lanes](crate::lanes) ([`circle_velocity_at`])
/// alike, so that the two give the same bits.
#[inline(always)]
pub(crate) fn circle_velocity_gradient<T: Real>(omega: T, dilation: T) -> [[T; 2]; 2] {
    const { assert!(QUARTER_TURN.x_axis.x == 0.0 && QUARTER_TURN.y_axis.y == 0.0) };
    let q = |entry: f64| T::splat(entry) * omega;
    [
        [dilation, q(QUARTER_TURN.x_axis.y)],
        [q(QUARTER_TURN.y_axis.x), dilation],
    ]
}

/// Velocity of the point at `offset` from a circle's centre, `v + (omega J + d I) offset`,
/// for [lanes](crate::lanes) of circles: the products of [`Frame::velocity_at`] for a circle
/// ([`circle_velocity_gradient`] times the offset, as glam's product orders them), zeros
/// included. `Frame::velocity_at` keeps glam's form: routed through this function it cost the
/// full level 36 instructions a grain-step (callgrind), for the same bits.
#[inline(always)]
pub(crate) fn circle_velocity_at<T: Real>(
    velocity: [T; 2],
    omega: T,
    dilation: T,
    offset: [T; 2],
) -> [T; 2] {
    let [[xx, xy], [yx, yy]] = circle_velocity_gradient(omega, dilation);
    [
        velocity[0] + (xx * offset[0] + yx * offset[1]),
        velocity[1] + (xy * offset[0] + yy * offset[1]),
    ]
}

/// What the pair pass carries of a candidate pair to the next step, whether it touches or not.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PairState {
    /// Where this pair's chains were: the next step's search starts there.
    pub hint: PairHint,
    /// The tangential spring's force (SPEC §13), carried to the next step while the contact
    /// stays closed; zero while the pair is open.
    pub tangential_history: f64,
}

/// What the last step measured of a contact besides its [`PairContact`] (see
/// [`World::contacts`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ContactMeasures {
    /// The contact's length `L_c`.
    pub contact_length: f64,
}

/// A contact of the last step between the two grains of a candidate pair: what the grain pass
/// reads, in one aligned cache line.
///
/// Only the pairs in contact have one written (see [`World::contacts`]): an open candidate
/// costs its step a flag and its [`PairState`], not a record (issue #16: a loose packing's step
/// misses the cache a quarter less often than when a 112-byte record was rewritten and read
/// back for every candidate; docs/performance.md).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[repr(C, align(64))]
pub struct PairContact {
    /// Normal from the pair's first grain towards its second.
    pub normal: DVec2,
    /// Total normal force (<= 0: repulsive); the force on the first grain is `force * normal`.
    pub force: f64,
    /// Tangential force on the first grain along `t = perp(normal)` (SPEC §13; zero without
    /// friction); the force on the first grain is `force * normal + tangential_force * t`.
    pub tangential_force: f64,
    pub point: DVec2,
    /// The areas of the two grains' caps cut off by the contact (`S_j` of SPEC §5).
    pub cap_area_first: f64,
    pub cap_area_second: f64,
}

// The pair pass writes a block's records as two rows of four words each (`PolygonsAhead::
// write_records_avx`): normal, force, tangential force; point, cap areas.
const _: () = {
    use std::mem::{offset_of, size_of};
    assert!(size_of::<DVec2>() == 16 && size_of::<PairContact>() == 64);
    assert!(offset_of!(PairContact, normal) == 0 && offset_of!(PairContact, force) == 16);
    assert!(offset_of!(PairContact, tangential_force) == 24);
    assert!(offset_of!(PairContact, point) == 32 && offset_of!(PairContact, cap_area_first) == 48);
    assert!(offset_of!(PairContact, cap_area_second) == 56);
};

impl PairContact {
    /// The contact force on the pair's first grain (on the second: its opposite).
    #[inline]
    pub fn force_on_first(&self) -> DVec2 {
        let normal = self.normal_force_on_first();
        // Frictionless contacts keep the sums of before friction existed, signed zeros included.
        if self.tangential_force == 0.0 {
            normal
        } else {
            normal + self.tangential_force * self.normal.perp()
        }
    }

    /// The normal part of the force on the first grain: all of it without friction.
    #[inline]
    pub fn normal_force_on_first(&self) -> DVec2 {
        self.force * self.normal
    }

    /// [`force_on_first`](Self::force_on_first) in a pass that knows whether pairs have
    /// friction (`FRICTIONAL`): without it the tangential force is +0 and the normal part is
    /// the whole force, bit for bit, without the test.
    #[inline(always)]
    pub fn force_on_first_in<const FRICTIONAL: bool>(&self) -> DVec2 {
        if FRICTIONAL {
            self.force_on_first()
        } else {
            self.normal_force_on_first()
        }
    }
}

/// Per-grain quantities of the last step, kept for output.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
// Fields in this order, with no padding: the grain pass writes blocks of records from lanes
// (`grain_block`).
#[repr(C)]
pub struct GrainStress {
    /// Love–Weber stress of the contact forces, global frame (xx, yy, xy), tension positive.
    pub external: [f64; 3],
    /// Constitutive principal stresses (sigma_1, sigma_2) along (e1, e2).
    pub principal: [f64; 2],
    /// Area lost to contacts, `sum_j S_j`.
    pub lost_area: f64,
    /// Number of grain–grain contacts.
    pub contacts: u32,
    pub wall_contacts: u32,
}

impl GrainStress {
    /// Mean of the Love–Weber stress, tension positive.
    pub fn mean_external(&self) -> f64 {
        0.5 * (self.external[0] + self.external[1])
    }
}

/// Totals of one step.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepTotals {
    /// Normal force that the grains exert on each wall, compression positive.
    pub wall_force: [f64; MAX_WALLS],
    /// Sum of current grain areas `pi R^2 (1+eps1)(1+eps2) - sum S_j`.
    pub grain_area: f64,
    pub elastic_energy: f64,
    /// Active grain–grain contacts (each counted once).
    pub contacts: u64,
    /// Contacts whose law denominator was held at its floor this step.
    pub capped_contacts: u64,
    /// Grains at each level (Rigid, Volumetric, Full) for the next step.
    pub level_counts: [u64; 3],
    /// Periodic cell only: the contacts' stress over the cell, `(1/A) sum sym(f_i ⊗ d_ij)`
    /// (xx, yy, xy), tension positive (SPEC §14). Zero in a box.
    pub cell_stress: [f64; 3],
    /// Energy dissipated by Coulomb sliding over the step, grain–grain and grain–wall.
    pub friction_dissipation: f64,
    /// Contacts sliding at the Coulomb limit (grain–grain and grain–wall).
    pub sliding_contacts: u64,
    /// A multi-rate cycle only: the grains that took its two substeps (0 after a plain step).
    pub fast_grains: u64,
}

/// Wall-clock seconds spent in each pass of the step since the world was made, as LAMMPS
/// prints its "Pair / Neigh / Other" breakdown: where a run's time goes. A diagnostic only;
/// nothing in the physics reads it.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhaseTimes {
    /// The frames pass: shapes and velocity fields of the grains.
    pub frames: f64,
    /// The neighbour list: the rebuild test every step, and the rebuilds.
    pub neighbors: f64,
    /// The pair pass: contact geometry and forces of the candidate pairs.
    pub pairs: f64,
    /// The grain pass: sums of each grain's contacts, its wall contacts, stresses and update;
    /// and the walls' or the cell's motion.
    pub grains: f64,
}

impl PhaseTimes {
    pub fn total(&self) -> f64 {
        self.frames + self.neighbors + self.pairs + self.grains
    }
}

/// Each pass's seconds and share of the steps' time: "frames 0.31 s (6.6%), ...".
impl std::fmt::Display for PhaseTimes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let share = |t: f64| 100.0 * t / self.total().max(f64::MIN_POSITIVE);
        let passes = [
            ("frames", self.frames),
            ("neighbour list", self.neighbors),
            ("pairs", self.pairs),
            ("grains", self.grains),
        ];
        for (k, (name, seconds)) in passes.into_iter().enumerate() {
            let separator = if k == 0 { "" } else { ", " };
            write!(
                f,
                "{separator}{name} {seconds:.3} s ({:.1}%)",
                share(seconds)
            )?;
        }
        Ok(())
    }
}

/// Writes into `states` the state of each of `pairs` (a run of a new neighbour list) that
/// `old_pairs` also held, from `old_states`, and the default state of each new pair. Both lists
/// are sorted by (i, j), compared as `i << 32 | j` in one comparison.
fn carry_pair_states(
    old_pairs: &[[u32; 2]],
    old_states: &[PairState],
    pairs: &[[u32; 2]],
    states: &mut [MaybeUninit<PairState>],
) {
    assert!(old_states.len() == old_pairs.len() && states.len() == pairs.len());
    let key = |&[i, j]: &[u32; 2]| u64::from(i) << 32 | u64::from(j);
    let Some(first) = pairs.first() else {
        return;
    };
    let first = key(first);
    let mut k = old_pairs.partition_point(|old| key(old) < first);
    for (pair, state) in pairs.iter().zip(states) {
        let pair = key(pair);
        while k < old_pairs.len() && key(&old_pairs[k]) < pair {
            k += 1;
        }
        state.write(if k < old_pairs.len() && key(&old_pairs[k]) == pair {
            old_states[k]
        } else {
            PairState::default()
        });
    }
}

/// Sums over the grain–grain contacts of one step.
#[derive(Debug, Clone, Copy, Default)]
struct PairSums {
    /// Contacts whose law denominator was held at its floor.
    capped: u64,
    /// Periodic cell only: `sum sym(f_i ⊗ d_ij)` (xx, yy, xy).
    moment: [f64; 3],
    /// Energy dissipated by sliding.
    dissipation: f64,
    sliding: u64,
    failure: Option<Instability>,
}

/// The grains' kinetic figures after the last step (see [`World::kinetic`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct KineticTotals {
    /// Kinetic energy of the grains, their deformation's included ([`Grain::kinetic_energy`]).
    pub energy: f64,
    /// Periodic cell only: the kinetic stress `-(1/A) sum m v ⊗ v` of the grains' velocities
    /// relative to the affine field (xx, yy, xy), tension positive. Zero in a box.
    pub stress: [f64; 3],
}

/// What the last step was, for the sums of [`World::kinetic`].
#[derive(Debug, Clone, Copy, PartialEq)]
enum LastStep {
    /// None since the world was made (zero figures) or restored (the checkpoint's).
    None(KineticTotals),
    Plain,
    /// A multi-rate cycle: its slow grains were summed after its first half, its fast grains
    /// (`World::fast`) after its second.
    Cycle,
}

/// What a grain pass returns besides the step's totals.
#[derive(Debug, Default)]
struct PassEnds {
    /// Grain–grain contact ends (each contact counted by both grains).
    contact_ends: u64,
    /// Grains a periodic cell wrapped back into it.
    wrapped: u64,
}

#[derive(Debug, Clone, Copy, Default)]
struct ChunkSums {
    totals: StepTotals,
    contact_ends: u64,
    /// Grains a periodic cell wrapped back into it.
    wrapped: u64,
    /// Frames written as circles (see [`Frame::circle`]).
    circle_frames: usize,
    failure: Option<Instability>,
}

/// The frictional state of a world (SPEC §13): the spring force of each closed frictional
/// contact, which a checkpoint must keep for a bitwise resume, and the energy friction has
/// dissipated.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ContactHistory {
    /// `([i, j], F_t)` of each grain pair (i < j as listed) with a history, in pair order.
    pub pairs: Vec<([u32; 2], f64)>,
    /// `(grain, wall, F_t)` of each grain–wall contact with a history, in grain order.
    pub walls: Vec<(u32, u32, f64)>,
    /// Energy dissipated by Coulomb sliding since the run started.
    pub dissipated: f64,
}

impl ContactHistory {
    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty() && self.walls.is_empty() && self.dissipated.to_bits() == 0
    }
}

/// Everything that evolves: grains, walls, time; plus the per-step work arrays.
#[derive(Debug, Clone)]
pub struct World {
    pub params: Parameters,
    /// The contours the contacts see: polygons, or the exact ellipses (`resolution_deg = 0`).
    pub contours: Contours,
    /// Read through [`World::grains`], changed through [`World::grains_mut`] (which marks the
    /// frames stale).
    grains: Vec<Grain>,
    /// The box walls; in a periodic cell, the four virtual walls that drive the cell (see
    /// [`PeriodicBoundary`]), which meet no grain.
    pub walls: Vec<Wall>,
    /// The periodic cell in place of walls, if any.
    pub periodic: Option<PeriodicBoundary>,
    pub time: f64,
    pub step: u64,
    pub neighbors: NeighborList,
    /// Each grain's frame, with the broad phase's copies of its centre and reach in `centers`
    /// and `reach`.
    frames: Vec<Frame>,
    /// Each grain's principal direction (see [`Grain::principal_direction`]), written with its
    /// frame from the frame's own sines and cosines, for the next step's stresses; stale
    /// beside a circle, which is never at the full level (the one level that reads it).
    directions: Vec<DVec2>,
    /// Whether `frames`, `centers` and `reach` describe the grains as they are now: the grain
    /// pass writes each grain's next frame right after its update, so that the next step
    /// need not read every grain again in a pass of its own (issue #16: that pass was a tenth
    /// of a 10⁵-grain run); a periodic cell's carry and wrap move the frames' centres with the
    /// grains'. Anything else that changes the grains or their levels clears it (the density,
    /// the one parameter a frame reads, is fixed for the world's life).
    frames_current: bool,
    /// How many frames are circles (see [`Frame::circle`]), kept with the frames: when all
    /// are, the pair pass takes every block of pairs to the circle lanes without reading the
    /// two frames' flags of each pair first (issue #16: 63 instructions a grain-step of rigid
    /// discs under callgrind); when none is (a world at the full level), it chooses each
    /// pair's path without reading them either.
    circle_frames: usize,
    /// Per candidate pair (the index of [`NeighborList::pairs`]): what it carries between steps,
    pair_state: Vec<PairState>,
    /// its contact length `L_c` in the last step (zero where it was open): a row of its own,
    /// not a field of the state, so that a pair of rigid discs, whose state does not change,
    /// writes 8 bytes a step instead of writing back its state's line (issue #16),
    pair_length: Vec<f64>,
    /// whether it touched in the last step,
    pair_active: Vec<bool>,
    /// and its contact where it did (a stale record elsewhere: read through
    /// [`World::contacts`]).
    pair_contacts: Vec<PairContact>,
    /// Whether some pair may hold a tangential spring though the world has no friction between
    /// grains: after a checkpoint's history was restored into it, until its next step, which
    /// drops them (see [`pairs::PairPass::springs_to_drop`]).
    pair_springs_to_drop: bool,
    /// Where the pair pass's chunks end (see [`pair_chunk_ends`]), recomputed with the list.
    pair_chunk_ends: Vec<usize>,
    /// The least first grain of each grain chunk's pairs
    /// ([`sweep::earliest_first_grains`]), recomputed with the list.
    earliest_first_grains: Vec<u32>,
    /// How the sweep's tasks share the chunks, made with `earliest_first_grains` (and again
    /// for another number of threads).
    sweep_plan: SweepPlan,
    pub grain_stress: Vec<GrainStress>,
    pub totals: StepTotals,
    /// Each grain's model level (all at `params.level` unless the level is adaptive).
    levels: Vec<GrainLevel>,
    /// Per-step scratch for the broad phase (kept to avoid an allocation every step).
    centers: Vec<DVec2>,
    reach: Vec<f64>,
    /// The last list's pairs and states, kept for the next rebuild to write its own into
    /// (their contents are stale): a rebuild that allocated them anew had the pages of some
    /// 12 MB at 10⁵ grains faulted in again (with huge pages, a serial 1.5 ms a rebuild on
    /// two threads, the neighbour list's time 1.65 times as long).
    spare_pairs: Vec<[u32; 2]>,
    spare_pair_state: Vec<PairState>,
    /// Per-step scratch of a periodic cell: the image shift each grain was wrapped by (written
    /// by the grain pass; sized for every world, whose chunks carry it).
    wraps: Vec<[i64; 2]>,
    /// Energy dissipated by Coulomb sliding since the run started.
    pub friction_work: f64,
    /// The tangential spring force of each grain's contact with each wall (SPEC §13; zero when
    /// the contact is open), kept for every grain so that the grain pass can own its row.
    wall_history: Vec<[f64; MAX_WALLS]>,
    /// Where the steps' wall-clock time went (a diagnostic).
    pub phase_times: PhaseTimes,
    /// The step sweeps so far, and how their tasks shared the chunks.
    pub sweep_tally: SweepTally,
    /// An affine phase (see [`BoxCarry`]): each step moves every grain centre with the box,
    /// inside the grain pass. Set by the run loop before each step; not in a periodic cell,
    /// whose grains follow the cell anyway.
    pub affine_carry: bool,
    /// The substep of the coming multi-rate cycle, if the next step is one (see
    /// [`World::step`]); set with the adaptive time step.
    cycle_substep: Option<f64>,
    /// Per-cycle scratch: whether each grain takes the two substeps of the cycle (kept after
    /// it for [`World::kinetic`]).
    fast: Vec<bool>,
    last_step: LastStep,
    /// Whether the grain pass may take chunks of full-level grains by blocks in lanes (see
    /// [`grain_block`]); always, but for the tests that compare the two paths.
    grain_blocks: bool,
}

/// The homogeneous deformation that maps the box with corners `from_lo`, `from_hi` (lower left,
/// upper right) onto the box `to_lo`, `to_hi`, each axis on its own: the affine part of an
/// affine compression. Velocities are left alone (they stay peculiar).
#[derive(Debug, Clone, Copy)]
struct BoxCarry {
    from_lo: DVec2,
    to_lo: DVec2,
    scale: DVec2,
}

impl BoxCarry {
    fn new((from_lo, from_hi): (DVec2, DVec2), (to_lo, to_hi): (DVec2, DVec2)) -> Self {
        Self {
            from_lo,
            to_lo,
            scale: (to_hi - to_lo) / (from_hi - from_lo),
        }
    }

    /// Where the point `x` of the first box goes.
    #[inline]
    fn apply(&self, x: DVec2) -> DVec2 {
        self.to_lo + (x - self.from_lo) * self.scale
    }
}

impl World {
    /// Whether every frame is a circle (see [`World::circle_frames`]).
    fn frames_all_circles(&self) -> bool {
        self.circle_frames == self.frames.len()
    }

    /// Whether no frame is a circle.
    fn frames_no_circle(&self) -> bool {
        self.circle_frames == 0
    }

    pub fn new(params: Parameters, grains: Vec<Grain>, walls: Vec<Wall>) -> Self {
        assert!(walls.len() <= MAX_WALLS, "at most {MAX_WALLS} walls");
        let contours = Contours::new(params.resolution_deg);
        let mean_radius = grains.iter().map(|g| g.radius).sum::<f64>() / grains.len().max(1) as f64;
        let skin = params.skin_fraction * mean_radius;
        let n = grains.len();
        // Adaptive: every grain starts rigid (a generated sample is at rest without contacts).
        let start = if params.adaptive.is_some() {
            ModelLevel::Rigid
        } else {
            params.level
        };
        let mut world = Self {
            params,
            contours,
            grains,
            walls,
            periodic: None,
            time: 0.0,
            step: 0,
            neighbors: NeighborList::new(skin),
            frames: Vec::with_capacity(n),
            directions: Vec::with_capacity(n),
            frames_current: false,
            circle_frames: 0,
            pair_state: Vec::new(),
            pair_length: Vec::new(),
            pair_active: Vec::new(),
            pair_contacts: Vec::new(),
            pair_springs_to_drop: false,
            pair_chunk_ends: Vec::new(),
            earliest_first_grains: Vec::new(),
            sweep_plan: SweepPlan::default(),
            grain_stress: vec![GrainStress::default(); n],
            totals: StepTotals::default(),
            levels: vec![GrainLevel::new(start); n],
            centers: Vec::with_capacity(n),
            reach: Vec::with_capacity(n),
            spare_pairs: Vec::new(),
            spare_pair_state: Vec::new(),
            wraps: Vec::new(),
            friction_work: 0.0,
            wall_history: vec![[0.0; MAX_WALLS]; n],
            phase_times: PhaseTimes::default(),
            sweep_tally: SweepTally::default(),
            affine_carry: false,
            cycle_substep: None,
            fast: Vec::new(),
            last_step: LastStep::None(KineticTotals::default()),
            grain_blocks: true,
        };
        world.count_levels();
        world
    }

    /// The grains.
    pub fn grains(&self) -> &[Grain] {
        &self.grains
    }

    /// The grains, to change between steps (the next step recomputes their frames).
    pub fn grains_mut(&mut self) -> &mut [Grain] {
        self.frames_current = false;
        &mut self.grains
    }

    /// Each grain's model level and the steps it has spent there.
    pub fn levels(&self) -> &[GrainLevel] {
        &self.levels
    }

    /// Sets every grain's level (a resumed run); with the adaptive level the time step follows.
    pub fn set_levels(&mut self, levels: &[GrainLevel]) {
        assert_eq!(levels.len(), self.grains.len(), "one level per grain");
        self.levels.copy_from_slice(levels);
        self.frames_current = false;
        self.count_levels();
    }

    /// Recounts the grains at each level and sets the adaptive time step from the highest one.
    fn count_levels(&mut self) {
        let mut counts = [0; 3];
        for l in &self.levels {
            counts[l.level.index()] += 1;
        }
        self.totals.level_counts = counts;
        self.apply_adaptive_dt();
    }

    /// The adaptive time step: that of the highest level any grain is at; with multi-rate
    /// cycles, twice that while at least [`MULTI_RATE_MIN_RIGID_SHARE`] of the grains are
    /// rigid and the rigid level's own step allows it (the next step is then a cycle).
    fn apply_adaptive_dt(&mut self) {
        self.cycle_substep = None;
        if let Some(adaptive) = &self.params.adaptive {
            let counts = &self.totals.level_counts;
            let highest = (0..3).rev().find(|&k| counts[k] > 0).unwrap_or(0);
            let step = adaptive.dt[highest];
            let grains: u64 = counts.iter().sum();
            let cycle = adaptive.multi_rate
                && highest > 0
                && adaptive.dt[0] >= 2.0 * step
                && counts[0] as f64 >= MULTI_RATE_MIN_RIGID_SHARE * grains as f64
                // Frictionless grains in a box (the scenario refuses the rest).
                && self.periodic.is_none()
                && self.params.friction.is_none();
            if cycle {
                self.cycle_substep = Some(step);
                self.params.dt = 2.0 * step;
            } else {
                self.params.dt = step;
            }
        }
    }

    /// The substep of the next step if it is a multi-rate cycle ([`World::step`]); its
    /// `params.dt` is then twice that.
    pub fn cycle_substep(&self) -> Option<f64> {
        self.cycle_substep
    }

    /// Whether each grain took the two substeps of the last multi-rate cycle (empty before the
    /// first cycle).
    pub fn cycle_roles(&self) -> &[bool] {
        &self.fast
    }

    /// The periodic cell now, if the world has one.
    pub fn cell(&self) -> Option<PeriodicCell> {
        self.periodic.map(|p| p.cell(&self.walls))
    }

    /// Makes the world periodic: the walls become the virtual walls of the cell they bound.
    pub fn with_periodic(mut self, periodic: PeriodicBoundary) -> Self {
        periodic.orient_walls(&mut self.walls);
        self.periodic = Some(periodic);
        // A periodic cell takes no multi-rate cycles: a cycle planned for the box is undone.
        if self.cycle_substep.is_some() {
            self.apply_adaptive_dt();
        }
        self
    }

    /// The tangential history of the contacts after the last step (entries whose bit pattern
    /// is not +0.0).
    pub fn contact_history(&self) -> ContactHistory {
        let pairs = self
            .neighbors
            .pairs
            .iter()
            .zip(&self.pair_state)
            .filter(|(_, s)| s.tangential_history.to_bits() != 0)
            .map(|(&pair, s)| (pair, s.tangential_history))
            .collect();
        let mut walls = Vec::new();
        for (g, row) in self.wall_history.iter().enumerate() {
            for (w, &h) in row.iter().enumerate() {
                if h.to_bits() != 0 {
                    walls.push((g as u32, w as u32, h));
                }
            }
        }
        ContactHistory {
            pairs,
            walls,
            dissipated: self.friction_work,
        }
    }

    /// Restores the tangential history of a checkpoint (before the first step of a resumed
    /// run: the next neighbour-list build carries the pairs' history over, as it does between
    /// builds).
    pub fn restore_contact_history(&mut self, history: &ContactHistory) -> Result<(), String> {
        let n = self.grains.len() as u32;
        let sorted = history.pairs.windows(2).all(|w| w[0].0 < w[1].0);
        if !sorted {
            return Err("contact history pairs out of order".into());
        }
        if let Some(([i, j], _)) = history.pairs.iter().find(|([i, j], _)| i >= j || *j >= n) {
            return Err(format!(
                "contact history of the pair ({i}, {j}) with {n} grains"
            ));
        }
        if let Some((g, w, _)) = history
            .walls
            .iter()
            .find(|(g, w, _)| *g >= n || *w as usize >= self.walls.len())
        {
            return Err(format!(
                "contact history of grain {g} on wall {w} with {n} grains and {} walls",
                self.walls.len()
            ));
        }
        self.neighbors.pairs = history.pairs.iter().map(|(pair, _)| *pair).collect();
        self.pair_state = history
            .pairs
            .iter()
            .map(|&(_, h)| PairState {
                tangential_history: h,
                ..Default::default()
            })
            .collect();
        self.pair_length = vec![0.0; history.pairs.len()];
        self.pair_springs_to_drop =
            !self.params.frictional_pairs() && history.pairs.iter().any(|(_, h)| h.to_bits() != 0);
        self.pair_active = vec![false; history.pairs.len()];
        self.pair_contacts = vec![PairContact::default(); history.pairs.len()];
        self.neighbors.invalidate();
        self.wall_history = vec![[0.0; MAX_WALLS]; self.grains.len()];
        for &(g, w, h) in &history.walls {
            self.wall_history[g as usize][w as usize] = h;
        }
        self.friction_work = history.dissipated;
        Ok(())
    }

    /// Recomputes shapes and velocity fields (when stale) and the neighbour list for the
    /// current state; the list's check keeps `reserve` of every grain's budget for motion
    /// before the next check (see [`NeighborList::needs_rebuild_with_reserve`]).
    fn prepare(&mut self, reserve: f64) -> Result<(), Instability> {
        let start = Instant::now();
        // A grain added after construction gets an empty row of wall history.
        self.wall_history
            .resize(self.grains.len(), [0.0; MAX_WALLS]);
        let density = self.params.material.density;
        let n = self.grains.len();
        if !self.frames_current || self.frames.len() != n {
            self.frames.resize(n, Frame::default());
            self.directions.resize(n, DVec2::ZERO);
            self.centers.resize(n, DVec2::ZERO);
            self.reach.resize(n, 0.0);
            // One parallel pass writes the frames and, beside them, the compact centres and
            // reaches of the broad phase: they were two serial passes over the frames, which
            // the second thread could not share.
            self.frames
                .par_iter_mut()
                .zip(self.directions.par_iter_mut())
                .zip(self.centers.par_iter_mut())
                .zip(self.reach.par_iter_mut())
                .zip(self.grains.par_iter().zip(self.levels.par_iter()))
                .with_min_len(GRAIN_CHUNK)
                .for_each(|((((frame, direction), center), reach), (g, level))| {
                    frame.write(direction, g, level.level, density);
                    *center = frame.center;
                    *reach = frame.bounding_radius;
                });
            self.circle_frames = self
                .frames
                .par_iter()
                .filter(|frame| frame.circle())
                .count();
            self.frames_current = true;
        }
        let frames_done = Instant::now();
        self.phase_times.frames += (frames_done - start).as_secs_f64();
        let (centers, reach) = (&self.centers, &self.reach);
        let cell = self.cell();
        // The widest skin the boundary allows a new list (see `adapt_skin`).
        let mut room = f64::INFINITY;
        let rebuild = match &cell {
            Some(cell) => {
                // Checked every step: between rebuilds the cell keeps shrinking.
                let max_reach = crate::geometry::broadphase::largest_reach(reach);
                let mut range = 2.0 * max_reach + self.neighbors.skin;
                if cell.check_range(range).is_err()
                    && self.neighbors.skin > self.neighbors.base_skin()
                {
                    // A skin widened when the cell was wider: back to the list's own.
                    self.neighbors.reset_skin();
                    range = 2.0 * max_reach + self.neighbors.skin;
                }
                if cell.check_range(range).is_err() {
                    return Err(Instability::CellTooNarrow {
                        step: self.step,
                        width: cell.widths()[0].min(cell.widths()[1]),
                        range,
                    });
                }
                // A widened range at most half what the cell takes, so that it may shrink a
                // while before the skin must narrow again.
                let width = cell.widths()[0].min(cell.widths()[1]);
                room = 0.25 * width - 2.0 * max_reach;
                self.neighbors
                    .needs_rebuild_periodic(centers, reach, cell, max_reach)
            }
            None => self
                .neighbors
                .needs_rebuild_with_reserve(centers, reach, reserve),
        };
        if rebuild {
            if self.neighbors.is_built_for(n) {
                self.neighbors.adapt_skin(room);
            }
            let old_pairs = std::mem::replace(
                &mut self.neighbors.pairs,
                std::mem::take(&mut self.spare_pairs),
            );
            // Only a pair's search hint and tangential spring carry over (its state); the
            // contact records of the old list are left to be overwritten.
            let old_state = std::mem::take(&mut self.pair_state);
            match &cell {
                Some(cell) => self.neighbors.build_periodic(centers, reach, cell),
                None => self.neighbors.build(centers, reach),
            }
            // Pair indices change with the list: carry each surviving pair's state over.
            // Both lists are sorted by (i, j), so the new list merges with the old one: each
            // parallel task finds its first pair by bisection, then walks both lists in step.
            // The states are written in place, in parallel: a vector filled with defaults
            // first was a serial pass over every pair.
            let pairs = &self.neighbors.pairs;
            let mut state = std::mem::take(&mut self.spare_pair_state);
            clear_with_room(&mut state, pairs.len());
            state.spare_capacity_mut()[..pairs.len()]
                .par_chunks_mut(PAIR_CHUNK)
                .zip(pairs.par_chunks(PAIR_CHUNK))
                .for_each(|(states, pairs)| {
                    carry_pair_states(&old_pairs, &old_state, pairs, states)
                });
            // SAFETY: the tasks above wrote each of the first `pairs.len()` entries, one for
            // each new pair.
            unsafe { state.set_len(pairs.len()) };
            self.pair_state = state;
            (self.spare_pairs, self.spare_pair_state) = (old_pairs, old_state);
            // The pair pass writes every flag and length, and a record wherever a flag is set,
            // before anything reads them.
            self.pair_active.resize(pairs.len(), false);
            self.pair_length.resize(pairs.len(), 0.0);
            self.pair_contacts
                .resize(pairs.len(), PairContact::default());
            self.pair_chunk_ends = pair_chunk_ends(pairs, n);
            self.earliest_first_grains = sweep::earliest_first_grains(&self.neighbors, n);
            // Made again for the new list before the sweep.
            self.sweep_plan = SweepPlan::default();
        } else {
            self.neighbors.kept();
        }
        self.phase_times.neighbors += frames_done.elapsed().as_secs_f64();
        Ok(())
    }

    /// The step's pair pass and grain pass, in one sweep over the chunks ([`sweep`]): the
    /// contact geometry and forces of every candidate pair (in the second half of a multi-rate
    /// cycle, `cycle == Some(true)`, of the pairs of two fast grains only; the others keep the
    /// first half's records), and each grain's update over `dt`. `pair_cell`: in a periodic
    /// cell, the cell where the pairs meet and its velocity gradient; `cell_motion`: its
    /// motion over the step, with which the grain pass carries and wraps the grains. Returns
    /// the pairs' sums and each grain chunk's, in chunk order ([`World::add_grain_sums`]). A
    /// failed pair leaves some grains updated and others not, each with its frame.
    fn pair_and_grain_passes(
        &mut self,
        dt: f64,
        cycle: Option<bool>,
        pair_cell: Option<(PeriodicCell, DMat2)>,
        carried_box: Option<((DVec2, DVec2), (DVec2, DVec2))>,
        cell_motion: Option<CellMotion>,
    ) -> Result<(PairSums, sweep::SweepResults), Instability> {
        let start = Instant::now();
        // The wraps are written by the pass in a periodic cell; elsewhere they are a scratch
        // row the chunks carry unread.
        self.wraps.resize(self.grains.len(), [0, 0]);
        let every_frame_a_circle = self.frames_all_circles();
        let springs_to_drop = self.pair_springs_to_drop;
        let no_frame_a_circle = self.frames_no_circle();
        let step = self.step;
        // Full-level and rigid grains are in a world at either level or with adaptive levels.
        let blocks = self.grain_blocks
            && cycle.is_none()
            && (self.params.level != ModelLevel::Volumetric || self.params.adaptive.is_some())
            && grain_block::blocks_available();
        let World {
            params,
            contours,
            neighbors,
            walls,
            fast,
            grains,
            grain_stress,
            levels,
            wall_history,
            frames,
            directions,
            centers,
            reach,
            wraps,
            pair_state,
            pair_length,
            pair_active,
            pair_contacts,
            pair_chunk_ends,
            earliest_first_grains,
            sweep_plan,
            ..
        } = self;
        let (params, contours, neighbors, fast) = (&*params, &*contours, &*neighbors, &*fast);
        // The cell at the start of the step (where the pairs met), before `cell_motion`.
        let cell = cell_motion.map(|motion| motion.before);
        // A periodic cell's virtual walls meet no grain.
        let walls: &[Wall] = if cell.is_some() { &[] } else { walls };
        let wall_friction = params
            .friction
            .as_ref()
            .map_or([0.0; MAX_WALLS], |f| f.walls);
        sweep_plan.refresh(earliest_first_grains);
        let rows = sweep::SweepRows {
            grains: GrainChunk {
                grains,
                stresses: grain_stress,
                levels,
                wall_histories: wall_history,
                frames,
                directions,
                centers,
                reach,
                wraps,
            },
            pair_states: pair_state,
            pair_lengths: pair_length,
            pair_active,
            pair_contacts,
            pair_chunk_ends,
            earliest_first_grains,
            plan: sweep_plan,
        };
        let swept = sweep::sweep(rows, |views| {
            let pair_pass = pairs::PairPass {
                params,
                contours,
                frames: views.frames,
                pairs: &neighbors.pairs,
                images: &neighbors.images,
                step,
                periodic: pair_cell,
                only_fast: (cycle == Some(true)).then_some(fast.as_slice()),
                every_frame_a_circle,
                no_frame_a_circle,
                springs_to_drop,
            };
            let grain_pass = GrainPass {
                params,
                contours,
                neighbors,
                pair_active: views.pair_active,
                pair_contacts: views.pair_contacts,
                frictional_pairs: params.frictional_pairs(),
                cell,
                walls,
                // A frictional wall drops the springs of the grains it no longer touches.
                wall_springs: (0..walls.len())
                    .filter(|&w| wall_friction[w] > 0.0)
                    .fold(0, |bits, w| bits | (1 << w)),
                // The affine carry is applied to each grain right after its update, where the
                // pass has the grain at hand (a pass of its own after the step cost some 4% of
                // a 10⁵-grain run).
                carry: carried_box.map(|(from, to)| BoxCarry::new(from, to)),
                cell_motion,
                step,
                dt,
                cycle: cycle.map(|second| CycleHalf { fast, second }),
                blocks,
            };
            (pair_pass, grain_pass)
        });
        let seconds = start.elapsed().as_secs_f64();
        self.phase_times.pairs += swept.pair_share * seconds;
        self.phase_times.grains += (1.0 - swept.pair_share) * seconds;
        self.sweep_tally.add(&swept);
        let mut totals = PairSums::default();
        for sums in swept.pair_sums() {
            if let Some(f) = sums.failure {
                // Some chunks' grains were updated and given their frames, others not: the
                // frames are written afresh from the grains before another step.
                self.frames_current = false;
                return Err(f);
            }
            totals.capped += sums.capped;
            for (sum, x) in totals.moment.iter_mut().zip(sums.moment) {
                *sum += x;
            }
            totals.dissipation += sums.dissipation;
            totals.sliding += sums.sliding;
        }
        Ok((totals, swept))
    }

    /// Advances the world by one time step: a plain step of `params.dt`, or a multi-rate cycle.
    ///
    /// A cycle ([`Adaptive::multi_rate`](parameters::Adaptive::multi_rate)) lasts `params.dt`
    /// = 2 h, h the deforming levels' step. The grains that deform, and the rigid grains whose
    /// bounding circles come within reach of one of theirs over the cycle (fast grains), take
    /// two steps of h; the other rigid grains (slow) take one step of 2 h, in the first half,
    /// with the forces at the cycle's start. The second half recomputes only the pairs of two
    /// fast grains: a fast grain meets its slow neighbours with the first half's force in
    /// both halves, so each pair's impulse over the cycle is the same on both sides. The walls
    /// and the affine carry move by h in each half, so that every grain follows the box as in
    /// plain steps. The cycle's wall forces are the mean over its halves.
    pub fn step(&mut self) -> Result<&StepTotals, Instability> {
        match self.cycle_substep {
            Some(substep) => self.step_cycle(substep)?,
            None => self.step_plain()?,
        }
        // Every pair was recorded, and dropped any spring a frictionless world held.
        self.pair_springs_to_drop = false;
        // The next step's time step, from the levels the grains chose (a fixed-order sum).
        let start = Instant::now();
        self.apply_adaptive_dt();
        self.phase_times.grains += start.elapsed().as_secs_f64();
        Ok(&self.totals)
    }

    fn step_plain(&mut self) -> Result<(), Instability> {
        self.prepare(0.0)?;
        let dt = self.params.dt;
        let carried_box = self.carried_box(dt);
        let pair_cell = self.pair_cell();
        // A periodic cell moves first: the grain pass carries and wraps each grain with it.
        // (Its motion depends only on the walls' velocities, which the loading set before the
        // step; the pairs meet in the cell at the step's start. A step that fails leaves the
        // cell moved.)
        let cell_motion = self.periodic.as_mut().map(|periodic| {
            let area_before = periodic.cell(&self.walls).area();
            (periodic.advance(&mut self.walls, dt), area_before)
        });
        let (pair_sums, swept) = self.pair_and_grain_passes(
            dt,
            None,
            pair_cell,
            carried_box,
            cell_motion.map(|(motion, _)| motion),
        )?;
        let grains_start = Instant::now();
        let mut totals = StepTotals {
            capped_contacts: pair_sums.capped,
            friction_dissipation: pair_sums.dissipation,
            sliding_contacts: pair_sums.sliding,
            ..Default::default()
        };
        let ends = self.add_grain_sums(swept.grain_sums(), &mut totals)?;
        totals.contacts = ends.contact_ends / 2;
        match cell_motion {
            Some((motion, area_before)) => {
                totals.cell_stress = pair_sums.moment.map(|m| m / area_before);
                self.follow_cell(&motion, ends.wrapped);
            }
            None => self.move_walls(dt, carried_box),
        }
        self.time += dt;
        self.step += 1;
        if self.params.friction.is_some() {
            self.friction_work += totals.friction_dissipation;
        }
        self.totals = totals;
        self.last_step = LastStep::Plain;
        self.phase_times.grains += grains_start.elapsed().as_secs_f64();
        Ok(())
    }

    /// A multi-rate cycle of two substeps `substep` (see [`World::step`]).
    fn step_cycle(&mut self, substep: f64) -> Result<(), Instability> {
        let start = Instant::now();
        let reserve = self.cycle_reserve(substep);
        self.phase_times.neighbors += start.elapsed().as_secs_f64();
        // Every pair that may close within the cycle is listed, and stays listed through its
        // second half.
        self.prepare(0.5 * reserve)?;
        let roles_start = Instant::now();
        let fast_grains = self.assign_cycle_roles(reserve);
        self.phase_times.neighbors += roles_start.elapsed().as_secs_f64();

        let mut totals = StepTotals::default();
        let mut ends = PassEnds::default();
        for second in [false, true] {
            let carried_box = self.carried_box(substep);
            let pair_cell = self.pair_cell();
            let (pair_sums, swept) =
                self.pair_and_grain_passes(substep, Some(second), pair_cell, carried_box, None)?;
            let grains_start = Instant::now();
            if !second {
                // The contacts capped at the cycle's start.
                totals.capped_contacts = pair_sums.capped;
            }
            let half = self.add_grain_sums(swept.grain_sums(), &mut totals)?;
            ends.contact_ends += half.contact_ends;
            self.move_walls(substep, carried_box);
            self.phase_times.grains += grains_start.elapsed().as_secs_f64();
        }
        totals.contacts = ends.contact_ends / 2;
        totals.fast_grains = fast_grains;
        self.time += 2.0 * substep;
        self.step += 1;
        self.totals = totals;
        self.last_step = LastStep::Cycle;
        Ok(())
    }

    /// How close (between bounding circles) a rigid grain must be to a deforming one to take
    /// the two substeps of a cycle: twice what any pair can close over the cycle, from the
    /// fastest grain's speed and growth and the box's deformation.
    fn cycle_reserve(&self, substep: f64) -> f64 {
        let (speed_squared, growth, reach) = self
            .grains
            .par_chunks(GRAIN_CHUNK)
            .map(|chunk| {
                let mut bound = (0.0f64, 0.0f64, 0.0f64);
                for g in chunk {
                    bound.0 = bound.0.max(g.velocity.length_squared());
                    bound.1 = bound
                        .1
                        .max(g.radius * g.eps1_rate.abs().max(g.eps2_rate.abs()));
                    bound.2 = bound.2.max(g.radius * (1.0 + g.eps1.max(g.eps2).max(0.0)));
                }
                bound
            })
            .reduce(
                || (0.0, 0.0, 0.0),
                |a, b| (a.0.max(b.0), a.1.max(b.1), a.2.max(b.2)),
            );
        let cycle = 2.0 * substep;
        // One grain's motion plus growth over the cycle; a pair closes by at most twice that.
        let motion = cycle * (speed_squared.sqrt() + growth);
        let closing = 2.0 * motion;
        let strain = match self.carried_box(cycle) {
            Some(((lo, hi), (lo_after, hi_after))) => ((hi_after - lo_after) / (hi - lo)
                - DVec2::ONE)
                .abs()
                .max_element(),
            None => 0.0,
        };
        2.0 * (closing + strain * (2.0 * reach + closing))
    }

    /// Each grain's role in the coming cycle: fast when it deforms, or when its bounding
    /// circle lies within `reserve` of a deforming grain's. Every such pair is listed (the
    /// list was checked with half that reserve), so the roles do not depend on when the list
    /// was built. Returns how many grains are fast.
    fn assign_cycle_roles(&mut self, reserve: f64) -> u64 {
        let (levels, neighbors) = (&self.levels, &self.neighbors);
        let (centers, reach) = (&self.centers, &self.reach);
        let deforming = |g: usize| levels[g].level != ModelLevel::Rigid;
        let near = |g: usize, other: usize| {
            deforming(other)
                && centers[g].distance(centers[other]) - reach[g] - reach[other] < reserve
        };
        self.fast.resize(self.grains.len(), false);
        self.fast
            .par_chunks_mut(GRAIN_CHUNK)
            .enumerate()
            .map(|(chunk, fast)| {
                let mut count = 0;
                for (k, fast) in fast.iter_mut().enumerate() {
                    let g = chunk * GRAIN_CHUNK + k;
                    *fast = deforming(g)
                        || neighbors
                            .second_ends_of(g)
                            .iter()
                            .any(|&p| near(g, neighbors.pairs[p as usize][0] as usize))
                        || neighbors
                            .first_ends_of(g)
                            .any(|p| near(g, neighbors.pairs[p][1] as usize));
                    count += *fast as u64;
                }
                count
            })
            .sum()
    }

    /// In a periodic cell, the cell where the pairs meet (at the start of the step, before it
    /// moves) and its velocity gradient.
    fn pair_cell(&self) -> Option<(PeriodicCell, DMat2)> {
        self.periodic
            .map(|p| (p.cell(&self.walls), p.velocity_gradient(&self.walls)))
    }

    /// The affine carry over `dt` in an affine phase (not in a periodic cell): from the box now
    /// to the box after the walls' move.
    fn carried_box(&self, dt: f64) -> Option<((DVec2, DVec2), (DVec2, DVec2))> {
        (self.affine_carry && self.periodic.is_none())
            .then(|| (box_corners(&self.walls), box_corners_after(&self.walls, dt)))
    }

    /// The walls' move over `dt`, after the grains were carried by `carried_box`.
    fn move_walls(&mut self, dt: f64, carried_box: Option<((DVec2, DVec2), (DVec2, DVec2))>) {
        if let Some((from, to)) = carried_box {
            self.neighbors.follow_affine(from, to);
        }
        for wall in &mut self.walls {
            wall.point = wall.point_after(dt);
        }
    }

    /// Adds the grain pass's chunk sums (in chunk order) to `totals`; returns its ends, or
    /// the first chunk's failure.
    fn add_grain_sums<'a>(
        &mut self,
        chunk_sums: impl Iterator<Item = &'a ChunkSums> + Clone,
        totals: &mut StepTotals,
    ) -> Result<PassEnds, Instability> {
        // Every grain was updated and given its next frame, failed steps included (a grain's
        // failure is reported after the pass).
        self.frames_current = true;
        self.circle_frames = chunk_sums.clone().map(|sums| sums.circle_frames).sum();

        let mut ends = PassEnds::default();
        for sums in chunk_sums {
            if let Some(f) = sums.failure {
                return Err(f);
            }
            for w in 0..MAX_WALLS {
                totals.wall_force[w] += sums.totals.wall_force[w];
            }
            totals.grain_area += sums.totals.grain_area;
            totals.elastic_energy += sums.totals.elastic_energy;
            totals.capped_contacts += sums.totals.capped_contacts;
            totals.friction_dissipation += sums.totals.friction_dissipation;
            totals.sliding_contacts += sums.totals.sliding_contacts;
            for l in 0..3 {
                totals.level_counts[l] += sums.totals.level_counts[l];
            }
            ends.contact_ends += sums.contact_ends;
            ends.wrapped += sums.wrapped;
        }
        Ok(ends)
    }

    /// The neighbour list after a periodic cell's step, whose grain pass carried and wrapped
    /// the grains (`wrapped` of them took an image shift, written to `self.wraps`): it keeps
    /// the pairs' images, or is rebuilt after a remap.
    fn follow_cell(&mut self, motion: &CellMotion, wrapped: u64) {
        if motion.remapped {
            self.neighbors.invalidate();
        } else if wrapped > 0 {
            self.neighbors.follow_wraps(&self.wraps);
        }
    }

    /// The contacts of the last step between grains, in pair order: the pair `[i, j]`, its
    /// contact, and what else the step measured of it (its length).
    pub fn contacts(&self) -> impl Iterator<Item = ([u32; 2], &PairContact, ContactMeasures)> + '_ {
        self.neighbors
            .pairs
            .iter()
            .zip(&self.pair_active)
            .zip(self.pair_contacts.iter().zip(&self.pair_length))
            .filter(|((_, active), _)| **active)
            .map(|((pair, _), (contact, &contact_length))| {
                (*pair, contact, ContactMeasures { contact_length })
            })
    }

    /// The grains' kinetic energy and (in a periodic cell) kinetic stress after the last step.
    ///
    /// Only outputs read them, so the grain pass does not sum them every step (issue #16: they
    /// were 48 of the 1,178 instructions a grain-step of a rigid step on LAMMPS's packing).
    /// They are functions of the grains as the step left them, summed here in the grain pass's
    /// order (in chunks of [`GRAIN_CHUNK`] grains, a multi-rate cycle's slow grains before its
    /// fast ones): the bits the pass's sums had. Before any step, the figures the world was
    /// made or restored with.
    pub fn kinetic(&self) -> KineticTotals {
        let cycle = match self.last_step {
            LastStep::None(figures) => return figures,
            LastStep::Plain => false,
            LastStep::Cycle => true,
        };
        let density = self.params.material.density;
        let scale = self.params.deformation_mass_scale;
        // The sums of the pass's chunks, of the grains `counted` takes.
        let chunk_sums = |counted: &(dyn Fn(usize) -> bool + Sync)| -> Vec<(f64, [f64; 3])> {
            self.grains
                .par_chunks(GRAIN_CHUNK)
                .enumerate()
                .map(|(chunk, grains)| {
                    let mut energy = 0.0;
                    let mut flux = [0.0; 3];
                    for (k, grain) in grains.iter().enumerate() {
                        if !counted(chunk * GRAIN_CHUNK + k) {
                            continue;
                        }
                        let mass = grain.mass(density);
                        energy += grain.kinetic_energy_of_mass(mass, scale);
                        let share = symmetric_dyad(mass * grain.velocity, grain.velocity);
                        for (sum, x) in flux.iter_mut().zip(share) {
                            *sum += x;
                        }
                    }
                    (energy, flux)
                })
                .collect()
        };
        let mut figures = KineticTotals::default();
        let mut momentum_flux = [0.0; 3];
        let mut add = |sums: Vec<(f64, [f64; 3])>| {
            for (energy, flux) in sums {
                figures.energy += energy;
                for (sum, x) in momentum_flux.iter_mut().zip(flux) {
                    *sum += x;
                }
            }
        };
        if cycle {
            // A cycle runs in a box (its stress stays zero).
            add(chunk_sums(&|g| !self.fast[g]));
            add(chunk_sums(&|g| self.fast[g]));
        } else {
            add(chunk_sums(&|_| true));
            if let Some(periodic) = &self.periodic {
                let area = periodic.cell(&self.walls).area();
                figures.stress = momentum_flux.map(|m| -m / area);
            }
        }
        figures
    }

    /// Sets the figures [`kinetic`](Self::kinetic) gives until the next step: a checkpoint's,
    /// for the world it restores.
    pub fn restore_kinetic(&mut self, figures: KineticTotals) {
        self.last_step = LastStep::None(figures);
    }

    /// Coordination numbers (z, z_nr, z_nr3) of the last step: `2C/N` over grain–grain
    /// contacts; the same over the grains with at least 2 grain contacts and the contacts between
    /// them; and the same without the rattlers of the 3-contact rule
    /// ([`coordination_without_rattlers`]).
    pub fn coordination(&self) -> (f64, f64, f64) {
        let (z, z_nr) = self.coordination_without_z_nr3();
        let wall_contacts: Vec<u32> = self.grain_stress.iter().map(|s| s.wall_contacts).collect();
        let pairs: Vec<(u32, u32)> = self
            .neighbors
            .pairs
            .iter()
            .zip(&self.pair_active)
            .filter(|(_, active)| **active)
            .map(|([i, j], _)| (*i, *j))
            .collect();
        let z_nr3 = coordination_without_rattlers(&wall_contacts, &pairs, 3);
        (z, z_nr, z_nr3)
    }

    /// `(z, z_nr)` of [`coordination`](Self::coordination), without the rattler removal.
    pub fn coordination_without_z_nr3(&self) -> (f64, f64) {
        let n = self.grains.len().max(1) as f64;
        let z = 2.0 * self.totals.contacts as f64 / n;
        let carrying = |g: u32| self.grain_stress[g as usize].contacts >= 2;
        let grains_nr = self.grain_stress.iter().filter(|s| s.contacts >= 2).count();
        let contacts_nr = self
            .neighbors
            .pairs
            .iter()
            .zip(&self.pair_active)
            .filter(|([i, j], active)| **active && carrying(*i) && carrying(*j))
            .count();
        let z_nr = if grains_nr > 0 {
            2.0 * contacts_nr as f64 / grains_nr as f64
        } else {
            0.0
        };
        (z, z_nr)
    }
}

/// Where the pair pass's chunks end, one chunk per grain chunk ([`GRAIN_CHUNK`]): chunk c
/// holds the pairs whose first grain lies in grain chunk c (the list is sorted by first grain).
///
/// The pair pass sums each chunk's contacts (the dissipation, a periodic cell's stress) in
/// pair order and then the chunks in order. Chunks of a fixed number of pairs would group
/// those sums by how many open candidates the list holds, so their last bits would follow
/// when the list was built (a resumed run rebuilds it at once, a thinner skin more often).
/// Aligned with the grains, each chunk sums the same contacts in the same order whatever else
/// the list holds.
fn pair_chunk_ends(pairs: &[[u32; 2]], grains: usize) -> Vec<usize> {
    let ends: Vec<usize> = (0..grains.div_ceil(GRAIN_CHUNK))
        .map(|chunk| pairs.partition_point(|pair| (pair[0] as usize) < (chunk + 1) * GRAIN_CHUNK))
        .collect();
    debug_assert!(
        ends.last().is_none_or(|&end| end == pairs.len()),
        "every pair's first grain is a grain"
    );
    ends
}

/// Asks the processor to bring the cache line of `address` in: a hint, whatever the address
/// (a prefetch neither faults nor changes anything but the caches).
#[inline(always)]
fn prefetch_address(address: *const u8) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch has no architectural effect, at any address.
    unsafe {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        _mm_prefetch::<_MM_HINT_T0>(address.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = address;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rebuilt_list_carries_the_state_of_each_pair_it_kept_and_only_those() {
        // Expectation: each pair of the new list has the state the old list held for the same
        // (i, j), and the default state where the old list had no such pair, whatever runs the
        // new list is cut into (pairs that share i and differ in j, and the reverse, included).
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = |bound: u32| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % u64::from(bound)) as u32
        };
        let mut list = |count: usize| {
            let mut pairs: Vec<[u32; 2]> = (0..count)
                .map(|_| {
                    let i = next(60);
                    [i, i + 1 + next(8)]
                })
                .collect();
            pairs.sort_unstable();
            pairs.dedup();
            pairs
        };
        let old_pairs = list(300);
        let new_pairs = list(300);
        let old_states: Vec<PairState> = (0..old_pairs.len())
            .map(|k| PairState {
                tangential_history: k as f64 + 1.0,
                ..Default::default()
            })
            .collect();
        let kept = new_pairs.iter().filter(|p| old_pairs.contains(p)).count();
        assert!(
            kept > 20 && kept < new_pairs.len() - 20,
            "{kept} of {}",
            new_pairs.len()
        );
        for run in [1, 7, 64, new_pairs.len()] {
            let mut states = vec![MaybeUninit::<PairState>::uninit(); new_pairs.len()];
            for (pairs, states) in new_pairs.chunks(run).zip(states.chunks_mut(run)) {
                carry_pair_states(&old_pairs, &old_states, pairs, states);
            }
            for (pair, state) in new_pairs.iter().zip(&states) {
                // SAFETY: every entry was written by one of the runs above.
                let state = unsafe { state.assume_init() };
                let want = match old_pairs.iter().position(|old| old == pair) {
                    Some(k) => old_states[k],
                    None => PairState::default(),
                };
                assert_eq!(state, want, "{pair:?}, runs of {run}");
            }
        }
    }

    /// The bench's dense packing of about `grains` grains, its walls moving in at four speeds.
    fn squeezed_packing(grains: usize) -> World {
        use crate::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP};
        let mut world = crate::run::bench::dense_packing(grains, 1.0);
        for (w, v) in [
            (LEFT, 1e-3),
            (RIGHT, -1.5e-3),
            (BOTTOM, 2e-3),
            (TOP, -0.5e-3),
        ] {
            let axis = if w == LEFT || w == RIGHT {
                DVec2::X
            } else {
                DVec2::Y
            };
            world.walls[w].velocity = axis * v;
        }
        world
    }

    #[test]
    fn springs_restored_into_a_frictionless_world_are_dropped_by_its_next_step() {
        // Expectation: a world without friction between grains holds no pair's spring after a
        // step, as every pair's record writes the frictionless response's zero. A checkpoint's
        // history restored into such a world (the only way one gets there) is reported until
        // the next step and dropped by it, on every path of the pair pass, the blocks of rigid
        // discs (which otherwise leave the pairs' states alone) included; and the steps are
        // the steps of the world without it, bit for bit.
        let mut plain = crate::run::bench::dense_packing(400, 1.0);
        crate::run::bench::with_model(&mut plain, ModelLevel::Rigid);
        plain.step().unwrap();
        let mut restored = plain.clone();
        let springs: Vec<([u32; 2], f64)> = restored
            .neighbors
            .pairs
            .iter()
            .step_by(3)
            .enumerate()
            .map(|(k, &pair)| (pair, 1e-4 * (k % 7) as f64 + 1e-5))
            .collect();
        assert!(springs.len() > 100);
        let history = ContactHistory {
            pairs: springs.clone(),
            ..Default::default()
        };
        restored.restore_contact_history(&history).unwrap();
        assert_eq!(restored.contact_history().pairs, springs);
        for _ in 0..3 {
            plain.step().unwrap();
            restored.step().unwrap();
            assert!(restored.contact_history().pairs.is_empty());
            assert_eq!(grain_bits(&restored), grain_bits(&plain));
        }
        // Every frame a circle: the pairs go by the discs' blocks.
        assert!(restored.frames_all_circles());
    }

    #[test]
    fn the_carry_inside_the_step_is_the_remap_after_it_bit_for_bit() {
        // Expectation: the affine carry that the grain pass applies to each grain is the map
        // the run loop applied after the step (from the box before the walls' move to the box
        // after it), so an affine run keeps its bits; the neighbour list's reference centres
        // follow alike (the rebuild decisions, hence the later steps, agree too).
        let squeezed = || squeezed_packing(400);
        let world = squeezed();
        let mut carried = world.clone();
        carried.affine_carry = true;
        let mut remapped = world;
        for _ in 0..60 {
            carried.step().unwrap();
            // The remap as the run loop did it, in a pass of its own after the step.
            let from = box_corners(&remapped.walls);
            remapped.step().unwrap();
            let to = box_corners(&remapped.walls);
            let map = BoxCarry::new(from, to);
            for g in remapped.grains_mut() {
                g.center = map.apply(g.center);
            }
            remapped.neighbors.follow_affine(from, to);
        }
        let state = |w: &World| -> Vec<u64> {
            w.grains
                .iter()
                .flat_map(|g| [g.center.x, g.center.y, g.velocity.x, g.eps1])
                .map(f64::to_bits)
                .collect()
        };
        assert_eq!(state(&carried), state(&remapped));
        assert_eq!(carried.neighbors.pairs, remapped.neighbors.pairs);
        // The carry did move the grains: without it they end elsewhere.
        let mut still = squeezed();
        for _ in 0..60 {
            still.step().unwrap();
        }
        assert_ne!(state(&still), state(&carried));
    }

    /// Every grain's state, word by word.
    fn grain_bits(w: &World) -> Vec<u64> {
        w.grains
            .iter()
            .flat_map(Grain::to_array)
            .map(f64::to_bits)
            .collect()
    }

    #[test]
    fn the_results_are_the_same_bits_whatever_the_skin() {
        // Expectation: the list holds every pair within its skin whichever skin it has, and
        // the step sums contacts alone in an order the list does not set, so the skin changes
        // the speed only. The bench's packing, released from its overlaps, rebuilds its list
        // every few steps at its own skin: the skin widens (adapted_skin), while a copy given a
        // skin eight times as thick, which lists next-nearest neighbours too, keeps its lists
        // long and its skin. Both, squeezed with the affine carry, then in a periodic cell that
        // shrinks and shears, step to the same bits with different lists.
        let mut squeezed = squeezed_packing(400);
        squeezed.affine_carry = true;
        let periodic = {
            let base = crate::run::bench::dense_packing(400, 1.0);
            let grains = base.grains.clone();
            World::new(base.params, grains, base.walls.clone())
                .with_periodic(PeriodicBoundary::default())
        };
        for (case, world) in [("squeezed box", squeezed), ("periodic cell", periodic)] {
            let own = world.neighbors.skin;
            let mut thick = world.clone();
            thick.neighbors = NeighborList::new(8.0 * own);
            let mut adapted = world;
            for _ in 0..80 {
                for w in [&mut adapted, &mut thick] {
                    if let Some(cell) = w.periodic.as_mut() {
                        cell.shear_rate = 1e-3;
                        let (width, _) = crate::boundary::walls::box_size(&w.walls);
                        w.walls[crate::boundary::walls::RIGHT].velocity.x = -1e-3 * width;
                    }
                    w.step().unwrap();
                }
            }
            assert!(
                adapted.neighbors.skin > 1.5 * own,
                "{case}: skin {} from {own}",
                adapted.neighbors.skin
            );
            assert_eq!(thick.neighbors.skin, 8.0 * own, "{case}");
            assert_ne!(adapted.neighbors.builds, thick.neighbors.builds, "{case}");
            assert_ne!(
                adapted.neighbors.pairs.len(),
                thick.neighbors.pairs.len(),
                "{case}: the lists should differ"
            );
            assert_eq!(grain_bits(&adapted), grain_bits(&thick), "{case}");
        }
    }

    #[test]
    fn a_skin_too_wide_for_the_cell_goes_back_to_the_scenarios() {
        // Expectation: a periodic cell too narrow for a widened skin (range 2 max reach + skin
        // over half its width) is not an error while the scenario's skin fits: the skin goes
        // back to the scenario's, and the steps are those of a world that never widened it.
        let base = crate::run::bench::dense_packing(100, 1.0);
        let world = World::new(base.params, base.grains.clone(), base.walls.clone())
            .with_periodic(PeriodicBoundary::default());
        let own = world.neighbors.skin;
        let (width, height) = crate::boundary::walls::box_size(&world.walls);
        let mut widened = world.clone();
        widened.neighbors.skin = 0.5 * width.min(height);
        let mut plain = world;
        widened.step().unwrap();
        assert_eq!(widened.neighbors.skin, own);
        plain.step().unwrap();
        // The list widens its skin again as its lists stay short, within what the cell takes.
        for _ in 0..20 {
            widened.step().unwrap();
            plain.step().unwrap();
        }
        assert!(widened.neighbors.skin < 0.25 * width.min(height));
        assert_eq!(grain_bits(&widened), grain_bits(&plain));
        // Without the reset, the first step fails.
        let mut fixed = widened.clone();
        fixed.neighbors = NeighborList::new(0.5 * width.min(height));
        assert!(matches!(
            fixed.step(),
            Err(Instability::CellTooNarrow { .. })
        ));
    }

    #[test]
    fn the_grain_pass_by_blocks_changes_no_bit() {
        // Expectation: a block's lanes are its grains' one-grain updates (a unit test of
        // grain_pass compares them), its pair loads gathered in lanes are `pair_load`'s sums
        // (in the cases without friction outside a cell; it fails when a second end's force
        // keeps the first's sign, or an arm takes the wrong coordinate: both checked), and
        // the pass around them keeps every order: a world
        // stepped with blocks is, bit for bit, the world stepped grain by grain (grains,
        // stress records, totals, frames, the pair records), in a box squeezed with the affine
        // carry, with friction, in a sheared periodic cell, with adaptive levels stepping down
        // (the levels and their counters too); rigid discs alike (their blocks' frames written
        // after them); and a step that fails reports the same first failure.
        use crate::contact::friction::FrictionSettings;
        use crate::integration::parameters::Friction;
        if !grain_block::blocks_available() {
            eprintln!("no AVX here: the grain pass takes no blocks, nothing to compare");
            return;
        }
        for case in [
            "affine box",
            "friction",
            "periodic cell",
            "adaptive levels",
            "rigid discs",
            "rigid discs with friction in a periodic cell",
        ] {
            let mut world = squeezed_packing(603);
            assert!(world.params.level == ModelLevel::Full && world.params.adaptive.is_none());
            if case.starts_with("rigid") {
                crate::run::bench::with_model(&mut world, ModelLevel::Rigid);
            }
            let frictional = |world: &mut World| {
                let settings = FrictionSettings {
                    grains: 0.4,
                    damping: 0.3,
                    ..Default::default()
                };
                world.params.friction = Friction::new(&settings, &[0.3; 4]);
            };
            let sheared = |world: World| {
                world.with_periodic(PeriodicBoundary {
                    shear_rate: 1e-3,
                    ..Default::default()
                })
            };
            match case {
                "affine box" | "rigid discs" => world.affine_carry = true,
                "friction" => frictional(&mut world),
                "periodic cell" => world = sheared(world),
                "rigid discs with friction in a periodic cell" => {
                    frictional(&mut world);
                    world = sheared(world);
                }
                _ => {
                    // Every grain starts at the full level, and many step down within a few
                    // steps (some back up): chunks and blocks of mixed levels, frozen rates.
                    let dt = world.params.dt;
                    world.params.adaptive = Some(crate::integration::parameters::Adaptive {
                        settings: crate::grain::adaptive::AdaptiveSettings {
                            full_down: 5e-2,
                            confirm: 2,
                            dwell: 5,
                            ..Default::default()
                        },
                        dt: [dt; 3],
                        multi_rate: false,
                    });
                    let n = world.grains.len();
                    world.set_levels(&vec![GrainLevel::new(ModelLevel::Full); n]);
                }
            }
            let mut by_grain = world.clone();
            by_grain.grain_blocks = false;
            let mut by_block = world;
            for step in 0..80 {
                by_grain.step().unwrap();
                by_block.step().unwrap();
                let at = format!("{case}, step {step}");
                // The first entry that differs, not two long lists.
                fn same<T: PartialEq + std::fmt::Debug>(what: &str, at: &str, a: &[T], b: &[T]) {
                    assert_eq!(a.len(), b.len(), "{at}: {what}");
                    if let Some(k) = (0..a.len()).find(|&k| a[k] != b[k]) {
                        panic!("{at}: {what}[{k}]: {:?} against {:?}", a[k], b[k]);
                    }
                }
                same(
                    "grain values",
                    &at,
                    &grain_bits(&by_block),
                    &grain_bits(&by_grain),
                );
                same(
                    "stresses",
                    &at,
                    &by_block.grain_stress,
                    &by_grain.grain_stress,
                );
                assert_eq!(by_block.totals, by_grain.totals, "{at}");
                same(
                    "contacts",
                    &at,
                    &by_block.pair_contacts,
                    &by_grain.pair_contacts,
                );
                let frames = |w: &World| w.frames.iter().map(frame_bits).collect::<Vec<_>>();
                same("frames", &at, &frames(&by_block), &frames(&by_grain));
                // The directions beside the frames that are not circles.
                let directions = |w: &World| {
                    w.frames
                        .iter()
                        .zip(&w.directions)
                        .filter(|(frame, _)| !frame.circle())
                        .map(|(_, d)| d.to_array().map(f64::to_bits))
                        .collect::<Vec<_>>()
                };
                same(
                    "directions",
                    &at,
                    &directions(&by_block),
                    &directions(&by_grain),
                );
                same("centres", &at, &by_block.centers, &by_grain.centers);
                same("reaches", &at, &by_block.reach, &by_grain.reach);
                same("levels", &at, by_block.levels(), by_grain.levels());
            }
            if case == "adaptive levels" {
                let counts = by_block.totals.level_counts;
                assert!(counts[0] + counts[1] > 20 && counts[2] > 20, "{counts:?}");
            }
            // Two grains, in two blocks, fail the speed check: the first is reported.
            for world in [&mut by_grain, &mut by_block] {
                let wave_speed =
                    (world.params.material.young / world.params.material.density).sqrt();
                for g in [301, 306] {
                    world.grains_mut()[g].velocity = DVec2::new(2.0 * wave_speed, 0.0);
                }
            }
            let failure = by_grain.step().unwrap_err();
            assert!(
                matches!(failure, Instability::Runaway { grain: 301, .. }),
                "{failure:?}"
            );
            assert_eq!(by_block.step().unwrap_err(), failure, "{case}");
        }
    }

    /// The bits of what a frame holds for its grain: the first line, and the second where the
    /// grain is not a circle (a circle's second line is stale by design).
    pub(super) fn frame_bits(f: &Frame) -> Vec<u64> {
        let mut v = vec![
            f.center.x.to_bits(),
            f.center.y.to_bits(),
            f.bounding_radius.to_bits(),
            f.mass.to_bits(),
            f.velocity.x.to_bits(),
            f.velocity.y.to_bits(),
            f.omega.to_bits(),
            f.circle_dilation.to_bits(),
        ];
        if !f.circle() {
            v.extend(bits(f.map));
            v.extend(bits(f.velocity_gradient));
        }
        v
    }

    /// Whether the world's frames, centres and reaches are, bit for bit, those the frames
    /// pass computes from its grains and levels now.
    fn frames_match_grains(world: &World) -> Result<(), String> {
        let density = world.params.material.density;
        for (g, (grain, level)) in world.grains.iter().zip(&world.levels).enumerate() {
            let mut expected = Frame::default();
            let mut direction = DVec2::NAN;
            expected.write(&mut direction, grain, level.level, density);
            let frame = &world.frames[g];
            if frame_bits(frame) != frame_bits(&expected) {
                return Err(format!("grain {g}: {frame:?} against {expected:?}"));
            }
            // Beside a frame that is not a circle, the grain's principal direction.
            let found = world.directions[g];
            if !frame.circle()
                && found.to_array().map(f64::to_bits) != direction.to_array().map(f64::to_bits)
            {
                return Err(format!(
                    "grain {g}: direction {found:?} against {direction:?}"
                ));
            }
            if world.centers[g] != frame.center || world.reach[g] != frame.bounding_radius {
                return Err(format!("grain {g}: broad-phase copies differ"));
            }
        }
        let all_circles = world.frames.iter().all(|frame| frame.circle());
        if world.frames_all_circles() != all_circles {
            return Err(format!(
                "frames_all_circles is {}, every frame a circle: {all_circles}",
                world.frames_all_circles()
            ));
        }
        let no_circle = !world.frames.iter().any(|frame| frame.circle());
        if world.frames_no_circle() != no_circle {
            return Err(format!(
                "frames_no_circle is {}, no frame a circle: {no_circle}",
                world.frames_no_circle()
            ));
        }
        Ok(())
    }

    #[test]
    fn the_pair_pass_is_told_every_frame_or_none_is_a_circle_only_when_so() {
        // Expectation: the flag that sends every block of pairs to the circle lanes follows
        // the frames, whichever pass writes them: set in a world of rigid discs, cleared as
        // soon as one grain deforms, set again when it is a disc again; and so does the flag
        // that no frame is a circle.
        let mut world = crate::run::bench::dense_packing(100, 1.0);
        crate::run::bench::with_model(&mut world, ModelLevel::Rigid);
        world.step().unwrap();
        assert!(world.frames_all_circles());
        frames_match_grains(&world).unwrap();
        let mut levels = vec![GrainLevel::new(ModelLevel::Rigid); world.grains.len()];
        levels[37] = GrainLevel::new(ModelLevel::Full);
        world.set_levels(&levels);
        world.prepare(0.0).unwrap();
        assert!(!world.frames_all_circles());
        for _ in 0..5 {
            world.step().unwrap();
            assert!(!world.frames_all_circles());
            frames_match_grains(&world).unwrap();
        }
        levels[37] = GrainLevel::new(ModelLevel::Rigid);
        world.set_levels(&levels);
        world.grains_mut()[37].eps2 = world.grains()[37].eps1;
        world.step().unwrap();
        assert!(world.frames_all_circles());
        frames_match_grains(&world).unwrap();
        // And the flag that spares the pair pass the frames' flags: set once no frame is a
        // circle, cleared when one is again.
        assert!(!world.frames_no_circle());
        let mut levels = vec![GrainLevel::new(ModelLevel::Full); world.grains.len()];
        world.set_levels(&levels);
        for _ in 0..3 {
            world.step().unwrap();
            assert!(world.frames_no_circle() && !world.frames_all_circles());
            frames_match_grains(&world).unwrap();
        }
        levels[12] = GrainLevel::new(ModelLevel::Rigid);
        world.set_levels(&levels);
        world.grains_mut()[12].eps2 = world.grains()[12].eps1;
        world.step().unwrap();
        assert!(!world.frames_no_circle());
        frames_match_grains(&world).unwrap();
    }

    #[test]
    fn the_grain_pass_leaves_the_frames_the_frames_pass_would_write() {
        // Expectation: the frame the grain pass writes for each updated grain is, every bit,
        // the one the frames pass would compute from that grain at the next step (the pass it
        // spares), for discs, rigid ellipses and deforming grains, with the affine carry and
        // walls moving; a change made through `grains_mut` or `set_levels` reaches the next
        // step's frames.
        use crate::boundary::walls::{LEFT, TOP};
        let mut world = crate::run::bench::dense_packing(400, 1.0);
        world.walls[LEFT].velocity = DVec2::X * 1e-3;
        world.walls[TOP].velocity = DVec2::Y * -2e-3;
        world.affine_carry = true;
        for _ in 0..10 {
            world.step().unwrap();
        }
        // Discs, ellipses held rigid after deforming, and deforming grains.
        for (k, g) in world.grains_mut().iter_mut().enumerate() {
            if k % 3 == 0 {
                g.eps2 = g.eps1;
            }
        }
        let levels: Vec<GrainLevel> = (0..world.grains.len())
            .map(|k| {
                GrainLevel::new(if k % 3 == 2 {
                    ModelLevel::Full
                } else {
                    ModelLevel::Rigid
                })
            })
            .collect();
        world.set_levels(&levels);
        assert!(!world.frames_current);
        let circles = |w: &World| w.frames.iter().filter(|f| f.circle()).count();
        for _ in 0..20 {
            world.step().unwrap();
            assert!(world.frames_current);
            frames_match_grains(&world).unwrap();
        }
        let n = world.grains.len();
        assert!(circles(&world) > n / 4 && circles(&world) < n / 2);
        // A change between steps: the next step's frames follow it.
        world.grains_mut()[5].velocity += DVec2::new(1e-3, 0.0);
        world.grains_mut()[6].eps2 += 1e-3;
        assert!(!world.frames_current);
        world.prepare(0.0).unwrap();
        frames_match_grains(&world).unwrap();
        world.step().unwrap();
        frames_match_grains(&world).unwrap();
    }

    #[test]
    fn a_periodic_cell_keeps_the_frames_current_through_its_carry_and_wraps() {
        // Expectation: the cell's affine carry and the wrap of grains that leave it move only
        // centres, so the frames the grain pass wrote stay, bit for bit, those the frames pass
        // would compute, while the cell compresses and shears and grains cross its sides.
        let base = crate::run::bench::dense_packing(100, 1.0);
        let (lo, hi) = box_corners(&base.walls);
        let spacing = (hi - lo) / 10.0;
        let steps = 200;
        let speed = spacing.x / (steps as f64 * base.params.dt);
        let grains = (0..100)
            .map(|k| {
                let cell = DVec2::new((k % 10) as f64 + 0.5, (k / 10) as f64 + 0.5);
                let mut g = Grain::at_rest(lo + cell * spacing, 0.3 * spacing.min_element());
                g.velocity = DVec2::new(-1.0, -0.6 + 0.01 * k as f64) * speed;
                g.omega = 0.1 * k as f64;
                g
            })
            .collect();
        let mut world = World::new(base.params, grains, base.walls.clone())
            .with_periodic(PeriodicBoundary::default());
        let start = world.grains.clone();
        for step in 0..steps {
            let (w, h) = crate::boundary::walls::box_size(&world.walls);
            world.walls[crate::boundary::walls::RIGHT].velocity.x = -1e-3 * w;
            world.walls[crate::boundary::walls::TOP].velocity.y = 1e-3 * h;
            world.periodic.as_mut().unwrap().shear_rate = 1e-3;
            world.step().unwrap();
            assert!(world.frames_current);
            frames_match_grains(&world)
                .map_err(|e| format!("step {step}: {e}"))
                .unwrap();
        }
        // Grains did cross the cell's sides (a wrap moves a centre by a cell width).
        let wrapped = start
            .iter()
            .zip(&world.grains)
            .filter(|(a, b)| (a.center.x - b.center.x).abs() > 2.0 * spacing.x)
            .count();
        assert!(wrapped >= 10, "{wrapped} grains wrapped");
    }

    fn bits(m: DMat2) -> [u64; 4] {
        m.to_cols_array().map(f64::to_bits)
    }

    fn shape_bits(s: &GrainShape) -> Vec<u64> {
        let mut v = vec![s.center.x.to_bits(), s.center.y.to_bits()];
        v.extend(bits(s.map));
        v.extend(bits(s.inv_map()));
        v.push(s.bounding_radius.to_bits());
        v
    }

    fn deformed_grain() -> Grain {
        Grain {
            radius: 0.013,
            center: DVec2::new(0.3, -0.2),
            velocity: DVec2::new(1e-3, -2e-3),
            theta: 0.7,
            omega: -0.4,
            eps1: 0.03,
            eps1_rate: 1e-3,
            eps2: -0.02,
            eps2_rate: -2e-3,
            alpha: 0.3,
            alpha_rate: 0.05,
        }
    }

    #[test]
    fn a_frame_is_two_cache_lines_and_a_circle_reads_one() {
        // The layout is the point of the type (issue #16): two aligned lines, the circle's
        // fields all in the first.
        assert_eq!(std::mem::size_of::<Frame>(), 128);
        assert_eq!(std::mem::align_of::<Frame>(), 64);
        let circle_end = std::mem::offset_of!(Frame, circle_dilation) + 8;
        assert!(circle_end <= 64, "circle fields end at byte {circle_end}");
        assert!(std::mem::offset_of!(Frame, map) >= 64);
    }

    #[test]
    fn a_pair_contact_is_one_cache_line() {
        // The grain pass reads one aligned line per contact (issue #16).
        assert_eq!(std::mem::size_of::<PairContact>(), 64);
        assert_eq!(std::mem::align_of::<PairContact>(), 64);
    }

    #[test]
    fn frames_give_the_grains_own_shape_and_velocity_field_bit_for_bit() {
        // Expectation: a deformed grain's frame rebuilds the shape and velocity gradient that
        // `Grain::shape_and_velocity_gradient` computes (inv_map = map.inverse()), every bit.
        let g = deformed_grain();
        let (shape, gradient) = g.shape_and_velocity_gradient();
        let frame = Frame::of_grain(&g, 2.0);
        assert!(!frame.circle());
        assert_eq!(shape_bits(&frame.shape()), shape_bits(&shape));
        assert_eq!(bits(frame.velocity_gradient()), bits(gradient));
        let x = DVec2::new(0.31, -0.19);
        assert_eq!(frame.velocity_at(x), g.velocity + gradient * (x - g.center));
        assert_eq!(frame.mass.to_bits(), g.mass(2.0).to_bits());

        // A circle (rigid, equal strains) is the disc of radius R (1 + eps) spinning at omega,
        // whatever stale second line the frame held before.
        let mut disc = deformed_grain();
        disc.eps2 = disc.eps1;
        let mut frame = Frame::of_grain(&g, 2.0);
        assert!(Frame::is_circle(&disc, ModelLevel::Rigid));
        frame.write_circle(&disc, ModelLevel::Rigid, 2.0);
        let radius = disc.radius * (1.0 + disc.eps1);
        let expected = GrainShape {
            center: disc.center,
            map: DMat2::from_diagonal(DVec2::splat(radius)),
            bounding_radius: radius,
            circle: true,
        };
        assert!(frame.circle());
        assert_eq!(shape_bits(&frame.shape()), shape_bits(&expected));
        assert_eq!(frame.velocity_gradient(), QUARTER_TURN * disc.omega);
        let arm = x - disc.center;
        assert_eq!(
            frame.velocity_at(x),
            disc.velocity + disc.omega * DVec2::new(-arm.y, arm.x)
        );

        // At the volumetric level the same disc dilates: both strains at one rate, its
        // velocity field is the grain's own (`Grain::velocity_gradient`, through the angles'
        // sines and cosines: equal to rounding), `omega J + eps_rate / (1 + eps) I`.
        disc.eps1_rate = -0.37;
        disc.eps2_rate = disc.eps1_rate;
        disc.alpha_rate = 0.0;
        assert!(Frame::is_circle(&disc, ModelLevel::Volumetric));
        assert!(!Frame::is_circle(&disc, ModelLevel::Full));
        frame.write_circle(&disc, ModelLevel::Volumetric, 2.0);
        assert!(frame.circle());
        assert_eq!(shape_bits(&frame.shape()), shape_bits(&expected));
        let gradient = disc.velocity_gradient();
        let dilation = disc.eps1_rate / (1.0 + disc.eps1);
        for (k, (circle, grain)) in bits(frame.velocity_gradient())
            .map(f64::from_bits)
            .into_iter()
            .zip(bits(gradient).map(f64::from_bits))
            .enumerate()
        {
            assert!(
                (circle - grain).abs() < 1e-14,
                "entry {k}: {circle} against {grain}"
            );
        }
        let expected_velocity =
            disc.velocity + disc.omega * DVec2::new(-arm.y, arm.x) + dilation * arm;
        assert!((frame.velocity_at(x) - expected_velocity).length() < 1e-14);
        // A deformed grain is no circle at any level.
        assert!(!Frame::is_circle(&g, ModelLevel::Volumetric));
    }
}
