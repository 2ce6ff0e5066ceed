//! The step's pairs and grains in one pass over units (issue #16): a unit is a run of grain
//! chunks that one task takes whole. It computes the pairs inside it, adds each contact to its
//! two grains' loads while its record is still in cache, and advances each chunk's grains as
//! soon as their loads are complete; the pairs that reach into a later unit (the crossing
//! pairs, a few percent in a spatially ordered sample) are computed first, in a pass of their
//! own.
//!
//! Every sum keeps the order of the two-pass step it replaces, so every bit stays:
//! - a grain's load sums its pairs `[i, g]`, then its pairs `[g, j]`, in pair order. Every pair
//!   has `i < j` and the list is sorted, so the pairs `[i, g]` from earlier units (crossing
//!   pairs, computed before) come first, then those of its own unit, which a walk of the unit's
//!   pairs in pair order meets before the pairs `[g, j]`;
//! - the pair sums (dissipation, a cell's stress) are summed per grain chunk in pair order: the
//!   crossing pairs' shares are kept and merged in where they stand;
//! - the grain sums are summed per grain chunk in grain order, as before.
//!
//! Which pairs cross, and so the unit size, changes no result: a pair's computation is the
//! same wherever it happens.

use super::GrainStress;
use super::grain_pass::{ContactLoad, GrainPass};
use super::pairs::{PairFailure, PairPass, PairShare, PairSink, PairSlots};
use super::{
    ChunkSums, Frame, GRAIN_CHUNK, MAX_WALLS, PairContact, PairState, PairSums, pair_chunks,
};
use crate::boundary::periodic::PeriodicCell;
use crate::grain::{Grain, GrainLevel};
use glam::DVec2;
use rayon::prelude::*;

/// Most grain chunks in a unit: 4096 grains, whose loads (72 bytes each) stay in a core's
/// second-level cache.
const MAX_CHUNKS_PER_UNIT: usize = 16;
/// Fewest units the pass aims at, so that the threads share the work evenly.
const MIN_UNITS: usize = 32;

/// How the step cuts the grains and pairs into units; rebuilt with the neighbour list.
#[derive(Debug, Clone, Default)]
pub(super) struct UnitLayout {
    grains: usize,
    /// Grain chunks per unit.
    chunks_per_unit: usize,
    /// Where each unit's pairs (those whose first grain is one of its grains) end.
    pair_ends: Vec<usize>,
    /// The crossing pairs: those whose second grain lies in a later unit, in pair order.
    crossing: Vec<u32>,
    /// Where each unit's crossing pairs end in `crossing`.
    crossing_ends: Vec<usize>,
    /// For grain g, the crossing pairs `[i, g]` (as places in `crossing`, in pair order):
    /// `incoming[incoming_offsets[g]..incoming_offsets[g + 1]]`.
    incoming_offsets: Vec<u32>,
    incoming: Vec<u32>,
}

/// A crossing pair's contact as the units after its own read it, and its share of the sums.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct CrossingContact {
    active: bool,
    force_on_first: DVec2,
    point: DVec2,
    cap_area_first: f64,
    cap_area_second: f64,
    share: PairShare,
}

/// What one grain chunk of the pass leaves: its pair sums and its grain sums.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct ChunkResult {
    pub pairs: PairSums,
    pub grains: ChunkSums,
}

/// Per-task scratch, kept between the units a task takes.
#[derive(Default)]
struct Scratch {
    loads: Vec<ContactLoad>,
    inner: Vec<u32>,
}

