//! Four lanes of the kernel in AVX registers: `f64`s in `__m256d`, node indices in `__m128i`
//! (SSE4.1, which AVX implies), lanes' selections as `movemask` bits and blend masks loaded
//! from a table. The half of [`super::avx_pair`]'s eight lanes.

use super::kernel::{Bits, V2, Wide};
use super::{BLOCK, BlockContacts, LanePair};
use crate::geometry::intersection::PairHint;
use std::arch::x86_64::*;
use std::ops::{Add, Div, Mul, Sub};

/// Four `f64` lanes.
#[derive(Clone, Copy)]
pub(super) struct Avx(__m256d);

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
unsafe fn mask(b: Bits) -> __m256d {
    debug_assert!(b < 16);
    // SAFETY: `b` lies in [0, 16) (four lanes' bits), and each entry is 32 bytes.
    unsafe { _mm256_loadu_pd(BLEND_MASKS.get_unchecked(b as usize).as_ptr().cast::<f64>()) }
}

/// All bits set in the lanes of `b`, as indices' mask.
#[inline(always)]
unsafe fn mask_i(b: Bits) -> __m128i {
    unsafe {
        let wide = mask(b);
        // Each 64-bit lane's low half.
        _mm_castps_si128(_mm_shuffle_ps::<0b10_00_10_00>(
            _mm256_castps256_ps128(_mm256_castpd_ps(wide)),
            _mm256_extractf128_ps::<1>(_mm256_castpd_ps(wide)),
        ))
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

/// Four pairs' hints (`pairs[..4]`) as lanes: first.lo, first.hi, second.lo, second.hi.
#[inline(always)]
pub(super) unsafe fn hints4(pairs: &[LanePair<'_>]) -> [__m128i; 4] {
    unsafe {
        // SAFETY: a `PairHint` is four i32s (`repr(C)`).
        let row = |l: usize| (&pairs.get_unchecked(l).hint as *const PairHint).cast::<__m128i>();
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

macro_rules! arithmetic {
    ($trait:ident, $method:ident, $intrinsic:ident) => {
        impl $trait for Avx {
            type Output = Avx;
            #[inline(always)]
            fn $method(self, other: Avx) -> Avx {
                // SAFETY: `Avx` lanes exist only inside a kernel compiled for AVX.
                Avx(unsafe { $intrinsic(self.0, other.0) })
            }
        }
    };
}
arithmetic!(Add, add, _mm256_add_pd);
arithmetic!(Sub, sub, _mm256_sub_pd);
arithmetic!(Mul, mul, _mm256_mul_pd);
arithmetic!(Div, div, _mm256_div_pd);

/// A comparison of lanes, as the lanes' bits.
macro_rules! compare {
    ($method:ident, $predicate:ident) => {
        #[inline(always)]
        unsafe fn $method(self, other: Self) -> Bits {
            unsafe { _mm256_movemask_pd(_mm256_cmp_pd::<$predicate>(self.0, other.0)) as Bits }
        }
    };
}

/// An operation on two index lanes.
macro_rules! binary_i {
    ($method:ident, $intrinsic:ident) => {
        #[inline(always)]
        unsafe fn $method(a: __m128i, b: __m128i) -> __m128i {
            unsafe { $intrinsic(a, b) }
        }
    };
}

// SAFETY: every method runs AVX (or SSE4.1) instructions, which the kernels calling them are
// compiled for.
unsafe impl Wide for Avx {
    type I = __m128i;
    /// All ones in the selected lanes.
    type M = __m128i;
    const LANES: usize = 4;
    const ALL: Bits = 0b1111;

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
    compare!(less, _CMP_LT_OQ);
    compare!(greater, _CMP_GT_OQ);
    compare!(at_least, _CMP_GE_OQ);
    compare!(at_most, _CMP_LE_OQ);
    compare!(not_at_most, _CMP_NLE_UQ);
    #[inline(always)]
    unsafe fn min(self, other: Self) -> Self {
        unsafe { Avx(_mm256_min_pd(self.0, other.0)) }
    }
    #[inline(always)]
    unsafe fn blend(self, other: Self, m: Bits) -> Self {
        unsafe { Avx(_mm256_blendv_pd(self.0, other.0, mask(m))) }
    }
    #[inline(always)]
    unsafe fn keep(self, m: Bits) -> Self {
        unsafe { Avx(_mm256_and_pd(self.0, mask(m))) }
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
    binary_i!(add_i, _mm_add_epi32);
    binary_i!(sub_i, _mm_sub_epi32);
    binary_i!(greater_i, _mm_cmpgt_epi32);
    binary_i!(equal_i, _mm_cmpeq_epi32);
    #[inline(always)]
    unsafe fn bits_i(m: __m128i) -> Bits {
        unsafe { _mm_movemask_ps(_mm_castsi128_ps(m)) as Bits }
    }
    #[inline(always)]
    unsafe fn where_i(m: __m128i, a: __m128i) -> __m128i {
        unsafe { _mm_and_si128(m, a) }
    }
    #[inline(always)]
    unsafe fn select_i(a: __m128i, b: __m128i, m: Bits) -> __m128i {
        unsafe { _mm_blendv_epi8(a, b, mask_i(m)) }
    }
    #[inline(always)]
    unsafe fn ones_i(m: Bits) -> __m128i {
        unsafe { _mm_srli_epi32::<31>(mask_i(m)) }
    }
    binary_i!(and_i, _mm_and_si128);
    binary_i!(max_unsigned_i, _mm_max_epu32);
    binary_i!(min_unsigned_i, _mm_min_epu32);
    binary_i!(max_i, _mm_max_epi32);
    binary_i!(min_i, _mm_min_epi32);
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
    unsafe fn hints(pairs: &[LanePair<'_>]) -> [__m128i; 4] {
        unsafe { hints4(pairs) }
    }
    #[inline(always)]
    unsafe fn store_hints(rows: [__m128i; 4], out: &mut [BlockContacts]) {
        unsafe { store_hints4(rows, out.get_unchecked_mut(0)) }
    }
}
