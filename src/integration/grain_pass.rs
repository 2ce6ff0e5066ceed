//! The grain pass of the step: each grain's pair contacts gathered in pair order, its wall
//! contacts, stresses and update (SPEC §3–§6, §9), and the sums over a chunk of grains in grain
//! order. A chunk's frames for the next step are written right after its grains' updates,
//! while they are still in cache, deforming grains four at a time (see
//! [`World::frames_current`](super::World)).

use super::grain_block::{
    BLOCK_GRAINS, BlockConstants, BlockLoads, advance_full_block, advance_rigid_block,
};
use super::sweep::SharedRows;
use super::{
    BoxCarry, ChunkSums, FRAME_LANES, Frame, GRAIN_CHUNK, GrainStress, Instability, MAX_WALLS,
    PairContact, Parameters, StepTotals, prefetch_address,
};
use crate::boundary::periodic::{CellMotion, PeriodicCell};
use crate::boundary::walls::Wall;
use crate::contact::law::damped_normal_force;
use crate::geometry::broadphase::NeighborList;
use crate::geometry::circle::disc_wall;
use crate::geometry::{Contours, Overlap};
use crate::grain::adaptive::stress_invariants;
use crate::grain::constitutive::{
    Moduli, incompressible_strains, principal_stress, strain_energy_density,
};
use crate::grain::{Grain, GrainLevel, ModelLevel};
use crate::lanes::Lanes;
use glam::{DMat2, DVec2};

/// What the grain pass reads, shared by every chunk.
pub(super) struct GrainPass<'a> {
    pub params: &'a Parameters,
    pub contours: &'a Contours,
    pub neighbors: &'a NeighborList,
    /// The pair pass's flags and records.
    pub pair_active: SharedRows<'a, bool>,
    pub pair_contacts: SharedRows<'a, PairContact>,
    /// Whether pairs have friction (see [`PairContact::force_on_first_in`]).
    pub frictional_pairs: bool,
    /// The periodic cell, if any: a pair's second grain is met at an image.
    pub cell: Option<PeriodicCell>,
    /// The walls grains meet (none in a periodic cell, whose virtual walls meet no grain).
    pub walls: &'a [Wall],
    /// The walls with friction, bit `w` for wall `w`: each drops the springs of the grains it
    /// no longer touches, and every chunk visits it.
    pub wall_springs: u32,
    /// An affine phase's carry of the grain centres over the step (over the half, in a
    /// multi-rate cycle).
    pub carry: Option<BoxCarry>,
    /// A periodic cell's motion over the step: each updated grain is carried with the cell's
    /// affine field and wrapped back into the cell, its image shift written to the chunk's
    /// `wraps` (in the pass, where the grain is at hand: with a pass of its own, a periodic
    /// step of LAMMPS's 10⁵ packing took 1.05 times as long on one thread, 1.2 on two).
    pub cell_motion: Option<CellMotion>,
    pub step: u64,
    /// The time step of a plain step; in a multi-rate cycle, that of the grains that take two.
    pub dt: f64,
    /// The half of a multi-rate cycle this pass runs; `None` for a plain step.
    pub cycle: Option<CycleHalf<'a>>,
    /// Whether chunks with full-level grains go by blocks (see [`GrainPass::by_blocks`]): on a
    /// plain step, where the processor runs them.
    pub blocks: bool,
}

/// One half of a multi-rate cycle (see [`World::step`](super::World::step)).
#[derive(Clone, Copy)]
pub(super) struct CycleHalf<'a> {
    /// Whether each grain takes two steps of the cycle (fast) or one of twice the length in the
    /// first half (slow).
    pub fast: &'a [bool],
    pub second: bool,
}

/// What a grain does in a pass.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Turn {
    Plain,
    /// The first of a fast grain's two steps: its sums are counted after the second, but for
    /// half its wall forces (the wall force of a cycle is its mean).
    FastFirst,
    /// A slow grain's step of twice the length, in the first half.
    SlowFirst,
    FastSecond,
    /// The second half: a slow grain only follows the box.
    SlowSecond,
}

impl Turn {
    /// The time step the grain takes, given the pass's step.
    #[inline]
    fn dt(self, dt: f64) -> f64 {
        if self == Turn::SlowFirst {
            2.0 * dt
        } else {
            dt
        }
    }

    /// The weight of the grain's wall forces in the step's (or cycle's) totals.
    #[inline]
    fn wall_weight(self) -> f64 {
        match self {
            Turn::FastFirst | Turn::FastSecond => 0.5,
            _ => 1.0,
        }
    }

    /// Whether the grain's sums other than wall forces are counted in this pass.
    #[inline]
    fn tallied(self) -> bool {
        self != Turn::FastFirst
    }

    /// Steps the adaptive level's counters advance by (a slow grain's step of a cycle counts
    /// as the two steps of the grains beside it).
    #[inline]
    fn level_steps(self) -> u32 {
        if self == Turn::SlowFirst { 2 } else { 1 }
    }
}

