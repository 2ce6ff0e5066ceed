//! The pair pass of the step: the contact geometry and force of every candidate pair, written to
//! the pair's own slot, and the sums over a chunk's contacts in pair order.
//!
//! Pairs of two circles (rigid discs, or discs at or held at a volumetric strain) take the
//! closed forms of [`circle`](crate::geometry::circle); where [`LANES`] consecutive pairs of a
//! chunk are all such pairs, they are computed side by side in the [lanes](crate::lanes) of
//! one kernel ([`disc_pair_forces`]), which vector instructions run four (AVX) or two (SSE2)
//! at a time (issue #16). Lane by lane, the kernel is the same sequence of operations as the
//! one-pair path: the same bits. A lane that leaves the kernel's regular case (an irregular contact: one
//! circle swallowing the other, a vanishing chord, a deep cap, the law out of its domain) is
//! computed again by the one-pair path, which handles those cases.
//!
//! Pairs of contour polygons that were in contact last step go eight at a time through the
//! common path of their contact in vector lanes ([`grain_grain_blocks`], two blocks of four):
//! the pass fills the blocks with the next such pairs within `POLYGON_WINDOW` and takes their
//! results in pair order (`PolygonsAhead`). The same lanes then give each block's normal
//! forces (the law, the relative velocity at the contact point and the dashpot: `polygon_pair_forces`). A lane gives
//! the one-pair path's bits or leaves the pair to it (a lane whose law left its domain leaves
//! from its contact), so the blocks' make-up (which changes with the chunks, and so with the
//! thread count) changes nothing.

use super::sweep::SharedRows;
use super::{
    Frame, Instability, PairContact, PairState, PairSums, Parameters, circle_velocity_at,
    prefetch_address,
};
use crate::boundary::periodic::{PeriodicCell, symmetric_dyad};
use crate::contact::friction::TangentialResponse;
use crate::contact::law::{SecantLaw, damped_normal_force};
use crate::geometry::circle::{
    chord_segment_area, degenerate_chord, disc_chord, disc_disc, disc_swallowed, discs_apart,
    shallow_cap, shallow_segment_area,
};
use crate::geometry::intersection::ContactGeometry;
use crate::geometry::intersection_lanes::{
    BLOCK, BLOCKS, BlockContacts, BlockKernel, LaneContact, LanePairs, PAIRS, grain_grain_blocks,
};
use crate::geometry::{ContourTable, Contours, GrainShape, Overlap, PairHint};
use crate::lanes::{Lanes, Real};
use glam::{DMat2, DVec2};

/// Pairs of circles computed side by side: two AVX registers' worth (see [`Lanes`]; 8 and 16
/// lanes time alike, 32 slower).
pub const LANES: usize = 8;
/// The lanes of [`LANES`] pairs.
pub type PairLanes = Lanes<LANES>;

/// How many pairs ahead the pair pass asks for the second grain's frame among polygons: both
/// its cache lines, for the next four pairs at each turn (issue #16: 1.028 times as fast at 10⁵
/// grains on one thread as the first line alone, for one pair a turn, which left three pairs
/// in four out where blocks of four were recorded at once; 16 ahead was 0.989 times as fast
/// as 8, and 32 ahead 0.96).
const PREFETCH_AHEAD: usize = 8;
/// How many pairs ahead the pair pass asks for the second grain's frame among circles, whose
/// pairs take a few nanoseconds each: the line a circle reads (at 10⁵ rigid discs, 32 pairs
/// ahead stepped 1.10 times as fast as 8 on one thread, 16 and 64 ahead 0.98 times as fast as
/// 32).
const CIRCLE_PREFETCH_AHEAD: usize = 32;
/// How many pairs ahead the pair pass asks for the rows of polygon pairs, where it records
/// blocks of four at once.
const ROWS_PREFETCH_AHEAD: usize = 32;

/// What the pair pass reads, shared by every chunk.
pub(super) struct PairPass<'a> {
    pub params: &'a Parameters,
    pub contours: &'a Contours,
    pub frames: SharedRows<'a, Frame>,
    pub pairs: &'a [[u32; 2]],
    /// Periodic cell only: each pair's image vector.
    pub images: &'a [[i64; 2]],
    pub step: u64,
    /// In a periodic cell: the cell, and the velocity gradient of the affine field, which adds
    /// `L d` to the relative velocity of a pair of branch vector d.
    pub periodic: Option<(PeriodicCell, DMat2)>,
    /// The second half of a multi-rate cycle: only the pairs of two grains that take two steps
    /// of it (`fast`) are computed; the others keep the first half's records.
    pub only_fast: Option<&'a [bool]>,
    /// Whether every frame is a circle (then so is every pair).
    pub every_frame_a_circle: bool,
    /// Whether no frame is a circle (then no pair has one): a world at the full level asks no
    /// frame whether it is one.
    pub no_frame_a_circle: bool,
    /// Whether some pair may hold a tangential spring that a step without friction between
    /// grains must drop: only where a checkpoint's history was restored into such a world,
    /// until its next step (see [`record_regular_block`](Self::record_regular_block)).
    pub springs_to_drop: bool,
}

/// Where the second grain of a pair is met: the centre of its image that meets the first, the
/// branch vector (periodic cell only; zero otherwise) and the affine field's `L d`.
#[derive(Clone, Copy)]
struct SecondEnd {
    center: DVec2,
    branch: DVec2,
    affine_rate: DVec2,
}

/// What a pair in contact carries out of its force computation.
struct Touch {
    geometry: ContactGeometry,
    stiffness: f64,
    capped: bool,
    /// The normal force, dashpot included.
    force: f64,
    relative_velocity: DVec2,
    effective_mass: f64,
}

/// A chunk's pairs' states, contact lengths, flags and records, as [`PairPass::chunk`] writes
/// them.
type ChunkSlots<'s> = (
    &'s mut [PairState],
    &'s mut [f64],
    &'s mut [bool],
    &'s mut [PairContact],
);

impl<'a> PairPass<'a> {
    /// The pairs of one chunk, the first of which is pair `first_pair`; returns their sums.
    pub fn chunk(
        &self,
        first_pair: usize,
        states: &mut [PairState],
        lengths: &mut [f64],
        actives: &mut [bool],
        records: &mut [PairContact],
    ) -> PairSums {
        let slots = (states, lengths, actives, records);
        #[cfg(target_arch = "x86_64")]
        if crate::lanes::Simd::discs_in_avx512() {
            // SAFETY: the processor has AVX-512 (`discs_in_avx512` holds only there).
            return unsafe { self.chunk_avx512(first_pair, slots) };
        }
        self.chunk_in(first_pair, slots)
    }