impl UnitLayout {
    /// The layout of `grains` grains and the sorted pair list `pairs`, whose grain chunks end
    /// at `chunk_ends` (see [`pair_chunk_ends`](super::pair_chunk_ends)); `chunks_per_unit`
    /// (at least 1) where it is set, else chosen from the number of grains.
    pub fn new(
        pairs: &[[u32; 2]],
        grains: usize,
        chunk_ends: &[usize],
        chunks_per_unit: Option<usize>,
    ) -> Self {
        let chunks = chunk_ends.len();
        let chunks_per_unit = match chunks_per_unit {
            Some(k) => k.max(1),
            None => (chunks / MIN_UNITS).clamp(1, MAX_CHUNKS_PER_UNIT),
        };
        let unit_grains = chunks_per_unit * GRAIN_CHUNK;
        let pair_ends: Vec<usize> = chunk_ends
            .chunks(chunks_per_unit)
            .map(|ends| ends[ends.len() - 1])
            .collect();
        let mut crossing = Vec::new();
        let mut crossing_ends = Vec::with_capacity(pair_ends.len());
        let mut start = 0;
        for (unit, &end) in pair_ends.iter().enumerate() {
            let unit_end = ((unit + 1) * unit_grains) as u32;
            crossing.extend(
                (start..end)
                    .filter(|&p| pairs[p][1] >= unit_end)
                    .map(|p| p as u32),
            );
            crossing_ends.push(crossing.len());
            start = end;
        }
        let mut incoming_offsets = vec![0u32; grains + 1];
        for &p in &crossing {
            incoming_offsets[pairs[p as usize][1] as usize + 1] += 1;
        }
        for g in 0..grains {
            incoming_offsets[g + 1] += incoming_offsets[g];
        }
        let mut fill: Vec<u32> = incoming_offsets[..grains].to_vec();
        let mut incoming = vec![0u32; crossing.len()];
        for (place, &p) in crossing.iter().enumerate() {
            let slot = &mut fill[pairs[p as usize][1] as usize];
            incoming[*slot as usize] = place as u32;
            *slot += 1;
        }
        Self {
            grains,
            chunks_per_unit,
            pair_ends,
            crossing,
            crossing_ends,
            incoming_offsets,
            incoming,
        }
    }

    /// Whether the layout is for `grains` grains and, where it is set, `chunks_per_unit`.
    pub fn fits(&self, grains: usize, chunks_per_unit: Option<usize>) -> bool {
        self.grains == grains && chunks_per_unit.is_none_or(|k| k.max(1) == self.chunks_per_unit)
    }

    /// The number of crossing pairs.
    pub fn crossing_count(&self) -> usize {
        self.crossing.len()
    }

    /// Grains per unit.
    pub fn unit_grains(&self) -> usize {
        self.chunks_per_unit * GRAIN_CHUNK
    }

    fn crossing_of(&self, unit: usize) -> std::ops::Range<usize> {
        let start = if unit == 0 {
            0
        } else {
            self.crossing_ends[unit - 1]
        };
        start..self.crossing_ends[unit]
    }

    fn incoming_of(&self, g: usize) -> &[u32] {
        &self.incoming[self.incoming_offsets[g] as usize..self.incoming_offsets[g + 1] as usize]
    }
}

/// The pass: the pair pass and the grain pass it composes, on a layout.
pub(super) struct UnitPass<'a> {
    pub layout: &'a UnitLayout,
    /// Where each grain chunk's pairs end.
    pub chunk_ends: &'a [usize],
    pub pairs: PairPass<'a>,
    pub grains: GrainPass<'a>,
}

