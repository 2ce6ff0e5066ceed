//! Eight lanes of the kernel in pairs of AVX registers, for processors without AVX-512: each
//! operation is [`Avx`]'s on both halves. Sixteen AVX registers do not hold the eight-lane
//! kernel's values (they spill), but the common path is a chain of dependent loads and
//! operations, and two blocks' chains side by side still run in less than twice one's time.

use super::avx::{Avx, SignMask};
use super::kernel::{Bits, V2, Wide};
use super::{BLOCK, BLOCKS, BlockContacts, LanePair};
use std::arch::x86_64::*;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};

/// Eight `f64` lanes: lanes 0 to 3, then 4 to 7.
#[derive(Clone, Copy)]
pub(super) struct AvxPair(Avx, Avx);

macro_rules! arithmetic {
    ($trait:ident, $method:ident) => {
        impl $trait for AvxPair {
            type Output = AvxPair;
            #[inline(always)]
            fn $method(self, other: AvxPair) -> AvxPair {
                AvxPair(self.0.$method(other.0), self.1.$method(other.1))
            }
        }
    };
}
arithmetic!(Add, add);
arithmetic!(Sub, sub);
arithmetic!(Mul, mul);
arithmetic!(Div, div);

/// A selection of eight lanes: the halves' selections.
#[derive(Clone, Copy)]
pub(super) struct PairMask(SignMask, SignMask);

impl BitAnd for PairMask {
    type Output = PairMask;
    #[inline(always)]
    fn bitand(self, other: PairMask) -> PairMask {
        PairMask(self.0 & other.0, self.1 & other.1)
    }
}

impl BitOr for PairMask {
    type Output = PairMask;
    #[inline(always)]
    fn bitor(self, other: PairMask) -> PairMask {
        PairMask(self.0 | other.0, self.1 | other.1)
    }
}

impl Not for PairMask {
    type Output = PairMask;
    #[inline(always)]
    fn not(self) -> PairMask {
        PairMask(!self.0, !self.1)
    }
}

/// Two halves of points as points of eight lanes.
#[inline(always)]
fn pair_points<const K: usize>(low: [V2<Avx>; K], high: [V2<Avx>; K]) -> [V2<AvxPair>; K] {
    std::array::from_fn(|k| V2 {
        x: AvxPair(low[k].x, high[k].x),
        y: AvxPair(low[k].y, high[k].y),
    })
}

macro_rules! compare {
    ($method:ident) => {
        #[inline(always)]
        unsafe fn $method(self, other: Self) -> PairMask {
            unsafe { PairMask(self.0.$method(other.0), self.1.$method(other.1)) }
        }
    };
}

type I = (__m128i, __m128i);

// SAFETY: every method is `Avx`'s on each half.
unsafe impl Wide for AvxPair {
    type I = I;
    type M = (__m128i, __m128i);
    type B = PairMask;
    const LANES: usize = 8;

    #[inline(always)]
    unsafe fn no_lanes() -> PairMask {
        unsafe { PairMask(Avx::no_lanes(), Avx::no_lanes()) }
    }
    #[inline(always)]
    unsafe fn all_lanes() -> PairMask {
        unsafe { PairMask(Avx::all_lanes(), Avx::all_lanes()) }
    }
    #[inline(always)]
    unsafe fn bits(b: PairMask) -> Bits {
        unsafe { Avx::bits(b.0) | (Avx::bits(b.1) << BLOCK) }
    }
    #[inline(always)]
    unsafe fn none(b: PairMask) -> bool {
        unsafe { Avx::none(b.0 | b.1) }
    }

    #[inline(always)]
    unsafe fn splat(value: f64) -> Self {
        unsafe { AvxPair(Avx::splat(value), Avx::splat(value)) }
    }
    #[inline(always)]
    unsafe fn sqrt(self) -> Self {
        unsafe { AvxPair(self.0.sqrt(), self.1.sqrt()) }
    }
    #[inline(always)]
    unsafe fn neg(self) -> Self {
        unsafe { AvxPair(self.0.neg(), self.1.neg()) }
    }
    compare!(less);
    compare!(greater);
    compare!(at_least);
    compare!(at_most);
    compare!(not_at_most);
    #[inline(always)]
    unsafe fn min(self, other: Self) -> Self {
        unsafe { AvxPair(self.0.min(other.0), self.1.min(other.1)) }
    }
    #[inline(always)]
    unsafe fn blend(self, other: Self, m: PairMask) -> Self {
        unsafe { AvxPair(self.0.blend(other.0, m.0), self.1.blend(other.1, m.1)) }
    }
    #[inline(always)]
    unsafe fn keep(self, m: PairMask) -> Self {
        unsafe { AvxPair(self.0.keep(m.0), self.1.keep(m.1)) }
    }
    #[inline(always)]
    unsafe fn from_indices(k: I) -> Self {
        unsafe { AvxPair(Avx::from_indices(k.0), Avx::from_indices(k.1)) }
    }
    #[inline(always)]
    unsafe fn write_lanes(self, to: &mut [f64; 8]) {
        let (mut low, mut high) = ([0.0; 8], [0.0; 8]);
        unsafe {
            self.0.write_lanes(&mut low);
            self.1.write_lanes(&mut high);
        }
        to[..BLOCK].copy_from_slice(&low[..BLOCK]);
        to[BLOCK..].copy_from_slice(&high[..BLOCK]);
    }
    #[inline(always)]
    unsafe fn store(
        self,
        out: &mut [BlockContacts],
        field: impl Fn(&mut BlockContacts) -> &mut [f64; BLOCK],
    ) {
        unsafe {
            let (low, high) = out.split_at_mut_unchecked(1);
            self.0.store(low, &field);
            self.1.store(high, &field);
        }
    }