    /// [`chunk`](Self::chunk) compiled for AVX-512.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn chunk_avx512(&self, first_pair: usize, slots: ChunkSlots<'_>) -> PairSums {
        self.chunk_in(first_pair, slots)
    }

    #[inline(always)]
    fn chunk_in(
        &self,
        first_pair: usize,
        (states, lengths, actives, records): ChunkSlots<'_>,
    ) -> PairSums {
        // A world without friction between grains takes a pass that leaves the tangential
        // response out.
        if self.params.frictional_pairs() {
            self.chunk_of::<true>(first_pair, states, lengths, actives, records)
        } else {
            self.chunk_of::<false>(first_pair, states, lengths, actives, records)
        }
    }

    /// [`chunk`](Self::chunk); `FRICTIONAL`: whether pairs have friction.
    #[inline(always)]
    fn chunk_of<const FRICTIONAL: bool>(
        &self,
        first_pair: usize,
        states: &mut [PairState],
        lengths: &mut [f64],
        actives: &mut [bool],
        records: &mut [PairContact],
    ) -> PairSums {
        let mut sums = PairSums::default();
        let count = states.len();
        if let Some(fast) = self.only_fast {
            for k in 0..count {
                let [i, j] = self.pairs[first_pair + k];
                if fast[i as usize] && fast[j as usize] {
                    self.one_pair::<FRICTIONAL>(
                        first_pair + k,
                        None,
                        &mut states[k],
                        &mut lengths[k],
                        &mut actives[k],
                        &mut records[k],
                        &mut sums,
                    );
                }
            }
            return sums;
        }
        let polygons = PolygonsAhead::new(self.contours, self.frames, self.every_frame_a_circle);
        // A world of circles (the rigid level's) takes a loop without the polygon blocks' test.
        if polygons.table.is_some() {
            self.chunk_in_order::<FRICTIONAL, true>(
                first_pair, polygons, states, lengths, actives, records,
            )
        } else {
            self.chunk_in_order::<FRICTIONAL, false>(
                first_pair, polygons, states, lengths, actives, records,
            )
        }
    }

    /// The chunk's pairs in order, circles in blocks where [`LANES`] consecutive pairs are
    /// pairs of circles; `POLYGONS`: whether `polygons` computes blocks of polygon pairs.
    #[inline(always)]
    fn chunk_in_order<const FRICTIONAL: bool, const POLYGONS: bool>(
        &self,
        first_pair: usize,
        mut polygons: PolygonsAhead<'a>,
        states: &mut [PairState],
        lengths: &mut [f64],
        actives: &mut [bool],
        records: &mut [PairContact],
    ) -> PairSums {
        let mut sums = PairSums::default();
        let count = states.len();
        let mut lanes = None;
        // No block of circles starts before this pair of the chunk: a pair that is not one of
        // two circles, found by a block's test, is in the windows of the pairs up to it too.
        let mut circle_blocks_from = 0;
        let mut k = 0;
        while k < count {
            let p = first_pair + k;
            // The same call as below's, on purpose: the compiler specialises each (one call
            // for both cost the full level 91 instructions a grain-step, 3%).
            if POLYGONS && let Some(lane) = polygons.computed(k) {
                // The second block of two computed at once (eight lanes): as the first below.
                if !FRICTIONAL && self.periodic.is_none() && polygons.holds_block_from(lane, k) {
                    polygons.record_block(lane, k, states, lengths, actives, records);
                    k += BLOCK;
                    continue;
                }
                self.polygon_lane::<FRICTIONAL>(
                    p,
                    &polygons,
                    lane,
                    &mut states[k],
                    &mut lengths[k],
                    &mut actives[k],
                    &mut records[k],
                    &mut sums,
                );
                k += 1;
                continue;
            }
            if k + LANES <= count
                && k >= circle_blocks_from
                && match self.first_not_circles(p) {
                    None => true,
                    Some(lane) => {
                        circle_blocks_from = k + lane + 1;
                        false
                    }
                }
            {
                for lane in 0..LANES {
                    self.prefetch_ahead::<1>(p + lane, CIRCLE_PREFETCH_AHEAD);
                }
                // The list's line (eight pairs) of a block further on, and the records the
                // block 32 pairs on will write (issue #16: with the grain pass's stress
                // records, 1.028 times as fast at 10⁵ rigid discs on one thread, 1.010 on
                // LAMMPS's packing).
                prefetch_address(
                    self.pairs
                        .as_ptr()
                        .wrapping_add(p + 3 * CIRCLE_PREFETCH_AHEAD)
                        .cast(),
                );
                let records_ahead = records.as_ptr().wrapping_add(k + CIRCLE_PREFETCH_AHEAD);
                for lane in 0..LANES {
                    prefetch_address(records_ahead.wrapping_add(lane).cast());
                }
                let block = k..k + LANES;
                let (input, out) = lanes.get_or_insert_with(Default::default);
                self.circle_block::<FRICTIONAL>(
                    p,
                    input,
                    out,
                    &mut states[block.clone()],
                    &mut lengths[block.clone()],
                    &mut actives[block.clone()],
                    &mut records[block],
                    &mut sums,
                );
                k += LANES;
            } else {
                for lane in 0..BLOCK {
                    self.prefetch_ahead::<2>(p + lane, PREFETCH_AHEAD);
                }
                let lane = if POLYGONS {
                    polygons.take(self, k, first_pair, states)
                } else {
                    None
                };
                // The common case of a dense packing: the block holds this pair and the
                // next three, all contacts of the common path, which (without friction or a
                // cell) leave nothing for the sums; their records are written at once.
                if !FRICTIONAL
                    && self.periodic.is_none()
                    && lane == Some(0)
                    && polygons.holds_block_from(0, k)
                {
                    polygons.record_block(0, k, states, lengths, actives, records);
                    self.prefetch_rows(
                        p + ROWS_PREFETCH_AHEAD,
                        k + ROWS_PREFETCH_AHEAD,
                        states,
                        records,
                    );
                    k += BLOCK;
                    continue;
                }
                let (state, length, active, record) = (
                    &mut states[k],
                    &mut lengths[k],
                    &mut actives[k],
                    &mut records[k],
                );
                match lane {
                    Some(lane) => self.polygon_lane::<FRICTIONAL>(
                        p, &polygons, lane, state, length, active, record, &mut sums,
                    ),
                    None => self
                        .one_pair::<FRICTIONAL>(p, None, state, length, active, record, &mut sums),
                }
                k += 1;
            }
        }
        sums
    }

    /// Whether pair `p` (hint `hint`) may take the polygons' common path: two grains that are
    /// not circles, whose contours crossed last step.
    #[inline(always)]
    fn on_polygon_path(&self, p: usize, hint: &PairHint) -> bool {
        hint.first.lo >= 0
            && hint.second.lo >= 0
            && (self.no_frame_a_circle || {
                let [i, j] = self.pairs[p];
                !self.frames.row(i as usize).circle() && !self.frames.row(j as usize).circle()
            })
    }

    /// Asks for the first `LINES` cache lines of the frame of the second grain of the pair
    /// `distance` pairs after `p`.
    #[inline(always)]
    fn prefetch_ahead<const LINES: usize>(&self, p: usize, distance: usize) {
        if let Some(&[_, ahead]) = self.pairs.get(p + distance) {
            let frame = (self.frames.row(ahead as usize) as *const Frame).cast::<u8>();
            for line in 0..LINES {
                prefetch_address(frame.wrapping_add(64 * line));
            }
        }
    }

    /// Asks for the rows of the block of polygon pairs from pair `p` (the chunk's `k`): the
    /// list's line, the states' and the records' (issue #16: where blocks of four are
    /// recorded at once, a block's turn is short, and its rows' loads stalled the window's
    /// tests of the hints).
    #[inline(always)]
    fn prefetch_rows(&self, p: usize, k: usize, states: &[PairState], records: &[PairContact]) {
        prefetch_address(self.pairs.as_ptr().wrapping_add(p).cast());
        let states_ahead = states.as_ptr().wrapping_add(k).cast::<u8>();
        prefetch_address(states_ahead);
        prefetch_address(states_ahead.wrapping_add(64));
        let records_ahead = records.as_ptr().wrapping_add(k);
        for lane in 0..BLOCK {
            prefetch_address(records_ahead.wrapping_add(lane).cast());
        }
    }

    /// The first of the `LANES` pairs from pair `p` on that is not a pair of two circles (its
    /// offset from `p`), or None where all are.
    #[inline(always)]
    fn first_not_circles(&self, p: usize) -> Option<usize> {
        if self.every_frame_a_circle {
            None
        } else if self.no_frame_a_circle {
            // No pair is one of two circles: the window's last is not, either.
            Some(LANES - 1)
        } else {
            self.pairs[p..p + LANES].iter().position(|&[i, j]| {
                !(self.frames.row(i as usize).circle() && self.frames.row(j as usize).circle())
            })
        }
    }

    #[inline(always)]
    fn second_end(&self, p: usize, first: &Frame, second: &Frame) -> SecondEnd {
        match &self.periodic {
            Some((cell, velocity_gradient)) => {
                let shift = cell.image_shift(self.images[p]);
                end_at_image(first, second, shift, velocity_gradient)
            }
            None => SecondEnd {
                center: second.center,
                branch: DVec2::ZERO,
                affine_rate: DVec2::ZERO,
            },
        }
    }

    /// Pair `p` on its own: any pair of grains, any case. `computed`: the pair's contact and
    /// next hint where a block of polygon lanes found them (see [`PolygonsAhead`]).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn one_pair<const FRICTIONAL: bool>(
        &self,
        p: usize,
        computed: LaneContact,
        state: &mut PairState,
        length: &mut f64,
        active: &mut bool,
        record: &mut PairContact,
        sums: &mut PairSums,
    ) {
        let [i, j] = self.pairs[p];
        let (fi, fj) = (self.frames.row(i as usize), self.frames.row(j as usize));
        let end = self.second_end(p, fi, fj);
        let mut hint = state.hint;
        let overlap = if let Some((contact, next_hint)) = computed {
            hint = next_hint;
            Overlap::Contact(contact)
        } else if fi.circle() && fj.circle() {
            disc_disc(
                fi.center,
                fi.bounding_radius,
                end.center,
                fj.bounding_radius,
            )
        } else {
            let shape_j = GrainShape {
                center: end.center,
                ..fj.shape()
            };
            self.contours.grain_grain(&fi.shape(), &shape_j, &mut hint)
        };
        let touch = match overlap {
            Overlap::Separate => None,
            Overlap::Swallowed => {
                sums.failure.get_or_insert(Instability::Swallowed {
                    step: self.step,
                    grain: i as usize,
                    other: Some(j as usize),
                });
                None
            }
            Overlap::Contact(c) => match self.params.law.response(c.length, c.normal_gap) {
                Err(exit) => {
                    sums.failure.get_or_insert(Instability::ContactDomain {
                        step: self.step,
                        grain: i as usize,
                        other: Some(j as usize),
                        length: exit.length,
                        normal_gap: exit.normal_gap,
                    });
                    None
                }
                Ok(response) => {
                    let velocity_j = fj.velocity + fj.velocity_gradient() * (c.point - end.center);
                    let relative_velocity = velocity_j - fi.velocity_at(c.point) + end.affine_rate;
                    let gap_rate = relative_velocity.dot(c.normal);
                    let effective_mass = fi.mass * fj.mass / (fi.mass + fj.mass);
                    let force = damped_normal_force(
                        response.force,
                        response.stiffness,
                        effective_mass,
                        self.params.contact_damping,
                        gap_rate,
                    );
                    Some(Touch {
                        geometry: c,
                        stiffness: response.stiffness,
                        capped: response.capped,
                        force,
                        relative_velocity,
                        effective_mass,
                    })
                }
            },
        };
        self.record::<FRICTIONAL>(touch, hint, end.branch, state, length, active, record, sums);
    }

    /// [`one_pair`](Self::one_pair) for the few pairs of a polygon block that leave its
    /// lanes, out of the pass's loop.
    #[cold]
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn one_pair_left_by_block<const FRICTIONAL: bool>(
        &self,
        p: usize,
        computed: LaneContact,
        state: &mut PairState,
        length: &mut f64,
        active: &mut bool,
        record: &mut PairContact,
        sums: &mut PairSums,
    ) {
        self.one_pair::<FRICTIONAL>(p, computed, state, length, active, record, sums);
    }

    /// Pair `p`, lane `lane` of the last polygon block: its contact and normal force as the
    /// block's lanes computed them (the one-pair path's bits). A lane off the common path takes
    /// the one-pair path, and one whose law left its domain takes the one-pair path from its
    /// contact (which caps the law or reports the exit).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn polygon_lane<const FRICTIONAL: bool>(
        &self,
        p: usize,
        polygons: &PolygonsAhead<'a>,
        lane: usize,
        state: &mut PairState,
        length: &mut f64,
        active: &mut bool,
        record: &mut PairContact,
        sums: &mut PairSums,
    ) {
        let (block, lane) = (lane / BLOCK, lane % BLOCK);
        let Some((geometry, hint)) = polygons.results[block].lane(lane) else {
            self.one_pair_left_by_block::<FRICTIONAL>(p, None, state, length, active, record, sums);
            return;
        };
        let forces = &polygons.forces[block];
        let at = |v: &BlockLanes| v.0[lane];
        if !SecantLaw::in_domain(at(&forces.denominator), at(&forces.floor)) {
            let computed = Some((geometry, hint));
            self.one_pair_left_by_block::<FRICTIONAL>(
                p, computed, state, length, active, record, sums,
            );
            return;
        }
        let pair = |v: &[BlockLanes; 2]| DVec2::new(at(&v[0]), at(&v[1]));
        let touch = Touch {
            geometry,
            stiffness: at(&forces.stiffness),
            capped: false,
            force: at(&forces.force),
            relative_velocity: pair(&forces.relative_velocity),
            effective_mass: at(&forces.effective_mass),
        };
        let branch = pair(&polygons.input[block].branch);
        self.record::<FRICTIONAL>(
            Some(touch),
            hint,
            branch,
            state,
            length,
            active,
            record,
            sums,
        );
    }

    /// Writes what the pair's step left: for a contact its record, its state (the tangential
    /// spring) and its share of the sums; for an open or failed pair only its search hint (its
    /// spring resets).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn record<const FRICTIONAL: bool>(
        &self,
        touch: Option<Touch>,
        hint: PairHint,
        branch: DVec2,
        state: &mut PairState,
        length: &mut f64,
        active: &mut bool,
        record: &mut PairContact,
        sums: &mut PairSums,
    ) {
        *active = touch.is_some();
        let Some(touch) = touch else {
            *state = PairState {
                hint,
                ..Default::default()
            };
            *length = 0.0;
            return;
        };
        let c = &touch.geometry;
        sums.capped += touch.capped as u64;
        let tangential = match &self.params.friction {
            // FRICTIONAL is the general path: it keeps the test of the friction it is given.
            Some(friction) if FRICTIONAL && friction.grains > 0.0 => friction.law.response(
                state.tangential_history,
                touch.stiffness,
                touch.force,
                touch.relative_velocity.dot(c.normal.perp()),
                friction.grains,
                touch.effective_mass,
                self.params.dt,
            ),
            _ => TangentialResponse::default(),
        };
        // Without friction the response is zero: the sums (from +0) would add +0.
        if FRICTIONAL {
            sums.dissipation += tangential.dissipated;
            sums.sliding += tangential.sliding as u64;
        }
        *record = PairContact {
            normal: c.normal,
            force: touch.force,
            tangential_force: tangential.force,
            point: c.point,
            cap_area_first: c.cap_area_i,
            cap_area_second: c.cap_area_j,
        };
        *state = PairState {
            hint,
            tangential_history: tangential.history,
        };
        *length = c.length;
        if self.periodic.is_some() {
            let share = symmetric_dyad(record.force_on_first_in::<FRICTIONAL>(), branch);
            for (sum, x) in sums.moment.iter_mut().zip(share) {
                *sum += x;
            }
        }
    }

    /// `LANES` consecutive pairs of circles from pair `first` on, side by side, then recorded
    /// one by one in pair order (so that the sums keep their order). `input` and `out` are the
    /// chunk's lanes: every lane of `input` is set here, every lane of `out` written by the
    /// kernel.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn circle_block<const FRICTIONAL: bool>(
        &self,
        first: usize,
        input: &mut DiscPairs<PairLanes>,
        out: &mut DiscPairForces<PairLanes>,
        states: &mut [PairState],
        lengths: &mut [f64],
        actives: &mut [bool],
        records: &mut [PairContact],
        sums: &mut PairSums,
    ) {
        // A plain loop: `array::from_fn` built such arrays aside and copied them (a `memcpy` a
        // block).
        let frames = self.frames;
        let mut ends = [(frames.row(0), frames.row(0)); LANES];
        for (end, &[i, j]) in ends.iter_mut().zip(&self.pairs[first..first + LANES]) {
            *end = (frames.row(i as usize), frames.row(j as usize));
        }
        input.set_circles(&ends);
        // Only the branch vectors outlive the lanes' setting (zero outside a periodic cell).
        let branches = match &self.periodic {
            Some((cell, velocity_gradient)) => {
                input.meet_images(cell, velocity_gradient, &self.images[first..first + LANES])
            }
            None => Default::default(),
        };
        disc_pair_forces_dispatch(input, &self.params.law, self.params.contact_damping, out);
        let radius = [&input.first.radius, &input.second.radius];
        if !FRICTIONAL
            && let Some(contact) = out
                .contacts_if_regular(radius)
                .or_else(|| out.contacts_with_exact_deep_caps(radius))
        {
            self.record_regular_block(
                out, &contact, &branches, states, lengths, actives, records, sums,
            );
            return;
        }
        for lane in 0..LANES {
            let p = first + lane;
            let branch = DVec2::new(branches[0].0[lane], branches[1].0[lane]);
            let (state, length, active, record) = (
                &mut states[lane],
                &mut lengths[lane],
                &mut actives[lane],
                &mut records[lane],
            );
            let radius = [input.first.radius.0[lane], input.second.radius.0[lane]];
            let touch = match out.lane(lane, &radius) {
                LaneCase::Irregular => {
                    self.one_pair::<FRICTIONAL>(p, None, state, length, active, record, sums);
                    continue;
                }
                LaneCase::Separate => None,
                LaneCase::Contact(touch) => Some(touch),
            };
            self.record::<FRICTIONAL>(
                touch, state.hint, branch, state, length, active, record, sums,
            );
        }
    }

    /// A frictionless block whose lanes are each apart or a contact in the kernel's regular
    /// case (`contact`): what [`record`](Self::record) writes for each lane, without the cases
    /// of [`DiscPairForces::lane`]. A regular contact is never capped and has no tangential
    /// force, and a pair of circles keeps its hint. Nor is its state read or written unless
    /// `springs_to_drop`: in a world without friction between grains every step writes the
    /// frictionless response's zero spring, so that a pair holds one only after a checkpoint's
    /// history was restored into it, until the next step. A pair of circles writes its length
    /// alone (issue #16: reading and writing back its state's line was some 4% of a step of
    /// rigid discs on LAMMPS's packing).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn record_regular_block(
        &self,
        out: &DiscPairForces<PairLanes>,
        contact: &[bool; LANES],
        branches: &[PairLanes; 2],
        states: &mut [PairState],
        lengths: &mut [f64],
        actives: &mut [bool],
        records: &mut [PairContact],
        sums: &mut PairSums,
    ) {
        let frictionless = TangentialResponse::default();
        let states = &mut states[..LANES];
        if self.springs_to_drop {
            for state in states.iter_mut() {
                state.tangential_history = frictionless.history;
            }
        }
        debug_assert!(
            states
                .iter()
                .all(|state| state.tangential_history.to_bits() == frictionless.history.to_bits())
        );
        let (lengths, actives, records) = (
            &mut lengths[..LANES],
            &mut actives[..LANES],
            &mut records[..LANES],
        );
        actives.copy_from_slice(contact);
        let periodic = self.periodic.is_some();
        for lane in 0..LANES {
            let at = |v: &PairLanes| v.0[lane];
            if !contact[lane] {
                lengths[lane] = 0.0;
                continue;
            }
            let pair = |v: &[PairLanes; 2]| DVec2::new(at(&v[0]), at(&v[1]));
            records[lane] = PairContact {
                normal: pair(&out.normal),
                force: at(&out.response.force),
                tangential_force: frictionless.force,
                point: pair(&out.point),
                cap_area_first: at(&out.cap_area[0]),
                cap_area_second: at(&out.cap_area[1]),
            };
            lengths[lane] = chord_length(at(&out.half_chord));
            if periodic {
                let branch = pair(branches);
                let share = symmetric_dyad(records[lane].normal_force_on_first(), branch);
                for (sum, x) in sums.moment.iter_mut().zip(share) {
                    *sum += x;
                }
            }
        }
    }
}