impl GrainPass<'_> {
    /// The grains of one chunk, from grain `first` on. `chunk.frames` holds their frames at
    /// the start of the step; each is replaced by the frame of its updated grain, and its
    /// centre and reach (the broad phase's) with it. Returns the chunk's sums, in grain order.
    pub fn chunk(&self, first: usize, mut chunk: GrainChunk<'_>) -> ChunkSums {
        let (params, walls) = (self.params, self.walls);
        let density = params.material.density;
        let mut sums = ChunkSums::default();
        let near = walls_in_reach(chunk.centers, chunk.reach, walls);
        let constants = UpdateConstants::new(params);
        let n = chunk.grains.len();
        let (mut full, mut rigid) = (0, 0);
        for level in chunk.levels.iter() {
            full += (level.level == ModelLevel::Full) as usize;
            rigid += (level.level == ModelLevel::Rigid) as usize;
        }
        let chunk_walls = ChunkWalls {
            walls,
            near,
            springs: self.wall_springs,
        };
        // A chunk with full-level or rigid grains, on a plain step, goes by blocks of four:
        // those whose grains are all at the full level, or all at the rigid level, have their
        // updates run side by side in lanes, the others go one by one. Any other chunk goes one
        // by one.
        let chunk_level = if full == n {
            Some(ModelLevel::Full)
        } else if rigid == n {
            Some(ModelLevel::Rigid)
        } else {
            None
        };
        let blocks_done = if self.blocks && full + rigid > 0 {
            self.by_blocks(
                first,
                &mut chunk,
                chunk_level,
                chunk_walls,
                &constants,
                &mut sums,
            )
        } else {
            let grains_at = chunk.grains.as_ptr();
            let stresses_at = chunk.stresses.as_ptr();
            for (k, (((((grain, stress), level), wall_history), frame), &direction)) in chunk
                .grains
                .iter_mut()
                .zip(chunk.stresses.iter_mut())
                .zip(chunk.levels.iter_mut())
                .zip(chunk.wall_histories.iter_mut())
                .zip(chunk.frames.iter())
                .zip(chunk.directions.iter())
                .enumerate()
            {
                // The state of the grain 8 ahead, and the stress record it will write.
                prefetch_grain(grains_at, k + GRAIN_PREFETCH_AHEAD);
                prefetch_address(stresses_at.wrapping_add(k + GRAIN_PREFETCH_AHEAD).cast());
                self.one_grain(
                    first + k,
                    grain,
                    stress,
                    level,
                    wall_history,
                    frame,
                    &mut chunk.wraps[k],
                    chunk_walls,
                    &constants,
                    direction,
                    &mut sums,
                );
            }
            0
        };
        write_frames(&mut chunk, blocks_done, density, &mut sums);
        sums
    }

    /// Grain `g` over the pass, alone: its contact loads, its update, its records, sums and
    /// failures. `frame`: its frame at the start of the step; `direction`: its
    /// [principal direction](Grain::principal_direction) (read at the full level only).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn one_grain(
        &self,
        g: usize,
        grain: &mut Grain,
        stress: &mut GrainStress,
        level: &mut GrainLevel,
        wall_history: &mut [f64; MAX_WALLS],
        frame: &Frame,
        wrap: &mut [i64; 2],
        chunk_walls: ChunkWalls<'_>,
        constants: &UpdateConstants,
        direction: DVec2,
        sums: &mut ChunkSums,
    ) {
        let turn = match &self.cycle {
            None => Turn::Plain,
            Some(c) => match (c.fast[g], c.second) {
                (true, false) => Turn::FastFirst,
                (false, false) => Turn::SlowFirst,
                (true, true) => Turn::FastSecond,
                (false, true) => Turn::SlowSecond,
            },
        };
        if turn == Turn::SlowSecond {
            self.follow_box(grain, wrap, sums);
            return;
        }
        let dt = turn.dt(self.dt);
        let tallied = turn.tallied();
        let load = self.contact_load(
            g,
            frame,
            turn,
            dt,
            chunk_walls,
            wall_history,
            &mut sums.totals,
            &mut sums.failure,
            None,
        );
        let update = advance_grain(
            self.params,
            dt,
            turn.level_steps(),
            grain,
            level,
            &load,
            constants,
            direction,
            g,
            self.step,
        );
        *stress = update.stress;
        if let Err(e) = update.result {
            sums.failure.get_or_insert(e);
        }
        if tallied {
            sums.totals.level_counts[level.level.index()] += 1;
            sums.totals.grain_area += update.area;
            sums.totals.elastic_energy += update.elastic_energy;
            sums.contact_ends += load.contacts as u64;
        }
        self.follow_box(grain, wrap, sums);
    }

    /// A chunk's grains on a plain step by blocks of [`BLOCK_GRAINS`]. A block whose grains are
    /// all at the full level, or all at the rigid level: its contact loads first, grain by
    /// grain, then their updates side by side ([`advance_full_block`], which writes their
    /// frames too, or [`advance_rigid_block`], which writes them where its four grains are
    /// circles and else leaves them to [`write_frames`]), then
    /// each grain's adaptive level, checks, sums and failures in grain order (a grain's first
    /// wall failure before its update's, as one by one). Any other block, and the chunk's last
    /// grains, one by one ([`GrainPass::one_grain`]). `chunk_level`: the level of every grain
    /// of the chunk, if they share one. Returns the blocks that wrote their grains' frames, bit
    /// `b` for the grains `4 b` to `4 b + 3`.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn by_blocks(
        &self,
        first: usize,
        chunk: &mut GrainChunk<'_>,
        chunk_level: Option<ModelLevel>,
        chunk_walls: ChunkWalls<'_>,
        constants: &UpdateConstants,
        sums: &mut ChunkSums,
    ) -> BlocksDone {
        let params = self.params;
        let density = params.material.density;
        let block_constants = BlockConstants {
            params,
            update: constants,
            dt: self.dt,
        };
        let n = chunk.grains.len();
        let grains_at = chunk.grains.as_ptr();
        let stresses_at = chunk.stresses.as_ptr();
        let mut done = 0;
        // A block's pair loads in lanes ([`GrainPass::pair_loads_avx`]): without friction
        // (whose tangential forces the lanes leave out) and outside a periodic cell (whose
        // ends need their images).
        #[cfg(target_arch = "x86_64")]
        let lanes_gather = !self.frictional_pairs
            && self.cell.is_none()
            && std::arch::is_x86_feature_detected!("avx");
        #[cfg(not(target_arch = "x86_64"))]
        let lanes_gather = false;
        // No grain's level may change and the box moves no grain: the chunk's part of what
        // makes a block plain (below).
        let level_and_box_still =
            params.adaptive.is_none() && self.carry.is_none() && self.cell_motion.is_none();
        for start in (0..n).step_by(BLOCK_GRAINS) {
            let block = start..(start + BLOCK_GRAINS).min(n);
            // The states of the grains ahead, and the stress records they will write, as one by
            // one.
            let ahead = block.start + GRAIN_PREFETCH_AHEAD;
            for k in ahead..ahead + BLOCK_GRAINS {
                prefetch_grain(grains_at, k);
            }
            let stresses_ahead = stresses_at.wrapping_add(ahead).cast::<u8>();
            for line in 0..(BLOCK_GRAINS * size_of::<GrainStress>()).div_ceil(64) {
                prefetch_address(stresses_ahead.wrapping_add(64 * line));
            }
            let block_level = if block.len() < BLOCK_GRAINS {
                None
            } else if chunk_level.is_some() {
                chunk_level
            } else {
                let first_level = chunk.levels[block.start].level;
                chunk.levels[block.clone()]
                    .iter()
                    .all(|level| level.level == first_level)
                    .then_some(first_level)
            };
            let rigid = match block_level {
                Some(ModelLevel::Full) => false,
                Some(ModelLevel::Rigid) => true,
                _ => {
                    for k in block {
                        self.one_grain(
                            first + k,
                            &mut chunk.grains[k],
                            &mut chunk.stresses[k],
                            &mut chunk.levels[k],
                            &mut chunk.wall_histories[k],
                            &chunk.frames[k],
                            &mut chunk.wraps[k],
                            chunk_walls,
                            constants,
                            chunk.directions[k],
                            sums,
                        );
                    }
                    continue;
                }
            };
            let mut loads = BlockLoads::default();
            let mut contacts = [[0u32; 2]; BLOCK_GRAINS];
            // The block's first wall failure and its grain: a later one would never be kept.
            let mut wall_failure = None;
            // SAFETY: `lanes_gather` holds only where the processor has AVX.
            #[cfg(target_arch = "x86_64")]
            let gathered = lanes_gather.then(|| unsafe {
                self.pair_loads_avx(first + start, &chunk.frames[block.clone()], &mut loads)
            });
            #[cfg(not(target_arch = "x86_64"))]
            let gathered: Option<[u32; BLOCK_GRAINS]> = None;
            let wall_failure_lane = match gathered {
                // Clear of the walls, the gathered pair loads are the grains' loads.
                Some(pair_contacts) if !chunk_walls.visits_any() => {
                    for (lane_contacts, pair_contacts) in contacts.iter_mut().zip(pair_contacts) {
                        lane_contacts[0] = pair_contacts;
                    }
                    BLOCK_GRAINS
                }
                Some(pair_contacts) => self.block_contact_loads::<true>(
                    first + start,
                    chunk,
                    start,
                    chunk_walls,
                    pair_contacts,
                    &mut loads,
                    &mut contacts,
                    sums,
                    &mut wall_failure,
                ),
                None => self.block_contact_loads::<false>(
                    first + start,
                    chunk,
                    start,
                    chunk_walls,
                    [0; BLOCK_GRAINS],
                    &mut loads,
                    &mut contacts,
                    sums,
                    &mut wall_failure,
                ),
            };
            let outcome = if rigid {
                let outcome = advance_rigid_block(
                    &mut chunk.grains[block.clone()],
                    &mut chunk.stresses[block.clone()],
                    &mut chunk.frames[block.clone()],
                    &loads,
                    &contacts,
                    &block_constants,
                );
                if outcome.circle_frames {
                    done |= 1 << (start / BLOCK_GRAINS);
                }
                outcome
            } else {
                done |= 1 << (start / BLOCK_GRAINS);
                advance_full_block(
                    &mut chunk.grains[block.clone()],
                    &mut chunk.stresses[block.clone()],
                    &mut chunk.frames[block.clone()],
                    &loads,
                    &contacts,
                    &mut chunk.directions[block],
                    &block_constants,
                )
            };
            // The common block: no grain's level may change, none is suspect, no wall failed
            // and the box moves no grain. Its sums are the loop's below, lane by lane in the
            // same order, without its tests (issue #16: the loop's sums, read and written
            // through memory grain by grain, were a tenth of this function's samples).
            let plain = level_and_box_still
                && outcome.suspect == 0
                && wall_failure.is_none()
                && (!rigid || outcome.circle_frames);
            if let (true, Some(level)) = (plain, block_level) {
                let totals = &mut sums.totals;
                totals.level_counts[level.index()] += BLOCK_GRAINS as u64;
                let (mut area, mut energy) = (totals.grain_area, totals.elastic_energy);
                let mut ends = 0;
                for (l, [pair_contacts, _]) in contacts.into_iter().enumerate() {
                    area += outcome.area.0[l];
                    energy += outcome.elastic_energy.0[l];
                    ends += pair_contacts as u64;
                }
                (totals.grain_area, totals.elastic_energy) = (area, energy);
                sums.contact_ends += ends;
                // A rigid block's frames are circles (`circle_frames`), a full one's are not.
                sums.circle_frames += if rigid { BLOCK_GRAINS } else { 0 };
                continue;
            }
            for (l, [pair_contacts, _]) in contacts.into_iter().enumerate() {
                let (k, g) = (start + l, first + start + l);
                let (grain, level) = (&mut chunk.grains[k], &mut chunk.levels[k]);
                if l == wall_failure_lane
                    && let Some(failure) = wall_failure.take()
                {
                    sums.failure.get_or_insert(failure);
                }
                // The adaptive level, as `advance_grain` takes it; a grain that steps down has
                // its rates frozen, and its frame is written again below.
                let mut stepped_down = false;
                if let Some(adaptive) = &params.adaptive {
                    let (mean, deviator) = stress_invariants(chunk.stresses[k].external);
                    let inv_young = constants.inv_young;
                    let next = adaptive.settings.next_level(
                        *level,
                        mean * inv_young,
                        deviator * inv_young,
                    );
                    if next.level < level.level {
                        freeze(grain, next.level);
                        stepped_down = true;
                    }
                    *level = next;
                }
                if outcome.suspect & (1 << l) != 0
                    && let Err(e) = check_suspect(grain, constants.wave_speed_squared, g, self.step)
                {
                    sums.failure.get_or_insert(e);
                }
                sums.totals.level_counts[level.level.index()] += 1;
                sums.totals.grain_area += outcome.area.0[l];
                sums.totals.elastic_energy += outcome.elastic_energy.0[l];
                sums.contact_ends += pair_contacts as u64;
                self.follow_box(grain, &mut chunk.wraps[k], sums);
                if rigid && !outcome.circle_frames {
                    // `write_frames` writes its frame, as one by one.
                    continue;
                }
                let frame = &mut chunk.frames[k];
                // A grain whose level changed takes the frame of its new level (a rigid one
                // that rose to the full level is no longer a circle, one that rose to the
                // volumetric level dilates), as `write_frames` would have written it.
                let changed = stepped_down || (rigid && level.level != ModelLevel::Rigid);
                if changed {
                    frame.write(&mut chunk.directions[k], grain, level.level, density);
                    sums.circle_frames += frame.circle() as usize;
                    continue;
                }
                sums.circle_frames += rigid as usize;
                if self.carry.is_some() || self.cell_motion.is_some() {
                    // The block wrote the frame before the box moved the grain, and a frame's
                    // centre is the only part of it that the move changes.
                    frame.center = grain.center;
                }
            }
        }
        done
    }

    /// [`pair_load`](Self::pair_load) without friction of the four grains `g..g + 4`
    /// (`frames`: theirs) side by side in AVX lanes, into `loads`; returns their counts of
    /// contacts. Lane `l` sums grain `g + l`'s second ends, then its first ones, with
    /// `pair_load`'s operations in its order, so that its sums are `pair_load`'s bits; a lane
    /// past its grain's last end of a kind adds an open pair's zeros, which leave its sums as
    /// they are (see [`contact_or_none`]). Outside a periodic cell only (a second end's image
    /// shift is taken as zero).
    ///
    /// # Safety
    /// The processor has AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn pair_loads_avx(
        &self,
        g: usize,
        frames: &[Frame],
        loads: &mut BlockLoads,
    ) -> [u32; BLOCK_GRAINS] {
        use std::arch::x86_64::*;
        assert!(frames.len() == BLOCK_GRAINS);
        let pairs = self.neighbors.pairs.len();
        assert!(self.pair_active.len() == pairs && self.pair_contacts.len() == pairs);
        let ends: [_; BLOCK_GRAINS] = std::array::from_fn(|l| self.neighbors.ends_of(g + l));
        // SAFETY: the processor has AVX (the caller's promise); the ends index the list's
        // pairs, as many as the flags and records (asserted above).
        unsafe {
            let center = |axis: usize| {
                _mm256_setr_pd(
                    frames[0].center[axis],
                    frames[1].center[axis],
                    frames[2].center[axis],
                    frames[3].center[axis],
                )
            };
            let zero = _mm256_setzero_pd();
            let mut sums = LaneLoads {
                force: [zero; 2],
                torque: zero,
                moment: [[zero; 2]; 2],
                lost_area: zero,
                contacts: [0; BLOCK_GRAINS],
            };
            // `pair_load`'s centre of a second end is `center + image`, the image zero here.
            let center = [center(0), center(1)];
            let image_center = center.map(|c| _mm256_add_pd(c, zero));
            self.add_ends_avx::<true>(
                ends.each_ref().map(|(second, _)| second.len()),
                |l, k| *ends[l].0.get_unchecked(k) as usize,
                image_center,
                &mut sums,
            );
            self.add_ends_avx::<false>(
                ends.each_ref().map(|(_, first)| first.len()),
                |l, k| ends[l].1.start + k,
                center,
                &mut sums,
            );
            let store =
                |to: &mut Lanes<BLOCK_GRAINS>, v: __m256d| _mm256_storeu_pd(to.0.as_mut_ptr(), v);
            store(&mut loads.force[0], sums.force[0]);
            store(&mut loads.force[1], sums.force[1]);
            store(&mut loads.torque, sums.torque);
            for (to, from) in loads.moment.iter_mut().zip(sums.moment) {
                store(&mut to[0], from[0]);
                store(&mut to[1], from[1]);
            }
            store(&mut loads.lost_area, sums.lost_area);
            sums.contacts
        }
    }

    /// Adds to `sums` the ends of one kind (`SECOND`: the pairs `[i, g]`, whose force on g is
    /// the opposite of the first grain's; else the pairs `[g, j]`) of a block's grains, the
    /// `count[l]` ends of lane `l` being the pairs `pair(l, k)`, at the arms from `center`
    /// (see [`pair_loads_avx`](Self::pair_loads_avx)).
    ///
    /// # Safety
    /// The processor has AVX, and every `pair(l, k)` with `k < count[l]` indexes the list's
    /// flags and records.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    unsafe fn add_ends_avx<const SECOND: bool>(
        &self,
        count: [usize; BLOCK_GRAINS],
        pair: impl Fn(usize, usize) -> usize,
        center: [std::arch::x86_64::__m256d; 2],
        sums: &mut LaneLoads,
    ) {
        use crate::lanes::avx::transpose;
        use std::arch::x86_64::*;
        let longest = count.iter().copied().max().unwrap_or(0);
        // SAFETY: as the function's; every load reads four f64s of a 64-byte aligned record.
        unsafe {
            let flip = _mm256_set1_pd(if SECOND { -0.0 } else { 0.0 });
            for k in 0..longest {
                let records: [&PairContact; BLOCK_GRAINS] = std::array::from_fn(|l| {
                    if k < count[l] {
                        let pair = pair(l, k);
                        let active = *self.pair_active.row_unchecked(pair);
                        sums.contacts[l] += active as u32;
                        contact_or_none(active, self.pair_contacts.row_unchecked(pair))
                    } else {
                        &NO_CONTACT
                    }
                });
                let words = records.map(|r| (r as *const PairContact).cast::<f64>());
                let [normal_x, normal_y, normal_force, _] =
                    transpose(words.map(|w| _mm256_load_pd(w)));
                let [point_x, point_y, cap_first, cap_second] =
                    transpose(words.map(|w| _mm256_load_pd(w.add(4))));
                // The force on the grain (on a second end, the opposite of the first's).
                let f = [
                    _mm256_xor_pd(_mm256_mul_pd(normal_force, normal_x), flip),
                    _mm256_xor_pd(_mm256_mul_pd(normal_force, normal_y), flip),
                ];
                let arm = [
                    _mm256_sub_pd(point_x, center[0]),
                    _mm256_sub_pd(point_y, center[1]),
                ];
                sums.force = [
                    _mm256_add_pd(sums.force[0], f[0]),
                    _mm256_add_pd(sums.force[1], f[1]),
                ];
                // glam's `arm.perp_dot(f)`: (arm.x f.y) - (arm.y f.x).
                sums.torque = _mm256_add_pd(
                    sums.torque,
                    _mm256_sub_pd(_mm256_mul_pd(arm[0], f[1]), _mm256_mul_pd(arm[1], f[0])),
                );
                // Column b of `f (x) arm` is `f arm_b`.
                for (column, arm) in sums.moment.iter_mut().zip(arm) {
                    for (entry, f) in column.iter_mut().zip(f) {
                        *entry = _mm256_add_pd(*entry, _mm256_mul_pd(f, arm));
                    }
                }
                let cap = if SECOND { cap_second } else { cap_first };
                sums.lost_area = _mm256_add_pd(sums.lost_area, cap);
            }
        }
    }

    /// The contact loads of the block of grains `g..g + 4`, the chunk's `k..k + 4`, into
    /// `loads` and `contacts`, the block's first wall failure to `wall_failure`; returns its
    /// lane ([`BLOCK_GRAINS`] for none). `GATHERED`: `loads` holds the grains' pair loads
    /// already ([`GrainPass::pair_loads_avx`], with their counts `pair_contacts`), to which
    /// the walls' are added.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn block_contact_loads<const GATHERED: bool>(
        &self,
        g: usize,
        chunk: &mut GrainChunk<'_>,
        k: usize,
        chunk_walls: ChunkWalls<'_>,
        pair_contacts: [u32; BLOCK_GRAINS],
        loads: &mut BlockLoads,
        contacts: &mut [[u32; 2]; BLOCK_GRAINS],
        sums: &mut ChunkSums,
        wall_failure: &mut Option<Instability>,
    ) -> usize {
        let mut wall_failure_lane = BLOCK_GRAINS;
        for (l, lane_contacts) in contacts.iter_mut().enumerate() {
            let load = self.contact_load(
                g + l,
                &chunk.frames[k + l],
                Turn::Plain,
                self.dt,
                chunk_walls,
                &mut chunk.wall_histories[k + l],
                &mut sums.totals,
                wall_failure,
                GATHERED.then(|| loads.lane(l, pair_contacts[l])),
            );
            if wall_failure.is_some() && wall_failure_lane == BLOCK_GRAINS {
                wall_failure_lane = l;
            }
            loads.set_lane(l, &load);
            *lane_contacts = [load.contacts, load.wall_contacts];
        }
        wall_failure_lane
    }

    /// The contact load of grain `g` (`frame`: the grain at the start of the step): its pairs'
    /// forces (`pairs`, where a block gathered them, else [`pair_load`](Self::pair_load)'s),
    /// then those of the walls its chunk reaches (`walls`). The walls' forces and counts go to
    /// `totals` too, and the grain's first failure to `failure`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn contact_load(
        &self,
        g: usize,
        frame: &Frame,
        turn: Turn,
        dt: f64,
        walls: ChunkWalls<'_>,
        wall_history: &mut [f64; MAX_WALLS],
        totals: &mut StepTotals,
        failure: &mut Option<Instability>,
        pairs: Option<ContactLoad>,
    ) -> ContactLoad {
        let mut load = pairs.unwrap_or_else(|| {
            if self.frictional_pairs {
                self.pair_load::<true>(g, frame)
            } else {
                self.pair_load::<false>(g, frame)
            }
        });
        let (params, step, tallied) = (self.params, self.step, turn.tallied());
        // In the walls' order, as the totals take their forces.
        let mut visit = walls.near | walls.springs;
        while visit != 0 {
            let w = visit.trailing_zeros() as usize;
            visit &= visit - 1;
            let wall = &walls.walls[w];
            // A contact that is open this step drops its history. A wall without friction
            // never has one: its row is left untouched, not rewritten with zeros every
            // step.
            let history = if walls.springs(w) {
                std::mem::take(&mut wall_history[w])
            } else {
                0.0
            };
            // Most grains are far from every wall: skip the call.
            if !walls.near(w) || wall.height(frame.center) >= frame.bounding_radius {
                continue;
            }
            let overlap = if frame.circle() {
                disc_wall(frame.center, frame.bounding_radius, wall.point, wall.normal)
            } else {
                self.contours
                    .grain_wall(&frame.shape(), wall.point, wall.normal)
            };
            match overlap {
                Overlap::Separate => {}
                Overlap::Swallowed => {
                    failure.get_or_insert(Instability::Swallowed {
                        step,
                        grain: g,
                        other: None,
                    });
                }
                Overlap::Contact(c) => match params.law.response(c.length, c.normal_gap) {
                    Err(exit) => {
                        failure.get_or_insert(Instability::ContactDomain {
                            step,
                            grain: g,
                            other: None,
                            length: exit.length,
                            normal_gap: exit.normal_gap,
                        });
                    }
                    Ok(response) => {
                        // The wall is the contact's second body.
                        let relative_velocity = wall.velocity - frame.velocity_at(c.point);
                        let gap_rate = relative_velocity.dot(c.normal);
                        let f = damped_normal_force(
                            response.force,
                            response.stiffness,
                            frame.mass,
                            params.contact_damping,
                            gap_rate,
                        );
                        let normal_force = f * c.normal;
                        let mut force = normal_force;
                        if let Some(friction) = &params.friction
                            && friction.walls[w] > 0.0
                        {
                            let t = friction.law.response(
                                history,
                                response.stiffness,
                                f,
                                relative_velocity.dot(c.normal.perp()),
                                friction.walls[w],
                                frame.mass,
                                dt,
                            );
                            wall_history[w] = t.history;
                            force += t.force * c.normal.perp();
                            totals.friction_dissipation += t.dissipated;
                            totals.sliding_contacts += t.sliding as u64;
                        }
                        load.add(force, c.point - frame.center, c.cap_area_i);
                        load.wall_contacts += 1;
                        totals.wall_force[w] += turn.wall_weight() * normal_force.dot(wall.normal);
                        if tallied {
                            totals.capped_contacts += response.capped as u64;
                        }
                    }
                },
            }
        }
        load
    }

    /// Moves an updated grain with its box: the affine carry of a box of walls, or a periodic
    /// cell's carry and wrap (`wrap`: the image shift it took; `sums.wrapped` counts the grains
    /// that took one).
    #[inline(always)]
    fn follow_box(&self, grain: &mut Grain, wrap: &mut [i64; 2], sums: &mut ChunkSums) {
        if let Some(carry) = &self.carry {
            grain.center = carry.apply(grain.center);
        }
        if let Some(motion) = &self.cell_motion {
            let (center, image) = motion.current.wrap(motion.carry(grain.center));
            grain.center = center;
            *wrap = image;
            sums.wrapped += (image != [0, 0]) as u64;
        }
    }

    /// The contact forces of grain `g`'s pairs on it (`frame`: the grain at the start of the
    /// step), summed in increasing pair order: the pairs `[i, g]` come before the pairs
    /// `[g, j]`. `FRICTIONAL`: whether a pair may carry a tangential force (see
    /// [`PairContact::force_on_first_in`]).
    #[inline(always)]
    fn pair_load<const FRICTIONAL: bool>(&self, g: usize, frame: &Frame) -> ContactLoad {
        let mut load = ContactLoad::default();
        let (second_ends, first_ends) = self.neighbors.ends_of(g);
        // One loop over the second ends for each case of the cell, so that the loop does not
        // ask which case it is in at every pair.
        match &self.cell {
            None => self.add_second_ends::<FRICTIONAL>(
                second_ends,
                frame.center,
                |_| DVec2::ZERO,
                &mut load,
            ),
            Some(cell) => {
                let images = &self.neighbors.images;
                assert!(images.len() == self.neighbors.pairs.len());
                self.add_second_ends::<FRICTIONAL>(
                    second_ends,
                    frame.center,
                    // SAFETY: `add_second_ends` calls this with indices of the list's pairs
                    // only, and in a cell the list has an image for each pair (asserted
                    // above).
                    |pair| cell.image_shift(unsafe { *images.get_unchecked(pair) }),
                    &mut load,
                )
            }
        }
        // The first ends are a run of the list: one bounds check for the run.
        let active = self.pair_active.rows(first_ends.clone());
        let contacts = self.pair_contacts.rows(first_ends);
        for (&active, c) in active.iter().zip(contacts) {
            let c = contact_or_none(active, c);
            load.add(
                c.force_on_first_in::<FRICTIONAL>(),
                c.point - frame.center,
                c.cap_area_first,
            );
            load.contacts += active as u32;
        }
        load
    }

    /// Adds to `load` the forces of the pairs `second_ends` (the pairs `[i, g]`) on their second
    /// grain g, centred at `center`; `image(pair)`: the shift of the image of g that met the
    /// pair's first grain.
    #[inline(always)]
    fn add_second_ends<const FRICTIONAL: bool>(
        &self,
        second_ends: &[u32],
        center: DVec2,
        image: impl Fn(usize) -> DVec2,
        load: &mut ContactLoad,
    ) {
        let (pair_active, pair_contacts) = (self.pair_active, self.pair_contacts);
        // The list's ends index its pairs, and the pair pass's records have one entry a pair.
        let pairs = self.neighbors.pairs.len();
        assert!(pair_active.len() == pairs && pair_contacts.len() == pairs);
        for &pair in second_ends {
            let pair = pair as usize;
            debug_assert!(pair < pairs);
            // SAFETY: `pair` is an entry of the list's index of second ends, which holds
            // indices of its pairs only (`NeighborList::index_second_ends`), and both
            // slices have one entry for each of the list's pairs (asserted above).
            let (active, c) = unsafe {
                (
                    *pair_active.row_unchecked(pair),
                    pair_contacts.row_unchecked(pair),
                )
            };
            let c = contact_or_none(active, c);
            // The contact point lies at the image of this grain that met the first.
            load.add(
                -c.force_on_first_in::<FRICTIONAL>(),
                c.point - (center + image(pair)),
                c.cap_area_second,
            );
            load.contacts += active as u32;
        }
    }
}

