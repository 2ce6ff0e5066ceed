//! Broad phase: a Verlet neighbour list with a skin, built on a uniform cell grid.
//!
//! Two grains are candidates when their bounding circles, inflated by the skin, overlap. The
//! list stays valid while every grain has moved plus grown by less than half the skin since
//! it was built: a pair not in the list cannot then have closed the gap. Everything here is
//! ordered (a stable counting sort into cells, pairs sorted by (i, j)), so the list and every
//! sum over it are the same whatever the thread count.

use crate::boundary::periodic::{PeriodicCell, floor_in_cell, nearest_integer};
use glam::{DMat2, DVec2};
use rayon::prelude::*;

/// Grains per parallel task of a build.
const BUILD_CHUNK: usize = 256;

/// A list that lasted fewer checks than this was rebuilt too often: the next is built with a
/// wider skin ([`adapted_skin`]).
pub const SHORT_LIST: u64 = 20;
/// A list that lasted more checks than this holds more open pairs than it needs: the next is
/// built with a narrower skin, down to the one the list was made with.
pub const LONG_LIST: u64 = 80;
/// The factors of one widening and one narrowing, and the widest skin as a multiple of the
/// list's own.
const WIDEN: f64 = 1.25;
const NARROW: f64 = 0.9;
const WIDEST: f64 = 4.0;

/// The skin of the next build, from the current `skin`, the list's own `base` and the checks
/// the last list `lasted` (issue #16). A thicker skin lists more open pairs, each a pair pass
/// turn, and is rebuilt less often: a dense packing that is still moving (the bench's lattice
/// after its release, 2.99 candidate pairs a grain at 0.2 to 0.4 mean radii) rebuilt its list
/// every 7 to 14 steps at 0.2, and its rigid discs ran 1.05 and 1.06 times as fast at 0.3 and
/// 0.4 with the same pairs, while the 10⁵ run's gas, whose list lasts a hundred steps, ran 0.95
/// times as fast at 0.3 (2.45 candidate pairs a grain against 2.33). So the skin widens while
/// lists last fewer than [`SHORT_LIST`] checks, up to four times the list's own and to `room`,
/// and narrows back while they last more than [`LONG_LIST`]. The list holds every pair within
/// its skin whichever it is, and the step's sums take the contacts alone, in an order that does
/// not depend on the list: the results are the same bits with any skin, only the speed differs.
pub fn adapted_skin(skin: f64, base: f64, lasted: u64, room: f64) -> f64 {
    if lasted < SHORT_LIST {
        // Where the room is below the current skin (a cell that shrank), the skin stays.
        (skin * WIDEN).min(WIDEST * base).min(room.max(skin))
    } else if lasted > LONG_LIST {
        (skin * NARROW).max(base)
    } else {
        skin
    }
}

/// The working arrays of a build, kept from one build to the next: made afresh each build, they
/// were pages the kernel zeroed and vectors copied as they grew, some 2% of a rigid step on
/// LAMMPS's 10⁵ packing, which rebuilds its list every 33 steps (issue #16). They hold nothing
/// between builds that a build reads.
#[derive(Clone, Default)]
struct BuildScratch {
    /// Each grain's bin: its index in a box, `column | row << 16` in a periodic cell.
    bin_of_grain: Vec<u32>,
    /// The bins' grains ([`sort_into_bins`]).
    bin_start: Vec<u32>,
    bin_grains: Vec<u32>,
    binned: Vec<BinnedGrain>,
    /// The pairs each chunk of [`BUILD_CHUNK`] grains lists, and (periodic) their images.
    chunk_pairs: Vec<Vec<[u32; 2]>>,
    chunk_images: Vec<Vec<[i64; 2]>>,
    /// The fill counts of a counting sort: [`sort_into_bins`]'s, then
    /// [`NeighborList::index_second_ends`]'s.
    fill: Vec<u32>,
}

impl std::fmt::Debug for BuildScratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("BuildScratch")
    }
}

#[derive(Debug, Clone, Default)]
pub struct NeighborList {
    /// Extra distance added to the bounding circles, in length units: the skin of the next
    /// build, which [`adapt_skin`](Self::adapt_skin) widens and narrows from `base_skin`.
    pub skin: f64,
    /// The skin the list was made with (a scenario's `contact.skin` times the mean radius):
    /// the adapted skin never falls below it.
    base_skin: f64,
    /// Checks that kept the list since its last build (see [`kept`](Self::kept)).
    checks_kept: u64,
    /// Candidate pairs (i, j), i < j, sorted.
    pub pairs: Vec<[u32; 2]>,
    /// The pairs `[g, j]` of grain g are `pairs[first_offsets[g]..first_offsets[g + 1]]`: one
    /// run, as the list is sorted.
    first_offsets: Vec<u32>,
    /// The pairs `[i, g]` of grain g (its ends as the second grain) are
    /// `second_pairs[second_offsets[g]..second_offsets[g + 1]]`, pair indices in increasing
    /// order. With the run above, they give g's pairs without reading `pairs`; in the sorted
    /// list all of them come before the run.
    second_offsets: Vec<u32>,
    second_pairs: Vec<u32>,
    /// Periodic cell only: for pair `[i, j]`, the image `n` of j that meets i (its centre is
    /// `x_j + H n`). Empty without a cell.
    pub images: Vec<[i64; 2]>,
    /// The centres at the last build; in a periodic cell their reduced coordinates.
    reference_centers: Vec<DVec2>,
    /// Periodic cell only: the cell matrix at the last build.
    reference_matrix: Option<DMat2>,
    reference_reach: Vec<f64>,
    /// Box only: the product of the affine scalings that carried the grains (and the reference
    /// centres with them) since the last build; (1, 1) without affine motion.
    affine_scale: DVec2,
    /// Number of builds so far (a diagnostic).
    pub builds: u64,
    scratch: BuildScratch,
}

impl NeighborList {
    pub fn new(skin: f64) -> Self {
        Self {
            skin,
            base_skin: skin,
            affine_scale: DVec2::ONE,
            ..Default::default()
        }
    }

    /// The skin the list was made with.
    pub fn base_skin(&self) -> f64 {
        self.base_skin
    }