/// How far ahead of the pair in hand the pair pass looks for pairs to fill a block of polygon
/// lanes.
const POLYGON_WINDOW: usize = 16;

/// Contacts of polygon pairs computed ahead, two blocks of [`BLOCK`] at a time, for the pair
/// pass to take in pair order: the first pair on the polygons' common path fills the blocks
/// with the next such pairs within [`POLYGON_WINDOW`] (each computed exactly as on its own, so
/// the blocks' make-up changes no bit).
struct PolygonsAhead<'a> {
    /// The table and the kernel, where the processor runs one and some frame is not a circle.
    table: Option<(&'a ContourTable, BlockKernel)>,
    /// The blocks' pairs (chunk indices, increasing) and their results; `taken` of them used.
    pairs: [usize; PAIRS],
    /// The blocks' pairs as the kernel reads them, kept from turn to turn (only their
    /// filling changes).
    lanes: AheadLanes<'a>,
    results: [BlockContacts; BLOCKS],
    /// The blocks' pairs as their normal forces read them, and those forces.
    input: [PolygonPairs; BLOCKS],
    forces: [PolygonPairForces; BLOCKS],
    filled: usize,
    taken: usize,
}

impl<'a> PolygonsAhead<'a> {
    /// Blocks of `contours`' polygons, where the processor runs them and some frame is not a
    /// circle.
    fn new(
        contours: &'a Contours,
        frames: SharedRows<'a, Frame>,
        every_frame_a_circle: bool,
    ) -> Self {
        Self {
            // Without frames there is no pair (and `AheadLanes` needs a row 0).
            table: match (contours, block_kernel()) {
                (Contours::Polygon(table), Some(kernel))
                    if !every_frame_a_circle && frames.len() > 0 =>
                {
                    Some((table, kernel))
                }
                _ => None,
            },
            pairs: [0; PAIRS],
            lanes: AheadLanes {
                frames,
                grains: [[0; 2]; PAIRS],
                hints: [PairHint::default(); PAIRS],
                shifts: [DVec2::ZERO; PAIRS],
            },
            results: [BlockContacts::default(); BLOCKS],
            input: [PolygonPairs::default(); BLOCKS],
            forces: [PolygonPairForces::default(); BLOCKS],
            filled: 0,
            taken: 0,
        }
    }

    /// The lane of the last blocks that holds the chunk's pair `k`, if one does: block
    /// `lane / BLOCK`, its lane `lane % BLOCK`.
    #[inline(always)]
    fn computed(&mut self, k: usize) -> Option<usize> {
        if self.taken < self.filled && self.pairs[self.taken] == k {
            self.taken += 1;
            return Some(self.taken - 1);
        }
        None
    }

    /// Whether `lane` is the first of a block that holds the chunk's pairs `k..k + BLOCK`,
    /// each one's contact from the common path and its law in its domain: what
    /// [`record_block`](Self::record_block) writes.
    #[inline(always)]
    fn holds_block_from(&self, lane: usize, k: usize) -> bool {
        if !lane.is_multiple_of(BLOCK) || self.filled < lane + BLOCK {
            return false;
        }
        let block = lane / BLOCK;
        let forces = &self.forces[block];
        // The blocks' pairs increase from their first.
        self.pairs[lane] == k
            && self.pairs[lane + BLOCK - 1] == k + BLOCK - 1
            && self.results[block].all_on_path()
            // Every lane tested, without a branch each: compared in lanes.
            && (0..BLOCK).fold(true, |all, l| {
                all & SecantLaw::in_domain(forces.denominator.0[l], forces.floor.0[l])
            })
    }

    /// Writes the states, flags and records of the chunk's pairs `k..k + BLOCK`, the block
    /// from `lane`, where [`holds_block_from`](Self::holds_block_from) says that they are its
    /// contacts, as
    /// [`PairPass::record`] writes each one's without friction: the contact with its normal
    /// force, no tangential force, its hint in the state and its length. Takes every lane of
    /// the block.
    #[inline(always)]
    fn record_block(
        &mut self,
        lane: usize,
        k: usize,
        states: &mut [PairState],
        lengths: &mut [f64],
        actives: &mut [bool],
        records: &mut [PairContact],
    ) {
        let pairs = k..k + BLOCK;
        let (states, lengths, actives, records): (
            &mut [PairState; BLOCK],
            &mut [f64; BLOCK],
            &mut [bool; BLOCK],
            &mut [PairContact; BLOCK],
        ) = (
            (&mut states[pairs.clone()])
                .try_into()
                .expect("a block's states"),
            (&mut lengths[pairs.clone()])
                .try_into()
                .expect("a block's lengths"),
            (&mut actives[pairs.clone()])
                .try_into()
                .expect("a block's flags"),
            (&mut records[pairs]).try_into().expect("a block's records"),
        );
        let block = lane / BLOCK;
        // SAFETY: blocks are computed only where the processor has AVX (`table` is set only
        // there: `new`).
        #[cfg(target_arch = "x86_64")]
        unsafe {
            self.write_records_avx(block, records)
        };
        let (_, _, length, _) = self.results[block].contact_lanes();
        let (_, _, hints) = self.results[block].cap_and_hint_lanes();
        for l in 0..BLOCK {
            states[l] = PairState {
                hint: hints[l],
                tangential_history: TangentialResponse::default().history,
            };
            lengths[l] = length[l];
            actives[l] = true;
        }
        self.taken = lane + BLOCK;
    }

    /// The records of [`record_block`](Self::record_block): the lanes' fields as rows of
    /// four words, transposed into the records' two halves.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn write_records_avx(&self, block: usize, records: &mut [PairContact; BLOCK]) {
        use crate::lanes::avx::transpose;
        use std::arch::x86_64::*;
        let (point, normal, _, _) = self.results[block].contact_lanes();
        let (cap_area_i, cap_area_j, _) = self.results[block].cap_and_hint_lanes();
        // SAFETY: every load reads four initialised f64s, and every store writes the first or
        // second half of a record: eight f64s, 64-byte aligned, in the order asserted
        // beside `PairContact`.
        unsafe {
            let load = |lanes: &[f64; BLOCK]| _mm256_loadu_pd(lanes.as_ptr());
            let tangential_force = _mm256_set1_pd(TangentialResponse::default().force);
            let heads = transpose([
                load(&normal[0]),
                load(&normal[1]),
                load(&self.forces[block].force.0),
                tangential_force,
            ]);
            let tails = transpose([
                load(&point[0]),
                load(&point[1]),
                load(cap_area_i),
                load(cap_area_j),
            ]);
            for (record, (head, tail)) in records.iter_mut().zip(heads.into_iter().zip(tails)) {
                let words = (record as *mut PairContact).cast::<f64>();
                _mm256_store_pd(words, head);
                _mm256_store_pd(words.add(4), tail);
            }
        }
    }

    /// The lane that holds the chunk's pair `k` (not in the last blocks), after computing
    /// blocks from `k` on where `k` is on the common path; `None` leaves the pair to the
    /// one-pair path.
    #[inline(always)]
    fn take(
        &mut self,
        pass: &PairPass<'a>,
        k: usize,
        first_pair: usize,
        states: &[PairState],
    ) -> Option<usize> {
        let (table, kernel) = self.table?;
        if !pass.on_polygon_path(first_pair + k, &states[k].hint) {
            return None;
        }
        // Read once, not at every pair: the stores below might reach it, for all the
        // compiler knows.
        let rows = self.lanes.frames.len();
        // A pair's grains, checked to be rows of the frames (see `AheadLanes::grains`).
        let checked = |grains: [u32; 2]| {
            assert!((grains[0] as usize) < rows && (grains[1] as usize) < rows);
            grains
        };
        let lanes = &mut self.lanes;
        lanes.grains[0] = checked(pass.pairs[first_pair + k]);
        lanes.hints[0] = states[k].hint;
        self.pairs[0] = k;
        let mut filled = 1;
        let window = k + 1..(k + POLYGON_WINDOW).min(states.len());
        // The window's pairs beside their states (one bounds check, not one a pair).
        let window_pairs = &pass.pairs[first_pair + window.start..first_pair + window.end];
        for ((ahead, state), &grains) in window.clone().zip(&states[window]).zip(window_pairs) {
            let hint = state.hint;
            let p = first_pair + ahead;
            if pass.on_polygon_path(p, &hint) {
                lanes.grains[filled] = checked(grains);
                lanes.hints[filled] = hint;
                self.pairs[filled] = ahead;
                filled += 1;
                if filled == PAIRS {
                    break;
                }
            }
        }
        // Spare lanes repeat the first pair; their results are not used.
        for lane in filled..PAIRS {
            lanes.grains[lane] = lanes.grains[0];
            lanes.hints[lane] = lanes.hints[0];
        }
        if let Some((cell, _)) = &pass.periodic {
            for (lane, shift) in lanes.shifts.iter_mut().enumerate() {
                let ahead = self.pairs[if lane < filled { lane } else { 0 }];
                *shift = cell.image_shift(pass.images[first_pair + ahead]);
            }
        }
        let shifted = pass.periodic.is_some();
        grain_grain_blocks(
            kernel,
            table,
            &self.lanes,
            shifted,
            filled,
            &mut self.results,
        );
        for b in 0..filled.div_ceil(BLOCK) {
            // SAFETY: a block is computed only where the processor has AVX (`table` is set
            // only there: `new`).
            #[cfg(target_arch = "x86_64")]
            unsafe {
                self.input[b].set_pairs_avx(pass, &self.lanes, b);
                polygon_pair_forces_avx(
                    &self.results[b],
                    &self.input[b],
                    &pass.params.law,
                    pass.params.contact_damping,
                    &mut self.forces[b],
                );
            }
        }
        self.filled = filled;
        self.taken = 1;
        Some(0)
    }
}