    #[inline(always)]
    unsafe fn load_points(lane: impl Fn(usize) -> *const f64) -> V2<Self> {
        unsafe {
            let [p] = pair_points(
                [Avx::load_points(&lane)],
                [Avx::load_points(|l| lane(l + BLOCK))],
            );
            p
        }
    }
    #[inline(always)]
    unsafe fn load_pairs(lane: impl Fn(usize) -> *const f64) -> [V2<Self>; 2] {
        unsafe { pair_points(Avx::load_pairs(&lane), Avx::load_pairs(|l| lane(l + BLOCK))) }
    }
    #[inline(always)]
    unsafe fn load_quads(lane: impl Fn(usize) -> *const f64) -> [V2<Self>; 4] {
        unsafe { pair_points(Avx::load_quads(&lane), Avx::load_quads(|l| lane(l + BLOCK))) }
    }

    #[inline(always)]
    unsafe fn splat_i(k: i32) -> I {
        unsafe { (Avx::splat_i(k), Avx::splat_i(k)) }
    }
    #[inline(always)]
    unsafe fn add_i(a: I, b: I) -> I {
        unsafe { (Avx::add_i(a.0, b.0), Avx::add_i(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn sub_i(a: I, b: I) -> I {
        unsafe { (Avx::sub_i(a.0, b.0), Avx::sub_i(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn greater_i(a: I, b: I) -> I {
        unsafe { (Avx::greater_i(a.0, b.0), Avx::greater_i(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn equal_i(a: I, b: I) -> I {
        unsafe { (Avx::equal_i(a.0, b.0), Avx::equal_i(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn lanes_i(m: I) -> PairMask {
        unsafe { PairMask(Avx::lanes_i(m.0), Avx::lanes_i(m.1)) }
    }
    #[inline(always)]
    unsafe fn where_i(m: I, a: I) -> I {
        unsafe { (Avx::where_i(m.0, a.0), Avx::where_i(m.1, a.1)) }
    }
    #[inline(always)]
    unsafe fn select_i(a: I, b: I, m: PairMask) -> I {
        unsafe { (Avx::select_i(a.0, b.0, m.0), Avx::select_i(a.1, b.1, m.1)) }
    }
    #[inline(always)]
    unsafe fn ones_i(m: PairMask) -> I {
        unsafe { (Avx::ones_i(m.0), Avx::ones_i(m.1)) }
    }
    #[inline(always)]
    unsafe fn and_i(a: I, b: I) -> I {
        unsafe { (Avx::and_i(a.0, b.0), Avx::and_i(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn max_unsigned_i(a: I, b: I) -> I {
        unsafe { (Avx::max_unsigned_i(a.0, b.0), Avx::max_unsigned_i(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn min_unsigned_i(a: I, b: I) -> I {
        unsafe { (Avx::min_unsigned_i(a.0, b.0), Avx::min_unsigned_i(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn max_i(a: I, b: I) -> I {
        unsafe { (Avx::max_i(a.0, b.0), Avx::max_i(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn min_i(a: I, b: I) -> I {
        unsafe { (Avx::min_i(a.0, b.0), Avx::min_i(a.1, b.1)) }
    }
    #[inline(always)]
    unsafe fn half_i(k: I) -> I {
        unsafe { (Avx::half_i(k.0), Avx::half_i(k.1)) }
    }
    #[inline(always)]
    unsafe fn index(k: I, l: usize) -> isize {
        unsafe {
            if l < BLOCK {
                Avx::index(k.0, l)
            } else {
                Avx::index(k.1, l - BLOCK)
            }
        }
    }

    #[inline(always)]
    unsafe fn hints(pairs: &[LanePair<'_>]) -> [I; 4] {
        unsafe {
            let low = Avx::hints(pairs.get_unchecked(..BLOCK));
            let high = Avx::hints(pairs.get_unchecked(BLOCK..));
            [
                (low[0], high[0]),
                (low[1], high[1]),
                (low[2], high[2]),
                (low[3], high[3]),
            ]
        }
    }
    #[inline(always)]
    unsafe fn store_hints(rows: [I; 4], out: &mut [BlockContacts]) {
        unsafe {
            let (low, high) = out.split_at_mut_unchecked(1);
            Avx::store_hints([rows[0].0, rows[1].0, rows[2].0, rows[3].0], low);
            Avx::store_hints([rows[0].1, rows[1].1, rows[2].1, rows[3].1], high);
        }
    }
}

/// [`super::grain_grain_blocks`] in pairs of AVX registers; the first block alone, in one
/// register's lanes, where the pairs that count (`filled`) fit in it.
///
/// # Safety
/// The processor has AVX.
#[target_feature(enable = "avx")]
pub(super) unsafe fn grain_grain_blocks(
    table: &crate::geometry::contour::ContourTable,
    pairs: &[LanePair<'_>; 2 * BLOCK],
    shifted: bool,
    filled: usize,
    out: &mut [BlockContacts; BLOCKS],
) {
    unsafe {
        if filled <= BLOCK {
            super::kernel::grain_grain_lanes::<Avx>(table, &pairs[..BLOCK], shifted, &mut out[..1]);
        } else {
            super::kernel::grain_grain_lanes::<AvxPair>(table, pairs, shifted, out);
        }
    }
}