    /// The skin as a multiple of the one the list was made with (1 for a list without one).
    pub fn skin_widening(&self) -> f64 {
        if self.base_skin > 0.0 {
            self.skin / self.base_skin
        } else {
            1.0
        }
    }

    /// Whether the list was built for `grains` grains and not invalidated since: a rebuild it
    /// then needs is one that the grains' motion asked for.
    pub fn is_built_for(&self, grains: usize) -> bool {
        grains > 0 && self.reference_centers.len() == grains
    }

    /// Counts a check that kept the list (one a step, or a multi-rate cycle).
    pub fn kept(&mut self) {
        self.checks_kept += 1;
    }

    /// Before a build that the grains' motion asked for: the skin of the new list from how
    /// many checks the old one lasted ([`adapted_skin`]), at most `room` (the widest skin the
    /// boundary allows; unbounded in a box).
    pub fn adapt_skin(&mut self, room: f64) {
        self.skin = adapted_skin(self.skin, self.base_skin, self.checks_kept, room);
    }

    /// Back to the skin the list was made with (a periodic cell too narrow for the widened
    /// skin); the next check rebuilds the list.
    pub fn reset_skin(&mut self) {
        self.skin = self.base_skin;
        self.invalidate();
    }

    /// Forgets the last build: the next check asks for a new one (after a cell remap, whose
    /// images change).
    pub fn invalidate(&mut self) {
        self.reference_centers.clear();
    }

    /// Whether some grain moved or grew enough since the last build that a pair may be missing.
    ///
    /// After affine motion ([`follow_affine`](Self::follow_affine)) the displacements are
    /// measured from the mapped reference centres, and the skin pays for the contraction: a pair
    /// of separation `d0 >= r_i + r_j + skin` at the build is at least `s d0` apart after the
    /// mapping (s the smallest scaling), so it cannot have closed its gap while
    /// `2 max(displacement + growth) < skin - (1 - s) (2 max reach + skin)`, as in a deforming
    /// periodic cell. In an affine compression the grains then keep one list for hundreds of
    /// steps instead of rebuilding it whenever the box has moved half a skin.
    pub fn needs_rebuild(&self, centers: &[DVec2], reach: &[f64]) -> bool {
        self.needs_rebuild_with_reserve(centers, reach, 0.0)
    }

    /// [`needs_rebuild`](Self::needs_rebuild), keeping `reserve` of every grain's budget for
    /// motion to come before the next check (the second half of a multi-rate cycle): once it
    /// answers false, every pair whose bounding circles are less than `2 reserve` apart is
    /// listed.
    pub fn needs_rebuild_with_reserve(
        &self,
        centers: &[DVec2],
        reach: &[f64],
        reserve: f64,
    ) -> bool {
        if self.reference_centers.len() != centers.len() || self.reference_matrix.is_some() {
            return true;
        }
        let contraction = (1.0 - self.affine_scale.min_element()).max(0.0);
        let budget = self.displacement_budget(contraction, || largest_reach(reach)) - reserve;
        if budget <= 0.0 {
            return true;
        }
        self.any_moved(centers, reach, budget, |c, c0| c.distance(c0))
    }

    /// The grains were carried by the affine map of the box with corners `from` (lower left,
    /// upper right) onto the box `to`, each axis on its own: the reference centres follow, and
    /// [`needs_rebuild`](Self::needs_rebuild) charges the contraction to the skin.
    pub fn follow_affine(&mut self, from: (DVec2, DVec2), to: (DVec2, DVec2)) {
        if self.reference_centers.is_empty() || self.reference_matrix.is_some() {
            return;
        }
        let scale = (to.1 - to.0) / (from.1 - from.0);
        self.reference_centers
            .par_iter_mut()
            .with_min_len(4096)
            .for_each(|c| *c = to.0 + (*c - from.0) * scale);
        self.affine_scale *= scale;
    }

    /// How far (displacement plus growth) every grain may still move before a pair not listed
    /// could close its gap, after a homogeneous deformation of norm `strain` since the build:
    /// `(skin - strain (2 max reach + skin)) / 2`; half the skin without deformation.
    fn displacement_budget(&self, strain: f64, max_reach: impl FnOnce() -> f64) -> f64 {
        if strain == 0.0 {
            return 0.5 * self.skin;
        }
        0.5 * (self.skin - strain * (2.0 * max_reach() + self.skin))
    }

    /// Whether some grain's displacement since the build (`displacement(centre, reference)`)
    /// plus its growth reaches `limit`.
    fn any_moved(
        &self,
        centers: &[DVec2],
        reach: &[f64],
        limit: f64,
        displacement: impl Fn(DVec2, DVec2) -> f64 + Sync,
    ) -> bool {
        // Whole chunks, each a plain loop without an exit: nearly every step tests every grain
        // and finds none, and a short-circuiting parallel `any` paid its plumbing per grain
        // (issue #16: 330 instructions a grain-step in a periodic cell).
        const CHUNK: usize = 4096;
        centers
            .par_chunks(CHUNK)
            .zip(reach.par_chunks(CHUNK))
            .zip(
                self.reference_centers
                    .par_chunks(CHUNK)
                    .zip(self.reference_reach.par_chunks(CHUNK)),
            )
            .any(|((centers, reach), (references, reference_reach))| {
                let mut moved = false;
                for ((c, r), (c0, r0)) in centers
                    .iter()
                    .zip(reach)
                    .zip(references.iter().zip(reference_reach))
                {
                    moved |= displacement(*c, *c0) + (r - r0).max(0.0) >= limit;
                }
                moved
            })
    }