#[cfg(test)]
thread_local! {
    /// Set by a test to run the pass with another kernel than the processor's fastest.
    static KERNEL_FOR_TESTS: std::cell::Cell<Option<BlockKernel>> =
        const { std::cell::Cell::new(None) };
}

/// The kernel of the polygon blocks: the fastest this processor runs, if it runs one.
fn block_kernel() -> Option<BlockKernel> {
    #[cfg(test)]
    if let Some(kernel) = KERNEL_FOR_TESTS.get() {
        return Some(kernel);
    }
    BlockKernel::best()
}

/// The pairs of a call of the polygon kernel as it reads them ([`LanePairs`]): each lane's two
/// grains, whose frames the kernel reads where they lie, and the pair's hint and the shift to
/// its second grain's image, copied as the window is filled. A lane costs the filling 24 bytes
/// written (and 16 more in a periodic cell) where a `LanePair` and the pair's two frame
/// references were 80 (issue #16).
struct AheadLanes<'a> {
    frames: SharedRows<'a, Frame>,
    /// Each lane's two grains: rows of `frames`, checked as they are written
    /// (`PolygonsAhead::take`; row 0 exists before: `PolygonsAhead::new`).
    grains: [[u32; 2]; PAIRS],
    hints: [PairHint; PAIRS],
    /// In a periodic cell only; zero, and not read, elsewhere.
    shifts: [DVec2; PAIRS],
}

impl<'a> AheadLanes<'a> {
    /// Lane `lane`'s two frames.
    #[inline(always)]
    fn frames_of(&self, lane: usize) -> [&'a Frame; 2] {
        // SAFETY: every lane's grains are rows of `frames` (see `grains`).
        self.grains[lane].map(|g| unsafe { self.frames.row_unchecked(g as usize) })
    }
}

// SAFETY: a lane's shape is its frame's (`Frame::lane_shape`), a row of the frames (see
// `grains`); its hint and shift are the lane's own.
unsafe impl LanePairs for AheadLanes<'_> {
    #[inline(always)]
    unsafe fn shape(&self, lane: usize, second: bool) -> [*const f64; 2] {
        // SAFETY: the lane is below `PAIRS` (the caller's), and its grain a row of `frames`
        // (see `grains`).
        let frame = unsafe {
            let grains = self.grains.get_unchecked(lane);
            self.frames.row_unchecked(grains[second as usize] as usize)
        };
        let shape = frame.lane_shape();
        [shape.center_and_radius.as_ptr(), shape.map.as_ptr()]
    }

    #[inline(always)]
    unsafe fn j_shift(&self, lane: usize) -> *const f64 {
        // SAFETY: the caller's. A shift is two f64s (`DVec2` is `repr(C)`).
        (unsafe { self.shifts.get_unchecked(lane) } as *const DVec2).cast()
    }

    #[inline(always)]
    unsafe fn hint(&self, lane: usize) -> *const PairHint {
        // SAFETY: the caller's.
        unsafe { self.hints.get_unchecked(lane) }
    }
}

/// The lanes of a block of polygon pairs.
type BlockLanes = Lanes<BLOCK>;

/// One grain of each pair of a polygon block, as the pair's normal force reads it: its centre,
/// velocity, velocity gradient (by glam's columns) and mass.
#[derive(Debug, Clone, Copy, Default)]
struct PolygonEnds {
    center: [BlockLanes; 2],
    velocity: [BlockLanes; 2],
    velocity_gradient: [[BlockLanes; 2]; 2],
    mass: BlockLanes,
}

impl PolygonEnds {
    /// The lanes set to the grains of `frames` (not circles), each at its own centre: the
    /// four frames' (centre, radius, mass) and velocity gradients loaded as four vectors each
    /// and transposed, their velocities as two-lane vectors interleaved.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn set_avx(&mut self, frames: [&Frame; BLOCK]) {
        use crate::lanes::avx::transpose;
        use std::arch::x86_64::*;
        // SAFETY: each load reads an array of four f64s (a frame's centre, bounding radius
        // and mass, `Frame::lane_shape`; its velocity gradient's columns) or a `repr(C)`
        // `DVec2`, all initialised.
        unsafe {
            // Not `array::map`: its closure is not inlined here, and its calls cost more than
            // the loads.
            let first_line =
                |k: usize| _mm256_loadu_pd(frames[k].lane_shape().center_and_radius.as_ptr());
            let gradient =
                |k: usize| _mm256_loadu_pd(frames[k].velocity_gradient.as_ref().as_ptr());
            let [x, y, _, mass] =
                transpose([first_line(0), first_line(1), first_line(2), first_line(3)]);
            let [lxx, lxy, lyx, lyy] =
                transpose([gradient(0), gradient(1), gradient(2), gradient(3)]);
            let velocity = |k: usize| _mm_loadu_pd((&frames[k].velocity as *const DVec2).cast());
            let u0 = _mm256_insertf128_pd(_mm256_castpd128_pd256(velocity(0)), velocity(2), 1);
            let u1 = _mm256_insertf128_pd(_mm256_castpd128_pd256(velocity(1)), velocity(3), 1);
            let [to_x, to_y] = &mut self.center;
            let [to_vx, to_vy] = &mut self.velocity;
            let [[to_lxx, to_lxy], [to_lyx, to_lyy]] = &mut self.velocity_gradient;
            for (lanes, value) in [
                (to_x, x),
                (to_y, y),
                (to_vx, _mm256_unpacklo_pd(u0, u1)),
                (to_vy, _mm256_unpackhi_pd(u0, u1)),
                (to_lxx, lxx),
                (to_lxy, lxy),
                (to_lyx, lyx),
                (to_lyy, lyy),
                (&mut self.mass, mass),
            ] {
                // Lanes are four f64s aligned to 32 bytes.
                _mm256_store_pd(lanes.0.as_mut_ptr(), value);
            }
        }
    }

    /// The velocity of each lane's material point at `x`: [`Frame::velocity_at`]'s
    /// `v + L (x - c)`, with glam's product of a matrix and a vector.
    #[inline(always)]
    fn velocity_at(&self, x: &[BlockLanes; 2]) -> [BlockLanes; 2] {
        let offset = [x[0] - self.center[0], x[1] - self.center[1]];
        let l = &self.velocity_gradient;
        [
            self.velocity[0] + (l[0][0] * offset[0] + l[1][0] * offset[1]),
            self.velocity[1] + (l[0][1] * offset[0] + l[1][1] * offset[1]),
        ]
    }
}

/// What the normal forces of a polygon block's pairs read besides their contacts: the pairs'
/// two grains, the second at its image that meets the first, and, in a periodic cell, the
/// branch vectors and the affine field's `L d` (zero outside one), as [`PairPass::second_end`]
/// gives them.
#[derive(Debug, Clone, Copy, Default)]
struct PolygonPairs {
    first: PolygonEnds,
    second: PolygonEnds,
    branch: [BlockLanes; 2],
    affine_rate: [BlockLanes; 2],
}

impl PolygonPairs {
    /// The lanes set to the pairs of `pass` in block `block` of `lanes`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn set_pairs_avx(&mut self, pass: &PairPass<'_>, lanes: &AheadLanes<'_>, block: usize) {
        let first = block * BLOCK;
        // Not `array::from_fn`: its closure may not be inlined here (see `set_avx`).
        let ends = [
            lanes.frames_of(first),
            lanes.frames_of(first + 1),
            lanes.frames_of(first + 2),
            lanes.frames_of(first + 3),
        ];
        self.first
            .set_avx([ends[0][0], ends[1][0], ends[2][0], ends[3][0]]);
        self.second
            .set_avx([ends[0][1], ends[1][1], ends[2][1], ends[3][1]]);
        let Some((_, velocity_gradient)) = &pass.periodic else {
            return;
        };
        // The lanes hold each pair's image shift already.
        for (lane, [first_end, second_end]) in ends.into_iter().enumerate() {
            let shift = lanes.shifts[first + lane];
            let end = end_at_image(first_end, second_end, shift, velocity_gradient);
            let values = [
                (&mut self.second.center, end.center),
                (&mut self.branch, end.branch),
                (&mut self.affine_rate, end.affine_rate),
            ];
            for ([x, y], value) in values {
                (x.0[lane], y.0[lane]) = (value.x, value.y);
            }
        }
    }
}

/// The normal response of lanes of contacts ([`lane_response`]): the law's denominator and its
/// floor (a lane is in the law's domain where [`SecantLaw::in_domain`] says so), and the
/// quantities of a [`Touch`] in that case.
#[derive(Debug, Clone, Copy, Default)]
pub struct LaneResponse<T> {
    pub denominator: T,
    pub floor: T,
    pub stiffness: T,
    pub force: T,
    pub relative_velocity: [T; 2],
    pub effective_mass: T,
}

/// The normal response of a polygon block's contacts.
type PolygonPairForces = LaneResponse<BlockLanes>;

/// The normal response of lanes of contacts of length `length` and normal gap `normal_gap`
/// along `normal`, whose grains' material points at the contact move at `velocity` (first,
/// second grain; the affine field adds `affine_rate`, zero outside a periodic cell): the law's
/// denominator and floor ([`SecantLaw::response`] is in its domain where
/// [`SecantLaw::in_domain`] says so), its stiffness, and the one-pair path's relative velocity,
/// effective mass and [`damped_normal_force`], in its order.
#[inline(always)]
fn lane_response<T: Real>(
    law: &SecantLaw,
    damping_ratio: f64,
    ((length, normal_gap), normal): ((T, T), &[T; 2]),
    [velocity_i, velocity_j]: [[T; 2]; 2],
    affine_rate: &[T; 2],
    [mass_i, mass_j]: [T; 2],
    out: &mut LaneResponse<T>,
) {
    let (denominator, floor) = law.denominator(length, normal_gap);
    let stiffness = law.stiffness(length, denominator);
    let elastic = stiffness * normal_gap;
    let relative_velocity = [
        velocity_j[0] - velocity_i[0] + affine_rate[0],
        velocity_j[1] - velocity_i[1] + affine_rate[1],
    ];
    let gap_rate = relative_velocity[0] * normal[0] + relative_velocity[1] * normal[1];
    let effective_mass = mass_i * mass_j / (mass_i + mass_j);
    let force = damped_normal_force(
        elastic,
        stiffness,
        effective_mass,
        T::splat(damping_ratio),
        gap_rate,
    );
    *out = LaneResponse {
        denominator,
        floor,
        stiffness,
        force,
        relative_velocity,
        effective_mass,
    };
}

/// The normal forces of a block of polygon contacts `contacts` of the pairs `pairs`, as
/// [`PairPass::one_pair`] computes the force of a contact in the law's domain, in its order:
/// [`SecantLaw::response`], the relative velocity at the contact point and
/// [`damped_normal_force`] ([`lane_response`]). Lanes off the path or out of the domain compute
/// values nobody reads.
#[inline(always)]
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn polygon_pair_forces(
    contacts: &BlockContacts,
    pairs: &PolygonPairs,
    law: &SecantLaw,
    damping_ratio: f64,
    out: &mut PolygonPairForces,
) {
    let (first, second, affine_rate) = (&pairs.first, &pairs.second, &pairs.affine_rate);
    let (point, normal, length, normal_gap) = contacts.contact_lanes();
    let point = [Lanes(point[0]), Lanes(point[1])];
    let normal = [Lanes(normal[0]), Lanes(normal[1])];
    let (length, normal_gap) = (Lanes(*length), Lanes(*normal_gap));
    let velocity = [first.velocity_at(&point), second.velocity_at(&point)];
    let masses = [first.mass, second.mass];
    let contact = ((length, normal_gap), &normal);
    lane_response(
        law,
        damping_ratio,
        contact,
        velocity,
        affine_rate,
        masses,
        out,
    );
}

