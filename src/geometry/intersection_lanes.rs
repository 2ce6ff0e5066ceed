//! The common path of [`grain_grain_hinted`] for four pairs side by side, in AVX registers
//! (issue #16): two contours that were in contact last step, whose chains' ends moved by at
//! most one node and whose crossings lie on, or next to, the edges of j they lay on last step.
//!
//! Nearly every contact of a dense packing takes that path every step, and one pair at a time
//! it is a long chain of dependent loads, products and branches. Here its arithmetic runs in
//! the four lanes of AVX vectors, each lane's choices made by masks and blends. Every quantity
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

/// Pairs in a block of [`grain_grain_block`]: one AVX register's worth.
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

/// Whether this processor runs [`grain_grain_block`]'s lanes (else every lane is `None`).
pub fn block_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        return true;
    }
    false
}

/// The contacts of [`BLOCK`] pairs on the common path (see the module's docs), written to
/// `contacts`: each lane's [`BlockContacts::lane`] is what [`grain_grain_hinted`] returns for
/// that pair (always a contact there) and the hint it leaves; `None` where the pair leaves the
/// path, or every lane without AVX. Neither grain of a pair is a circle ([`LaneShape`]);
/// `shifted`: j's centres are moved by the pairs' `j_shift` (a periodic cell's images). Out of
/// line, so that the lanes stay in vector registers.
#[inline(never)]
pub fn grain_grain_block(
    table: &ContourTable,
    pairs: &[LanePair<'_>; BLOCK],
    shifted: bool,
    contacts: &mut BlockContacts,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the processor has AVX (tested just above).
        unsafe { avx::grain_grain_block(table, pairs, shifted, contacts) };
        return;
    }
    let _ = (table, pairs, shifted);
    contacts.on_path = 0;
}

// The helpers are `unsafe` for they run AVX instructions: every one is inlined into
// `avx::grain_grain_block`, which is compiled for AVX and called only where the processor has it.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_op_in_unsafe_fn)]
mod avx {
    use super::{BLOCK, BlockContacts, LanePair};
    use crate::geometry::contour::ContourTable;
    use crate::geometry::intersection::{ChainHint, PairHint};
    use std::arch::x86_64::*;

    type V = __m256d;

    #[derive(Clone, Copy)]
    struct V2 {
        x: V,
        y: V,
    }

    /// A 2×2 matrix by columns, as glam's `DMat2`: `(x0, x1)` its first column.
    #[derive(Clone, Copy)]
    struct M2 {
        x0: V,
        x1: V,
        y0: V,
        y1: V,
    }

    #[inline(always)]
    unsafe fn lanes(v: V) -> [f64; 4] {
        // SAFETY: both are 32 bytes of four f64s, lane 0 first.
        unsafe { std::mem::transmute::<V, [f64; 4]>(v) }
    }

    /// Lanes as bits: bit `l` for lane `l` (what `_mm256_movemask_pd` gives).
    type Bits = i32;

    /// Every lane.
    const ALL: Bits = 0b1111;

    /// The blend masks of the sixteen sets of lanes, `BLEND_MASKS[b]` all ones in the lanes of
    /// `b`: one load where a mask built lane by lane took a branch and an insert a lane.
    static BLEND_MASKS: [[i64; 4]; 16] = {
        let mut masks = [[0; 4]; 16];
        let mut b = 0;
        while b < 16 {
            let mut l = 0;
            while l < 4 {
                if b & (1 << l) != 0 {
                    masks[b][l] = -1;
                }
                l += 1;
            }
            b += 1;
        }
        masks
    };

    /// All bits set in the lanes of `b`: a blend mask.
    #[inline(always)]
    unsafe fn mask(b: Bits) -> V {
        debug_assert!((0..16).contains(&b));
        // SAFETY: `b` lies in [0, 16) (four lanes' bits), and each entry is 32 bytes.
        _mm256_loadu_pd(BLEND_MASKS.get_unchecked(b as usize).as_ptr().cast::<f64>())
    }

    /// Whether lane `l` is in `b`.
    #[inline(always)]
    fn has(b: Bits, l: usize) -> bool {
        b & (1 << l) != 0
    }

    /// Four lanes of node indices, as `i32`s (N is far below 2^31): SSE4.1, which AVX
    /// implies.
    type I = __m128i;

    #[inline(always)]
    unsafe fn splat_i(k: i32) -> I {
        _mm_set1_epi32(k)
    }

    #[inline(always)]
    unsafe fn add_i(a: I, b: I) -> I {
        _mm_add_epi32(a, b)
    }

    #[inline(always)]
    unsafe fn sub_i(a: I, b: I) -> I {
        _mm_sub_epi32(a, b)
    }