/// A pair's record where it touched (`active`), else [`NO_CONTACT`], chosen without a branch:
/// a grain's ends are read one after the other, and where some of its candidate pairs are open
/// (a sixth of the ends on LAMMPS's packing) the branch that skipped them was mispredicted
/// often. An open pair's turn adds zeros to the sums, which leaves them as they were, bit for
/// bit: a sum that starts at +0 is never -0 (x + y is -0 only where both are), and adding a
/// zero of either sign to anything else that is not -0 returns it.
#[inline(always)]
fn contact_or_none(active: bool, record: &PairContact) -> &PairContact {
    std::hint::select_unpredictable(active, record, &NO_CONTACT)
}

/// An open pair's record in the grain pass's sums (see [`contact_or_none`]): a force of zero,
/// at the origin, cutting no caps. Its arm to a grain's centre is finite, so that every product
/// with the zero force is a zero.
static NO_CONTACT: PairContact = PairContact {
    normal: DVec2::ZERO,
    force: 0.0,
    tangential_force: 0.0,
    point: DVec2::ZERO,
    cap_area_first: 0.0,
    cap_area_second: 0.0,
};

/// Writes the next step's frames of a chunk's updated grains but those of `blocks_done` (see
/// [`GrainPass::by_blocks`], which wrote their own), and the broad phase's copies of every
/// grain's centre and reach:
/// circles one at a time, the other grains in blocks of [`FRAME_LANES`]
/// ([`Frame::write_full_block`]). After all of the chunk's updates, which read each grain's
/// frame of the step's start.
fn write_frames(
    chunk: &mut GrainChunk<'_>,
    blocks_done: BlocksDone,
    density: f64,
    sums: &mut ChunkSums,
) {
    let mut block = [0; FRAME_LANES];
    let mut filled = 0;
    let n = chunk.grains.len();
    let mut k = 0;
    while k < n {
        if blocks_done != 0 && blocks_done & (1 << (k / BLOCK_GRAINS)) != 0 {
            k += BLOCK_GRAINS;
            continue;
        }
        let grain = &chunk.grains[k];
        let level = chunk.levels[k].level;
        if Frame::is_circle(grain, level) {
            chunk.frames[k].write_circle(grain, level, density);
            sums.circle_frames += 1;
        } else {
            block[filled] = k;
            filled += 1;
            if filled == FRAME_LANES {
                Frame::write_full_block(
                    chunk.frames,
                    chunk.directions,
                    chunk.grains,
                    block,
                    density,
                );
                filled = 0;
            }
        }
        k += 1;
    }
    for &k in &block[..filled] {
        (chunk.frames[k], chunk.directions[k]) =
            Frame::of_grain_and_direction(&chunk.grains[k], density);
    }
    for ((frame, center), reach) in chunk
        .frames
        .iter()
        .zip(chunk.centers.iter_mut())
        .zip(chunk.reach.iter_mut())
    {
        *center = frame.center;
        *reach = frame.bounding_radius;
    }
}

