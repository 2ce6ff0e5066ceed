//! Eight lanes of the kernel in AVX-512 registers: `f64`s in `__m512d`, node indices in
//! `__m256i` (AVX2 and AVX-512VL), lanes' selections in mask registers. Two blocks of
//! [`BLOCK`] pairs a call: the common path is a long chain of dependent loads and operations,
//! and eight lanes run two blocks' chains in the time of one.

use super::avx::{hints4, store_hints4};
use super::kernel::{
    Bits, V2, Wide, index_operations, lane_arithmetic, lane_comparisons, selection_ops,
};
use super::{BLOCK, BLOCKS, BlockContacts, LanePairs};
use crate::geometry::intersection::PairHint;
use std::arch::x86_64::*;

/// Eight `f64` lanes.
#[derive(Clone, Copy)]
pub(super) struct Avx512(__m512d);

lane_arithmetic!(Avx512: Add add _mm512_add_pd, Sub sub _mm512_sub_pd,
    Mul mul _mm512_mul_pd, Div div _mm512_div_pd);

/// The eight lanes' pointers, `lane(0)` to `lane(7)`, taken first: no closure calls an
/// intrinsic (a closure is not compiled for AVX-512, and its intrinsics would become calls).
#[inline(always)]
fn lane_pointers(lane: impl Fn(usize) -> *const f64) -> [*const f64; 8] {
    [
        lane(0),
        lane(1),
        lane(2),
        lane(3),
        lane(4),
        lane(5),
        lane(6),
        lane(7),
    ]
}

/// Two 256-bit halves as one vector, `low` in lanes 0 to 3.
#[inline(always)]
unsafe fn join(low: __m256d, high: __m256d) -> __m512d {
    unsafe { _mm512_insertf64x4::<1>(_mm512_castpd256_pd512(low), high) }
}

/// Two points (`a`'s two f64s, then `b`'s) as one vector.
#[inline(always)]
unsafe fn two_points(a: *const f64, b: *const f64) -> __m256d {
    unsafe { _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(_mm_loadu_pd(a)), _mm_loadu_pd(b)) }
}

/// One coordinate of four points of eight rows, as four vectors of eight lanes: 128-bit lane
/// `k` of `q01` holds point k's coordinate of rows 0 and 1, and so on.
#[inline(always)]
unsafe fn points_of_rows(q01: __m512d, q23: __m512d, q45: __m512d, q67: __m512d) -> [__m512d; 4] {
    // Points (0, 2) and (1, 3) of rows 0 to 3, then of rows 4 to 7, then of all.
    const EVEN: i32 = 0b10_00_10_00;
    const ODD: i32 = 0b11_01_11_01;
    unsafe {
        let (low_even, low_odd) = (
            _mm512_shuffle_f64x2::<EVEN>(q01, q23),
            _mm512_shuffle_f64x2::<ODD>(q01, q23),
        );
        let (high_even, high_odd) = (
            _mm512_shuffle_f64x2::<EVEN>(q45, q67),
            _mm512_shuffle_f64x2::<ODD>(q45, q67),
        );
        [
            _mm512_shuffle_f64x2::<EVEN>(low_even, high_even),
            _mm512_shuffle_f64x2::<EVEN>(low_odd, high_odd),
            _mm512_shuffle_f64x2::<ODD>(low_even, high_even),
            _mm512_shuffle_f64x2::<ODD>(low_odd, high_odd),
        ]
    }
}

/// A selection of eight lanes, a mask register's bits.
#[derive(Clone, Copy)]
pub(super) struct Lanes(__mmask8);

selection_ops!(
    Lanes,
    a,
    b,
    and: Lanes(a.0 & b.0),
    or: Lanes(a.0 | b.0),
    not: Lanes(!a.0),
);

// SAFETY: every method runs AVX-512F, AVX-512VL or AVX2 instructions, which the kernel calling
// them is compiled for.
unsafe impl Wide for Avx512 {
    type I = __m256i;
    type M = __mmask8;
    type B = Lanes;
    const LANES: usize = 8;

    #[inline(always)]
    unsafe fn no_lanes() -> Lanes {
        Lanes(0)
    }
    #[inline(always)]
    unsafe fn all_lanes() -> Lanes {
        Lanes(0xff)
    }
    #[inline(always)]
    unsafe fn bits(b: Lanes) -> Bits {
        b.0 as Bits
    }
    #[inline(always)]
    unsafe fn none(b: Lanes) -> bool {
        b.0 == 0
    }