impl UnitPass<'_> {
    /// The crossing pairs of every unit, in parallel: their contacts, records and states, and
    /// what the later units read of them (`crossing`). Returns the failure of the lowest pair.
    pub fn crossing_pairs(
        &self,
        states: &mut [PairState],
        actives: &mut [bool],
        records: &mut [PairContact],
        crossing: &mut [CrossingContact],
    ) -> PairFailure {
        let layout = self.layout;
        let units = pair_chunks(&layout.pair_ends, states, actives, records);
        let mut crossing_units = Vec::with_capacity(units.len());
        let mut rest = crossing;
        for unit in 0..units.len() {
            let (this, after) =
                std::mem::take(&mut rest).split_at_mut(layout.crossing_of(unit).len());
            crossing_units.push(this);
            rest = after;
        }
        units
            .into_par_iter()
            .zip(crossing_units)
            .enumerate()
            .filter_map(|(unit, ((first, states, actives, records), contacts))| {
                let list = &layout.crossing[layout.crossing_of(unit)];
                let mut slots = PairSlots {
                    first,
                    states,
                    actives,
                    records,
                };
                if self.pairs.frictional() {
                    self.crossing_unit::<true>(list, &mut slots, contacts)
                } else {
                    self.crossing_unit::<false>(list, &mut slots, contacts)
                }
            })
            .min_by_key(|(p, _)| *p)
    }

    fn crossing_unit<const FRICTIONAL: bool>(
        &self,
        list: &[u32],
        slots: &mut PairSlots,
        contacts: &mut [CrossingContact],
    ) -> PairFailure {
        let mut failure = None;
        let mut sink = KeepCrossing::<FRICTIONAL> { contacts };
        self.pairs
            .compute::<FRICTIONAL>(list, slots, &mut failure, &mut sink);
        failure
    }

    /// Each unit whole, in parallel, once [`crossing_pairs`](Self::crossing_pairs) is done:
    /// its other pairs, its grains' loads and its grains' updates; the sums of each grain
    /// chunk go to `results`.
    #[allow(clippy::too_many_arguments)]
    pub fn units(
        &self,
        states: &mut [PairState],
        actives: &mut [bool],
        records: &mut [PairContact],
        crossing: &[CrossingContact],
        grains: &mut [Grain],
        stresses: &mut [GrainStress],
        levels: &mut [GrainLevel],
        wall_histories: &mut [[f64; MAX_WALLS]],
        results: &mut [ChunkResult],
    ) {
        let layout = self.layout;
        let unit_grains = layout.unit_grains();
        let units = pair_chunks(&layout.pair_ends, states, actives, records);
        units
            .into_par_iter()
            .zip(grains.par_chunks_mut(unit_grains))
            .zip(stresses.par_chunks_mut(unit_grains))
            .zip(levels.par_chunks_mut(unit_grains))
            .zip(wall_histories.par_chunks_mut(unit_grains))
            .zip(results.par_chunks_mut(layout.chunks_per_unit))
            .enumerate()
            .for_each_init(
                Scratch::default,
                |scratch,
                 (
                    unit,
                    (
                        (((((first, states, actives, records), grains), stresses), levels), walls),
                        results,
                    ),
                )| {
                    let mut slots = PairSlots {
                        first,
                        states,
                        actives,
                        records,
                    };
                    let grains = GrainArrays {
                        grains,
                        stresses,
                        levels,
                        wall_histories: walls,
                    };
                    if self.pairs.frictional() {
                        self.unit::<true>(unit, &mut slots, crossing, grains, results, scratch);
                    } else {
                        self.unit::<false>(unit, &mut slots, crossing, grains, results, scratch);
                    }
                },
            );
    }

    fn unit<const FRICTIONAL: bool>(
        &self,
        unit: usize,
        slots: &mut PairSlots,
        crossing: &[CrossingContact],
        grains: GrainArrays,
        results: &mut [ChunkResult],
        scratch: &mut Scratch,
    ) {
        let layout = self.layout;
        let frames = self.pairs.frames;
        let pairs = self.pairs.pairs;
        let first_grain = unit * layout.unit_grains();
        let end_grain = (first_grain + grains.grains.len()) as u32;
        let periodic = self.pairs.periodic.as_ref().map(|(cell, _)| cell);
        // Each grain's load starts with its crossing pairs from earlier units, in pair order.
        scratch.loads.clear();
        scratch
            .loads
            .extend((first_grain..end_grain as usize).map(|g| {
                let mut load = ContactLoad::default();
                for &place in layout.incoming_of(g) {
                    let c = &crossing[place as usize];
                    if c.active {
                        let p = layout.crossing[place as usize] as usize;
                        load.add_second_end(
                            c.force_on_first,
                            c.point,
                            c.cap_area_second,
                            frames[g].center,
                            image_shift(periodic, self.pairs.images, p),
                        );
                    }
                }
                load
            }));
        let mut crossing_place = layout.crossing_of(unit).start;
        let GrainArrays {
            grains,
            stresses,
            levels,
            wall_histories,
        } = grains;
        for (c, result) in results.iter_mut().enumerate() {
            let chunk = unit * layout.chunks_per_unit + c;
            let pair_start = if chunk == 0 {
                0
            } else {
                self.chunk_ends[chunk - 1]
            };
            let pair_end = self.chunk_ends[chunk];
            // The chunk's pairs inside the unit, computed here. Each contact goes to both its
            // grains' loads as soon as it is recorded, and its share to the chunk's sums; the
            // crossing pairs' kept contacts are merged in where they stand in pair order (to
            // their first grain only: the second is in a later unit).
            scratch.inner.clear();
            scratch.inner.extend(
                (pair_start..pair_end)
                    .filter(|&p| pairs[p][1] < end_grain)
                    .map(|p| p as u32),
            );
            let mut sink = InnerSink::<FRICTIONAL> {
                sums: PairSums::default(),
                loads: &mut scratch.loads,
                first_grain,
                crossing_pairs: &layout.crossing,
                crossing,
                crossing_place,
                pairs,
                frames,
                periodic: self.pairs.periodic.as_ref().map(|(cell, _)| cell),
                images: self.pairs.images,
            };
            let mut failure = None;
            self.pairs
                .compute::<FRICTIONAL>(&scratch.inner, slots, &mut failure, &mut sink);
            sink.crossing_before(pair_end);
            crossing_place = sink.crossing_place;
            result.pairs = PairSums {
                failure,
                ..sink.sums
            };
            // The chunk's grains are complete: a later pair has a later first grain.
            let range = c * GRAIN_CHUNK..((c + 1) * GRAIN_CHUNK).min(grains.len());
            result.grains = self.grains.chunk(
                first_grain + range.start,
                &mut grains[range.clone()],
                &mut stresses[range.clone()],
                &mut levels[range.clone()],
                &mut wall_histories[range.clone()],
                &scratch.loads[range],
            );
        }
    }
}

