//! Four lanes of the kernel in AVX registers: `f64`s in `__m256d`, node indices in `__m128i`
//! (SSE4.1, which AVX implies), lanes' selections by sign bits ([`SignMask`]); a call's two
//! blocks one after the other ([`grain_grain_blocks`]).

use super::kernel::{
    Bits, V2, Wide, index_operations, lane_arithmetic, lane_comparisons, selection_ops,
};
use super::{BLOCK, BLOCKS, BlockContacts, LanePairs, PAIRS};
use crate::geometry::intersection::PairHint;
use std::arch::x86_64::*;

/// Four `f64` lanes.
#[derive(Clone, Copy)]
pub(super) struct Avx(__m256d);

/// A selection of four lanes: lane `l` selected where the sign bit of its `f64` is set, the
/// one bit that `blendv`, `movemask` and `vtestpd` read. A comparison sets every bit of a lane
/// it selects; an index comparison, converted to `f64`s, gives -1.0 (only the sign and a few
/// exponent bits); and, or and not keep the sign bit right for both. A blend reads it where a
/// table of masks indexed by `movemask` bits needed three dependent instructions more.
#[derive(Clone, Copy)]
pub(super) struct SignMask(__m256d);

// SAFETY: `SignMask`s exist only inside a kernel compiled for AVX. `!` is an exclusive or with
// all ones, which an `and` after it folds into `andnpd`.
selection_ops!(
    SignMask,
    a,
    b,
    and: SignMask(unsafe { _mm256_and_pd(a.0, b.0) }),
    or: SignMask(unsafe { _mm256_or_pd(a.0, b.0) }),
    not: SignMask(unsafe { _mm256_xor_pd(a.0, _mm256_castsi256_pd(_mm256_set1_epi64x(-1))) }),
);

impl SignMask {
    /// The selection of index lanes (`i32`s): each 64-bit lane's upper half, which holds its
    /// sign bit.
    #[inline(always)]
    unsafe fn narrow(self) -> __m128 {
        unsafe {
            let m = _mm256_castpd_ps(self.0);
            _mm_shuffle_ps::<0b11_01_11_01>(
                _mm256_castps256_ps128(m),
                _mm256_extractf128_ps::<1>(m),
            )
        }
    }
}

/// Two points of each of four lanes, `(x0 y0 x1 y1)` a lane, as two points of four lanes.
#[inline(always)]
unsafe fn transpose_pairs(a: __m256d, b: __m256d, c: __m256d, d: __m256d) -> [V2<Avx>; 2] {
    unsafe {
        // (x0 of a and b, x1 of a and b), and the same of y, c and d.
        let (ab_x, ab_y) = (_mm256_unpacklo_pd(a, b), _mm256_unpackhi_pd(a, b));
        let (cd_x, cd_y) = (_mm256_unpacklo_pd(c, d), _mm256_unpackhi_pd(c, d));
        [
            V2 {
                x: Avx(_mm256_permute2f128_pd::<0x20>(ab_x, cd_x)),
                y: Avx(_mm256_permute2f128_pd::<0x20>(ab_y, cd_y)),
            },
            V2 {
                x: Avx(_mm256_permute2f128_pd::<0x31>(ab_x, cd_x)),
                y: Avx(_mm256_permute2f128_pd::<0x31>(ab_y, cd_y)),
            },
        ]
    }
}