/// [`polygon_pair_forces`] compiled for AVX (the blocks' lanes run only where the processor
/// has it).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn polygon_pair_forces_avx(
    contacts: &BlockContacts,
    pairs: &PolygonPairs,
    law: &SecantLaw,
    damping_ratio: f64,
    out: &mut PolygonPairForces,
) {
    polygon_pair_forces(contacts, pairs, law, damping_ratio, out);
}

/// In a periodic cell, where the second grain of a pair (`first`, `second`) is met: at its image
/// shifted by `shift`, with the branch vector and the affine field's `L d` (`velocity_gradient`
/// L).
#[inline(always)]
fn end_at_image(
    first: &Frame,
    second: &Frame,
    shift: DVec2,
    velocity_gradient: &DMat2,
) -> SecondEnd {
    let center = second.center + shift;
    let branch = center - first.center;
    SecondEnd {
        center,
        branch,
        affine_rate: affine_rate(velocity_gradient, branch.into()).into(),
    }
}

/// The contact length `L_c` of a chord of half length `half_chord`.
#[inline(always)]
fn chord_length(half_chord: f64) -> f64 {
    2.0 * half_chord
}

/// The affine field's velocity `L d` at branch vector `d` (`velocity_gradient` L), summed as
/// glam's product of a matrix and a vector; for one pair or for lanes of pairs.
#[inline(always)]
fn affine_rate<T: Real>(velocity_gradient: &DMat2, branch: [T; 2]) -> [T; 2] {
    let (l, m) = (T::splat, velocity_gradient);
    [
        l(m.x_axis.x) * branch[0] + l(m.y_axis.x) * branch[1],
        l(m.x_axis.y) * branch[0] + l(m.y_axis.y) * branch[1],
    ]
}

/// What the kernel needs of pairs of circles: lanes of the pairs' first circles and second
/// circles, and the affine field's `L d`.
#[derive(Debug, Clone, Copy, Default)]
pub struct DiscPairs<T> {
    pub first: DiscLanes<T>,
    pub second: DiscLanes<T>,
    pub affine_rate: [T; 2],
}

/// One circle of each pair: lanes of centres, radii, masses, velocities, spins and dilation
/// rates ([`Frame::circle_dilation_rate`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct DiscLanes<T> {
    pub center: [T; 2],
    pub radius: T,
    pub mass: T,
    pub velocity: [T; 2],
    pub omega: T,
    pub dilation: T,
}

impl DiscLanes<PairLanes> {
    /// The lanes in the order of [`FRAME_LINE`]: centre x, centre y, radius, mass, velocity x,
    /// velocity y, spin, dilation rate.
    #[inline(always)]
    fn in_frame_order(&mut self) -> [&mut PairLanes; 8] {
        let [x, y] = &mut self.center;
        let [vx, vy] = &mut self.velocity;
        [
            x,
            y,
            &mut self.radius,
            &mut self.mass,
            vx,
            vy,
            &mut self.omega,
            &mut self.dilation,
        ]
    }

    /// Lane `lane` set to the circle of `frame`.
    #[inline(always)]
    fn set_lane(&mut self, lane: usize, frame: &Frame) {
        let values = [
            frame.center.x,
            frame.center.y,
            frame.bounding_radius,
            frame.mass,
            frame.velocity.x,
            frame.velocity.y,
            frame.omega,
            frame.circle_dilation,
        ];
        for (lanes, value) in self.in_frame_order().into_iter().zip(values) {
            lanes.0[lane] = value;
        }
    }
}

impl DiscPairs<PairLanes> {
    /// Sets lane `lane` to the pair of circles `fi`, `fj`, the second met at `end`.
    #[inline(always)]
    #[cfg(test)]
    fn set_lane(&mut self, lane: usize, fi: &Frame, fj: &Frame, end: &SecondEnd) {
        self.first.set_lane(lane, fi);
        self.second.set_lane(lane, fj);
        self.set_second_end(lane, end);
    }

    /// Sets every lane to its pair of circles (`ends`: the two frames), the second at its own
    /// centre, leaving the affine rate as it is: what the kernel reads of a frame is its first
    /// 56 bytes, moved four frames at a time with vector shuffles where the processor has AVX
    /// (the same values, so the same bits). In a periodic cell,
    /// [`meet_images`](Self::meet_images) follows.
    #[inline(always)]
    fn set_circles(&mut self, ends: &[(&Frame, &Frame); LANES]) {
        #[cfg(target_arch = "x86_64")]
        if crate::lanes::Simd::discs_in_avx512() {
            // SAFETY: the processor has AVX-512 (`discs_in_avx512` holds only there).
            unsafe { self.set_circles_avx512(ends) };
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the processor has AVX (tested just above).
            unsafe { self.set_circles_avx(ends) };
            return;
        }
        for (lane, (fi, fj)) in ends.iter().enumerate() {
            self.first.set_lane(lane, fi);
            self.second.set_lane(lane, fj);
        }
    }

    /// In a periodic cell, moves each lane's second circle to its image `images[lane]` (the
    /// one that meets the first), sets the affine rate `L d` of the branch vector d and returns
    /// the branch vectors' lanes: the operations of [`PairPass::second_end`], lane by lane (the
    /// shifts, zero or not, are added as there).
    #[inline(always)]
    fn meet_images(
        &mut self,
        cell: &PeriodicCell,
        velocity_gradient: &DMat2,
        images: &[[i64; 2]],
    ) -> [PairLanes; 2] {
        let mut shift = [PairLanes::default(); 2];
        for (lane, &image) in images.iter().enumerate() {
            let s = cell.image_shift(image);
            (shift[0].0[lane], shift[1].0[lane]) = (s.x, s.y);
        }
        for (center, shift) in self.second.center.iter_mut().zip(shift) {
            *center = *center + shift;
        }
        let branch = [
            self.second.center[0] - self.first.center[0],
            self.second.center[1] - self.first.center[1],
        ];
        self.affine_rate = affine_rate(velocity_gradient, branch);
        branch
    }

    /// The second circle of lane `lane` met at `end` (a periodic image), with the affine rate.
    #[inline(always)]
    #[cfg(test)]
    fn set_second_end(&mut self, lane: usize, end: &SecondEnd) {
        self.second.center[0].0[lane] = end.center.x;
        self.second.center[1].0[lane] = end.center.y;
        self.affine_rate[0].0[lane] = end.affine_rate.x;
        self.affine_rate[1].0[lane] = end.affine_rate.y;
    }

    /// [`set_circles`](Self::set_circles) with AVX-512: for each circle of the pairs, the eight
    /// frames' halves of a line (centre, radius, mass; velocity, spin, dilation rate) loaded as
    /// two-frame vectors and transposed (issue #16: the eight lanes in one register each, where
    /// AVX took two quads of four).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn set_circles_avx512(&mut self, ends: &[(&Frame, &Frame); LANES]) {
        use std::arch::x86_64::*;
        const _: () = assert!(LANES == 8);
        for (second, circles) in [(false, &mut self.first), (true, &mut self.second)] {
            let frame = |k: usize| {
                let (fi, fj) = ends[k];
                if second { fj } else { fi }
            };
            // The loads read through a pointer to the whole frame (a pointer to one field may
            // not read past it).
            let line = |k: usize| (frame(k) as *const Frame).cast::<f64>();
            // SAFETY: as in `set_circles_avx`: a frame is aligned to 64 bytes and holds the
            // eight f64s of `FRAME_LINE` in its first line, all initialised; the lanes are
            // stored unaligned, eight values each.
            unsafe {
                // Half `h` of the line of frames k and k + 4 in one register: [k | k + 4].
                let pair = |k: usize, h: usize| {
                    _mm512_insertf64x4::<1>(
                        _mm512_castpd256_pd512(_mm256_load_pd(line(k).add(4 * h))),
                        _mm256_load_pd(line(k + 4).add(4 * h)),
                    )
                };
                let even = _mm512_setr_epi64(0, 1, 8, 9, 4, 5, 12, 13);
                let odd = _mm512_setr_epi64(2, 3, 10, 11, 6, 7, 14, 15);
                // The four words of half `h` of the eight frames, a register each.
                let transposed = |h: usize| {
                    let (z0, z1, z2, z3) = (pair(0, h), pair(1, h), pair(2, h), pair(3, h));
                    // Per 256-bit half: words (0, 0', 2, 2') and (1, 1', 3, 3') of two
                    // consecutive frames.
                    let (t0, t1) = (_mm512_unpacklo_pd(z0, z1), _mm512_unpackhi_pd(z0, z1));
                    let (t2, t3) = (_mm512_unpacklo_pd(z2, z3), _mm512_unpackhi_pd(z2, z3));
                    [
                        _mm512_permutex2var_pd(t0, even, t2),
                        _mm512_permutex2var_pd(t1, even, t3),
                        _mm512_permutex2var_pd(t0, odd, t2),
                        _mm512_permutex2var_pd(t1, odd, t3),
                    ]
                };
                let [x, y, radius, mass] = transposed(0);
                let [vx, vy, omega, dilation] = transposed(1);
                let values = [x, y, radius, mass, vx, vy, omega, dilation];
                for (lanes, value) in circles.in_frame_order().into_iter().zip(values) {
                    _mm512_storeu_pd(lanes.0.as_mut_ptr(), value);
                }
            }
        }
    }

    /// [`set_circles`](Self::set_circles) with AVX: for each circle of the pairs and each four
    /// lanes, the four frames' (centre, radius, mass) loaded as four vectors and transposed,
    /// their (velocity) and (spin, dilation rate) as two-lane vectors interleaved.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn set_circles_avx(&mut self, ends: &[(&Frame, &Frame); LANES]) {
        use std::arch::x86_64::*;
        for (second, circles) in [(false, &mut self.first), (true, &mut self.second)] {
            for quad in 0..LANES / 4 {
                let frame = |k: usize| {
                    let (fi, fj) = ends[4 * quad + k];
                    if second { fj } else { fi }
                };
                // The loads read through a pointer to the whole frame (a pointer to one field
                // may not read past it).
                let line = |k: usize| (frame(k) as *const Frame).cast::<f64>();
                // SAFETY: a frame is aligned to 64 bytes and holds the eight f64s of
                // `FRAME_LINE` in its first line (as `FRAME_LINE` asserts), all initialised; a
                // lane vector is aligned to 32 bytes and the four lanes from `4 quad` are
                // within its eight.
                unsafe {
                    let first_half = |k: usize| _mm256_load_pd(line(k));
                    let (a0, a1, a2, a3) =
                        (first_half(0), first_half(1), first_half(2), first_half(3));
                    let (t0, t1) = (_mm256_unpacklo_pd(a0, a1), _mm256_unpackhi_pd(a0, a1));
                    let (t2, t3) = (_mm256_unpacklo_pd(a2, a3), _mm256_unpackhi_pd(a2, a3));
                    let x = _mm256_permute2f128_pd(t0, t2, 0x20);
                    let y = _mm256_permute2f128_pd(t1, t3, 0x20);
                    let radius = _mm256_permute2f128_pd(t0, t2, 0x31);
                    let mass = _mm256_permute2f128_pd(t1, t3, 0x31);
                    // The second half's two pairs of words, (velocity x, y) and (spin,
                    // dilation rate), each as two-lane vectors of frames (k, k + 2)
                    // interleaved: fewer lane-crossing shuffles than its transpose (which made
                    // the whole `set_circles_avx` a fifth slower on the rigid lattice).
                    let words = |k: usize, w: usize| _mm_load_pd(line(k).add(w));
                    let interleaved = |w: usize| {
                        let u0 = _mm256_insertf128_pd(
                            _mm256_castpd128_pd256(words(0, w)),
                            words(2, w),
                            1,
                        );
                        let u1 = _mm256_insertf128_pd(
                            _mm256_castpd128_pd256(words(1, w)),
                            words(3, w),
                            1,
                        );
                        [_mm256_unpacklo_pd(u0, u1), _mm256_unpackhi_pd(u0, u1)]
                    };
                    let [vx, vy] = interleaved(FRAME_LINE[4] / 8);
                    let [omega, dilation] = interleaved(FRAME_LINE[6] / 8);
                    let values = [x, y, radius, mass, vx, vy, omega, dilation];
                    for (lanes, value) in circles.in_frame_order().into_iter().zip(values) {
                        _mm256_store_pd(lanes.0.as_mut_ptr().add(4 * quad), value);
                    }
                }
            }
        }
    }
}