/// The blocks of a chunk whose frames [`GrainPass::by_blocks`] wrote: bit `b` for its grains
/// `4 b` to `4 b + 3`.
type BlocksDone = u64;

const _: () = assert!(GRAIN_CHUNK / BLOCK_GRAINS <= BlocksDone::BITS as usize);

/// One chunk of the grain pass's per-grain arrays, all of the same grains.
pub(super) struct GrainChunk<'a> {
    pub grains: &'a mut [Grain],
    pub stresses: &'a mut [GrainStress],
    pub levels: &'a mut [GrainLevel],
    pub wall_histories: &'a mut [[f64; MAX_WALLS]],
    pub frames: &'a mut [Frame],
    /// Their grains' principal directions, written with the frames (see `World::directions`).
    pub directions: &'a mut [DVec2],
    /// The broad phase's copies of the frames' centres and bounding radii.
    pub centers: &'a mut [DVec2],
    pub reach: &'a mut [f64],
    /// In a periodic cell, the image shift each grain's wrap took this step.
    pub wraps: &'a mut [[i64; 2]],
}

/// For each wall, whether a grain of a chunk of the grain pass may reach it: false when the
/// box around the grains' bounding circles (`centers`, `reach`: the broad phase's copies of
/// their frames' centres and bounding radii) clears the wall, so that the grain pass tests no
/// grain of the chunk against it. Most chunks of a large sample are clear of every wall, and
/// four tests a chunk replace four a grain. The compact copies, not the frames: the frames'
/// first reads here were a tenth of the rigid grain pass at 10⁵ grains, a stream of 128-byte
/// frames in a loop with nothing else to do, where the grain loop that reads them next
/// overlaps that stream with its work.
fn walls_in_reach(centers: &[DVec2], reach: &[f64], walls: &[Wall]) -> u32 {
    let mut near = 0;
    if walls.is_empty() || centers.is_empty() {
        return near;
    }
    let (mut lo, mut hi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
    // min and max pass a NaN over; the sum does not (nor an infinity), and a chunk with a
    // value that is not finite has every wall tested, as before.
    let mut sum = 0.0;
    for (&center, &radius) in centers.iter().zip(reach) {
        let reach = DVec2::splat(radius);
        lo = lo.min(center - reach);
        hi = hi.max(center + reach);
        sum += center.x + center.y + radius;
    }
    for (w, wall) in walls.iter().enumerate() {
        near |= ((!sum.is_finite() || !wall.clears_box(lo, hi)) as u32) << w;
    }
    near
}

/// The walls a chunk's grains visit, bit `w` for wall `w` of `walls`: those within reach of
/// the chunk (`near`, [`walls_in_reach`]), and those with friction (`springs`), which drop
/// the springs of grains they no longer touch. A chunk clear of every wall of a box without
/// friction visits none; one beside a wall visits that one only.
#[derive(Clone, Copy)]
struct ChunkWalls<'a> {
    walls: &'a [Wall],
    near: u32,
    springs: u32,
}