    /// The periodic version of [`needs_rebuild`](Self::needs_rebuild), for a cell that deforms.
    ///
    /// The centres move with the cell's affine deformation (`F = H H0^-1` since the build) plus
    /// their own displacement `H Δs` (Δs: the change of reduced coordinates, to the nearest
    /// lattice shift). For a pair of separation `d0 >= r_i + r_j + skin` at the build, the gap
    /// can shrink by at most `|H Δs_i| + |H Δs_j| + |F - I| |d0|` plus the growths; at `d0` near
    /// the listing limit, a pair not listed cannot have closed its gap while
    /// `2 max(|H Δs| + growth) + |F - I| (2 max reach + skin) < skin`. `max_reach`: the
    /// largest of `reach` ([`largest_reach`]), which the step measures anyway for the cell's
    /// width.
    pub fn needs_rebuild_periodic(
        &self,
        centers: &[DVec2],
        reach: &[f64],
        cell: &PeriodicCell,
        max_reach: f64,
    ) -> bool {
        let Some(reference_matrix) = self.reference_matrix else {
            return true;
        };
        if self.reference_centers.len() != centers.len() {
            return true;
        }
        let strain = cell.matrix() * reference_matrix.inverse() - DMat2::IDENTITY;
        let strain_norm = strain.x_axis.length_squared() + strain.y_axis.length_squared();
        let budget = self.displacement_budget(strain_norm.sqrt(), || max_reach);
        if budget <= 0.0 {
            return true;
        }
        // Reduced coordinates are stored: the displacement is `H Δs`, to the nearest lattice
        // shift (a grain may have been wrapped since).
        self.any_moved(centers, reach, budget, |c, s0| {
            let ds = cell.reduced(c) - s0;
            (cell.matrix() * (ds - nearest_integer(ds))).length()
        })
    }

    /// Rebuilds the list for grains with the given centres and bounding radii.
    pub fn build(&mut self, centers: &[DVec2], reach: &[f64]) {
        let n = centers.len();
        if !self.start_build(centers, reach) {
            return;
        }
        let max_reach = largest_reach(reach);
        let mut cell = (2.0 * max_reach + self.skin).max(f64::MIN_POSITIVE);
        // The grains' bounding box, in parallel: min and max are exact, so the box does not
        // depend on how the threads split the grains (but for the sign of a zero bound, which
        // no bin or width below tells apart).
        let (lo, hi) = centers
            .par_iter()
            .with_min_len(8192)
            .fold(
                || (centers[0], centers[0]),
                |(lo, hi), &c| (lo.min(c), hi.max(c)),
            )
            .reduce(
                || (centers[0], centers[0]),
                |(lo_a, hi_a), (lo_b, hi_b)| (lo_a.min(lo_b), hi_a.max(hi_b)),
            );
        // At most max(4 n, 2^16) cells: grains far apart for their size (a sparse or absurd
        // sample, e.g. radii of 1e-45 in a sample file) would otherwise ask for up to 2^30, and
        // their quotients below would overflow usize. A coarser grid finds the same pairs (each
        // list is sorted), so results do not change.
        let side = ((4 * n).max(1 << 16) as f64).sqrt().floor() - 1.0;
        cell = cell.max((hi.x - lo.x) / side).max((hi.y - lo.y) / side);
        let cols = (((hi.x - lo.x) / cell) as usize + 1).min(1 << 15);
        let rows = (((hi.y - lo.y) / cell) as usize + 1).min(1 << 15);
        let cell_of = |c: DVec2| -> (usize, usize) {
            let cx = (((c.x - lo.x) / cell) as usize).min(cols - 1);
            let cy = (((c.y - lo.y) / cell) as usize).min(rows - 1);
            (cx, cy)
        };
        let mut scratch = std::mem::take(&mut self.scratch);
        // Each grain's bin, in parallel: the divisions were most of the serial sort below.
        scratch.bin_of_grain.clear();
        scratch
            .bin_of_grain
            .par_extend(centers.par_iter().with_min_len(4096).map(|&c| {
                let (cx, cy) = cell_of(c);
                (cy * cols + cx) as u32
            }));
        let bin_of_grain = &scratch.bin_of_grain;
        let bins = (
            &mut scratch.bin_start,
            &mut scratch.fill,
            &mut scratch.bin_grains,
        );
        sort_into_bins(n, cols * rows, |g| bin_of_grain[g] as usize, bins);
        // The grains in bin order, with what the search reads of them: the bins of a row are
        // consecutive, so that a grain's three neighbouring bins in a row are one run of it,
        // read in order (a third of the loops over bins, and no reads scattered over the
        // grains' arrays).
        BinnedGrain::in_order(&mut scratch, centers, reach, |_| true);
        let (bin_of_grain, cell_start, binned) =
            (&scratch.bin_of_grain, &scratch.bin_start, &scratch.binned);
        scratch
            .chunk_pairs
            .resize_with(n.div_ceil(BUILD_CHUNK), Vec::new);
        let skin = self.skin;
        // Chunks of grains, each listing its pairs in order: two allocations a chunk, not one
        // a grain (they were a tenth of a build).
        // Each task also writes its grains' first ends into `first_offsets`, counted from the
        // chunk's first pair (`append_chunks` adds where the chunk starts).
        self.first_offsets[1..]
            .par_chunks_mut(BUILD_CHUNK)
            .zip(scratch.chunk_pairs.par_iter_mut())
            .enumerate()
            .for_each(|(chunk, (first_ends, pairs))| {
                pairs.clear();
                let mut found = Vec::new();
                let start = chunk * BUILD_CHUNK;
                for (i, first_end) in (start..).zip(first_ends) {
                    let (ci, reach_i) = (centers[i], reach[i]);
                    let bin = bin_of_grain[i] as usize;
                    let (cx, cy) = (bin % cols, bin / cols);
                    let (first_column, last_column) =
                        (cx.saturating_sub(1), (cx + 1).min(cols - 1));
                    found.clear();
                    for ny in cy.saturating_sub(1)..=(cy + 1).min(rows - 1) {
                        let run = cell_start[ny * cols + first_column] as usize
                            ..cell_start[ny * cols + last_column + 1] as usize;
                        let run = &binned[run];
                        found.reserve(run.len());
                        for other in run {
                            let limit = reach_i + other.reach + skin;
                            let near = ci.distance_squared(other.center) < limit * limit;
                            push_if(&mut found, other.grain, near & (other.grain as usize > i));
                        }
                    }
                    found.sort_unstable();
                    pairs.extend(found.iter().map(|&j| [i as u32, j]));
                    *first_end = pairs.len() as u32;
                }
            });
        self.append_chunks(&scratch.chunk_pairs, None);
        self.index_second_ends(n, &mut scratch.fill);
        self.scratch = scratch;
    }