/// The byte offsets in a [`Frame`] of what a circle's lanes read, in the order of
/// [`DiscLanes::in_frame_order`]: centre x and y, radius and mass in the first 32 bytes, then
/// the velocity, the spin and the dilation rate in the next 32, which the vector loads of
/// [`DiscPairs::set_circles`] rely on.
const FRAME_LINE: [usize; 8] = [0, 8, 16, 24, 32, 40, 48, 56];
const _: () = {
    use std::mem::offset_of;
    let center = offset_of!(Frame, center);
    let velocity = offset_of!(Frame, velocity);
    assert!(center + offset_of!(DVec2, x) == FRAME_LINE[0]);
    assert!(center + offset_of!(DVec2, y) == FRAME_LINE[1]);
    assert!(offset_of!(Frame, bounding_radius) == FRAME_LINE[2]);
    assert!(offset_of!(Frame, mass) == FRAME_LINE[3]);
    assert!(velocity + offset_of!(DVec2, x) == FRAME_LINE[4]);
    assert!(velocity + offset_of!(DVec2, y) == FRAME_LINE[5]);
    assert!(offset_of!(Frame, omega) == FRAME_LINE[6]);
    assert!(offset_of!(Frame, circle_dilation) == FRAME_LINE[7]);
    assert!(std::mem::align_of::<Frame>() >= 32);
    assert!(std::mem::align_of::<PairLanes>() >= 32);
};

/// The contact of each lane's circles computed as if they met in the kernel's regular case;
/// [`DiscPairForces::lane`] says, lane by lane, whether they do.
#[derive(Debug, Clone, Copy, Default)]
pub struct DiscPairForces<T> {
    pub distance_squared: T,
    pub reach: T,
    pub distance: T,
    pub half_chord: T,
    /// Distances of the chord from the two centres, and `sin theta` of the two caps.
    pub chord_distance: [T; 2],
    pub sine: [T; 2],
    pub normal: [T; 2],
    pub point: [T; 2],
    pub cap_area: [T; 2],
    pub normal_gap: T,
    /// The normal response.
    pub response: LaneResponse<T>,
}

/// What one lane of [`DiscPairForces`] is.
enum LaneCase {
    Separate,
    /// Not the kernel's regular case: the one-pair path decides.
    Irregular,
    Contact(Touch),
}

impl DiscPairForces<PairLanes> {
    /// Lane `lane`, whose circles have the radii `radius`: the tests of [`disc_disc`],
    /// [`chord_segment_area`](crate::geometry::circle::chord_segment_area) and
    /// [`SecantLaw::response`], in their order.
    #[inline(always)]
    fn lane(&self, lane: usize, radius: &[f64; 2]) -> LaneCase {
        let at = |v: &PairLanes| v.0[lane];
        if discs_apart(at(&self.distance_squared), at(&self.reach)) {
            return LaneCase::Separate;
        }
        if !self.regular(lane, radius) {
            return LaneCase::Irregular;
        }
        let pair = |v: &[PairLanes; 2]| DVec2::new(at(&v[0]), at(&v[1]));
        LaneCase::Contact(Touch {
            geometry: ContactGeometry {
                point: pair(&self.point),
                normal: pair(&self.normal),
                length: chord_length(at(&self.half_chord)),
                cap_area_i: at(&self.cap_area[0]),
                cap_area_j: at(&self.cap_area[1]),
                normal_gap: at(&self.normal_gap),
            },
            stiffness: at(&self.response.stiffness),
            capped: false,
            force: at(&self.response.force),
            relative_velocity: pair(&self.response.relative_velocity),
            effective_mass: at(&self.response.effective_mass),
        })
    }

    /// Whether lane `lane`'s circles, if they overlap, meet in the kernel's regular case.
    #[inline(always)]
    fn regular(&self, lane: usize, radius: &[f64; 2]) -> bool {
        // `&`, not `&&`: the tests have no effects, and without branches they run on whole
        // vectors in `contacts_if_regular`.
        self.regular_but_caps(lane, radius) & self.shallow_caps(lane)
    }

    /// [`regular`](Self::regular) but for the depth of the caps: the circles cross, and the
    /// law holds.
    #[inline(always)]
    fn regular_but_caps(&self, lane: usize, radius: &[f64; 2]) -> bool {
        let at = |v: &PairLanes| v.0[lane];
        !disc_swallowed(at(&self.distance), radius[0], radius[1])
            & !degenerate_chord(at(&self.half_chord), at(&self.reach))
            & SecantLaw::in_domain(at(&self.response.denominator), at(&self.response.floor))
    }

    /// Whether both caps of lane `lane` lie in the range of the kernel's series
    /// ([`shallow_cap`]).
    #[inline(always)]
    fn shallow_caps(&self, lane: usize) -> bool {
        let at = |v: &PairLanes| v.0[lane];
        shallow_cap(at(&self.chord_distance[0]), at(&self.sine[0]))
            & shallow_cap(at(&self.chord_distance[1]), at(&self.sine[1]))
    }

    /// [`contacts_if_regular`](Self::contacts_if_regular) of a block that is not regular,
    /// where the only lanes out of the regular case are those with a deep cap (past the range
    /// of the kernel's series): those caps take [`chord_segment_area`] (the one-pair path's
    /// bits, its closed form) in place of the series, and the block is regular. On `sdem
    /// bench`'s lattice a third of the blocks hold a deep cap (one lane in 25); such a block
    /// went lane by lane, its deep pairs by the one-pair path. One lane at a time, out of the
    /// common path: the arc tangent in every lane of such blocks, or in the kernel, cost more
    /// than the one-pair path it saved.
    #[cold]
    #[inline(never)]
    fn contacts_with_exact_deep_caps(&mut self, radius: [&PairLanes; 2]) -> Option<[bool; LANES]> {
        // The lanes' tests without a branch a lane (a third of such blocks' lanes would be
        // mispredicted), the deep ones as bits.
        let mut contact = [false; LANES];
        let mut irregular = false;
        let mut deep = 0u32;
        for (lane, contact) in contact.iter_mut().enumerate() {
            let lane_radius = [radius[0].0[lane], radius[1].0[lane]];
            *contact = !discs_apart(self.distance_squared.0[lane], self.reach.0[lane]);
            irregular |= *contact & !self.regular_but_caps(lane, &lane_radius);
            deep |= ((*contact & !self.shallow_caps(lane)) as u32) << lane;
        }
        if irregular {
            return None;
        }
        while deep != 0 {
            let lane = deep.trailing_zeros() as usize;
            deep &= deep - 1;
            for (k, radius) in radius.iter().enumerate() {
                self.cap_area[k].0[lane] = chord_segment_area(
                    radius.0[lane],
                    self.chord_distance[k].0[lane],
                    self.half_chord.0[lane],
                );
            }
        }
        Some(contact)
    }

    /// Which lanes are contacts, when [`lane`](Self::lane) is apart or a contact for every
    /// lane (`radius`: the lanes of the first circles' radii and of the second's); None when a
    /// lane is irregular. The lanes are tested without branches, so that the tests can run on
    /// whole vectors.
    #[inline(always)]
    fn contacts_if_regular(&self, radius: [&PairLanes; 2]) -> Option<[bool; LANES]> {
        #[cfg(target_arch = "x86_64")]
        if crate::lanes::Simd::discs_in_avx512() {
            // SAFETY: the processor has AVX-512 (`discs_in_avx512` holds only there).
            return unsafe { self.contacts_if_regular_avx512(radius) };
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the processor has AVX (tested just above).
            return unsafe { self.contacts_if_regular_avx(radius) };
        }
        self.contacts_if_regular_in(radius)
    }

    /// [`contacts_if_regular`](Self::contacts_if_regular) compiled for AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn contacts_if_regular_avx(&self, radius: [&PairLanes; 2]) -> Option<[bool; LANES]> {
        self.contacts_if_regular_in(radius)
    }

    /// [`contacts_if_regular`](Self::contacts_if_regular) compiled for AVX-512.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f")]
    fn contacts_if_regular_avx512(&self, radius: [&PairLanes; 2]) -> Option<[bool; LANES]> {
        self.contacts_if_regular_in(radius)
    }

    #[inline(always)]
    fn contacts_if_regular_in(&self, radius: [&PairLanes; 2]) -> Option<[bool; LANES]> {
        let mut contact = [false; LANES];
        let mut irregular = false;
        for (lane, contact) in contact.iter_mut().enumerate() {
            let at = |v: &PairLanes| v.0[lane];
            let apart = discs_apart(at(&self.distance_squared), at(&self.reach));
            let regular = self.regular(lane, &[radius[0].0[lane], radius[1].0[lane]]);
            *contact = !apart;
            irregular |= !apart & !regular;
        }
        (!irregular).then_some(contact)
    }
}

/// The closed-form contact and normal force of pairs of circles, all taken as overlapping with
/// shallow caps and the law in its domain (the regular case; see [`DiscPairForces::lane`]): the
/// sequence of operations of [`disc_disc`], [`SecantLaw::response`] and
/// [`damped_normal_force`] in the one-pair path. Written to `out` field by field: a struct
/// built and then moved into place costs a copy of its 1.5 KB (see
/// [`disc_pair_forces_dispatch`]).
#[inline(always)]
pub fn disc_pair_forces<T: Real>(
    input: &DiscPairs<T>,
    law: &SecantLaw,
    damping_ratio: f64,
    out: &mut DiscPairForces<T>,
) {
    let (ci, cj) = (input.first.center, input.second.center);
    let (radius_i, radius_j) = (input.first.radius, input.second.radius);
    let branch = [cj[0] - ci[0], cj[1] - ci[1]];
    let distance_squared = branch[0] * branch[0] + branch[1] * branch[1];
    let reach = radius_i + radius_j;
    let distance = distance_squared.sqrt();
    let chord = disc_chord(branch, distance, radius_i, radius_j, reach);
    let half_chord = chord.half_chord;
    let normal = chord.normal;
    let chord_distance = [radius_i - chord.depth_i, radius_j - chord.depth_j];
    let sine = [half_chord / radius_i, half_chord / radius_j];
    let cap_area = [
        shallow_segment_area(radius_i, sine[0]),
        shallow_segment_area(radius_j, sine[1]),
    ];
    let point = [
        ci[0] + chord_distance[0] * normal[0],
        ci[1] + chord_distance[0] * normal[1],
    ];
    let length = T::splat(2.0) * half_chord;
    let normal_gap = T::splat(-0.5) * chord.overlap;
    let velocity_j = circle_velocity_at(
        input.second.velocity,
        input.second.omega,
        input.second.dilation,
        [point[0] - cj[0], point[1] - cj[1]],
    );
    let velocity_i = circle_velocity_at(
        input.first.velocity,
        input.first.omega,
        input.first.dilation,
        [point[0] - ci[0], point[1] - ci[1]],
    );
    let contact = ((length, normal_gap), &normal);
    let masses = [input.first.mass, input.second.mass];
    let velocity = [velocity_i, velocity_j];
    let response = &mut out.response;
    lane_response(
        law,
        damping_ratio,
        contact,
        velocity,
        &input.affine_rate,
        masses,
        response,
    );
    out.distance_squared = distance_squared;
    out.reach = reach;
    out.distance = distance;
    out.half_chord = half_chord;
    out.chord_distance = chord_distance;
    out.sine = sine;
    out.normal = normal;
    out.point = point;
    out.cap_area = cap_area;
    out.normal_gap = normal_gap;
}