impl ChunkWalls<'_> {
    /// Whether the chunk's grains visit any wall.
    #[inline(always)]
    fn visits_any(self) -> bool {
        self.near | self.springs != 0
    }

    /// Whether wall `w` lies within the chunk's reach.
    #[inline(always)]
    fn near(self, w: usize) -> bool {
        self.near & (1 << w) != 0
    }

    /// Whether wall `w` has friction.
    #[inline(always)]
    fn springs(self, w: usize) -> bool {
        self.springs & (1 << w) != 0
    }
}

/// How many grains ahead the pass one grain at a time asks for a grain's state (issue #16: at
/// 10⁵ rigid discs, where a grain's turn is some 30 ns, 8 ahead stepped 1.05 times as fast as
/// leaving it to the processor's own prefetching).
const GRAIN_PREFETCH_AHEAD: usize = 8;

/// Asks for the two cache lines from grain `k` of the grains at `grains` (a [`Grain`] is 104
/// bytes; wherever `k` lies: a prefetch changes nothing but the caches).
#[inline(always)]
fn prefetch_grain(grains: *const Grain, k: usize) {
    let grain = grains.wrapping_add(k).cast::<u8>();
    prefetch_address(grain);
    prefetch_address(grain.wrapping_add(64));
}

/// [`ContactLoad`]'s sums of a block's four grains in AVX lanes (lane `l`: grain `l`), as
/// [`GrainPass::pair_loads_avx`] adds them up.
#[cfg(target_arch = "x86_64")]
struct LaneLoads {
    force: [std::arch::x86_64::__m256d; 2],
    torque: std::arch::x86_64::__m256d,
    /// `moment[b][a]`: `f_a r_b`.
    moment: [[std::arch::x86_64::__m256d; 2]; 2],
    lost_area: std::arch::x86_64::__m256d,
    contacts: [u32; BLOCK_GRAINS],
}

/// The sums a grain needs from its contacts.
#[derive(Debug, Clone, Copy)]
struct ContactLoad {
    force: DVec2,
    torque: f64,
    /// `sum_c f_c (x) r_c`: column b holds `f r_b`.
    moment: DMat2,
    lost_area: f64,
    contacts: u32,
    wall_contacts: u32,
}

// Not derived: glam's `DMat2::default()` is the identity, and the moment sum must start at zero.
impl Default for ContactLoad {
    fn default() -> Self {
        Self {
            force: DVec2::ZERO,
            torque: 0.0,
            moment: DMat2::ZERO,
            lost_area: 0.0,
            contacts: 0,
            wall_contacts: 0,
        }
    }
}