    #[inline(always)]
    unsafe fn splat(value: f64) -> Self {
        unsafe { Avx512(_mm512_set1_pd(value)) }
    }
    #[inline(always)]
    unsafe fn sqrt(self) -> Self {
        unsafe { Avx512(_mm512_sqrt_pd(self.0)) }
    }
    #[inline(always)]
    unsafe fn neg(self) -> Self {
        unsafe {
            Avx512(_mm512_castsi512_pd(_mm512_xor_si512(
                _mm512_castpd_si512(self.0),
                _mm512_set1_epi64(i64::MIN),
            )))
        }
    }
    lane_comparisons!(Lanes, _mm512_cmp_pd_mask);
    #[inline(always)]
    unsafe fn min(self, other: Self) -> Self {
        unsafe { Avx512(_mm512_min_pd(self.0, other.0)) }
    }
    #[inline(always)]
    unsafe fn blend(self, other: Self, m: Lanes) -> Self {
        unsafe { Avx512(_mm512_mask_blend_pd(m.0, self.0, other.0)) }
    }
    #[inline(always)]
    unsafe fn keep(self, m: Lanes) -> Self {
        unsafe { Avx512(_mm512_maskz_mov_pd(m.0, self.0)) }
    }
    #[inline(always)]
    unsafe fn from_indices(k: __m256i) -> Self {
        unsafe { Avx512(_mm512_cvtepi32_pd(k)) }
    }
    #[inline(always)]
    unsafe fn write_lanes(self, to: &mut [f64; 8]) {
        unsafe { _mm512_storeu_pd(to.as_mut_ptr(), self.0) }
    }
    #[inline(always)]
    unsafe fn store(
        self,
        out: &mut [BlockContacts],
        field: impl Fn(&mut BlockContacts) -> &mut [f64; BLOCK],
    ) {
        unsafe {
            _mm256_storeu_pd(
                field(out.get_unchecked_mut(0)).as_mut_ptr(),
                _mm512_castpd512_pd256(self.0),
            );
            _mm256_storeu_pd(
                field(out.get_unchecked_mut(1)).as_mut_ptr(),
                _mm512_extractf64x4_pd::<1>(self.0),
            );
        }
    }

    #[inline(always)]
    unsafe fn load_points(lane: impl Fn(usize) -> *const f64) -> V2<Self> {
        unsafe {
            let p = lane_pointers(lane);
            // (points 0, 2, 4, 6) and (points 1, 3, 5, 7), interleaved into x's and y's.
            let even = join(two_points(p[0], p[2]), two_points(p[4], p[6]));
            let odd = join(two_points(p[1], p[3]), two_points(p[5], p[7]));
            V2 {
                x: Avx512(_mm512_unpacklo_pd(even, odd)),
                y: Avx512(_mm512_unpackhi_pd(even, odd)),
            }
        }
    }
    #[inline(always)]
    unsafe fn load_pairs(lane: impl Fn(usize) -> *const f64) -> [V2<Self>; 2] {
        unsafe {
            let p = lane_pointers(lane);
            // Rows l and l + 4 side by side: (x0 y0 x1 y1) of each.
            let (a, b, c, d) = (
                join(_mm256_loadu_pd(p[0]), _mm256_loadu_pd(p[4])),
                join(_mm256_loadu_pd(p[1]), _mm256_loadu_pd(p[5])),
                join(_mm256_loadu_pd(p[2]), _mm256_loadu_pd(p[6])),
                join(_mm256_loadu_pd(p[3]), _mm256_loadu_pd(p[7])),
            );
            // (x0 of a and b, x1 of a and b) in each half, and the same of y, c and d.
            let (ab_x, ab_y) = (_mm512_unpacklo_pd(a, b), _mm512_unpackhi_pd(a, b));
            let (cd_x, cd_y) = (_mm512_unpacklo_pd(c, d), _mm512_unpackhi_pd(c, d));
            // The first point's lanes 0, 1 from ab, 2, 3 from cd, 4, 5 from ab's upper half
            // and 6, 7 from cd's; the second point's the same from the 128-bit lanes after.
            let first = _mm512_set_epi64(13, 12, 5, 4, 9, 8, 1, 0);
            let second = _mm512_set_epi64(15, 14, 7, 6, 11, 10, 3, 2);
            [
                V2 {
                    x: Avx512(_mm512_permutex2var_pd(ab_x, first, cd_x)),
                    y: Avx512(_mm512_permutex2var_pd(ab_y, first, cd_y)),
                },
                V2 {
                    x: Avx512(_mm512_permutex2var_pd(ab_x, second, cd_x)),
                    y: Avx512(_mm512_permutex2var_pd(ab_y, second, cd_y)),
                },
            ]
        }
    }
    #[inline(always)]
    unsafe fn load_quads(lane: impl Fn(usize) -> *const f64) -> [V2<Self>; 4] {
        unsafe {
            let p = lane_pointers(lane);
            let (r0, r1, r2, r3) = (
                _mm512_loadu_pd(p[0]),
                _mm512_loadu_pd(p[1]),
                _mm512_loadu_pd(p[2]),
                _mm512_loadu_pd(p[3]),
            );
            let (r4, r5, r6, r7) = (
                _mm512_loadu_pd(p[4]),
                _mm512_loadu_pd(p[5]),
                _mm512_loadu_pd(p[6]),
                _mm512_loadu_pd(p[7]),
            );
            // Each 128-bit lane k of `x01` holds point k's x of rows 0 and 1, of `y01` its y.
            let (x01, y01) = (_mm512_unpacklo_pd(r0, r1), _mm512_unpackhi_pd(r0, r1));
            let (x23, y23) = (_mm512_unpacklo_pd(r2, r3), _mm512_unpackhi_pd(r2, r3));
            let (x45, y45) = (_mm512_unpacklo_pd(r4, r5), _mm512_unpackhi_pd(r4, r5));
            let (x67, y67) = (_mm512_unpacklo_pd(r6, r7), _mm512_unpackhi_pd(r6, r7));
            let x = points_of_rows(x01, x23, x45, x67);
            let y = points_of_rows(y01, y23, y45, y67);
            std::array::from_fn(|k| V2 {
                x: Avx512(x[k]),
                y: Avx512(y[k]),
            })
        }
    }