/// [`disc_pair_forces`] on the lanes, with AVX where the processor has it (chosen at run time:
/// the same bits either way), written to `out`. The pair pass keeps one `input` and one `out`
/// for a chunk's blocks: built for each block, the two (2.5 KB) cost a clear and a copy that
/// took about 5% of the rigid level's step (perf, 10⁵ grains).
#[inline(always)]
pub fn disc_pair_forces_dispatch(
    input: &DiscPairs<PairLanes>,
    law: &SecantLaw,
    damping_ratio: f64,
    out: &mut DiscPairForces<PairLanes>,
) {
    #[cfg(target_arch = "x86_64")]
    if crate::lanes::Simd::discs_in_avx512() {
        // SAFETY: the processor has AVX-512 (`discs_in_avx512` holds only there).
        unsafe { disc_pair_forces_avx512(input, law, damping_ratio, out) };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the processor has AVX (tested just above).
        unsafe { disc_pair_forces_avx(input, law, damping_ratio, out) };
        return;
    }
    disc_pair_forces(input, law, damping_ratio, out);
}

/// [`disc_pair_forces`] of [`PairLanes`] compiled for the target feature `$feature`, as `$name`.
macro_rules! disc_pair_forces_for {
    ($name:ident, $feature:literal) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $feature)]
        fn $name(
            input: &DiscPairs<PairLanes>,
            law: &SecantLaw,
            damping_ratio: f64,
            out: &mut DiscPairForces<PairLanes>,
        ) {
            disc_pair_forces(input, law, damping_ratio, out);
        }
    };
}

