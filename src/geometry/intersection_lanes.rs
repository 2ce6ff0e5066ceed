//! The common path of [`grain_grain_hinted`] for eight pairs at a call, in AVX-512 registers
//! or four at a time in AVX ones (issue #16): two contours that were in contact last step,
//! whose chains' ends moved by at most one node and whose crossings lie on, or next to, the
//! edges of j they lay on last step.
//!
//! Nearly every contact of a dense packing takes that path every step, and one pair at a time
//! it is a long chain of dependent loads, products and branches. Here its arithmetic runs in
//! the lanes of vectors, each lane's choices made by masks and blends; the kernel is written
//! once (`kernel`, over a width's lanes) for four lanes in AVX registers (`avx`) and eight in
//! AVX-512 ones (`avx512`). The chain, not the arithmetic, bounds its time, so that eight
//! lanes compute two blocks in about one's time. Every quantity
//! is computed with the operations of the one-pair path, in its order (products and sums as
//! glam computes them), so that a lane gives that path's bits; a lane that would leave the path
//! (an end that moved further, a node in the thin ring where the inside test needs its sector,
//! a crossing two edges off its guess, a chord shorter than rounding, ...) is reported as such,
//! and its pair is computed by [`grain_grain_hinted`] itself. Which pairs share a block
//! therefore changes nothing. Without AVX every pair takes the one-pair path.

use super::contour::{ContourTable, GrainShape};
use super::intersection::{ContactGeometry, PairHint};
use glam::DVec2;

#[cfg(doc)]
use super::intersection::grain_grain_hinted;

/// Pairs in a block: one AVX register's worth of lanes, the unit of [`BlockContacts`].
pub const BLOCK: usize = 4;

/// One grain of a pair as a block reads it, where it lies: its centre and bounding radius,
/// the first three of four `f64`s `[x, y, r, _]`, and its map `A R` by columns
/// `[x0, x1, y0, y1]` (see [`GrainShape`]). Not a circle: the one-pair path takes a circle's
/// inverse map as `1/r` times the identity, which a block does not, so such pairs are left to
/// it.
#[derive(Debug, Clone, Copy)]
pub struct LaneShape<'a> {
    pub center_and_radius: &'a [f64; 4],
    pub map: &'a [f64; 4],
}

/// What a spare lane reads.
static ZEROS: [f64; 4] = [0.0; 4];

impl Default for LaneShape<'_> {
    fn default() -> Self {
        Self {
            center_and_radius: &ZEROS,
            map: &ZEROS,
        }
    }
}

/// A [`LaneShape`]'s values, owned: the shape of a [`GrainShape`].
#[derive(Debug, Clone, Copy)]
pub struct OwnedLaneShape {
    center_and_radius: [f64; 4],
    map: [f64; 4],
}

impl OwnedLaneShape {
    pub fn of(shape: &GrainShape) -> Self {
        let c = shape.center;
        Self {
            center_and_radius: [c.x, c.y, shape.bounding_radius, 0.0],
            map: shape.map.to_cols_array(),
        }
    }

    pub fn lane_shape(&self) -> LaneShape<'_> {
        LaneShape {
            center_and_radius: &self.center_and_radius,
            map: &self.map,
        }
    }
}

/// One pair of a block: the two shapes, the shift of j's centre to the image that meets i
/// (added where the block is told the pairs are shifted, in a periodic cell), and the pair's
/// hint from last step.
#[derive(Debug, Clone, Copy, Default)]
pub struct LanePair<'a> {
    pub i: LaneShape<'a>,
    pub j: LaneShape<'a>,
    pub j_shift: DVec2,
    pub hint: PairHint,
}

/// Where a call of [`grain_grain_blocks`] reads its pairs, lane by lane: each pair's two
/// shapes as a [`LaneShape`] holds them (its centre and bounding radius, then its map, four
/// `f64`s each), the shift of j's centre to its image and the pair's hint. An array of
/// [`LanePair`]s is one; the pair pass reads its frames where they lie through another, so
/// that filling a call's lanes writes only each pair's grains and hint (issue #16).
///
/// # Safety
/// For every lane below [`PAIRS`], the pointers returned are valid for reads while the source
/// is borrowed: `shape`'s of four `f64`s each, `j_shift`'s of two, `hint`'s of a [`PairHint`].
pub unsafe trait LanePairs {
    /// Where lane `lane`'s grain i (`second` false) or j has its centre and bounding radius,
    /// and its map.
    ///
    /// # Safety
    /// `lane` is below [`PAIRS`].
    unsafe fn shape(&self, lane: usize, second: bool) -> [*const f64; 2];
    /// Where the lane's shift of j lies.
    ///
    /// # Safety
    /// `lane` is below [`PAIRS`].
    unsafe fn j_shift(&self, lane: usize) -> *const f64;
    /// Where the lane's hint lies.
    ///
    /// # Safety
    /// `lane` is below [`PAIRS`].
    unsafe fn hint(&self, lane: usize) -> *const PairHint;
}