impl ContactLoad {
    #[inline]
    fn add(&mut self, force: DVec2, arm: DVec2, cap_area: f64) {
        self.force += force;
        self.torque += arm.perp_dot(force);
        self.moment += DMat2::from_cols(force * arm.x, force * arm.y);
        self.lost_area += cap_area;
    }
}

impl BlockLoads {
    /// The load in lane `l`, with its grain's `contacts` (and no walls').
    #[inline(always)]
    fn lane(&self, l: usize, contacts: u32) -> ContactLoad {
        ContactLoad {
            force: DVec2::new(self.force[0].0[l], self.force[1].0[l]),
            torque: self.torque.0[l],
            moment: DMat2::from_cols(
                DVec2::new(self.moment[0][0].0[l], self.moment[0][1].0[l]),
                DVec2::new(self.moment[1][0].0[l], self.moment[1][1].0[l]),
            ),
            lost_area: self.lost_area.0[l],
            contacts,
            wall_contacts: 0,
        }
    }

    /// Puts a grain's load in lane `l`.
    #[inline(always)]
    fn set_lane(&mut self, l: usize, load: &ContactLoad) {
        self.force[0].0[l] = load.force.x;
        self.force[1].0[l] = load.force.y;
        self.torque.0[l] = load.torque;
        self.moment[0][0].0[l] = load.moment.x_axis.x;
        self.moment[0][1].0[l] = load.moment.x_axis.y;
        self.moment[1][0].0[l] = load.moment.y_axis.x;
        self.moment[1][1].0[l] = load.moment.y_axis.y;
        self.lost_area.0[l] = load.lost_area;
    }
}

/// What every grain's update reads that depends on the parameters alone, computed once a
/// chunk: some were divisions, and together some 20 instructions a grain-step.
pub(super) struct UpdateConstants {
    pub moduli: Moduli,
    /// `E / rho`, the square of the elastic wave speed (see [`check_grain`]).
    pub wave_speed_squared: f64,
    /// `1 / E`, the scale of the adaptive level's stresses.
    pub inv_young: f64,
    pub gravity: Option<DVec2>,
}

impl UpdateConstants {
    fn new(params: &Parameters) -> Self {
        let material = &params.material;
        Self {
            moduli: material.moduli(),
            wave_speed_squared: material.young / material.density,
            inv_young: 1.0 / material.young,
            gravity: (params.gravity != DVec2::ZERO).then_some(params.gravity),
        }
    }
}

struct GrainUpdate {
    result: Result<(), Instability>,
    stress: GrainStress,
    area: f64,
    elastic_energy: f64,
}

/// Stresses, accelerations and the symplectic Euler update of one grain over `dt` (SPEC
/// §3–§6); the adaptive level's counters advance by `level_steps` steps under the same stress.
/// `e1`: the grain's [principal direction](Grain::principal_direction) (read at the full level
/// only).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn advance_grain(
    params: &Parameters,
    dt: f64,
    level_steps: u32,
    grain: &mut Grain,
    level: &mut GrainLevel,
    load: &ContactLoad,
    constants: &UpdateConstants,
    e1: DVec2,
    index: usize,
    step: u64,
) -> GrainUpdate {
    debug_assert!(
        level.level != ModelLevel::Full || e1 == grain.principal_direction(),
        "grain {index}: a stale principal direction {e1:?}"
    );
    let material = &params.material;
    let density = material.density;
    let reference_area = grain.reference_area();
    let lost_fraction = load.lost_area / reference_area;
    let current_area = grain.ellipse_area() - load.lost_area;

    // Love–Weber stress (eq. 47) and its components in the principal frame {e1, e2}, which only
    // the full level reads; the volumetric level reads their sum, the trace, which is the same
    // in any frame (its diagonal here: no direction needed).
    let symmetric = 0.5 * (load.moment + load.moment.transpose());
    let external = symmetric * (1.0 / current_area.max(f64::MIN_POSITIVE));
    let (ext11, ext22, ext12) = match level.level {
        ModelLevel::Rigid => (0.0, 0.0, 0.0),
        ModelLevel::Volumetric => (external.x_axis.x, external.y_axis.y, 0.0),
        ModelLevel::Full => {
            let e2 = e1.perp();
            (
                e1.dot(external * e1),
                e2.dot(external * e2),
                e1.dot(external * e2),
            )
        }
    };
    let moduli = &constants.moduli;
    let (sigma1, sigma2) = principal_stress(moduli, grain.eps1, grain.eps2, lost_fraction);
    let stress = GrainStress {
        external: [external.x_axis.x, external.y_axis.y, external.y_axis.x],
        principal: [sigma1, sigma2],
        lost_area: load.lost_area,
        contacts: load.contacts,
        wall_contacts: load.wall_contacts,
    };
    let elastic_energy =
        reference_area * strain_energy_density(moduli, grain.eps1, grain.eps2, lost_fraction);

    // Rigid-body motion.
    let mass = grain.mass(density);
    grain.velocity += load.force * (dt / mass);
    if let Some(gravity) = constants.gravity {
        grain.velocity += gravity * dt;
    }
    grain.omega += load.torque / grain.rotational_inertia_of_mass(mass) * dt;
    grain.center += grain.velocity * dt;
    grain.theta += grain.omega * dt;

    // Deformation (tension positive, eq. 4 of SPEC): eps_dd = 4 s / (rho R^2) - gamma rate,
    // M_eps scaled by the deformation mass scale.
    let inv_modal_mass =
        4.0 / (density * grain.radius * grain.radius * params.deformation_mass_scale);
    let damping = params.deformation_damping;
    let (s11, s22) = (ext11 - sigma1, ext22 - sigma2);
    match level.level {
        ModelLevel::Rigid => {}
        ModelLevel::Volumetric => {
            // The mean strain eps evolves, the deviator eps1 - eps2 and alpha are held (zero for
            // a grain that never deformed: then eps1 = eps2 = eps): generalized mass 2 M_eps,
            // force pi R^2 (s11 + s22).
            let mean_rate = 0.5 * (grain.eps1_rate + grain.eps2_rate);
            let acc = 0.5 * inv_modal_mass * (s11 + s22) - damping * mean_rate;
            let mean_rate = mean_rate + acc * dt;
            let half_difference = 0.5 * (grain.eps1 - grain.eps2);
            let mean = 0.5 * (grain.eps1 + grain.eps2) + mean_rate * dt;
            grain.eps1_rate = mean_rate;
            grain.eps2_rate = mean_rate;
            grain.eps1 = mean + half_difference;
            grain.eps2 = mean - half_difference;
        }
        ModelLevel::Full => {
            grain.eps1_rate += (inv_modal_mass * s11 - damping * grain.eps1_rate) * dt;
            grain.eps2_rate += (inv_modal_mass * s22 - damping * grain.eps2_rate) * dt;
            let difference = grain.eps1 - grain.eps2;
            // eq. 60: M_alpha / M_eps = 2 (eps1 - eps2)^2; below k_alpha the alpha force is dropped.
            let alpha_force_acc = if 2.0 * difference * difference > params.k_alpha {
                inv_modal_mass * ext12 / (difference * params.alpha_mass_scale)
            } else {
                0.0
            };
            grain.alpha_rate += (alpha_force_acc - damping * grain.alpha_rate) * dt;
            grain.eps1 += grain.eps1_rate * dt;
            grain.eps2 += grain.eps2_rate * dt;
            grain.alpha += grain.alpha_rate * dt;
        }
    }
    if moduli.incompressible && level.level != ModelLevel::Rigid {
        // SPEC §6: keep the deviator, restore the area; the mean strain rate follows the
        // corrected mean strain so that rates stay consistent with positions.
        let mean_before =
            0.5 * (grain.eps1 + grain.eps2) - 0.5 * (grain.eps1_rate + grain.eps2_rate) * dt;
        let (eps1, eps2) = incompressible_strains(grain.eps1, grain.eps2, lost_fraction);
        let mean_rate = (0.5 * (eps1 + eps2) - mean_before) / dt;
        let half_difference_rate = 0.5 * (grain.eps1_rate - grain.eps2_rate);
        grain.eps1 = eps1;
        grain.eps2 = eps2;
        grain.eps1_rate = mean_rate + half_difference_rate;
        grain.eps2_rate = mean_rate - half_difference_rate;
    }

    if let Some(adaptive) = &params.adaptive {
        let (mean, deviator) = stress_invariants(stress.external);
        let inv_young = constants.inv_young;
        for _ in 0..level_steps {
            let next = adaptive
                .settings
                .next_level(*level, mean * inv_young, deviator * inv_young);
            if next.level < level.level {
                freeze(grain, next.level);
            }
            *level = next;
        }
    }

    let result = check_grain(grain, constants.wave_speed_squared, index, step);
    GrainUpdate {
        result,
        stress,
        area: current_area,
        elastic_energy,
    }
}