disc_pair_forces_for!(disc_pair_forces_avx512, "avx512f");
disc_pair_forces_for!(disc_pair_forces_avx, "avx");

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::friction::FrictionSettings;
    use crate::grain::{Grain, Material, ModelLevel};
    use crate::integration::parameters::Friction;
    use crate::sample::unit_random;
    use rand::SeedableRng;

    /// A chunk's pairs' states, contact lengths, flags and records.
    type Slots = (Vec<PairState>, Vec<f64>, Vec<bool>, Vec<PairContact>);

    /// `pass.chunk` over all of the pass's pairs from `start`, held to the one-pair path pair
    /// by pair as it handles any world (with FRICTIONAL, a world without friction gets a zero
    /// tangential response; `chunk` takes the frictionless pass where there is no friction and
    /// must give the same bits): every record, state, flag and sum the same, bit for bit,
    /// signed zeros included. Returns the chunk's slots and sums.
    fn chunk_is_one_pair_by_pair(
        pass: &PairPass<'_>,
        start: &Slots,
        seed: u64,
    ) -> (Slots, PairSums) {
        let mut lanes = start.clone();
        let lane_sums = pass.chunk(0, &mut lanes.0, &mut lanes.1, &mut lanes.2, &mut lanes.3);
        let mut one = start.clone();
        let mut one_sums = PairSums::default();
        for p in 0..start.0.len() {
            let (state, length, active, record) =
                (&mut one.0[p], &mut one.1[p], &mut one.2[p], &mut one.3[p]);
            pass.one_pair::<true>(p, None, state, length, active, record, &mut one_sums);
        }
        assert_eq!(format!("{lanes:?}"), format!("{one:?}"), "seed {seed}");
        assert_eq!(
            format!("{lane_sums:?}"),
            format!("{one_sums:?}"),
            "seed {seed}"
        );
        (lanes, lane_sums)
    }

    /// Pairs of circles (grain 2k with grain 2k + 1) at every kind of separation: apart, shallow
    /// and deep overlaps (caps past the series' range, the law out of its domain), one circle
    /// swallowing the other, and grazing. The count is not a multiple of the lanes, so that the
    /// chunk's last pairs take the one-pair path.
    fn circle_pairs(seed: u64) -> (Vec<Frame>, Vec<[u32; 2]>) {
        circle_pairs_among_polygons(seed, |_| false)
    }

    /// [`circle_pairs`], but for the pairs `k` where `polygon(k)`, whose first grain is an
    /// ellipse's polygon (its strains apart by 0.02): a rigid grain that deformed and stepped
    /// down keeps its shape, and its pairs with discs are pairs of a circle and a polygon.
    fn circle_pairs_among_polygons(
        seed: u64,
        polygon: impl Fn(usize) -> bool,
    ) -> (Vec<Frame>, Vec<[u32; 2]>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut random = |lo: f64, hi: f64| lo + (hi - lo) * unit_random(&mut rng);
        let separations = [1.2, 1.0 - 1e-15, 0.999, 0.98, 0.9, 0.7, 0.5, 0.25, 0.05];
        let mut frames = Vec::new();
        let mut pairs = Vec::new();
        for k in 0..(10 * LANES + 3) {
            let grain = |center: DVec2, random: &mut dyn FnMut(f64, f64) -> f64, polygon: bool| {
                let mut g = Grain::at_rest(center, random(0.5, 1.0));
                let eps = random(-0.05, 0.0);
                (g.eps1, g.eps2) = (eps, eps);
                g.velocity = DVec2::new(random(-1.0, 1.0), random(-1.0, 1.0));
                g.omega = random(-2.0, 2.0);
                let density = random(0.5, 2.0);
                let mut frame = Frame::default();
                if polygon {
                    g.eps1 += 0.02;
                    frame = Frame::of_grain(&g, density);
                } else {
                    // Rigid discs, and discs at the volumetric level that dilate (both
                    // strains at one rate), half and half.
                    let level = if random(0.0, 1.0) < 0.5 {
                        ModelLevel::Rigid
                    } else {
                        let rate = random(-0.5, 0.5);
                        (g.eps1_rate, g.eps2_rate) = (rate, rate);
                        ModelLevel::Volumetric
                    };
                    frame.write_circle(&g, level, density);
                }
                frame
            };
            let first = grain(
                DVec2::new(random(-5.0, 5.0), random(-5.0, 5.0)),
                &mut random,
                polygon(k),
            );
            let mut second = grain(DVec2::ZERO, &mut random, false);
            // Most blocks hold contacts only; every third holds one of each kind, and each
            // block after it contacts and pairs apart (a block without irregular lanes).
            let separation = match (k / LANES) % 3 {
                0 => separations[k % separations.len()],
                1 if k % 3 == 0 => 1.2,
                _ => random(0.97, 0.999),
            };
            let reach = first.bounding_radius + second.bounding_radius;
            let angle = random(0.0, std::f64::consts::TAU);
            second.center = first.center + separation * reach * DVec2::from_angle(angle);
            frames.extend([first, second]);
            pairs.push([2 * k as u32, 2 * k as u32 + 1]);
        }
        (frames, pairs)
    }

    fn parameters(friction: bool) -> Parameters {
        let material = Material {
            young: 1.0,
            poisson: 0.5,
            density: 1.0,
        };
        let mut params = Parameters::new(material, 1e-3);
        if friction {
            let settings = FrictionSettings {
                grains: 0.4,
                damping: 0.3,
                ..Default::default()
            };
            params.friction = Friction::new(&settings, &[0.0; 4]);
        }
        params
    }

    #[test]
    fn a_block_irregular_only_by_its_deep_caps_takes_their_exact_areas() {
        // Expectation: a block of circle contacts whose only lanes out of the kernel's regular
        // case have a deep cap (sin theta > 0.3, the law in its domain) is a regular block once
        // those caps take chord_segment_area: every lane's cap areas are disc_disc's, bit for
        // bit, and the deep lane's is the closed form's, not the series' it had. A block with
        // another irregular lane (a swallowed pair) is left as it was, to the one-pair path.
        let law = SecantLaw::new(1.0, 0.58, 2.0);
        fn lanes(f: impl Fn(usize) -> f64) -> PairLanes {
            PairLanes::from_fn(f)
        }
        // Unit circles 1.98 apart (shallow caps, sin theta 0.2), lane 3 1.8 apart (depth 0.1,
        // sin theta 0.44).
        let distance = |l: usize| if l == 3 { 1.8 } else { 1.98 };
        let mut input = DiscPairs {
            first: DiscLanes {
                center: [lanes(|l| 5.0 * l as f64), lanes(|_| 0.0)],
                radius: lanes(|_| 1.0),
                mass: lanes(|_| 3.0),
                velocity: [lanes(|_| 0.1), lanes(|_| 0.0)],
                omega: lanes(|_| 0.2),
                dilation: lanes(|_| 0.0),
            },
            second: DiscLanes {
                center: [lanes(|l| 5.0 * l as f64 + distance(l)), lanes(|_| 0.0)],
                radius: lanes(|_| 1.0),
                mass: lanes(|_| 3.0),
                velocity: [lanes(|_| -0.1), lanes(|_| 0.0)],
                omega: lanes(|_| -0.2),
                dilation: lanes(|_| 0.0),
            },
            affine_rate: [lanes(|_| 0.0), lanes(|_| 0.0)],
        };
        let mut out = DiscPairForces::default();
        disc_pair_forces_dispatch(&input, &law, 1.0, &mut out);
        let radius = [&input.first.radius, &input.second.radius];
        assert!(out.contacts_if_regular(radius).is_none());
        let series = out.cap_area[0].0[3];
        let contact = out.contacts_with_exact_deep_caps(radius);
        assert_eq!(contact, Some([true; LANES]));
        for lane in 0..LANES {
            let at = |v: &PairLanes| v.0[lane];
            let (first, second) = (&input.first, &input.second);
            let center = |c: &[PairLanes; 2]| DVec2::new(at(&c[0]), at(&c[1]));
            let Overlap::Contact(exact) = disc_disc(
                center(&first.center),
                at(&first.radius),
                center(&second.center),
                at(&second.radius),
            ) else {
                panic!("lane {lane} is a contact");
            };
            assert_eq!(at(&out.cap_area[0]).to_bits(), exact.cap_area_i.to_bits());
            assert_eq!(at(&out.cap_area[1]).to_bits(), exact.cap_area_j.to_bits());
        }
        assert_ne!(out.cap_area[0].0[3], series);

        // Lane 5's second circle swallowed by its first.
        input.second.radius.0[5] = 0.3;
        input.second.center[0].0[5] = input.first.center[0].0[5] + 0.5;
        disc_pair_forces_dispatch(&input, &law, 1.0, &mut out);
        let radius = [&input.first.radius, &input.second.radius];
        assert!(out.contacts_with_exact_deep_caps(radius).is_none());
        assert_eq!(out.cap_area[0].0[3], series);
    }

    #[test]
    fn lanes_of_circle_pairs_give_the_one_pair_paths_bits() {
        // Expectation: the lane kernel is the one-pair path's sequence of operations, and a
        // lane outside its regular case is handed to that path; a frictionless block without
        // such a lane is recorded without the per-lane cases: every record, state, flag and
        // sum (the first failure included) is the same, bit for bit, signed zeros included.
        // Where pairs of a circle and a polygon break the runs of pairs of circles (seeds 6
        // and 7, as the rigid ellipses of an adaptive run do), the runs of eight still take
        // blocks and the rest go one by one: the same bits.
        let contours = Contours::new(1.0);
        for (seed, friction, periodic) in [
            (1, false, false),
            (2, true, false),
            (3, false, false),
            (4, false, true),
            (5, true, true),
            (6, false, false),
            (7, false, true),
        ] {
            let params = parameters(friction);
            // Runs of 2 to 9 pairs of circles between pairs with a polygon.
            let breaks = [0, 3, 9, 14, 20, 27, 35, 40, 45, 51, 61, 66];
            let polygon = |k: usize| seed >= 6 && breaks.contains(&(k % 70));
            let (frames, pairs) = circle_pairs_among_polygons(seed, polygon);
            // A periodic cell adds the branch vectors' affine rate and the cell stress's sum;
            // one pair in three meets the image of its second grain across a side or a corner
            // (the grain moved back by that image's shift: the same pair, give or take
            // rounding).
            let cell = PeriodicCell::rectangle(DVec2::splat(-50.0), 100.0, 100.0).unwrap();
            let mut frames = frames;
            let mut images = Vec::new();
            if periodic {
                for (p, &[_, j]) in pairs.iter().enumerate() {
                    let image = [[0, 0], [1, 0], [-1, 1]][p % 3];
                    frames[j as usize].center -= cell.image_shift(image);
                    images.push(image);
                }
            }
            let velocity_gradient = DMat2::from_cols_array(&[0.01, 0.002, -0.003, -0.02]);
            let pass = PairPass {
                params: &params,
                contours: &contours,
                frames: SharedRows::new(&frames),
                pairs: &pairs,
                images: &images,
                step: 7,
                periodic: periodic.then_some((cell, velocity_gradient)),
                only_fast: None,
                // Every frame here is a circle but where polygons break the runs: told so, or
                // found so block by block.
                every_frame_a_circle: seed % 2 == 1 && seed < 6,
                no_frame_a_circle: false,
                // The pairs start with springs, which the frictionless worlds drop.
                springs_to_drop: true,
            };
            let count = pairs.len();
            let start: Vec<PairState> = (0..count)
                .map(|p| PairState {
                    tangential_history: 1e-3 * (p % 5) as f64 - 2e-3,
                    ..Default::default()
                })
                .collect();
            let start = (
                start,
                vec![0.0; count],
                vec![false; count],
                vec![PairContact::default(); count],
            );
            let (lanes, lane_sums) = chunk_is_one_pair_by_pair(&pass, &start, seed);
            // The cases the test means to cover are there.
            let touching = lanes.2.iter().filter(|&&a| a).count();
            assert!(
                touching > count / 2 && touching < count,
                "{touching} of {count}"
            );
            assert!(
                lane_sums.failure.is_some(),
                "a swallowed or out-of-domain pair"
            );
            if friction {
                assert!(lane_sums.sliding > 0 && lane_sums.sliding < touching as u64);
            }
        }
    }

    /// Deforming, moving grains in pairs (grain 2k with grain 2k + 1), each pair in contact
    /// (its centres closer than the sum of its grains' smallest semi-axes). `shift` 1 moves
    /// each second grain along the line of centres by up to 1e-3 from where `shift` 0 puts it,
    /// a step's motion: the same draws either way.
    fn polygon_grains(seed: u64, shift: f64) -> (Vec<Grain>, Vec<[u32; 2]>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut random = |lo: f64, hi: f64| lo + (hi - lo) * unit_random(&mut rng);
        let mut grains = Vec::new();
        let mut pairs = Vec::new();
        for k in 0..(6 * BLOCK + 3) {
            let grain = |center: DVec2, random: &mut dyn FnMut(f64, f64) -> f64| {
                let mut g = Grain::at_rest(center, random(0.8, 1.0));
                (g.eps1, g.eps2) = (random(-0.1, 0.05), random(-0.1, 0.05));
                (g.theta, g.alpha) = (random(-3.0, 3.0), random(-1.0, 1.0));
                g.velocity = DVec2::new(random(-1.0, 1.0), random(-1.0, 1.0));
                g.omega = random(-2.0, 2.0);
                (g.eps1_rate, g.eps2_rate, g.alpha_rate) =
                    (random(-0.1, 0.1), random(-0.1, 0.1), random(-0.5, 0.5));
                g
            };
            let first = grain(DVec2::new(30.0 * k as f64, 0.0), &mut random);
            let mut second = grain(DVec2::ZERO, &mut random);
            let direction = DVec2::from_angle(random(0.0, 6.0));
            // Within the sum of the grains' smallest semi-axes: always in contact.
            let reach = |g: &Grain| g.radius * (1.0 + g.eps1.min(g.eps2));
            let distance =
                (reach(&first) + reach(&second)) * random(0.9, 0.98) + shift * random(-1e-3, 1e-3);
            second.center = first.center + distance * direction;
            pairs.push([grains.len() as u32, grains.len() as u32 + 1]);
            grains.extend([first, second]);
        }
        (grains, pairs)
    }

    #[test]
    fn polygon_pairs_in_blocks_give_the_one_pair_paths_bits() {
        // Expectation: a pair computed in a block of polygon lanes is recorded exactly as the
        // one-pair path records it from the same hint: every record, state, flag and sum the
        // same, bit for bit, with and without friction, in a periodic cell (the second grain
        // met at an image) and out of one, and with the law out of its domain for some of the
        // pairs (capped, or the exit reported) while the others' forces come from the lanes.
        // The hints come from a first pass over the pairs a step before, as in a run. With
        // every kernel this processor runs.
        for kernel in BlockKernel::available() {
            KERNEL_FOR_TESTS.set(Some(kernel));
            polygon_pairs_in_blocks();
        }
        KERNEL_FOR_TESTS.set(None);
    }

    /// [`polygon_pairs_in_blocks_give_the_one_pair_paths_bits`] with the kernel
    /// `KERNEL_FOR_TESTS` sets.
    fn polygon_pairs_in_blocks() {
        let contours = Contours::new(1.0);
        for (seed, friction, periodic, floor, cap) in [
            (1, false, false, None, false),
            (2, true, false, None, false),
            (3, false, true, None, false),
            (4, true, true, None, false),
            (5, true, true, Some(0.88), true),
            (6, false, false, Some(0.88), false),
        ] {
            let mut params = parameters(friction);
            if let Some(floor) = floor {
                (params.law.floor, params.law.cap) = (floor, cap);
            }
            let cell = PeriodicCell::rectangle(DVec2::splat(-500.0), 1000.0, 1000.0).unwrap();
            let velocity_gradient = DMat2::from_cols_array(&[0.01, 0.002, -0.003, -0.02]);
            let frames_of = |shift: f64| {
                let (grains, pairs) = polygon_grains(seed, shift);
                let mut frames: Vec<Frame> =
                    grains.iter().map(|g| Frame::of_grain(g, 1.0)).collect();
                let mut images = Vec::new();
                if periodic {
                    for (p, &[_, j]) in pairs.iter().enumerate() {
                        let image = [[0, 0], [1, 0], [-1, 1]][p % 3];
                        frames[j as usize].center -= cell.image_shift(image);
                        images.push(image);
                    }
                }
                (frames, pairs, images)
            };
            let (before, pairs, images) = frames_of(0.0);
            let (after, _, _) = frames_of(1.0);
            let pass = |frames| PairPass {
                params: &params,
                contours: &contours,
                frames: SharedRows::new(frames),
                pairs: &pairs,
                images: &images,
                step: 3,
                periodic: periodic.then_some((cell, velocity_gradient)),
                only_fast: None,
                every_frame_a_circle: false,
                no_frame_a_circle: false,
                springs_to_drop: false,
            };
            let count = pairs.len();
            let fresh = || {
                (
                    vec![PairState::default(); count],
                    vec![0.0; count],
                    vec![false; count],
                    vec![PairContact::default(); count],
                )
            };
            let mut hinted = fresh();
            pass(&before).chunk(
                0,
                &mut hinted.0,
                &mut hinted.1,
                &mut hinted.2,
                &mut hinted.3,
            );
            let (lanes, sums) = chunk_is_one_pair_by_pair(&pass(&after), &hinted, seed);
            if floor.is_some() {
                // Some pairs out of the law's domain, not all: capped, or left without a
                // contact (their exit reported).
                let out = match cap {
                    true => sums.capped as usize,
                    false => lanes.2.iter().filter(|&&a| !a).count(),
                };
                assert!(out > 0 && out < count, "{out} of {count} out of the domain");
                let exit = matches!(sums.failure, Some(Instability::ContactDomain { .. }));
                assert_eq!(exit, !cap, "{sums:?}");
                continue;
            }
            // Every pair touches, and has last step's chains to start from: the blocks' path
            // (the lanes' own test counts how many leave it).
            assert!(lanes.2.iter().all(|&a| a), "every pair in contact");
            assert!(
                (lanes.0.iter()).all(|state| state.hint.first.lo >= 0 && state.hint.second.lo >= 0),
                "every pair with a hint"
            );
        }
    }

    /// Checks that `shuffle` puts eight pairs of circles into lanes as setting the lanes one
    /// value at a time does (`what` names it); returns the lanes so set.
    fn assert_shuffled_as_one_by_one(
        what: &str,
        shuffle: impl Fn(&mut DiscPairs<PairLanes>, &[(&Frame, &Frame); LANES]),
    ) -> DiscPairs<PairLanes> {
        let (frames, pairs) = circle_pairs(6);
        let mut ends = [(&frames[0], &frames[0]); LANES];
        for (end, &[i, j]) in ends.iter_mut().zip(&pairs[LANES..]) {
            *end = (&frames[i as usize], &frames[j as usize]);
        }
        let mut shuffled = DiscPairs::<PairLanes>::default();
        shuffle(&mut shuffled, &ends);
        let mut one_by_one = DiscPairs::<PairLanes>::default();
        for (lane, (fi, fj)) in ends.iter().enumerate() {
            one_by_one.first.set_lane(lane, fi);
            one_by_one.second.set_lane(lane, fj);
        }
        assert_eq!(format!("{shuffled:?}"), format!("{one_by_one:?}"), "{what}");
        one_by_one
    }

    #[test]
    fn the_frames_shuffled_into_lanes_are_the_frames_set_lane_by_lane() {
        // Expectation: `set_circles` moves values and computes nothing: whatever instructions
        // it takes (AVX or AVX-512 shuffles here where the processor has them), every lane
        // holds what setting the lanes one value at a time puts there.
        let mut one_by_one =
            assert_shuffled_as_one_by_one("set_circles", |lanes, ends| lanes.set_circles(ends));
        // Every lane was set (no value of the frames is zero but the rigid discs' dilation
        // rates; the dilating discs' are not).
        for circles in [&mut one_by_one.first, &mut one_by_one.second] {
            let lanes = circles.in_frame_order();
            assert!(lanes[..7].iter().all(|l| l.0.iter().all(|&x| x != 0.0)));
        }
        let dilations = [one_by_one.first.dilation, one_by_one.second.dilation];
        assert!(dilations.iter().any(|l| l.0.iter().any(|&x| x != 0.0)));
    }

    #[test]
    fn every_shuffle_of_the_frames_into_lanes_is_the_lanes_set_one_by_one() {
        // Expectation: as above, for the AVX shuffle and the AVX-512 one each where the
        // processor has it (the dispatch takes only the widest).
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx") {
                // SAFETY: the processor has AVX (tested just above).
                assert_shuffled_as_one_by_one("AVX", |lanes, ends| unsafe {
                    lanes.set_circles_avx(ends)
                });
            }
            if std::arch::is_x86_feature_detected!("avx512f") {
                // SAFETY: the processor has AVX-512 (tested just above).
                assert_shuffled_as_one_by_one("AVX-512", |lanes, ends| unsafe {
                    lanes.set_circles_avx512(ends)
                });
            }
        }
    }

    #[test]
    fn the_affine_rate_is_glams_product_bit_for_bit_on_one_pair_and_on_lanes() {
        // Expectation: `L d` is the matrix-vector product glam computes (the one-pair path's
        // before it was shared with the lanes), lane by lane the same bits.
        let l = DMat2::from_cols_array(&[0.01, 0.002, -0.003, -0.02]);
        let branches = PairLanes::from_fn(|k| 0.37 * k as f64 - 1.1);
        let other = PairLanes::from_fn(|k| 1e-3 / (k as f64 + 0.3));
        let lanes = affine_rate(&l, [branches, other]);
        for k in 0..LANES {
            let d = DVec2::new(branches.0[k], other.0[k]);
            let expected = l * d;
            let one: [f64; 2] = affine_rate(&l, d.into());
            assert_eq!(one.map(f64::to_bits), expected.to_array().map(f64::to_bits));
            assert_eq!([lanes[0].0[k], lanes[1].0[k]], one);
        }
    }

    #[test]
    fn the_vector_kernel_is_the_portable_one_bit_for_bit() {
        // Expectation: the run-time choice of instructions (AVX or SSE2) changes no bit.
        let params = parameters(false);
        let (frames, pairs) = circle_pairs(4);
        let mut input = DiscPairs::<PairLanes>::default();
        for (lane, &[i, j]) in pairs.iter().take(LANES).enumerate() {
            let (fi, fj) = (&frames[i as usize], &frames[j as usize]);
            let end = SecondEnd {
                center: fj.center,
                branch: DVec2::ZERO,
                affine_rate: DVec2::new(1e-3, -2e-3),
            };
            input.set_lane(lane, fi, fj, &end);
        }
        let mut portable = DiscPairForces::default();
        disc_pair_forces(&input, &params.law, params.contact_damping, &mut portable);
        let mut chosen = DiscPairForces::default();
        disc_pair_forces_dispatch(&input, &params.law, params.contact_damping, &mut chosen);
        assert_eq!(format!("{portable:?}"), format!("{chosen:?}"));
    }
}