// SAFETY: each lane's pointers are its `LanePair`'s fields, borrowed with the array.
unsafe impl LanePairs for [LanePair<'_>; PAIRS] {
    #[inline(always)]
    unsafe fn shape(&self, lane: usize, second: bool) -> [*const f64; 2] {
        // SAFETY: the caller's.
        let pair = unsafe { self.get_unchecked(lane) };
        let shape = if second { &pair.j } else { &pair.i };
        [shape.center_and_radius.as_ptr(), shape.map.as_ptr()]
    }

    #[inline(always)]
    unsafe fn j_shift(&self, lane: usize) -> *const f64 {
        // SAFETY: the caller's. A shift is two f64s (`DVec2` is `repr(C)`).
        (unsafe { &self.get_unchecked(lane).j_shift } as *const DVec2).cast()
    }

    #[inline(always)]
    unsafe fn hint(&self, lane: usize) -> *const PairHint {
        // SAFETY: the caller's.
        unsafe { &self.get_unchecked(lane).hint }
    }
}

/// What a lane found: the pair's contact and its hint for next step, or `None` where the pair
/// leaves the common path (then [`grain_grain_hinted`] decides, from the old hint).
pub type LaneContact = Option<(ContactGeometry, PairHint)>;

/// What a block found, lane by lane ([`lane`](Self::lane)): the contacts' quantities as the
/// kernel's vectors left them, one array a quantity, which the lanes on the path fill.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(32))]
pub struct BlockContacts {
    point: [[f64; BLOCK]; 2],
    normal: [[f64; BLOCK]; 2],
    length: [f64; BLOCK],
    cap_area_i: [f64; BLOCK],
    cap_area_j: [f64; BLOCK],
    normal_gap: [f64; BLOCK],
    hint: [PairHint; BLOCK],
    /// The lanes on the common path: bit `l` for lane `l`.
    on_path: u32,
}

impl BlockContacts {
    /// The lanes' contact points and normals (by coordinate), lengths and normal gaps, as the
    /// kernel left them: a lane's are its contact's where it is on the path, and are otherwise
    /// not to be read.
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    pub fn contact_lanes(
        &self,
    ) -> (
        &[[f64; BLOCK]; 2],
        &[[f64; BLOCK]; 2],
        &[f64; BLOCK],
        &[f64; BLOCK],
    ) {
        (&self.point, &self.normal, &self.length, &self.normal_gap)
    }

    /// Whether every lane is on the common path.
    #[inline(always)]
    pub fn all_on_path(&self) -> bool {
        self.on_path == (1 << BLOCK) - 1
    }

    /// The lanes' cap areas (of the pairs' first grains, of their second grains) and next
    /// hints, as the kernel left them (see [`contact_lanes`](Self::contact_lanes)).
    #[inline(always)]
    pub fn cap_and_hint_lanes(&self) -> (&[f64; BLOCK], &[f64; BLOCK], &[PairHint; BLOCK]) {
        (&self.cap_area_i, &self.cap_area_j, &self.hint)
    }

    /// Lane `l`'s contact and next hint, `None` off the path.
    #[inline(always)]
    pub fn lane(&self, l: usize) -> LaneContact {
        if self.on_path & (1 << l) == 0 {
            return None;
        }
        Some((
            ContactGeometry {
                point: DVec2::new(self.point[0][l], self.point[1][l]),
                normal: DVec2::new(self.normal[0][l], self.normal[1][l]),
                length: self.length[l],
                cap_area_i: self.cap_area_i[l],
                cap_area_j: self.cap_area_j[l],
                normal_gap: self.normal_gap[l],
            },
            self.hint[l],
        ))
    }
}

/// Pairs a call of [`grain_grain_blocks`] computes: two blocks.
pub const PAIRS: usize = 2 * BLOCK;

/// The blocks of a call of [`grain_grain_blocks`].
pub const BLOCKS: usize = PAIRS / BLOCK;

/// How [`grain_grain_blocks`] computes its eight lanes: a block at a time in AVX registers,
/// or both at once in AVX-512 ones. Made only by [`available`](Self::available) and [`best`](Self::best), so that
/// a kernel in hand runs on this processor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlockKernel(Width);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Width {
    Avx,
    Avx512,
}