    /// Appends the pairs of a build's chunks (the chunks of [`BUILD_CHUNK`] grains, in order)
    /// to the list, and their images (a periodic build) to `images`; each chunk's grains'
    /// `first_offsets`, counted from the chunk's first pair, are moved to the list's. In
    /// parallel, chunk by chunk: serial, the copies (with a count of the first ends) ran on
    /// one thread whatever the thread count (docs/performance.md, twenty-ninth session).
    fn append_chunks(&mut self, chunks: &[Vec<[u32; 2]>], images: Option<&[Vec<[i64; 2]>]>) {
        let starts: Vec<usize> = chunks
            .iter()
            .scan(0, |start, chunk| {
                let first = *start;
                *start += chunk.len();
                Some(first)
            })
            .collect();
        concatenate_in_parallel(&mut self.pairs, chunks);
        assert!(
            self.pairs.len() < 1 << 31,
            "{} candidate pairs: the index of grain ends holds at most 2^31",
            self.pairs.len()
        );
        if let Some(images) = images {
            concatenate_in_parallel(&mut self.images, images);
        }
        self.first_offsets[1..]
            .par_chunks_mut(BUILD_CHUNK)
            .zip(&starts)
            .for_each(|(first_ends, &start)| {
                for end in first_ends {
                    *end += start as u32;
                }
            });
    }

    /// Resets the list for a build; false when there are no grains.
    fn start_build(&mut self, centers: &[DVec2], reach: &[f64]) -> bool {
        let n = centers.len();
        self.builds += 1;
        self.checks_kept = 0;
        // Copied in parallel (an indexed iterator's `par_extend` writes in place): serial, the
        // copies were a serial part of every build.
        self.reference_centers.clear();
        self.reference_centers
            .par_extend(centers.par_iter().with_min_len(8192).copied());
        self.reference_reach.clear();
        self.reference_reach
            .par_extend(reach.par_iter().with_min_len(8192).copied());
        self.reference_matrix = None;
        self.affine_scale = DVec2::ONE;
        self.pairs.clear();
        self.images.clear();
        self.second_pairs.clear();
        for offsets in [&mut self.first_offsets, &mut self.second_offsets] {
            offsets.clear();
            offsets.resize(n + 1, 0);
        }
        n > 0
    }

    /// Rebuilds the list in a periodic cell: each pair with the image of its second grain
    /// nearest the first ([`PeriodicCell::minimum_image`]), in [`images`](Self::images).
    ///
    /// The grid is laid in reduced coordinates, `cols` bins across h1 and `rows` across h2,
    /// each at least the interaction range wide across the cell (the cell's widths over the
    /// range, rounded down), so that every pair within range lies in neighbouring bins, the
    /// bins wrapping round the cell. The cell must be at least twice the range wide
    /// ([`PeriodicCell::check_range`]).
    pub fn build_periodic(&mut self, centers: &[DVec2], reach: &[f64], cell: &PeriodicCell) {
        let n = centers.len();
        if !self.start_build(centers, reach) {
            self.reference_matrix = Some(cell.matrix());
            return;
        }
        for c in &mut self.reference_centers {
            *c = cell.reduced(*c);
        }
        self.reference_matrix = Some(cell.matrix());
        let max_reach = largest_reach(reach);
        let range = (2.0 * max_reach + self.skin).max(f64::MIN_POSITIVE);
        let [width1, width2] = cell.widths();
        let cols = ((width1 / range) as usize).clamp(1, 1 << 15);
        let rows = ((width2 / range) as usize).clamp(1, 1 << 15);
        // Each grain's bin column and row once, in parallel, as in `build` (computed where they
        // were used, three times a grain, each with two floor calls), packed as `cx | cy << 16`
        // so that neither takes a division to recover.
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.bin_of_grain.clear();
        scratch
            .bin_of_grain
            .par_extend(
                self.reference_centers
                    .par_iter()
                    .with_min_len(4096)
                    .map(|&s| {
                        // The fractional part, `s - s.floor()` (no call for a grain inside
                        // the cell).
                        let f = DVec2::new(s.x - floor_in_cell(s.x), s.y - floor_in_cell(s.y));
                        let cx = ((f.x * cols as f64) as usize).min(cols - 1);
                        let cy = ((f.y * rows as f64) as usize).min(rows - 1);
                        (cx | cy << 16) as u32
                    }),
            );
        let unpack = |packed: u32| ((packed & 0xffff) as usize, (packed >> 16) as usize);
        let column_and_row = &scratch.bin_of_grain;
        let bins = (
            &mut scratch.bin_start,
            &mut scratch.fill,
            &mut scratch.bin_grains,
        );
        sort_into_bins(
            n,
            cols * rows,
            |g| {
                let (cx, cy) = unpack(column_and_row[g]);
                cy * cols + cx
            },
            bins,
        );
        // The grains in bin order, as in `build`: a row's neighbouring bins are one run of it
        // unless they wrap round the cell.
        let reduced = &self.reference_centers;
        BinnedGrain::in_order(&mut scratch, centers, reach, |g| in_cell(reduced[g]));
        let (column_and_row, cell_start, binned) =
            (&scratch.bin_of_grain, &scratch.bin_start, &scratch.binned);
        let chunks = n.div_ceil(BUILD_CHUNK);
        scratch.chunk_pairs.resize_with(chunks, Vec::new);
        scratch.chunk_images.resize_with(chunks, Vec::new);
        // A grain in the cell whose neighbouring bins do not wrap round it meets the grains of
        // those bins that are in the cell at their own positions: both reduced coordinates lie
        // in `[0, 1)` and less than two bins apart, at most 2/5 of the cell with five bins or
        // more across, so the nearest integer of their reduced separation is zero, and so is
        // the image `minimum_image_in_range` would give (its separation differs from theirs
        // at most by the sign of a zero). The images' arithmetic was most of a build (issue
        // #16: 145 ns a grain on LAMMPS's 10⁵ packing, against some 60 in a box).
        let inside = |k: usize, count: usize| count >= 5 && k >= 1 && k + 2 <= count;
        let skin = self.skin;
        // Chunks of grains, each listing its pairs in order, as in `build`: one vector a grain
        // (and one for its bins) made a rebuild six times as long as a box's (issue #16).
        self.first_offsets[1..]
            .par_chunks_mut(BUILD_CHUNK)
            .zip(
                scratch
                    .chunk_pairs
                    .par_iter_mut()
                    .zip(scratch.chunk_images.par_iter_mut()),
            )
            .enumerate()
            .for_each(|(chunk, (first_ends, (pairs, images)))| {
                pairs.clear();
                images.clear();
                let mut found: Vec<(u32, [i64; 2])> = Vec::new();
                for (i, first_end) in (chunk * BUILD_CHUNK..).zip(first_ends) {
                    let (ci, reach_i) = (centers[i], reach[i]);
                    let (cx, cy) = unpack(column_and_row[i]);
                    found.clear();
                    let at_own_images = inside(cx, cols) && inside(cy, rows) && in_cell(reduced[i]);
                    let column_runs = NeighborBins::around(cx, cols);
                    for ny in NeighborBins::around(cy, rows).runs().flatten() {
                        for columns in column_runs.runs() {
                            let run = cell_start[ny * cols + columns.start] as usize
                                ..cell_start[ny * cols + columns.end] as usize;
                            let run = &binned[run];
                            found.reserve(run.len());
                            for other in run {
                                let j = other.grain;
                                let limit = reach_i + other.reach + skin;
                                if at_own_images && other.in_cell {
                                    let d = other.center - ci;
                                    let near = d.length_squared() < limit * limit;
                                    push_if(&mut found, (j, [0, 0]), near & (j as usize > i));
                                    continue;
                                }
                                if (j as usize) <= i {
                                    continue;
                                }
                                // `d = x_j - x_i - H m`: the image of j nearest i is at
                                // `x_j - H m`.
                                let (d, [m1, m2]) = cell.minimum_image_in_range(other.center - ci);
                                if d.length_squared() < limit * limit {
                                    found.push((j, [-m1, -m2]));
                                }
                            }
                        }
                    }
                    found.sort_unstable_by_key(|(j, _)| *j);
                    pairs.extend(found.iter().map(|&(j, _)| [i as u32, j]));
                    images.extend(found.iter().map(|&(_, image)| image));
                    *first_end = pairs.len() as u32;
                }
            });
        self.append_chunks(&scratch.chunk_pairs, Some(&scratch.chunk_images));
        self.index_second_ends(n, &mut scratch.fill);
        self.scratch = scratch;
    }