struct GrainArrays<'a> {
    grains: &'a mut [Grain],
    stresses: &'a mut [GrainStress],
    levels: &'a mut [GrainLevel],
    wall_histories: &'a mut [[f64; MAX_WALLS]],
}

/// The shift of the image of pair `p`'s second grain that meets the first: zero outside a
/// periodic cell.
#[inline(always)]
fn image_shift(cell: Option<&PeriodicCell>, images: &[[i64; 2]], p: usize) -> DVec2 {
    match cell {
        Some(cell) => cell.image_shift(images[p]),
        None => DVec2::ZERO,
    }
}

/// Keeps what the later units read of each crossing pair.
struct KeepCrossing<'a, const FRICTIONAL: bool> {
    contacts: &'a mut [CrossingContact],
}

impl<const FRICTIONAL: bool> PairSink for KeepCrossing<'_, FRICTIONAL> {
    #[inline(always)]
    fn pair(&mut self, k: usize, _: usize, contact: Option<(&PairContact, PairShare)>) {
        self.contacts[k] = match contact {
            None => CrossingContact::default(),
            Some((record, share)) => CrossingContact {
                active: true,
                force_on_first: record.force_on_first_in::<FRICTIONAL>(),
                point: record.point,
                cap_area_first: record.cap_area_first,
                cap_area_second: record.cap_area_second,
                share,
            },
        };
    }
}

/// A grain chunk's pairs inside its unit as they are computed: each contact to both its
/// grains' loads, its share to the chunk's sums, and before it the crossing pairs that precede
/// it in pair order (to their first grain only: the second lies in a later unit).
struct InnerSink<'a, const FRICTIONAL: bool> {
    sums: PairSums,
    /// The unit's grains' loads, from grain `first_grain` on.
    loads: &'a mut [ContactLoad],
    first_grain: usize,
    crossing_pairs: &'a [u32],
    crossing: &'a [CrossingContact],
    /// The next crossing pair to merge in (a place in `crossing_pairs`).
    crossing_place: usize,
    pairs: &'a [[u32; 2]],
    frames: &'a [Frame],
    periodic: Option<&'a PeriodicCell>,
    images: &'a [[i64; 2]],
}

impl<const FRICTIONAL: bool> InnerSink<'_, FRICTIONAL> {
    /// Merges in the crossing pairs before pair `p`.
    #[inline(always)]
    fn crossing_before(&mut self, p: usize) {
        while let Some(&q) = self.crossing_pairs.get(self.crossing_place)
            && (q as usize) < p
        {
            let c = &self.crossing[self.crossing_place];
            if c.active {
                self.sums
                    .add::<FRICTIONAL>(&c.share, self.periodic.is_some());
                let i = self.pairs[q as usize][0] as usize;
                self.loads[i - self.first_grain].add_first_end(
                    c.force_on_first,
                    c.point,
                    c.cap_area_first,
                    self.frames[i].center,
                );
            }
            self.crossing_place += 1;
        }
    }
}

impl<const FRICTIONAL: bool> PairSink for InnerSink<'_, FRICTIONAL> {
    #[inline(always)]
    fn pair(&mut self, _: usize, p: usize, contact: Option<(&PairContact, PairShare)>) {
        self.crossing_before(p);
        let Some((record, share)) = contact else {
            return;
        };
        self.sums.add::<FRICTIONAL>(&share, self.periodic.is_some());
        let [i, j] = self.pairs[p];
        let (i, j) = (i as usize, j as usize);
        let force_on_first = record.force_on_first_in::<FRICTIONAL>();
        self.loads[i - self.first_grain].add_first_end(
            force_on_first,
            record.point,
            record.cap_area_first,
            self.frames[i].center,
        );
        self.loads[j - self.first_grain].add_second_end(
            force_on_first,
            record.point,
            record.cap_area_second,
            self.frames[j].center,
            image_shift(self.periodic, self.images, p),
        );
    }
}