impl BlockKernel {
    /// The kernels this processor runs, the fastest last; none without AVX.
    pub fn available() -> Vec<BlockKernel> {
        let mut kernels = Vec::new();
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx") {
                kernels.push(BlockKernel(Width::Avx));
            }
            if avx512::available() {
                kernels.push(BlockKernel(Width::Avx512));
            }
        }
        kernels
    }

    /// The fastest kernel this processor runs, `None` without AVX; AVX where `SDEM_SIMD=avx`
    /// (see [`Simd`](crate::lanes::Simd)).
    pub fn best() -> Option<BlockKernel> {
        static BEST: std::sync::OnceLock<Option<BlockKernel>> = std::sync::OnceLock::new();
        *BEST.get_or_init(|| {
            Self::available()
                .into_iter()
                .rfind(|k| k.0 != Width::Avx512 || crate::lanes::Simd::polygons_in_avx512())
        })
    }

    /// The kernel's name, as benches and notes give it.
    pub fn name(self) -> &'static str {
        match self.0 {
            Width::Avx => "AVX",
            Width::Avx512 => "AVX-512",
        }
    }
}

/// The contacts of [`BLOCKS`] blocks of [`BLOCK`] pairs on the common path (see the module's
/// docs), block `b`'s pairs the source's lanes `4b..4b + 4` to `contacts[b]`, by `kernel`, of which the
/// first `filled` count (a block after theirs may be left unwritten): each lane's
/// [`BlockContacts::lane`] is what [`grain_grain_hinted`] returns for that pair (always a
/// contact there) and the hint it leaves, whichever the kernel; `None` where the pair leaves
/// the path. Neither grain of a pair is a circle ([`LaneShape`]); `shifted`: j's centres are
/// moved by the lanes' shifts (a periodic cell's images). Out of line, so that the lanes
/// stay in vector registers.
#[inline(never)]
pub fn grain_grain_blocks<P: LanePairs>(
    kernel: BlockKernel,
    table: &ContourTable,
    pairs: &P,
    shifted: bool,
    filled: usize,
    contacts: &mut [BlockContacts; BLOCKS],
) {
    #[cfg(target_arch = "x86_64")]
    match kernel.0 {
        // SAFETY: a kernel is made only where the processor runs it (`BlockKernel::available`).
        Width::Avx => unsafe { avx::grain_grain_blocks(table, pairs, shifted, filled, contacts) },
        Width::Avx512 => unsafe { avx512::grain_grain_blocks(table, pairs, shifted, contacts) },
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (kernel, table, pairs, shifted, filled);
        unreachable!("no block kernel is made on this processor");
    }
}

#[cfg(target_arch = "x86_64")]
mod kernel;

#[cfg(target_arch = "x86_64")]
mod avx;