    /// Fills `second_offsets` and `second_pairs` from `pairs`: a transposition (a pass that
    /// scatters), serial. The first ends are runs of the list, counted by the build's tasks.
    fn index_second_ends(&mut self, n: usize, fill: &mut Vec<u32>) {
        for [_, j] in &self.pairs {
            self.second_offsets[*j as usize + 1] += 1;
        }
        for g in 0..n {
            self.second_offsets[g + 1] += self.second_offsets[g];
        }
        clear_with_room(&mut self.second_pairs, self.pairs.len());
        self.second_pairs.resize(self.pairs.len(), 0);
        fill.clear();
        fill.extend_from_slice(&self.second_offsets[..n]);
        for (p, [_, j]) in self.pairs.iter().enumerate() {
            let slot = &mut fill[*j as usize];
            self.second_pairs[*slot as usize] = p as u32;
            *slot += 1;
        }
    }

    /// After grains were wrapped back into the cell (grain g moved by `-H wraps[g]`, as
    /// [`PeriodicCell::wrap`] moves it), the image of each pair that keeps its branch vector
    /// `x_j + H n - x_i`.
    pub fn follow_wraps(&mut self, wraps: &[[i64; 2]]) {
        self.pairs
            .par_iter()
            .zip(self.images.par_iter_mut())
            .with_min_len(4096)
            .for_each(|([i, j], image)| {
                let (wi, wj) = (wraps[*i as usize], wraps[*j as usize]);
                image[0] += wj[0] - wi[0];
                image[1] += wj[1] - wi[1];
            });
    }

    /// The pairs `[i, g]` that hold grain g as their second grain, in increasing order.
    #[inline]
    pub fn second_ends_of(&self, g: usize) -> &[u32] {
        &self.second_pairs[self.second_offsets[g] as usize..self.second_offsets[g + 1] as usize]
    }

    /// The pairs `[g, j]` that hold grain g as their first grain: a run of the list.
    #[inline]
    pub fn first_ends_of(&self, g: usize) -> std::ops::Range<usize> {
        self.first_offsets[g] as usize..self.first_offsets[g + 1] as usize
    }

    /// [`second_ends_of`](Self::second_ends_of) and [`first_ends_of`](Self::first_ends_of) of
    /// grain g, with one bounds check for both: the step's gather reads them for every grain,
    /// and their six checks were some 20 instructions a grain-step (issue #16).
    #[inline(always)]
    pub fn ends_of(&self, g: usize) -> (&[u32], std::ops::Range<usize>) {
        let (first, second) = (&self.first_offsets, &self.second_offsets);
        assert!(g + 1 < first.len() && first.len() == second.len());
        // SAFETY: g + 1 is below both offsets' lengths (asserted above). The offsets of the
        // second ends are prefix sums of counts (`index_second_ends`, which writes them and
        // `second_pairs` together; nothing else does but to clear both), so that
        // `second[g] <= second[g + 1] <= second_pairs.len()`.
        unsafe {
            let ends = *second.get_unchecked(g) as usize..*second.get_unchecked(g + 1) as usize;
            debug_assert!(ends.start <= ends.end && ends.end <= self.second_pairs.len());
            (
                self.second_pairs.get_unchecked(ends),
                *first.get_unchecked(g) as usize..*first.get_unchecked(g + 1) as usize,
            )
        }
    }
}

/// The largest of the bounding radii (0 for none), in parallel: max is exact, so the result
/// does not depend on how the threads split the slice. A serial fold was a step's only serial
/// pass over the grains while a box moves affinely.
pub fn largest_reach(reach: &[f64]) -> f64 {
    reach
        .par_iter()
        .with_min_len(8192)
        .cloned()
        .reduce(|| 0.0, f64::max)
}