/// Zeroes the rates of the degrees of freedom a grain loses when it steps down to `level`; the
/// values themselves are held (the shape does not jump).
fn freeze(grain: &mut Grain, level: ModelLevel) {
    match level {
        ModelLevel::Rigid => {
            grain.eps1_rate = 0.0;
            grain.eps2_rate = 0.0;
            grain.alpha_rate = 0.0;
        }
        ModelLevel::Volumetric => {
            let mean_rate = 0.5 * (grain.eps1_rate + grain.eps2_rate);
            grain.eps1_rate = mean_rate;
            grain.eps2_rate = mean_rate;
            grain.alpha_rate = 0.0;
        }
        ModelLevel::Full => {}
    }
}

/// [`check_grain`] of a grain a block's lanes flagged, out of line: the rare case.
#[cold]
#[inline(never)]
fn check_suspect(
    grain: &Grain,
    wave_speed_squared: f64,
    index: usize,
    step: u64,
) -> Result<(), Instability> {
    check_grain(grain, wave_speed_squared, index, step)
}

/// The per-grain failures of SPEC §9.
#[inline(always)]
fn check_grain(
    grain: &Grain,
    wave_speed_squared: f64,
    index: usize,
    step: u64,
) -> Result<(), Instability> {
    let values = [
        grain.center.x,
        grain.center.y,
        grain.velocity.x,
        grain.velocity.y,
        grain.theta,
        grain.omega,
        grain.eps1,
        grain.eps1_rate,
        grain.eps2,
        grain.eps2_rate,
        grain.alpha,
        grain.alpha_rate,
    ];
    // The common case is all finite, and a sum is finite only if every term is (a NaN or an
    // infinity makes it NaN or infinite): one test, summed as a tree of pairs, each pair a
    // vector register's two lanes. Only a sum that is not finite (or that overflowed) has each
    // value tested.
    let pair = |k: usize| DVec2::new(values[k], values[k + 1]);
    let sum = ((pair(0) + pair(2)) + (pair(4) + pair(6))) + (pair(8) + pair(10));
    let sum = sum.x + sum.y;
    if !sum.is_finite() && !values.iter().all(|v| v.is_finite()) {
        return Err(Instability::NonFinite { step, grain: index });
    }
    if grain.eps1 <= -1.0 || grain.eps2 <= -1.0 {
        return Err(Instability::Inverted {
            step,
            grain: index,
            eps1: grain.eps1,
            eps2: grain.eps2,
        });
    }
    // A grain moving faster than the elastic wave speed sqrt(E/rho) has been thrown by a
    // numerical instability, not by any quasi-static load.
    let speed_squared = grain.velocity.length_squared();
    if speed_squared > wave_speed_squared {
        return Err(Instability::Runaway {
            step,
            grain: index,
            speed: speed_squared.sqrt(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A value's bits, every NaN as one: IEEE leaves a NaN's sign and payload open, and a
    /// vector instruction may give another NaN than its scalar twin (seen in the frame of an
    /// inverted grain, which fails the step).
    fn bits(x: f64) -> u64 {
        if x.is_nan() {
            f64::NAN.to_bits()
        } else {
            x.to_bits()
        }
    }

    fn grain_bits(g: &Grain) -> [u64; 13] {
        g.to_array().map(bits)
    }

    fn frame_bits(f: &Frame) -> Vec<u64> {
        let mut bits = vec![u64::from(f.circle())];
        for x in [
            f.center.x,
            f.center.y,
            f.bounding_radius,
            f.mass,
            f.velocity.x,
            f.velocity.y,
            f.omega,
            f.circle_dilation,
        ]
        .into_iter()
        .chain(f.map.to_cols_array())
        .chain(f.velocity_gradient.to_cols_array())
        {
            bits.push(self::bits(x));
        }
        bits
    }

    fn stress_bits(s: &GrainStress) -> Vec<u64> {
        let mut bits: Vec<u64> = s
            .external
            .iter()
            .chain(&s.principal)
            .chain([&s.lost_area])
            .map(|&x| self::bits(x))
            .collect();
        bits.extend([u64::from(s.contacts), u64::from(s.wall_contacts)]);
        bits
    }

    #[test]
    fn a_block_gives_each_grain_the_one_grain_updates_bits() {
        // Expectation: a block's lanes are four one-grain updates side by side (`advance_grain`
        // at the full level, then `Frame::of_grain` of the updated grain; or at the rigid
        // level): every field of the grains, their stress records, areas, elastic energies
        // and (full level) next frames bit for bit, compressible and incompressible, with and
        // without gravity, strain differences on both sides of k_alpha's threshold (zero
        // included). A grain the one-grain checks fail
        // is flagged for them.
        use super::super::grain_block::{
            BLOCK_GRAINS, BlockLoads, BlockOutcome, advance_full_block, advance_rigid_block,
            blocks_available,
        };
        use crate::grain::constitutive::Material;
        use crate::sample::unit_random;
        use rand::SeedableRng;
        if !blocks_available() {
            eprintln!("no AVX here: the grain pass takes no blocks, nothing to compare");
            return;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(16);
        let mut random = |lo: f64, hi: f64| lo + (hi - lo) * unit_random(&mut rng);
        let mut flagged = 0;
        for (case, (poisson, gravity)) in [
            (0.5, DVec2::ZERO),
            (0.3, DVec2::ZERO),
            (0.5, DVec2::new(0.1, -9.8)),
        ]
        .into_iter()
        .enumerate()
        {
            let material = Material {
                young: 1.0,
                poisson,
                density: 1.3,
            };
            let mut params = Parameters::new(material, 1e-3);
            params.gravity = gravity;
            params.deformation_damping = 0.7;
            params.k_alpha = 1e-3;
            params.alpha_mass_scale = 2.0;
            params.deformation_mass_scale = 3.0;
            let constants = UpdateConstants::new(&params);
            let block_constants = BlockConstants {
                params: &params,
                update: &constants,
                dt: params.dt,
            };
            let density = material.density;
            for trial in 0..300 {
                let grains: [Grain; BLOCK_GRAINS] = std::array::from_fn(|l| {
                    let eps1 = random(-0.3, 0.3);
                    // Equal strains, a difference under k_alpha's threshold, or any.
                    let eps2 = match (trial + l) % 4 {
                        0 => eps1,
                        1 => eps1 + random(-0.02, 0.02),
                        _ => random(-0.3, 0.3),
                    };
                    Grain {
                        radius: random(0.5, 1.5),
                        center: DVec2::new(random(-10.0, 10.0), random(-10.0, 10.0)),
                        velocity: DVec2::new(random(-0.1, 0.1), random(-0.1, 0.1)),
                        theta: random(-20.0, 20.0),
                        omega: random(-1.0, 1.0),
                        eps1,
                        eps1_rate: random(-0.1, 0.1),
                        eps2,
                        eps2_rate: random(-0.1, 0.1),
                        alpha: random(-4.0, 4.0),
                        alpha_rate: random(-1.0, 1.0),
                    }
                });
                let mut grains = grains;
                // Some blocks of circles only (equal strains in every lane), whose frames the
                // rigid block writes.
                if trial % 7 == 3 {
                    for grain in &mut grains {
                        grain.eps2 = grain.eps1;
                    }
                }
                // Lanes the checks must catch: a NaN, an inverted strain, a runaway.
                match trial {
                    10 => grains[2].velocity.y = f64::NAN,
                    11 => grains[1].eps2 = -1.5,
                    12 => grains[3].velocity.x = 5.0,
                    _ => {}
                }
                let loads: [ContactLoad; BLOCK_GRAINS] = std::array::from_fn(|l| ContactLoad {
                    force: DVec2::new(random(-0.01, 0.01), random(-0.01, 0.01)),
                    torque: random(-1e-3, 1e-3),
                    moment: DMat2::from_cols(
                        DVec2::new(random(-0.01, 0.01), random(-0.01, 0.01)),
                        DVec2::new(random(-0.01, 0.01), random(-0.01, 0.01)),
                    ),
                    lost_area: if l == 0 { 0.0 } else { random(0.0, 0.1) },
                    contacts: l as u32 + 2,
                    wall_contacts: l as u32 % 2,
                });
                let directions = grains.map(|g| g.principal_direction());
                // Each grain's one-grain update at `level` (`directions` read at the full level
                // only), and the updated grains.
                let one_by_one = |level: ModelLevel| {
                    let mut updated = grains;
                    let updates: Vec<GrainUpdate> = (0..BLOCK_GRAINS)
                        .map(|l| {
                            advance_grain(
                                &params,
                                params.dt,
                                1,
                                &mut updated[l],
                                &mut GrainLevel::new(level),
                                &loads[l],
                                &constants,
                                if level == ModelLevel::Full {
                                    directions[l]
                                } else {
                                    DVec2::ZERO
                                },
                                l,
                                7,
                            )
                        })
                        .collect();
                    (updated, updates)
                };
                // A block's lanes against the one-grain updates; returns the failed grains.
                let compare = |what: &str,
                               block: &[Grain; BLOCK_GRAINS],
                               stresses: &[GrainStress; BLOCK_GRAINS],
                               outcome: &BlockOutcome,
                               updated: &[Grain; BLOCK_GRAINS],
                               updates: &[GrainUpdate]| {
                    let mut failed = 0;
                    for l in 0..BLOCK_GRAINS {
                        let at = format!("{what}: case {case}, trial {trial}, lane {l}");
                        assert_eq!(grain_bits(&block[l]), grain_bits(&updated[l]), "{at}");
                        assert_eq!(
                            stress_bits(&stresses[l]),
                            stress_bits(&updates[l].stress),
                            "{at}"
                        );
                        assert_eq!(bits(outcome.area.0[l]), bits(updates[l].area), "{at}");
                        assert_eq!(
                            bits(outcome.elastic_energy.0[l]),
                            bits(updates[l].elastic_energy),
                            "{at}"
                        );
                        let suspect = outcome.suspect & (1 << l) != 0;
                        if updates[l].result.is_err() {
                            assert!(suspect, "{at}: a failed grain not flagged");
                            failed += 1;
                        }
                        if (10..=12).contains(&trial) {
                            assert_eq!(suspect, updates[l].result.is_err(), "{at}");
                        }
                    }
                    failed
                };
                let mut block_loads = BlockLoads::default();
                for (l, load) in loads.iter().enumerate() {
                    block_loads.set_lane(l, load);
                }
                let contacts = loads.map(|load| [load.contacts, load.wall_contacts]);

                let (updated, updates) = one_by_one(ModelLevel::Full);
                let mut block = grains;
                let mut stresses = [GrainStress::default(); BLOCK_GRAINS];
                let mut frames = [Frame::default(); BLOCK_GRAINS];
                let mut block_directions = directions;
                let outcome = advance_full_block(
                    &mut block,
                    &mut stresses,
                    &mut frames,
                    &block_loads,
                    &contacts,
                    &mut block_directions,
                    &block_constants,
                );
                flagged += compare("full", &block, &stresses, &outcome, &updated, &updates);
                for l in 0..BLOCK_GRAINS {
                    let (frame, direction) = Frame::of_grain_and_direction(&updated[l], density);
                    let at = format!("frame: case {case}, trial {trial}, lane {l}");
                    assert_eq!(frame_bits(&frames[l]), frame_bits(&frame), "{at}");
                    assert_eq!(
                        block_directions[l].to_array().map(bits),
                        direction.to_array().map(bits),
                        "{at}"
                    );
                }

                // The same grains at the rigid level: the rigid block against the one-grain
                // update at that level (which reads no principal direction); the frames of a
                // block of circles as `Frame::write_circle` writes them, the others the
                // caller's (left as they were).
                let (updated, updates) = one_by_one(ModelLevel::Rigid);
                let mut block = grains;
                let mut stresses = [GrainStress::default(); BLOCK_GRAINS];
                let mut frames = [Frame::default(); BLOCK_GRAINS];
                let outcome = advance_rigid_block(
                    &mut block,
                    &mut stresses,
                    &mut frames,
                    &block_loads,
                    &contacts,
                    &block_constants,
                );
                flagged += compare("rigid", &block, &stresses, &outcome, &updated, &updates);
                let circles = grains.iter().all(|g| g.eps1 == g.eps2);
                assert_eq!(outcome.circle_frames, circles, "case {case}, trial {trial}");
                for l in 0..BLOCK_GRAINS {
                    let mut frame = Frame::default();
                    if circles {
                        frame.write_circle(&updated[l], ModelLevel::Rigid, density);
                    }
                    let at = format!("circle frame: case {case}, trial {trial}, lane {l}");
                    assert_eq!(frame_bits(&frames[l]), frame_bits(&frame), "{at}");
                }
            }
        }
        assert_eq!(
            flagged,
            2 * 3 * 3,
            "each case's three failing grains, at either level"
        );
    }

    #[test]
    fn the_volumetric_update_reads_the_trace_and_no_direction() {
        // Expectation: the volumetric level moves the mean strain by the mean of the external
        // stress's principal components, the trace's half, which is the same in any frame: its
        // update is the same, every bit, whatever direction it is handed, and within rounding
        // of the update that projects the stress on the grain's own principal axes.
        use crate::grain::constitutive::Material;
        let material = Material {
            young: 1.0,
            poisson: 0.5,
            density: 1.3,
        };
        let params = Parameters::new(material, 1e-3);
        let constants = UpdateConstants::new(&params);
        let grain = Grain {
            theta: 0.7,
            alpha: -2.1,
            eps1: -0.04,
            eps2: -0.04,
            eps1_rate: 0.01,
            eps2_rate: 0.01,
            ..Grain::at_rest(DVec2::new(0.5, 0.25), 1.0)
        };
        let load = ContactLoad {
            force: DVec2::new(1e-3, -2e-3),
            torque: 1e-4,
            moment: DMat2::from_cols(DVec2::new(-0.03, 0.004), DVec2::new(0.006, -0.02)),
            lost_area: 0.01,
            contacts: 3,
            wall_contacts: 0,
        };
        let update = |e1: DVec2| {
            let mut updated = grain;
            let mut level = GrainLevel::new(ModelLevel::Volumetric);
            advance_grain(
                &params,
                params.dt,
                1,
                &mut updated,
                &mut level,
                &load,
                &constants,
                e1,
                0,
                1,
            );
            updated
        };
        let along_axes = update(grain.principal_direction());
        for e1 in [DVec2::X, DVec2::new(0.6, -0.8), DVec2::ZERO] {
            assert_eq!(
                update(e1).to_array().map(bits),
                along_axes.to_array().map(bits)
            );
        }
        // The size of the change of rounding (the figure its commit states): the sum of the
        // projections on the grain's axes, which the update read before, is the trace to
        // 1e-15 relative. Arithmetic only: the update itself is tested above.
        let e1 = grain.principal_direction();
        let e2 = e1.perp();
        let current_area = grain.ellipse_area() - load.lost_area;
        let external = 0.5 * (load.moment + load.moment.transpose()) * (1.0 / current_area);
        let projected = e1.dot(external * e1) + e2.dot(external * e2);
        let trace = external.x_axis.x + external.y_axis.y;
        assert!(
            (projected - trace).abs() < 1e-15 * trace.abs(),
            "{projected} {trace}"
        );
    }

    #[test]
    fn check_grain_finds_a_value_that_is_not_finite_in_any_field_and_only_then() {
        // Expectation: SPEC §9's non-finite failure for a NaN or an infinity in any of the
        // twelve values, whichever lane of the sum it falls in; none for finite values whose
        // sum overflows (the values are then tested one by one).
        let base = Grain::at_rest(DVec2::new(1.0, 2.0), 1.0);
        let fields: [fn(&mut Grain) -> &mut f64; 12] = [
            |g| &mut g.center.x,
            |g| &mut g.center.y,
            |g| &mut g.velocity.x,
            |g| &mut g.velocity.y,
            |g| &mut g.theta,
            |g| &mut g.omega,
            |g| &mut g.eps1,
            |g| &mut g.eps1_rate,
            |g| &mut g.eps2,
            |g| &mut g.eps2_rate,
            |g| &mut g.alpha,
            |g| &mut g.alpha_rate,
        ];
        let wave_speed_squared = 1e6;
        assert!(check_grain(&base, wave_speed_squared, 3, 7).is_ok());
        for (f, field) in fields.iter().enumerate() {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                let mut grain = base;
                *field(&mut grain) = bad;
                assert!(
                    matches!(
                        check_grain(&grain, wave_speed_squared, 3, 7),
                        Err(Instability::NonFinite { step: 7, grain: 3 })
                    ),
                    "field {f}, value {bad}"
                );
            }
        }
        let mut huge = base;
        for field in [
            fields[0], fields[1], fields[4], fields[5], fields[10], fields[11],
        ] {
            *field(&mut huge) = f64::MAX;
        }
        assert!(check_grain(&huge, wave_speed_squared, 3, 7).is_ok());
    }
}