/// The transpose of four lanes of four `i32`s: lane `l` of vector `c` is `rows[l]`'s `c`th.
#[inline(always)]
pub(super) unsafe fn transpose_i(rows: [__m128i; 4]) -> [__m128i; 4] {
    unsafe {
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
}

/// Four pairs' hints (lane `l`'s at `hint(l)`) as lanes: first.lo, first.hi, second.lo,
/// second.hi.
#[inline(always)]
pub(super) unsafe fn hints4(hint: impl Fn(usize) -> *const PairHint) -> [__m128i; 4] {
    unsafe {
        // SAFETY: a `PairHint` is four i32s (`repr(C)`).
        let row = |l: usize| hint(l).cast::<__m128i>();
        transpose_i([
            _mm_loadu_si128(row(0)),
            _mm_loadu_si128(row(1)),
            _mm_loadu_si128(row(2)),
            _mm_loadu_si128(row(3)),
        ])
    }
}

/// Four lanes of hints stored to a block's hints.
#[inline(always)]
pub(super) unsafe fn store_hints4(rows: [__m128i; 4], out: &mut BlockContacts) {
    unsafe {
        for (hint, row) in out.hint.iter_mut().zip(transpose_i(rows)) {
            // SAFETY: a `PairHint` is four i32s (`repr(C)`).
            _mm_storeu_si128((hint as *mut PairHint).cast::<__m128i>(), row);
        }
    }
}

lane_arithmetic!(Avx: Add add _mm256_add_pd, Sub sub _mm256_sub_pd, Mul mul _mm256_mul_pd,
    Div div _mm256_div_pd);

// SAFETY: every method runs AVX (or SSE4.1) instructions, which the kernels calling them are
// compiled for.
unsafe impl Wide for Avx {
    type I = __m128i;
    /// All ones in the selected lanes.
    type M = __m128i;
    type B = SignMask;
    const LANES: usize = 4;

    #[inline(always)]
    unsafe fn no_lanes() -> SignMask {
        unsafe { SignMask(_mm256_setzero_pd()) }
    }
    #[inline(always)]
    unsafe fn all_lanes() -> SignMask {
        unsafe { SignMask(_mm256_castsi256_pd(_mm256_set1_epi64x(-1))) }
    }
    #[inline(always)]
    unsafe fn bits(b: SignMask) -> Bits {
        unsafe { _mm256_movemask_pd(b.0) as Bits }
    }
    #[inline(always)]
    unsafe fn none(b: SignMask) -> bool {
        unsafe { _mm256_testz_pd(b.0, b.0) != 0 }
    }

    #[inline(always)]
    unsafe fn splat(value: f64) -> Self {
        unsafe { Avx(_mm256_set1_pd(value)) }
    }
    #[inline(always)]
    unsafe fn sqrt(self) -> Self {
        unsafe { Avx(_mm256_sqrt_pd(self.0)) }
    }
    #[inline(always)]
    unsafe fn neg(self) -> Self {
        unsafe { Avx(_mm256_xor_pd(self.0, _mm256_set1_pd(-0.0))) }
    }
    lane_comparisons!(SignMask, _mm256_cmp_pd);
    #[inline(always)]
    unsafe fn min(self, other: Self) -> Self {
        unsafe { Avx(_mm256_min_pd(self.0, other.0)) }
    }
    #[inline(always)]
    unsafe fn blend(self, other: Self, m: SignMask) -> Self {
        unsafe { Avx(_mm256_blendv_pd(self.0, other.0, m.0)) }
    }
    #[inline(always)]
    unsafe fn keep(self, m: SignMask) -> Self {
        unsafe { Avx(_mm256_blendv_pd(_mm256_setzero_pd(), self.0, m.0)) }
    }
    #[inline(always)]
    unsafe fn from_indices(k: __m128i) -> Self {
        unsafe { Avx(_mm256_cvtepi32_pd(k)) }
    }
    #[inline(always)]
    unsafe fn write_lanes(self, to: &mut [f64; 8]) {
        unsafe { _mm256_storeu_pd(to.as_mut_ptr(), self.0) }
    }
    #[inline(always)]
    unsafe fn store(
        self,
        out: &mut [BlockContacts],
        field: impl Fn(&mut BlockContacts) -> &mut [f64; BLOCK],
    ) {
        unsafe { _mm256_storeu_pd(field(out.get_unchecked_mut(0)).as_mut_ptr(), self.0) }
    }

    #[inline(always)]
    unsafe fn load_points(lane: impl Fn(usize) -> *const f64) -> V2<Self> {
        unsafe {
            // (point 0 | point 2) and (point 1 | point 3), interleaved into x's and y's.
            let p02 = _mm256_insertf128_pd::<1>(
                _mm256_castpd128_pd256(_mm_loadu_pd(lane(0))),
                _mm_loadu_pd(lane(2)),
            );
            let p13 = _mm256_insertf128_pd::<1>(
                _mm256_castpd128_pd256(_mm_loadu_pd(lane(1))),
                _mm_loadu_pd(lane(3)),
            );
            V2 {
                x: Avx(_mm256_unpacklo_pd(p02, p13)),
                y: Avx(_mm256_unpackhi_pd(p02, p13)),
            }
        }
    }
    #[inline(always)]
    unsafe fn load_pairs(lane: impl Fn(usize) -> *const f64) -> [V2<Self>; 2] {
        unsafe {
            transpose_pairs(
                _mm256_loadu_pd(lane(0)),
                _mm256_loadu_pd(lane(1)),
                _mm256_loadu_pd(lane(2)),
                _mm256_loadu_pd(lane(3)),
            )
        }
    }
    #[inline(always)]
    unsafe fn load_quads(lane: impl Fn(usize) -> *const f64) -> [V2<Self>; 4] {
        unsafe {
            let at = [lane(0), lane(1), lane(2), lane(3)];
            let [n0, n1] = Self::load_pairs(|l| at[l]);
            let [n2, n3] = Self::load_pairs(|l| at[l].add(4));
            [n0, n1, n2, n3]
        }
    }

    #[inline(always)]
    unsafe fn splat_i(k: i32) -> __m128i {
        unsafe { _mm_set1_epi32(k) }
    }
    index_operations!(__m128i: add_i _mm_add_epi32, sub_i _mm_sub_epi32,
        greater_i _mm_cmpgt_epi32, equal_i _mm_cmpeq_epi32, and_i _mm_and_si128,
        max_unsigned_i _mm_max_epu32, min_unsigned_i _mm_min_epu32, max_i _mm_max_epi32,
        min_i _mm_min_epi32);
    /// (-1 converts to -1.0, 0 to +0.0.)
    #[inline(always)]
    unsafe fn lanes_i(m: __m128i) -> SignMask {
        unsafe { SignMask(_mm256_cvtepi32_pd(m)) }
    }
    #[inline(always)]
    unsafe fn where_i(m: __m128i, a: __m128i) -> __m128i {
        unsafe { _mm_and_si128(m, a) }
    }
    #[inline(always)]
    unsafe fn select_i(a: __m128i, b: __m128i, m: SignMask) -> __m128i {
        unsafe {
            _mm_castps_si128(_mm_blendv_ps(
                _mm_castsi128_ps(a),
                _mm_castsi128_ps(b),
                m.narrow(),
            ))
        }
    }
    #[inline(always)]
    unsafe fn ones_i(m: SignMask) -> __m128i {
        unsafe { _mm_srli_epi32::<31>(_mm_castps_si128(m.narrow())) }
    }
    #[inline(always)]
    unsafe fn half_i(k: __m128i) -> __m128i {
        unsafe { _mm_srai_epi32::<1>(k) }
    }
    #[inline(always)]
    unsafe fn index(k: __m128i, l: usize) -> isize {
        // SAFETY: both are 16 bytes of four i32s, lane 0 first.
        unsafe { std::mem::transmute::<__m128i, [i32; 4]>(k)[l] as isize }
    }

    #[inline(always)]
    unsafe fn hints(hint: impl Fn(usize) -> *const PairHint) -> [__m128i; 4] {
        unsafe { hints4(hint) }
    }
    #[inline(always)]
    unsafe fn store_hints(rows: [__m128i; 4], out: &mut [BlockContacts]) {
        unsafe { store_hints4(rows, out.get_unchecked_mut(0)) }
    }
}

/// [`super::grain_grain_blocks`] in AVX registers, a block of four lanes at a time: the blocks
/// that hold the pairs that count (`filled`). Eight lanes in pairs of AVX registers, each
/// operation on both halves, spilled from the sixteen registers and ran the full level at
/// 0.94–0.97 of this, with 4% more instructions (issue #16, thirty-seventh session).
///
/// # Safety
/// The processor has AVX.
#[target_feature(enable = "avx")]
pub(super) unsafe fn grain_grain_blocks<P: LanePairs>(
    table: &crate::geometry::contour::ContourTable,
    pairs: &P,
    shifted: bool,
    filled: usize,
    out: &mut [BlockContacts; BLOCKS],
) {
    // Block b's lanes are the source's 4b..4b + 4, below PAIRS.
    const { assert!(PAIRS == BLOCKS * BLOCK) };
    for (b, out) in out
        .chunks_exact_mut(1)
        .enumerate()
        .take(filled.div_ceil(BLOCK))
    {
        // SAFETY: the caller's processor has AVX, and each block is four of the source's
        // lanes with one block of contacts.
        unsafe {
            super::kernel::grain_grain_lanes::<Avx, P>(table, pairs, b * BLOCK, shifted, out)
        };
    }
}