#[cfg(target_arch = "x86_64")]
mod avx512;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::intersection::tests::unit_randoms;
    use crate::geometry::{Overlap, grain_grain_hinted};
    use glam::DVec2;

    /// A pair in contact, given by the grains' states, and the same pair a small step later.
    fn pair_and_its_next_step(
        next: &mut impl FnMut() -> f64,
        step: f64,
    ) -> (GrainShape, GrainShape, GrainShape, GrainShape) {
        let state = |next: &mut dyn FnMut() -> f64, strain: f64| {
            [
                6.0 * next(),
                strain * (2.0 * next() - 1.0),
                strain * (2.0 * next() - 1.0),
                6.0 * next(),
            ]
        };
        let [ti, e1i, e2i, ai] = state(next, 0.2);
        let rj = 0.3 + 1.2 * next();
        let [tj, e1j, e2j, aj] = state(next, 0.15);
        let direction = DVec2::from_angle(6.3 * next());
        let cj = direction * (1.0 + rj) * (0.8 + 0.2 * next());
        let i = GrainShape::new(DVec2::ZERO, 1.0, ti, e1i, e2i, ai);
        let j = GrainShape::new(cj, rj, tj, e1j, e2j, aj);
        let mut nudge = || step * (2.0 * next() - 1.0);
        let i_next = GrainShape::new(
            DVec2::new(nudge(), nudge()),
            1.0,
            ti + nudge(),
            e1i + nudge(),
            e2i + nudge(),
            ai + nudge(),
        );
        let j_next = GrainShape::new(
            cj + DVec2::new(nudge(), nudge()),
            rj,
            tj + nudge(),
            e1j + nudge(),
            e2j + nudge(),
            aj + nudge(),
        );
        (i, j, i_next, j_next)
    }

    #[test]
    fn lanes_give_the_one_pair_paths_contact_and_hint_bit_for_bit() {
        // Expectation: a lane on the common path returns exactly what `grain_grain_hinted`
        // returns for its pair from the same hint (contact and next hint), whatever the lane,
        // the pairs beside it and the kernel (AVX-512 or AVX, each where
        // the processor runs it); and most pairs a step after a contact take that path.
        if BlockKernel::available().is_empty() {
            return;
        }
        let table = ContourTable::new(1.0);
        let mut next = unit_randoms(23);
        let (mut on_path, mut total) = (0, 0);
        for step in [1e-4, 1e-3, 1e-2, 3e-2] {
            let (on_before, total_before) = (on_path, total);
            let mut pairs = Vec::new();
            for _ in 0..600 {
                let (i, j, i_next, j_next) = pair_and_its_next_step(&mut next, step);
                let mut hint = PairHint::default();
                if let Overlap::Contact(_) = grain_grain_hinted(&table, &i, &j, &mut hint) {
                    let shapes = [OwnedLaneShape::of(&i_next), OwnedLaneShape::of(&j_next)];
                    pairs.push((shapes, hint, i_next, j_next));
                }
            }
            for (block, rotation) in pairs.chunks_exact(PAIRS).zip(0..) {
                let mut block: [_; PAIRS] = block.try_into().unwrap();
                block.rotate_left(rotation % PAIRS);
                // Every other block meets j at an image: j's shape is stored moved back by the
                // lane's shift, which the block adds (and the one-pair path sees j where the
                // shift brings it back).
                let shifted = rotation % 2 == 1;
                let shift = |l: usize| DVec2::new(3.0, -5.0) * (l + 1) as f64;
                let mut stored = block.map(|(shapes, _, _, _)| shapes);
                if shifted {
                    for (l, [_, j]) in stored.iter_mut().enumerate() {
                        j.center_and_radius[0] -= shift(l).x;
                        j.center_and_radius[1] -= shift(l).y;
                    }
                }
                let mut lanes = [LanePair::default(); PAIRS];
                for (l, lane) in lanes.iter_mut().enumerate() {
                    *lane = LanePair {
                        i: stored[l][0].lane_shape(),
                        j: stored[l][1].lane_shape(),
                        j_shift: if shifted { shift(l) } else { DVec2::ZERO },
                        hint: block[l].1,
                    };
                }
                // Every kernel this processor runs, on both blocks and on the first alone (which
                // a kernel may compute in fewer lanes): the same contacts, bit for bit, in the
                // lanes that count.
                let mut results: Vec<(&str, usize, [BlockContacts; BLOCKS])> = Vec::new();
                for kernel in BlockKernel::available() {
                    for filled in [PAIRS, BLOCK] {
                        let mut contacts = [BlockContacts::default(); BLOCKS];
                        grain_grain_blocks(kernel, &table, &lanes, shifted, filled, &mut contacts);
                        results.push((kernel.name(), filled, contacts));
                    }
                }
                let contacts = results[0].2;
                for (l, (_, start_hint, i, j)) in block.iter().enumerate() {
                    let mut j = *j;
                    if shifted {
                        let [x, y, ..] = stored[l][1].center_and_radius;
                        j.center = DVec2::new(x, y) + shift(l);
                    }
                    let mut hint = *start_hint;
                    let one = grain_grain_hinted(&table, i, &j, &mut hint);
                    total += 1;
                    let lane = contacts[l / BLOCK].lane(l % BLOCK);
                    // Bit for bit: `{:?}` writes each f64 exactly, and the sign of a zero.
                    for (kernel, filled, other) in results.iter().filter(|r| l < r.1) {
                        assert_eq!(
                            format!("{:?}", other[l / BLOCK].lane(l % BLOCK)),
                            format!("{lane:?}"),
                            "lane {l} of {filled}, {kernel}"
                        );
                    }
                    if let Some((contact, next_hint)) = lane {
                        assert_eq!(one, Overlap::Contact(contact), "lane {l}");
                        assert_eq!(hint, next_hint, "lane {l}");
                        on_path += 1;
                    }
                }
            }
            // Moves of a ten-thousandth of a radius, a step's in a dense packing: nearly every
            // pair stays on the path.
            if step == 1e-4 {
                let (on, of) = (on_path - on_before, total - total_before);
                assert!(of > 400 && on * 10 > 9 * of, "{on} of {of} on the path");
            }
        }
        assert!(total > 1500, "{total}");
        assert!(
            on_path * 4 < total * 3,
            "{on_path} of {total}: the fallback is seldom tested"
        );
    }
}