    #[inline(always)]
    unsafe fn splat_i(k: i32) -> __m256i {
        unsafe { _mm256_set1_epi32(k) }
    }
    index_operations!(__m256i: add_i _mm256_add_epi32, sub_i _mm256_sub_epi32,
        and_i _mm256_and_si256, max_unsigned_i _mm256_max_epu32,
        min_unsigned_i _mm256_min_epu32, max_i _mm256_max_epi32, min_i _mm256_min_epi32);
    #[inline(always)]
    unsafe fn greater_i(a: __m256i, b: __m256i) -> __mmask8 {
        unsafe { _mm256_cmpgt_epi32_mask(a, b) }
    }
    #[inline(always)]
    unsafe fn equal_i(a: __m256i, b: __m256i) -> __mmask8 {
        unsafe { _mm256_cmpeq_epi32_mask(a, b) }
    }
    #[inline(always)]
    unsafe fn lanes_i(m: __mmask8) -> Lanes {
        Lanes(m)
    }
    #[inline(always)]
    unsafe fn where_i(m: __mmask8, a: __m256i) -> __m256i {
        unsafe { _mm256_maskz_mov_epi32(m, a) }
    }
    #[inline(always)]
    unsafe fn select_i(a: __m256i, b: __m256i, m: Lanes) -> __m256i {
        unsafe { _mm256_mask_blend_epi32(m.0, a, b) }
    }
    #[inline(always)]
    unsafe fn ones_i(m: Lanes) -> __m256i {
        unsafe { _mm256_maskz_mov_epi32(m.0, _mm256_set1_epi32(1)) }
    }
    #[inline(always)]
    unsafe fn half_i(k: __m256i) -> __m256i {
        unsafe { _mm256_srai_epi32::<1>(k) }
    }
    #[inline(always)]
    unsafe fn index(k: __m256i, l: usize) -> isize {
        // SAFETY: both are 32 bytes of eight i32s, lane 0 first.
        unsafe { std::mem::transmute::<__m256i, [i32; 8]>(k)[l] as isize }
    }

    #[inline(always)]
    unsafe fn hints(hint: impl Fn(usize) -> *const PairHint) -> [__m256i; 4] {
        unsafe {
            let low = hints4(&hint);
            let high = hints4(|l| hint(BLOCK + l));
            [
                _mm256_set_m128i(high[0], low[0]),
                _mm256_set_m128i(high[1], low[1]),
                _mm256_set_m128i(high[2], low[2]),
                _mm256_set_m128i(high[3], low[3]),
            ]
        }
    }
    #[inline(always)]
    unsafe fn store_hints(rows: [__m256i; 4], out: &mut [BlockContacts]) {
        unsafe {
            let low = [
                _mm256_castsi256_si128(rows[0]),
                _mm256_castsi256_si128(rows[1]),
                _mm256_castsi256_si128(rows[2]),
                _mm256_castsi256_si128(rows[3]),
            ];
            let high = [
                _mm256_extracti128_si256::<1>(rows[0]),
                _mm256_extracti128_si256::<1>(rows[1]),
                _mm256_extracti128_si256::<1>(rows[2]),
                _mm256_extracti128_si256::<1>(rows[3]),
            ];
            store_hints4(low, out.get_unchecked_mut(0));
            store_hints4(high, out.get_unchecked_mut(1));
        }
    }
}

/// Whether this processor runs the eight-lane kernel.
pub(super) fn available() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
}

/// [`super::grain_grain_blocks`] on a processor with AVX-512F and AVX-512VL.
///
/// # Safety
/// The processor has them.
#[target_feature(enable = "avx512f,avx512vl,avx2,avx")]
pub(super) unsafe fn grain_grain_blocks<P: LanePairs>(
    table: &crate::geometry::contour::ContourTable,
    pairs: &P,
    shifted: bool,
    out: &mut [BlockContacts; BLOCKS],
) {
    unsafe { super::kernel::grain_grain_lanes::<Avx512, P>(table, pairs, 0, shifted, out) }
}