/// The bins next to bin `k` along one axis of a periodic cell's `count`, as runs of
/// consecutive bins that hold each bin once: `k - 1`, `k` and `k + 1` round the cell, every bin
/// where there are at most three.
struct NeighborBins {
    runs: [std::ops::Range<usize>; 2],
    count: usize,
}

impl NeighborBins {
    fn around(k: usize, count: usize) -> Self {
        let (runs, count) = if count <= 3 {
            ([0..count, 0..0], 1)
        } else if k == 0 {
            ([0..2, count - 1..count], 2)
        } else if k == count - 1 {
            ([0..1, k - 1..count], 2)
        } else {
            ([k - 1..k + 2, 0..0], 1)
        };
        NeighborBins { runs, count }
    }

    fn runs(&self) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
        self.runs.iter().take(self.count).cloned()
    }
}

/// A grain as the searches read it from the bins.
#[derive(Clone, Copy)]
struct BinnedGrain {
    center: DVec2,
    reach: f64,
    grain: u32,
    /// A periodic search's: whether the centre lies in the cell (reduced coordinates in
    /// `[0, 1)`), as after each step's wrap nearly every grain's does.
    in_cell: bool,
}

impl BinnedGrain {
    /// Writes `scratch.binned`: the grains of `scratch.bin_grains` (the bins' grains, bin after
    /// bin), each with its centre and reach, and whether it is `in_cell`.
    fn in_order(
        scratch: &mut BuildScratch,
        centers: &[DVec2],
        reach: &[f64],
        in_cell: impl Fn(usize) -> bool + Sync,
    ) {
        scratch.binned.clear();
        scratch
            .binned
            .par_extend(
                scratch
                    .bin_grains
                    .par_iter()
                    .with_min_len(8192)
                    .map(|&j| BinnedGrain {
                        center: centers[j as usize],
                        reach: reach[j as usize],
                        grain: j,
                        in_cell: in_cell(j as usize),
                    }),
            );
    }
}

/// Whether reduced coordinates `s` lie in the cell, `[0, 1)` on both axes.
#[inline(always)]
fn in_cell(s: DVec2) -> bool {
    (0.0..1.0).contains(&s.x) && (0.0..1.0).contains(&s.y)
}

/// Stable counting sort of grains `0..n` into `bins` bins, into `(start, fill, grains)`: the
/// grains of bin k are `grains[start[k]..start[k + 1]]`, in increasing order (`fill`: the
/// sort's counts).
fn sort_into_bins(
    n: usize,
    bins: usize,
    bin_of: impl Fn(usize) -> usize,
    (start, fill, grains): (&mut Vec<u32>, &mut Vec<u32>, &mut Vec<u32>),
) {
    start.clear();
    start.resize(bins + 1, 0);
    for g in 0..n {
        start[bin_of(g) + 1] += 1;
    }
    for k in 0..bins {
        start[k + 1] += start[k];
    }
    fill.clear();
    fill.extend_from_slice(start);
    grains.clear();
    grains.resize(n, 0);
    for g in 0..n {
        let slot = &mut fill[bin_of(g)];
        grains[*slot as usize] = g as u32;
        *slot += 1;
    }
}

/// Appends `value` to `vector` where `keep` holds, without a branch on it: written always, and
/// the length moved past it or not. The searches' tests of a candidate (an index above the
/// grain's, and within range) go either way about as often, and their branches were
/// mispredicted often (issue #16). `vector` must have room for one more entry.
#[inline(always)]
fn push_if<T: Copy>(vector: &mut Vec<T>, value: T, keep: bool) {
    let len = vector.len();
    assert!(len < vector.capacity());
    // SAFETY: `len` is within the capacity (asserted above); the entry is written before the
    // length may take it in.
    unsafe {
        vector.as_mut_ptr().add(len).write(value);
        vector.set_len(len + keep as usize);
    }
}

/// Empties `vector` and gives it room for `needed` entries: where it has too little, a new
/// vector of at least twice its capacity, as a vector grows, rather than the old one grown
/// (which copies its stale entries into fresh pages). (With some 6% more than needed instead, a
/// compaction's growing list freed a vector every few hundred steps, and the freed ones stayed
/// in the heap: `scenarios/isotropic_100k.ron` peaked at 198 MB against 122 MB.)
pub(crate) fn clear_with_room<T>(vector: &mut Vec<T>, needed: usize) {
    vector.clear();
    if vector.capacity() < needed {
        *vector = Vec::with_capacity(needed.max(2 * vector.capacity()));
    }
}