    /// The lanes where `a > b`.
    #[inline(always)]
    unsafe fn greater_i(a: I, b: I) -> Bits {
        _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpgt_epi32(a, b)))
    }

    /// All bits set in the lanes of `b`, as indices' mask.
    #[inline(always)]
    unsafe fn mask_i(b: Bits) -> I {
        let wide = mask(b);
        // Each 64-bit lane's low half.
        _mm_castps_si128(_mm_shuffle_ps::<0b10_00_10_00>(
            _mm256_castps256_ps128(_mm256_castpd_ps(wide)),
            _mm256_extractf128_ps::<1>(_mm256_castpd_ps(wide)),
        ))
    }

    /// `b` in the lanes of `m`, else `a`.
    #[inline(always)]
    unsafe fn select_i(a: I, b: I, m: Bits) -> I {
        _mm_blendv_epi8(a, b, mask_i(m))
    }

    /// 1 in the lanes of `b`, else 0.
    #[inline(always)]
    unsafe fn ones_i(b: Bits) -> I {
        _mm_srli_epi32::<31>(mask_i(b))
    }

    /// The lanes as `isize`s.
    #[inline(always)]
    unsafe fn index_lanes(v: I) -> [isize; 4] {
        // SAFETY: both are 16 bytes of four i32s, lane 0 first.
        let k = std::mem::transmute::<I, [i32; 4]>(v);
        [k[0] as isize, k[1] as isize, k[2] as isize, k[3] as isize]
    }

    /// `ContourTable::next` of indices in [0, N): k + 1, N - 1 to 0.
    #[inline(always)]
    unsafe fn next_i(k: I, n: i32) -> I {
        let next = add_i(k, splat_i(1));
        _mm_andnot_si128(_mm_cmpeq_epi32(next, splat_i(n)), next)
    }

    /// `ContourTable::previous` of indices in [0, N): k - 1, 0 to N - 1.
    #[inline(always)]
    unsafe fn previous_i(k: I, n: i32) -> I {
        let before = add_i(k, splat_i(-1));
        add_i(
            before,
            _mm_and_si128(_mm_cmpgt_epi32(_mm_setzero_si128(), before), splat_i(n)),
        )
    }

    /// `ContourTable::wrap` of indices within one turn of [0, N), [-N, 2N).
    #[inline(always)]
    unsafe fn wrap_i(k: I, n: i32) -> I {
        let turn = splat_i(n);
        let below = _mm_cmpgt_epi32(_mm_setzero_si128(), k);
        let beyond = _mm_cmpgt_epi32(k, splat_i(n - 1));
        add_i(
            k,
            sub_i(_mm_and_si128(below, turn), _mm_and_si128(beyond, turn)),
        )
    }

    /// The transpose of four lanes of four `i32`s: lane `l` of vector `c` is `rows[l]`'s `c`th.
    #[inline(always)]
    unsafe fn transpose_i(rows: [I; 4]) -> [I; 4] {
        let (ab_low, cd_low) = (
            _mm_unpacklo_epi32(rows[0], rows[1]),
            _mm_unpacklo_epi32(rows[2], rows[3]),
        );
        let (ab_high, cd_high) = (
            _mm_unpackhi_epi32(rows[0], rows[1]),
            _mm_unpackhi_epi32(rows[2], rows[3]),
        );
        [
            _mm_unpacklo_epi64(ab_low, cd_low),
            _mm_unpackhi_epi64(ab_low, cd_low),
            _mm_unpacklo_epi64(ab_high, cd_high),
            _mm_unpackhi_epi64(ab_high, cd_high),
        ]
    }

    /// The pairs' hints as lanes: first.lo, first.hi, second.lo, second.hi.
    #[inline(always)]
    unsafe fn hints(pairs: &[LanePair<'_>; BLOCK]) -> [I; 4] {
        // SAFETY: a `PairHint` is four i32s (`repr(C)`).
        let row = |l: usize| (&pairs[l].hint as *const PairHint).cast::<I>();
        transpose_i([
            _mm_loadu_si128(row(0)),
            _mm_loadu_si128(row(1)),
            _mm_loadu_si128(row(2)),
            _mm_loadu_si128(row(3)),
        ])
    }

    /// `b` in the lanes of `m`, else `a`.
    #[inline(always)]
    unsafe fn blend(a: V2, b: V2, m: V) -> V2 {
        V2 {
            x: _mm256_blendv_pd(a.x, b.x, m),
            y: _mm256_blendv_pd(a.y, b.y, m),
        }
    }

    #[inline(always)]
    unsafe fn store(to: &mut [f64; 4], v: V) {
        _mm256_storeu_pd(to.as_mut_ptr(), v);
    }

    /// The lanes where a comparison's result `v` holds.
    #[inline(always)]
    unsafe fn bits(v: V) -> Bits {
        _mm256_movemask_pd(v)
    }

    #[inline(always)]
    unsafe fn neg(v: V) -> V {
        _mm256_xor_pd(v, _mm256_set1_pd(-0.0))
    }

    #[inline(always)]
    unsafe fn add(a: V2, b: V2) -> V2 {
        V2 {
            x: _mm256_add_pd(a.x, b.x),
            y: _mm256_add_pd(a.y, b.y),
        }
    }

    #[inline(always)]
    unsafe fn sub(a: V2, b: V2) -> V2 {
        V2 {
            x: _mm256_sub_pd(a.x, b.x),
            y: _mm256_sub_pd(a.y, b.y),
        }
    }

    #[inline(always)]
    unsafe fn scale(a: V2, s: V) -> V2 {
        V2 {
            x: _mm256_mul_pd(a.x, s),
            y: _mm256_mul_pd(a.y, s),
        }
    }

    /// glam's `dot`: `(a.x b.x) + (a.y b.y)`.
    #[inline(always)]
    unsafe fn dot(a: V2, b: V2) -> V {
        _mm256_add_pd(_mm256_mul_pd(a.x, b.x), _mm256_mul_pd(a.y, b.y))
    }

    /// glam's `perp_dot`: `(a.x b.y) - (a.y b.x)`.
    #[inline(always)]
    unsafe fn perp_dot(a: V2, b: V2) -> V {
        _mm256_sub_pd(_mm256_mul_pd(a.x, b.y), _mm256_mul_pd(a.y, b.x))
    }

    /// glam's `DMat2 * DVec2`: `(x0 v.x) + (y0 v.y)`, `(x1 v.x) + (y1 v.y)`.
    #[inline(always)]
    unsafe fn mul_vec(m: M2, v: V2) -> V2 {
        V2 {
            x: _mm256_add_pd(_mm256_mul_pd(m.x0, v.x), _mm256_mul_pd(m.y0, v.y)),
            y: _mm256_add_pd(_mm256_mul_pd(m.x1, v.x), _mm256_mul_pd(m.y1, v.y)),
        }
    }

    /// glam's `m.transpose() * v`.
    #[inline(always)]
    unsafe fn transpose_mul_vec(m: M2, v: V2) -> V2 {
        mul_vec(
            M2 {
                x0: m.x0,
                x1: m.y0,
                y0: m.x1,
                y1: m.y1,
            },
            v,
        )
    }

    /// glam's `DMat2 * DMat2`: the left matrix times each column.
    #[inline(always)]
    unsafe fn mul_mat(a: M2, b: M2) -> M2 {
        let x = mul_vec(a, V2 { x: b.x0, y: b.x1 });
        let y = mul_vec(a, V2 { x: b.y0, y: b.y1 });
        M2 {
            x0: x.x,
            x1: x.y,
            y0: y.x,
            y1: y.y,
        }
    }

    /// glam's `determinant`: `x0 y1 - x1 y0`.
    #[inline(always)]
    unsafe fn determinant(m: M2) -> V {
        _mm256_sub_pd(_mm256_mul_pd(m.x0, m.y1), _mm256_mul_pd(m.x1, m.y0))
    }

    /// glam's `inverse`: through `1 / det`, the off-diagonal times `-(1 / det)`.
    #[inline(always)]
    unsafe fn inverse(m: M2) -> M2 {
        let inv_det = _mm256_div_pd(_mm256_set1_pd(1.0), determinant(m));
        let minus = neg(inv_det);
        M2 {
            x0: _mm256_mul_pd(m.y1, inv_det),
            x1: _mm256_mul_pd(m.x1, minus),
            y0: _mm256_mul_pd(m.y0, minus),
            y1: _mm256_mul_pd(m.x0, inv_det),
        }
    }

    /// Four consecutive nodes of the unit polygon in each lane, `start[l]` to `start[l] + 3`:
    /// each lane's 64 bytes of the ring loaded as two vectors, and the four lanes transposed.
    ///
    /// # Safety
    /// Every `start[l]` lies in [-N, 2N - 3), so that the four nodes lie within the ring
    /// (see `grain_grain_block` for why the kernel's do), and the processor has AVX.
    #[inline(always)]
    unsafe fn ring4(table: &ContourTable, start: I) -> [V2; 4] {
        let ring = table.vertex_ring().as_ptr();
        let nodes = table.nodes as isize;
        let at = index_lanes(add_i(start, splat_i(nodes as i32)));
        debug_assert!(at.iter().all(|&k| 0 <= k && k + 3 < 3 * nodes));
        let (a, b, c, d) = (
            ring.offset(at[0]).cast::<f64>(),
            ring.offset(at[1]).cast::<f64>(),
            ring.offset(at[2]).cast::<f64>(),
            ring.offset(at[3]).cast::<f64>(),
        );
        let [n0, n1] = load_pairs([a, b, c, d], 0);
        let [n2, n3] = load_pairs([a, b, c, d], 4);
        [n0, n1, n2, n3]
    }

    /// Four f64s from `lane[l] + at` in each lane `l`, read as two points of four lanes (see
    /// [`transpose_pairs`]).
    #[inline(always)]
    unsafe fn load_pairs(lane: [*const f64; 4], at: usize) -> [V2; 2] {
        transpose_pairs(
            _mm256_loadu_pd(lane[0].add(at)),
            _mm256_loadu_pd(lane[1].add(at)),
            _mm256_loadu_pd(lane[2].add(at)),
            _mm256_loadu_pd(lane[3].add(at)),
        )
    }

    /// Two points of each of four lanes, `(x0 y0 x1 y1)` a lane, as two points of four lanes.
    #[inline(always)]
    unsafe fn transpose_pairs(a: V, b: V, c: V, d: V) -> [V2; 2] {
        // (x0 of a and b, x1 of a and b), and the same of y, c and d.
        let (ab_x, ab_y) = (_mm256_unpacklo_pd(a, b), _mm256_unpackhi_pd(a, b));
        let (cd_x, cd_y) = (_mm256_unpacklo_pd(c, d), _mm256_unpackhi_pd(c, d));
        [
            V2 {
                x: _mm256_permute2f128_pd::<0x20>(ab_x, cd_x),
                y: _mm256_permute2f128_pd::<0x20>(ab_y, cd_y),
            },
            V2 {
                x: _mm256_permute2f128_pd::<0x31>(ab_x, cd_x),
                y: _mm256_permute2f128_pd::<0x31>(ab_y, cd_y),
            },
        ]
    }

    /// The inside tests of `ContourTable::contains` that need no sector, as bit masks of the
    /// lanes: inside the inscribed circle, and outside the circumscribed one (a point in the
    /// ring between them, or a NaN, is in neither).
    #[inline(always)]
    unsafe fn inside_outside(table: &ContourTable, u: V2) -> (Bits, Bits) {
        let r2 = dot(u, u);
        (
            bits(_mm256_cmp_pd::<_CMP_LT_OQ>(
                r2,
                _mm256_set1_pd(table.apothem_squared),
            )),
            bits(_mm256_cmp_pd::<_CMP_GE_OQ>(r2, _mm256_set1_pd(1.0))),
        )
    }

    /// The ends of one chain of last step (`end`, its chain running on from it against
    /// `outward`): its nodes `end + c outward`, c = -1..=2, mapped into the other grain's frame
    /// (`u = m v + t`), and where the end is now, as the one-pair path's `end_moved` settles
    /// it: the lanes whose end moved back by a node, stayed, or moved on by one ([`Moved`]).
    /// A lane in none of them moved further, or a node it tests lies in the ring between the
    /// inscribed and circumscribed circles (where the inside test needs the node's sector).
    #[inline(always)]
    unsafe fn end_moved(
        table: &ContourTable,
        m: M2,
        t: V2,
        end: I,
        outward: isize,
    ) -> ([V2; 4], [V2; 4], Moved) {
        // The four nodes lie together in memory: from end - 1 up for the hi end (outward
        // 1), from end - 2 up, in the reverse order, for the lo end.
        let raw = if outward == 1 {
            ring4(table, add_i(end, splat_i(-1)))
        } else {
            let [a, b, c, d] = ring4(table, add_i(end, splat_i(-2)));
            [d, c, b, a]
        };
        let nodes = [
            add(mul_vec(m, raw[0]), t),
            add(mul_vec(m, raw[1]), t),
            add(mul_vec(m, raw[2]), t),
            add(mul_vec(m, raw[3]), t),
        ];
        let (back_inside, _) = inside_outside(table, nodes[0]);
        let (at_end_inside, at_end_outside) = inside_outside(table, nodes[1]);
        let (beyond_inside, beyond_outside) = inside_outside(table, nodes[2]);
        let (_, further_outside) = inside_outside(table, nodes[3]);
        // The end moved back (its node left, the one behind it is in), stayed, or moved on
        // (the node beyond came in, the one after it is out): bit l of each for lane l.
        // The three exclude each other: a node is not both in and out.
        let moved = Moved {
            back: at_end_outside & back_inside,
            stayed: at_end_inside & beyond_outside,
            on: at_end_inside & beyond_inside & further_outside,
        };
        (raw, nodes, moved)
    }

    /// Where a chain's end moved, lanes as bits (see [`end_moved`]).
    #[derive(Clone, Copy)]
    struct Moved {
        back: Bits,
        stayed: Bits,
        on: Bits,
    }

    impl Moved {
        /// The lanes whose end moved by at most a node.
        #[inline(always)]
        fn settled(self) -> Bits {
            self.back | self.stayed | self.on
        }

        /// The offsets of the ends along their outward direction: -1, 0 or 1.
        #[inline(always)]
        unsafe fn offsets(self) -> I {
            sub_i(ones_i(self.on), ones_i(self.back))
        }

        /// The blend masks of the lanes that moved back, and of those that moved on.
        #[inline(always)]
        unsafe fn masks(self) -> (V, V) {
            (mask(self.back), mask(self.on))
        }
    }

    /// The chain's end node and the node beyond it, from [`end_moved`]'s nodes and the masks
    /// of the end's offsets ([`Moved::masks`]).
    #[inline(always)]
    unsafe fn end_and_beyond(nodes: &[V2; 4], (back, on): (V, V)) -> (V2, V2) {
        (
            blend(blend(nodes[1], nodes[0], back), nodes[2], on),
            blend(blend(nodes[2], nodes[1], back), nodes[3], on),
        )
    }

    /// b's unit-polygon edges `s[l]`: starts, ends and outward normals.
    ///
    /// # Safety
    /// Every `s[l]` lies in [0, N) (the guesses are hints checked to lie there, and
    /// `exit_near` steps them round the polygon), and the processor has AVX.
    #[inline(always)]
    unsafe fn edges(table: &ContourTable, s: I) -> [V2; 3] {
        let edges = table.edges().as_ptr();
        let s = index_lanes(s);
        debug_assert!(
            s.iter()
                .all(|&k| 0 <= k && k < table.edges().len() as isize)
        );
        // An edge is its start, end and normal, six f64s in this order (`repr(C)`).
        let e = [
            edges.offset(s[0]).cast::<f64>(),
            edges.offset(s[1]).cast::<f64>(),
            edges.offset(s[2]).cast::<f64>(),
            edges.offset(s[3]).cast::<f64>(),
        ];
        let [start, end] = load_pairs(e, 0);
        let normal = load_points([e[0].add(4), e[1].add(4), e[2].add(4), e[3].add(4)]);
        [start, end, normal]
    }

    /// Two f64s from `lane[l]` in each lane `l`, read as a point of four lanes.
    #[inline(always)]
    unsafe fn load_points(lane: [*const f64; 4]) -> V2 {
        // (point 0 | point 2) and (point 1 | point 3), interleaved into x's and y's. (No
        // closure here: a closure is not compiled for AVX, and its intrinsics become calls.)
        let p02 = _mm256_insertf128_pd::<1>(
            _mm256_castpd128_pd256(_mm_loadu_pd(lane[0])),
            _mm_loadu_pd(lane[2]),
        );
        let p13 = _mm256_insertf128_pd::<1>(
            _mm256_castpd128_pd256(_mm_loadu_pd(lane[1])),
            _mm_loadu_pd(lane[3]),
        );
        V2 {
            x: _mm256_unpacklo_pd(p02, p13),
            y: _mm256_unpackhi_pd(p02, p13),
        }
    }

    /// Where a's edge from its node inside b (`p_in`, in b's reference coordinates) to the
    /// node outside (`p_out`) leaves b's polygon, when it leaves through b's edge `guess` or a
    /// neighbour of it: the exit parameter and b's edge, as the one-pair path's
    /// `crossing_and_edge` finds them on its first or second try; `false` in `found` where
    /// that path would try further, or search.
    #[inline(always)]
    unsafe fn exit_near(
        table: &ContourTable,
        p_in: V2,
        p_out: V2,
        guess: I,
    ) -> (V, I, Bits, [V2; 2]) {
        let direction = sub(p_out, p_in);
        let apothem = _mm256_set1_pd(table.apothem);
        let (zero, one) = (_mm256_setzero_pd(), _mm256_set1_pd(1.0));
        let mut edge = guess;
        let mut t = zero;
        let mut found = 0;
        // The lanes still looking.
        let mut open = ALL;
        let mut ends = [V2 { x: zero, y: zero }; 2];
        for _try in 0..2 {
            let [start, end, normal] = edges(table, edge);
            // The ends of each lane's edge (the first try's, or the second's where it tried
            // again): a chain of j runs between two of them.
            let tried = mask(open);
            ends = [blend(ends[0], start, tried), blend(ends[1], end, tried)];
            let rate = dot(direction, normal);
            let t_try = _mm256_div_pd(_mm256_sub_pd(apothem, dot(p_in, normal)), rate);
            let q = add(p_in, scale(direction, t_try));
            let rising = bits(_mm256_cmp_pd::<_CMP_GT_OQ>(rate, zero));
            let after_start = bits(_mm256_cmp_pd::<_CMP_GE_OQ>(perp_dot(start, q), zero));
            let before_end = bits(_mm256_cmp_pd::<_CMP_LE_OQ>(perp_dot(end, q), zero));
            // Within the edge of a (false for a NaN, as the one-pair path's test).
            let within = bits(_mm256_and_pd(
                _mm256_cmp_pd::<_CMP_GT_OQ>(t_try, zero),
                _mm256_cmp_pd::<_CMP_LE_OQ>(t_try, one),
            ));
            // A lane whose edge of a does not rise through b's edge line stops, unfound.
            let hit = open & rising & after_start & before_end;
            found |= hit & within;
            t = _mm256_blendv_pd(t, t_try, mask(hit));
            open &= rising & !hit;
            if open == 0 {
                break;
            }
            // The next edge round where the crossing lies after this one's start, else the one
            // before.
            let turn = table.nodes as i32;
            let stepped = select_i(previous_i(edge, turn), next_i(edge, turn), after_start);
            edge = select_i(edge, stepped, open);
        }
        (t, edge, found, ends)
    }

    /// The crossing on a's edge from its node `v_in` to `v_out` (reference coordinates) at
    /// parameter `t`, in global coordinates: `c + A R (v_in + (v_out - v_in) t)`.
    #[inline(always)]
    unsafe fn crossing(center: V2, map: M2, v_in: V2, v_out: V2, t: V) -> V2 {
        add(center, mul_vec(map, add(v_in, scale(sub(v_out, v_in), t))))
    }

    /// The one-pair path's `cap_area_and_depth` for chains `lo..=hi` of a grain (`center`,
    /// `map`): the area of its cap (from, chain, to) and the depth of its deepest node beyond
    /// `origin` along `outward`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    unsafe fn cap_area_and_depth(
        table: &ContourTable,
        center: V2,
        map: M2,
        (lo, hi): (I, I),
        (vertex_lo, vertex_hi): (V2, V2),
        from: V2,
        to: V2,
        origin: V2,
        outward: V2,
    ) -> (V, [f64; 4]) {
        let first = mul_vec(map, vertex_lo);
        let last = mul_vec(map, vertex_hi);
        let (from, to) = (sub(from, center), sub(to, center));
        let spanned = _mm256_cvtepi32_pd(sub_i(hi, lo));
        let fan = _mm256_mul_pd(
            _mm256_mul_pd(spanned, determinant(map)),
            _mm256_set1_pd(table.sin_dbeta),
        );
        let twice_area = _mm256_add_pd(
            _mm256_add_pd(
                _mm256_add_pd(perp_dot(from, first), fan),
                perp_dot(last, to),
            ),
            perp_dot(to, from),
        );
        // The deepest node is one of the two or three around the chain's middle (see the
        // one-pair path); the last is repeated where there are fewer.
        let one = splat_i(1);
        let sum = add_i(lo, hi);
        // `>> 1` rounds down, as the one-pair path's on `isize`.
        let middle = _mm_srai_epi32::<1>(sum);
        let start = _mm_max_epi32(add_i(sub_i(middle, one), _mm_and_si128(sum, one)), lo);
        let count = add_i(sub_i(_mm_min_epi32(add_i(middle, one), hi), start), one);
        // The lanes with more than one node, and with more than two.
        let more = [0, greater_i(count, one), greater_i(count, splat_i(2))];
        let support = transpose_mul_vec(map, outward);
        let around = ring4(table, start);
        let mut reach = dot(around[0], support);
        for k in 1..3 {
            let r = dot(around[k], support);
            let further = _mm256_and_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(r, reach), mask(more[k]));
            reach = _mm256_blendv_pd(reach, r, further);
        }
        let mut depth = lanes(_mm256_add_pd(dot(sub(center, origin), outward), reach));
        for d in depth.iter_mut() {
            *d = d.max(0.0);
        }
        (_mm256_mul_pd(_mm256_set1_pd(0.5), twice_area), depth)
    }

    /// A grain's centre, map and bounding radius, side i or j of each pair.
    #[inline(always)]
    unsafe fn shapes(pairs: &[LanePair<'_>; BLOCK], second: bool) -> (V2, M2, V) {
        let side = |l: usize| if second { pairs[l].j } else { pairs[l].i };
        let (a, b, c, d) = (side(0), side(1), side(2), side(3));
        let [center, radius] = load_pairs(
            [
                a.center_and_radius.as_ptr(),
                b.center_and_radius.as_ptr(),
                c.center_and_radius.as_ptr(),
                d.center_and_radius.as_ptr(),
            ],
            0,
        );
        let [x_axis, y_axis] = load_pairs(
            [
                a.map.as_ptr(),
                b.map.as_ptr(),
                c.map.as_ptr(),
                d.map.as_ptr(),
            ],
            0,
        );
        (
            center,
            M2 {
                x0: x_axis.x,
                x1: x_axis.y,
                y0: y_axis.x,
                y1: y_axis.y,
            },
            radius.x,
        )
    }

    #[target_feature(enable = "avx")]
    pub(super) unsafe fn grain_grain_block(
        table: &ContourTable,
        pairs: &[LanePair<'_>; BLOCK],
        shifted: bool,
        out: &mut BlockContacts,
    ) {
        let n = table.nodes as isize;
        let half = n / 2;
        let turn = n as i32;
        // Last step's chain of i inside j, unwrapped, and the guesses of j's edges the
        // crossings lie on: p_lo on j's edge (hi, hi + 1) of last step's chain of j, p_hi on
        // (lo - 1, lo).
        let [first_lo, first_hi, second_lo, second_hi] = hints(pairs);
        let chain_hi = add_i(
            first_hi,
            _mm_and_si128(_mm_cmpgt_epi32(first_lo, first_hi), splat_i(turn)),
        );
        // All four hints in [0, N), compared unsigned: a negative hint (NONE) wraps above N.
        let largest = _mm_max_epu32(
            _mm_max_epu32(first_lo, first_hi),
            _mm_max_epu32(second_lo, second_hi),
        );
        let hints_in_turn = _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(
            _mm_min_epu32(largest, splat_i(turn - 1)),
            largest,
        )));
        let short = greater_i(splat_i(half as i32), sub_i(chain_hi, first_lo));

        let (center_i, map_i, reach_i) = shapes(pairs, false);
        let (mut center_j, map_j, reach_j) = shapes(pairs, true);
        if shifted {
            // A shift is two f64s (`DVec2` is `repr(C)`).
            let shift = |l: usize| (&pairs[l].j_shift as *const glam::DVec2).cast::<f64>();
            center_j = add(
                center_j,
                load_points([shift(0), shift(1), shift(2), shift(3)]),
            );
        }
        // Lanes on the path so far; a lane that leaves it computes on with safe indices. The
        // ring is read without bounds checks (`ring4`), so every node index formed here lies
        // in [-N, 2N - 3) (N >= 8): a lane starts with hints in [0, N), checked above (a lane
        // without them takes node 0), and a chain shorter than N / 2; the ends' nodes reach
        // from lo - 2 to hi + 2, i's new chain keeps lo in [-1, N] and hi under lo + N / 2, and
        // j's chain runs within [0, 2N) with its middle under 3N / 2.
        let mut on_path: Bits = hints_in_turn & short;
        let zero_i = _mm_setzero_si128();
        let mut lo = select_i(zero_i, first_lo, on_path);
        let mut hi = select_i(zero_i, chain_hi, on_path);
        let guess_lo = select_i(zero_i, second_hi, on_path);
        let guess_hi = select_i(zero_i, previous_i(second_lo, turn), on_path);

        let branch = sub(center_i, center_j);
        let reach = _mm256_add_pd(reach_i, reach_j);
        let near = bits(_mm256_cmp_pd::<_CMP_LT_OQ>(
            dot(branch, branch),
            _mm256_mul_pd(reach, reach),
        ));
        let inv_j = inverse(map_j);
        let m = mul_mat(inv_j, map_i);
        let t = mul_vec(inv_j, branch);

        // The lo end runs outward to lower indices, the hi end to higher ones.
        // Each end's node and the node beyond it, picked at once so that its four nodes need
        // not outlive the other end's (fewer registers spilled): by the end's own offsets,
        // since a lane that leaves the path below may compute on with any values.
        let (raw_lo, nodes_lo, moved_lo) = end_moved(table, m, t, lo, -1);
        let (lo_in, lo_out) = end_and_beyond(&nodes_lo, moved_lo.masks());
        // The same nodes in i's reference coordinates.
        let (vertex_lo, vertex_lo_out) = end_and_beyond(&raw_lo, moved_lo.masks());
        let (raw_hi, nodes_hi, moved_hi) = end_moved(table, m, t, hi, 1);
        let (hi_in, hi_out) = end_and_beyond(&nodes_hi, moved_hi.masks());
        let (vertex_hi, vertex_hi_out) = end_and_beyond(&raw_hi, moved_hi.masks());
        // The lanes whose ends both moved by at most a node, into a chain still short: they
        // take the new ends; the others keep theirs and leave the path.
        let (new_lo, new_hi) = (sub_i(lo, moved_lo.offsets()), add_i(hi, moved_hi.offsets()));
        let moved = moved_lo.settled()
            & moved_hi.settled()
            & near
            & !greater_i(new_lo, new_hi)
            & greater_i(splat_i(half as i32), sub_i(new_hi, new_lo));
        lo = select_i(lo, new_lo, moved);
        hi = select_i(hi, new_hi, moved);
        on_path &= moved;

        let (t_lo, edge_lo, found_lo, ends_lo) = exit_near(table, lo_in, lo_out, guess_lo);
        let (t_hi, edge_hi, found_hi, ends_hi) = exit_near(table, hi_in, hi_out, guess_hi);
        let p_lo = crossing(center_i, map_i, vertex_lo, vertex_lo_out, t_lo);
        let p_hi = crossing(center_i, map_i, vertex_hi, vertex_hi_out, t_hi);
        // j's chain runs from the edge after p_hi's to p_lo's (none when both share an edge).
        on_path &= found_lo & found_hi;
        let j_chain =
            on_path & !_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(edge_lo, edge_hi)));
        let first = next_i(edge_hi, turn);
        let last = add_i(
            edge_lo,
            _mm_and_si128(_mm_cmpgt_epi32(first, edge_lo), splat_i(turn)),
        );
        let (j_lo, j_hi) = (
            select_i(zero_i, first, j_chain),
            select_i(zero_i, last, j_chain),
        );

        // The chord (the one-pair path's `Chord::between`).
        let chord = sub(p_hi, p_lo);
        let length = _mm256_sqrt_pd(dot(chord, chord));
        let normal = V2 {
            x: _mm256_div_pd(chord.y, length),
            y: neg(_mm256_div_pd(chord.x, length)),
        };
        let point = scale(add(p_lo, p_hi), _mm256_set1_pd(0.5));

        let (cap_area_i, depth_i) = cap_area_and_depth(
            table,
            center_i,
            map_i,
            (lo, hi),
            (vertex_lo, vertex_hi),
            p_lo,
            p_hi,
            point,
            normal,
        );
        let minus_normal = V2 {
            x: neg(normal.x),
            y: neg(normal.y),
        };
        let (cap_area_j, depth_j) = cap_area_and_depth(
            table,
            center_j,
            map_j,
            (j_lo, j_hi),
            // j's chain runs from the end of p_hi's edge to the start of p_lo's.
            (ends_hi[1], ends_lo[0]),
            p_hi,
            p_lo,
            point,
            minus_normal,
        );
        // A chord shorter than rounding is no contact (a NaN length stays, as in the one-pair
        // path's test).
        let shortest = _mm256_mul_pd(
            _mm256_set1_pd(f64::EPSILON),
            _mm256_min_pd(reach_i, reach_j),
        );
        on_path &= bits(_mm256_cmp_pd::<_CMP_NLE_UQ>(length, shortest));
        out.on_path = on_path as u32;
        store(&mut out.point[0], point.x);
        store(&mut out.point[1], point.y);
        store(&mut out.normal[0], normal.x);
        store(&mut out.normal[1], normal.y);
        store(&mut out.length, length);
        store(&mut out.cap_area_i, cap_area_i);
        // Without a chain of j its cap and depth are zero.
        let j_chain_mask = mask(j_chain);
        store(&mut out.cap_area_j, _mm256_and_pd(cap_area_j, j_chain_mask));
        for l in 0..4 {
            let depth_j = if has(j_chain, l) { depth_j[l] } else { 0.0 };
            out.normal_gap[l] = -0.5 * (depth_i[l] + depth_j);
        }
        // The next hints, pair by pair: without a chain of j its hint is none.
        let none = splat_i(ChainHint::NONE.lo);
        let rows = transpose_i([
            wrap_i(lo, turn),
            wrap_i(hi, turn),
            select_i(none, wrap_i(j_lo, turn), j_chain),
            select_i(none, wrap_i(j_hi, turn), j_chain),
        ]);
        for (hint, row) in out.hint.iter_mut().zip(rows) {
            // SAFETY: a `PairHint` is four i32s (`repr(C)`).
            _mm_storeu_si128((hint as *mut PairHint).cast::<I>(), row);
        }
    }
}

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
        // returns for its pair from the same hint (contact and next hint), whatever the lane and
        // the pairs beside it; and most pairs a step after a contact take that path.
        if !block_available() {
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
            for (block, rotation) in pairs.chunks_exact(4).zip(0..) {
                let mut block: [_; BLOCK] = block.try_into().unwrap();
                block.rotate_left(rotation % BLOCK);
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
                let mut lanes = [LanePair::default(); BLOCK];
                for (l, lane) in lanes.iter_mut().enumerate() {
                    *lane = LanePair {
                        i: stored[l][0].lane_shape(),
                        j: stored[l][1].lane_shape(),
                        j_shift: if shifted { shift(l) } else { DVec2::ZERO },
                        hint: block[l].1,
                    };
                }
                let mut contacts = BlockContacts::default();
                grain_grain_block(&table, &lanes, shifted, &mut contacts);
                for (l, (_, start_hint, i, j)) in block.iter().enumerate() {
                    let mut j = *j;
                    if shifted {
                        let [x, y, ..] = stored[l][1].center_and_radius;
                        j.center = DVec2::new(x, y) + shift(l);
                    }
                    let mut hint = *start_hint;
                    let one = grain_grain_hinted(&table, i, &j, &mut hint);
                    total += 1;
                    if let Some((contact, next_hint)) = contacts.lane(l) {
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