/// Replaces the contents of `to` with the `chunks` one after the other, each chunk copied by a
/// task of its own.
fn concatenate_in_parallel<T: Copy + Send + Sync>(to: &mut Vec<T>, chunks: &[Vec<T>]) {
    let total: usize = chunks.iter().map(Vec::len).sum();
    clear_with_room(to, total);
    let mut places = Vec::with_capacity(chunks.len());
    let mut rest = &mut to.spare_capacity_mut()[..total];
    for chunk in chunks {
        let (place, tail) = std::mem::take(&mut rest).split_at_mut(chunk.len());
        places.push(place);
        rest = tail;
    }
    places
        .into_par_iter()
        .zip(chunks)
        .for_each(|(place, chunk)| {
            for (slot, &value) in place.iter_mut().zip(chunk) {
                slot.write(value);
            }
        });
    // SAFETY: the places cut from the first `total` entries of the spare capacity, one for
    // each chunk and as long as it, were each written in full above.
    unsafe { to.set_len(total) };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_skin_widens_after_short_lists_and_narrows_back_after_long_ones() {
        // Expectation (adapted_skin's rule): a list that lasted fewer than SHORT_LIST checks
        // gives a skin 1.25 times as wide, up to four times the list's own and to the room;
        // one that lasted more than LONG_LIST a skin 0.9 times as wide, down to the list's
        // own; any other keeps its skin.
        let base = 0.01;
        assert_eq!(
            adapted_skin(base, base, SHORT_LIST - 1, f64::INFINITY),
            1.25 * base
        );
        assert_eq!(adapted_skin(base, base, SHORT_LIST, f64::INFINITY), base);
        assert_eq!(adapted_skin(base, base, LONG_LIST, f64::INFINITY), base);
        assert_eq!(
            adapted_skin(0.03, base, LONG_LIST + 1, f64::INFINITY),
            0.9 * 0.03
        );
        assert_eq!(
            adapted_skin(0.0105, base, LONG_LIST + 1, f64::INFINITY),
            base
        );
        assert_eq!(adapted_skin(0.038, base, 0, f64::INFINITY), 4.0 * base);
        assert_eq!(adapted_skin(base, base, 0, 0.011), 0.011);
        // A room below the skin (a cell that shrank) neither widens nor narrows it.
        assert_eq!(adapted_skin(0.02, base, 0, 0.015), 0.02);
        // Widened from the list's own, it stops at four times it.
        let mut skin = base;
        for _ in 0..20 {
            skin = adapted_skin(skin, base, 3, f64::INFINITY);
        }
        assert_eq!(skin, 4.0 * base);
        // Narrowed back, it stops at the list's own.
        for _ in 0..40 {
            skin = adapted_skin(skin, base, 500, f64::INFINITY);
        }
        assert_eq!(skin, base);
    }

    /// Runs `work` on a pool of `threads` threads.
    fn on_threads(threads: usize, work: impl FnOnce() + Send) {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(work)
    }

    /// Expectation: two builds of the same grains give the same list and index, entry for
    /// entry (`threads`: the thread count of `list`'s build, for the message).
    fn assert_same_list(list: &NeighborList, expected: &NeighborList, threads: usize) {
        assert_eq!(list.pairs, expected.pairs, "{threads} threads");
        assert_eq!(list.images, expected.images, "{threads} threads");
        assert_eq!(
            list.first_offsets, expected.first_offsets,
            "{threads} threads"
        );
        assert_eq!(
            list.second_offsets, expected.second_offsets,
            "{threads} threads"
        );
        assert_eq!(
            list.second_pairs, expected.second_pairs,
            "{threads} threads"
        );
    }

    #[test]
    fn finds_exactly_the_pairs_of_a_brute_force_search() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(12345);
        let mut next = || crate::sample::unit_random(&mut rng);
        let centers: Vec<DVec2> = (0..500)
            .map(|_| DVec2::new(next() * 3.0, next() * 2.0))
            .collect();
        let reach: Vec<f64> = (0..500).map(|_| 0.02 + 0.05 * next()).collect();
        // The build's tasks write their chunks' pairs and first ends in parallel: the list
        // must not depend on how many threads run them.
        let build_on = |threads: usize| {
            let mut list = NeighborList::new(0.01);
            on_threads(threads, || list.build(&centers, &reach));
            list
        };
        let list = build_on(1);
        for threads in [2, 3, 5] {
            assert_same_list(&build_on(threads), &list, threads);
        }
        let mut brute = Vec::new();
        for i in 0..500 {
            for j in i + 1..500 {
                let limit = reach[i] + reach[j] + 0.01;
                if centers[i].distance_squared(centers[j]) < limit * limit {
                    brute.push([i as u32, j as u32]);
                }
            }
        }
        assert_eq!(list.pairs, brute);
        // Each grain's ends: exactly the pairs that hold it as second grain, then as first,
        // each in increasing pair order.
        for g in 0..500 {
            let holding = |end: usize| -> Vec<usize> {
                (0..brute.len())
                    .filter(|&p| brute[p][end] as usize == g)
                    .collect()
            };
            let seconds: Vec<usize> = list.second_ends_of(g).iter().map(|&p| p as usize).collect();
            assert_eq!(seconds, holding(1), "grain {g} as second");
            assert_eq!(
                list.first_ends_of(g).collect::<Vec<_>>(),
                holding(0),
                "grain {g} as first"
            );
        }
        assert!(!list.needs_rebuild(&centers, &reach));
        let mut moved = centers.clone();
        moved[7].x += 0.006;
        assert!(list.needs_rebuild(&moved, &reach));
    }

    /// Expectation: under an affine compression followed by the list, every pair that comes
    /// within reach is listed until the list asks for a rebuild (brute force after each step),
    /// and the list lasts far longer than the half skin the box walls travel per rebuild.
    #[test]
    fn an_affinely_compressed_list_misses_no_pair() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(99);
        let mut next = || crate::sample::unit_random(&mut rng);
        let n = 400;
        let mut centers: Vec<DVec2> = (0..n)
            .map(|_| DVec2::new(next() * 2.0, next() * 1.5))
            .collect();
        let reach: Vec<f64> = (0..n).map(|_| 0.02 + 0.02 * next()).collect();
        let jitter: Vec<DVec2> = (0..n)
            .map(|_| 2e-5 * DVec2::new(next() - 0.5, next() - 0.5))
            .collect();
        let skin = 0.01;
        let mut list = NeighborList::new(skin);
        list.build(&centers, &reach);
        let (mut lo, mut hi) = (DVec2::ZERO, DVec2::new(2.0, 1.5));
        let mut steps_without_rebuild = 0;
        for step in 0..400 {
            // 1e-3 of strain per step on x, 5e-4 on y, plus a small peculiar motion.
            let (to_lo, to_hi) = (
                lo + (hi - lo) * DVec2::new(5e-4, 2.5e-4),
                hi - (hi - lo) * DVec2::new(5e-4, 2.5e-4),
            );
            let scale = (to_hi - to_lo) / (hi - lo);
            for (c, j) in centers.iter_mut().zip(&jitter) {
                *c = to_lo + (*c - lo) * scale + *j;
            }
            list.follow_affine((lo, hi), (to_lo, to_hi));
            (lo, hi) = (to_lo, to_hi);
            if list.needs_rebuild(&centers, &reach) {
                list.build(&centers, &reach);
                if step > 0 && steps_without_rebuild == 0 {
                    panic!("rebuilt on consecutive steps at step {step}");
                }
                steps_without_rebuild = 0;
            } else {
                steps_without_rebuild += 1;
            }
            for i in 0..n {
                for j in i + 1..n {
                    let limit = reach[i] + reach[j];
                    if centers[i].distance_squared(centers[j]) < limit * limit {
                        assert!(
                            list.pairs.binary_search(&[i as u32, j as u32]).is_ok(),
                            "step {step}: pair ({i}, {j}) missing"
                        );
                    }
                }
            }
        }
        // The wall at x = 2 moves 1e-3 per step: half a skin in 5 steps. The affine list
        // rebuilds once the contraction has eaten the skin: (1 - s) (2 * 0.04 + 0.01) ~ 0.01.
        assert!(
            list.builds < 400 / 40,
            "{} builds in 400 steps",
            list.builds
        );
    }

    /// Expectation: the runs round bin k hold k - 1, k and k + 1 modulo the count, each once
    /// (all the bins, each once, where there are at most three).
    #[test]
    fn the_neighbouring_bins_round_a_cell_are_each_visited_once() {
        for count in 1..=7 {
            for k in 0..count {
                let mut visited: Vec<usize> =
                    NeighborBins::around(k, count).runs().flatten().collect();
                visited.sort_unstable();
                let mut expected: Vec<usize> =
                    [count - 1, 0, 1].iter().map(|d| (k + d) % count).collect();
                expected.sort_unstable();
                expected.dedup();
                assert_eq!(visited, expected, "bin {k} of {count}");
            }
        }
    }

    #[test]
    fn a_list_rebuilt_over_other_grains_is_the_list_built_afresh() {
        // Expectation: a build keeps its working arrays (and the list's vectors) from the
        // last build, so that a rebuild allocates nothing; it reads nothing of them, so one
        // list rebuilt in turn over samples of more and fewer grains, in a box and in a cell,
        // on one thread and on three, is each time the list a new one builds.
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(31);
        let mut next = || crate::sample::unit_random(&mut rng);
        let cell =
            PeriodicCell::new(DVec2::ZERO, DVec2::new(1.0, 0.0), DVec2::new(0.2, 0.9)).unwrap();
        let skin = 0.01;
        let mut reused = NeighborList::new(skin);
        let mut pairs_seen = Vec::new();
        for (round, count) in [700usize, 300, 1100, 20, 700].into_iter().enumerate() {
            let centers: Vec<DVec2> = (0..count)
                .map(|_| cell.position(DVec2::new(next(), next())))
                .collect();
            let reach: Vec<f64> = (0..count).map(|_| 0.01 + 0.02 * next()).collect();
            for periodic in [false, true] {
                let build = |list: &mut NeighborList| {
                    if periodic {
                        list.build_periodic(&centers, &reach, &cell)
                    } else {
                        list.build(&centers, &reach)
                    }
                };
                let threads = 1 + 2 * (round % 2);
                on_threads(threads, || build(&mut reused));
                let mut fresh = NeighborList::new(skin);
                build(&mut fresh);
                assert_same_list(&reused, &fresh, threads);
                assert_eq!(reused.first_offsets.len(), count + 1);
                pairs_seen.push(fresh.pairs.len());
            }
        }
        assert!(pairs_seen.iter().all(|&p| p > 0), "{pairs_seen:?}");
    }

    /// Expectation: the periodic list holds exactly the pairs whose minimum-image distance is
    /// within range, found by brute force over all pairs, each with that image (in cells of
    /// more grains than a build's task holds, and of only two bins across).
    #[test]
    fn the_periodic_list_finds_exactly_the_pairs_of_a_brute_force_search() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(7);
        let mut next = || crate::sample::unit_random(&mut rng);
        for (h1, h2, count) in [
            (DVec2::new(1.0, 0.0), DVec2::new(0.0, 0.8), 400),
            (DVec2::new(1.0, 0.0), DVec2::new(0.45, 0.8), 400),
            (DVec2::new(0.4, 0.0), DVec2::new(-0.15, 0.35), 60),
            // Two bins across each way: the 3 x 3 neighbouring bins repeat.
            (DVec2::new(0.25, 0.0), DVec2::new(0.05, 0.24), 40),
        ] {
            let cell = PeriodicCell::new(DVec2::new(-0.3, 0.2), h1, h2).unwrap();
            // Centres anywhere, some outside the cell.
            let centers: Vec<DVec2> = (0..count)
                .map(|_| cell.position(DVec2::new(next() * 1.4 - 0.2, next() * 1.4 - 0.2)))
                .collect();
            let reach: Vec<f64> = (0..count).map(|_| 0.02 + 0.03 * next()).collect();
            let skin = 0.01;
            cell.check_range(2.0 * 0.05 + skin).unwrap();
            let mut list = NeighborList::new(skin);
            list.build_periodic(&centers, &reach, &cell);
            let mut brute = Vec::new();
            for i in 0..count {
                for j in i + 1..count {
                    let (d, [m1, m2]) = cell.minimum_image(centers[j] - centers[i]);
                    let limit = reach[i] + reach[j] + skin;
                    if d.length() < limit {
                        assert!(
                            (centers[j] + cell.image_shift([-m1, -m2]) - centers[i] - d).length()
                                < 1e-12
                        );
                        brute.push(([i as u32, j as u32], [-m1, -m2]));
                    }
                }
            }
            let found: Vec<([u32; 2], [i64; 2])> = list
                .pairs
                .iter()
                .copied()
                .zip(list.images.iter().copied())
                .collect();
            assert_eq!(found, brute, "cell {h1:?} {h2:?}");
            // Each grain's ends, as in a box, whatever the thread count.
            for g in 0..count {
                let holding = |end: usize| -> Vec<usize> {
                    (0..brute.len())
                        .filter(|&p| brute[p].0[end] as usize == g)
                        .collect()
                };
                let seconds: Vec<usize> =
                    list.second_ends_of(g).iter().map(|&p| p as usize).collect();
                assert_eq!(seconds, holding(1), "grain {g} as second");
                assert_eq!(list.first_ends_of(g).collect::<Vec<_>>(), holding(0));
            }
            for threads in [1, 3] {
                let mut other = NeighborList::new(skin);
                on_threads(threads, || other.build_periodic(&centers, &reach, &cell));
                assert_same_list(&other, &list, threads);
            }
            assert!(!list.needs_rebuild_periodic(&centers, &reach, &cell, largest_reach(&reach)));
        }
    }
}
