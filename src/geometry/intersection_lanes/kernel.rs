//! The common path's arithmetic, written once over [`Wide`]: lanes of `f64`s and of node
//! indices, four in AVX registers ([`super::avx`]) or eight in AVX-512 ones
//! ([`super::avx512`]). Every lane computes with the operations of the
//! one-pair path, in its order, whichever the registers: the kernels give the same bits.

use super::{BLOCK, BlockContacts, LanePairs};
use crate::geometry::contour::ContourTable;
use crate::geometry::intersection::{ChainHint, PairHint};
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};

/// Lanes as bits: bit `l` for lane `l`.
pub(super) type Bits = u32;

/// Lanes of `f64`s (`Self`), of `i32` node indices ([`Wide::I`]) and selections of lanes
/// ([`Wide::B`]), and the loads, stores and selections the kernel needs. Every method is an instruction or a few of the width's
/// instruction set, inlined into a kernel compiled for it; calling one elsewhere is unsound.
///
/// # Safety
/// Implementations run instructions the processor must have: every method is `unsafe` to call
/// for that reason, and only from a function compiled for them.
pub(super) unsafe trait Wide:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    /// Lanes of node indices.
    type I: Copy;
    /// A selection of index lanes, as comparisons of indices give it.
    type M: Copy;
    /// A selection of lanes, as comparisons give it and blends take it: kept in the form the
    /// width's blends read (a vector register where they read one, a mask register in
    /// AVX-512), so that a comparison feeds a blend without a round trip through bits.
    type B: Copy + BitAnd<Output = Self::B> + BitOr<Output = Self::B> + Not<Output = Self::B>;
    const LANES: usize;

    /// No lane, and every lane.
    unsafe fn no_lanes() -> Self::B;
    unsafe fn all_lanes() -> Self::B;
    /// The selection as bits (none above `LANES`).
    unsafe fn bits(b: Self::B) -> Bits;
    /// Whether the selection is empty.
    unsafe fn none(b: Self::B) -> bool;

    unsafe fn splat(value: f64) -> Self;
    unsafe fn sqrt(self) -> Self;
    /// The sign flipped (an exclusive or of the sign bit).
    unsafe fn neg(self) -> Self;
    /// The lanes where `self < other` (false for a NaN).
    unsafe fn less(self, other: Self) -> Self::B;
    /// `self > other`.
    unsafe fn greater(self, other: Self) -> Self::B;
    /// `self >= other`.
    unsafe fn at_least(self, other: Self) -> Self::B;
    /// `self <= other`.
    unsafe fn at_most(self, other: Self) -> Self::B;
    /// `!(self <= other)`: true for a NaN.
    unsafe fn not_at_most(self, other: Self) -> Self::B;
    /// The `minpd` instruction's minimum: `other` where either is a NaN or both are zeros.
    unsafe fn min(self, other: Self) -> Self;
    /// `other` in the lanes of `m`, else `self`.
    unsafe fn blend(self, other: Self, m: Self::B) -> Self;
    /// `self` in the lanes of `m`, else `+0.0`.
    unsafe fn keep(self, m: Self::B) -> Self;
    unsafe fn from_indices(k: Self::I) -> Self;
    /// The lanes written to `to[..LANES]`.
    unsafe fn write_lanes(self, to: &mut [f64; 8]);
    /// The lanes stored to `field` of the blocks `out[..LANES / BLOCK]`, four lanes a block.
    unsafe fn store(
        self,
        out: &mut [BlockContacts],
        field: impl Fn(&mut BlockContacts) -> &mut [f64; BLOCK],
    );

    /// Two f64s from `lane(l)` in each lane `l`, read as a point.
    unsafe fn load_points(lane: impl Fn(usize) -> *const f64) -> V2<Self>;
    /// Four f64s from `lane(l)` in each lane `l`, read as two points.
    unsafe fn load_pairs(lane: impl Fn(usize) -> *const f64) -> [V2<Self>; 2];
    /// Eight f64s from `lane(l)` in each lane `l`, read as four points.
    unsafe fn load_quads(lane: impl Fn(usize) -> *const f64) -> [V2<Self>; 4];

    unsafe fn splat_i(k: i32) -> Self::I;
    unsafe fn add_i(a: Self::I, b: Self::I) -> Self::I;
    unsafe fn sub_i(a: Self::I, b: Self::I) -> Self::I;
    /// The lanes where `a > b` (signed).
    unsafe fn greater_i(a: Self::I, b: Self::I) -> Self::M;
    /// The lanes where `a == b`.
    unsafe fn equal_i(a: Self::I, b: Self::I) -> Self::M;
    unsafe fn lanes_i(m: Self::M) -> Self::B;
    /// `a` in the lanes of `m`, else 0.
    unsafe fn where_i(m: Self::M, a: Self::I) -> Self::I;
    /// `b` in the lanes of `m`, else `a`.
    unsafe fn select_i(a: Self::I, b: Self::I, m: Self::B) -> Self::I;
    /// 1 in the lanes of `m`, else 0.
    unsafe fn ones_i(m: Self::B) -> Self::I;
    unsafe fn and_i(a: Self::I, b: Self::I) -> Self::I;
    /// Unsigned maximum and minimum, signed maximum and minimum.
    unsafe fn max_unsigned_i(a: Self::I, b: Self::I) -> Self::I;
    unsafe fn min_unsigned_i(a: Self::I, b: Self::I) -> Self::I;
    unsafe fn max_i(a: Self::I, b: Self::I) -> Self::I;
    unsafe fn min_i(a: Self::I, b: Self::I) -> Self::I;
    /// `k >> 1`, rounding down (arithmetic shift).
    unsafe fn half_i(k: Self::I) -> Self::I;
    /// Lane `l` as an `isize`.
    unsafe fn index(k: Self::I, l: usize) -> isize;

    /// The pairs' hints (lane `l`'s at `hint(l)`) as lanes: first.lo, first.hi, second.lo,
    /// second.hi.
    unsafe fn hints(hint: impl Fn(usize) -> *const PairHint) -> [Self::I; 4];
    /// Lanes of hints (first.lo, first.hi, second.lo, second.hi) stored to the blocks' hints.
    unsafe fn store_hints(rows: [Self::I; 4], out: &mut [BlockContacts]);
}

/// `&`, `|` and `!` of a width's selections of lanes ([`Wide::B`]) `$ty`: each the expression
/// given, of `$a` (and `$b`). Expressions, not closures: a closure is not compiled for the
/// kernel's instructions, and its intrinsics would stay calls.
macro_rules! selection_ops {
    ($ty:ident, $a:ident, $b:ident, and: $and:expr, or: $or:expr, not: $not:expr $(,)?) => {
        selection_ops!(@binary $ty, BitAnd, bitand, $a, $b, $and);
        selection_ops!(@binary $ty, BitOr, bitor, $a, $b, $or);
        impl std::ops::Not for $ty {
            type Output = $ty;
            #[inline(always)]
            fn not(self) -> $ty {
                let $a = self;
                $not
            }
        }
    };
    (@binary $ty:ident, $trait:ident, $method:ident, $a:ident, $b:ident, $body:expr) => {
        impl std::ops::$trait for $ty {
            type Output = $ty;
            #[inline(always)]
            fn $method(self, $b: $ty) -> $ty {
                let $a = self;
                $body
            }
        }
    };
}
pub(super) use selection_ops;

/// `+`, `-`, `*` and `/` of a width's `f64` lanes `$ty` (its vector in field 0), each by its
/// intrinsic: safe methods, as the lanes exist only inside a kernel compiled for the width's
/// instructions, into which they inline.
macro_rules! lane_arithmetic {
    ($ty:ident: $($trait:ident $method:ident $intrinsic:ident),+ $(,)?) => {$(
        impl std::ops::$trait for $ty {
            type Output = $ty;
            #[inline(always)]
            fn $method(self, other: $ty) -> $ty {
                // SAFETY: `$ty` lanes exist only inside a kernel compiled for their
                // instructions.
                $ty(unsafe { $intrinsic(self.0, other.0) })
            }
        }
    )+};
}
pub(super) use lane_arithmetic;

/// [`Wide`]'s comparisons of `f64` lanes in an impl: each `$compare::<predicate>` of the two
/// vectors (field 0), as the selection `$selection`.
macro_rules! lane_comparisons {
    ($selection:ident, $compare:ident) => {
        lane_comparisons!(@one $selection, $compare, less, _CMP_LT_OQ);
        lane_comparisons!(@one $selection, $compare, greater, _CMP_GT_OQ);
        lane_comparisons!(@one $selection, $compare, at_least, _CMP_GE_OQ);
        lane_comparisons!(@one $selection, $compare, at_most, _CMP_LE_OQ);
        lane_comparisons!(@one $selection, $compare, not_at_most, _CMP_NLE_UQ);
    };
    (@one $selection:ident, $compare:ident, $method:ident, $predicate:ident) => {
        #[inline(always)]
        unsafe fn $method(self, other: Self) -> $selection {
            unsafe { $selection($compare::<$predicate>(self.0, other.0)) }
        }
    };
}
pub(super) use lane_comparisons;

/// [`Wide`]'s operations on two index lanes (`$index`) in an impl, each by its intrinsic.
macro_rules! index_operations {
    ($index:ty: $($method:ident $intrinsic:ident),+ $(,)?) => {$(
        #[inline(always)]
        unsafe fn $method(a: $index, b: $index) -> $index {
            unsafe { $intrinsic(a, b) }
        }
    )+};
}
pub(super) use index_operations;

/// A point of lanes.
#[derive(Clone, Copy)]
pub(super) struct V2<V> {
    pub x: V,
    pub y: V,
}

/// A 2×2 matrix of lanes by columns, as glam's `DMat2`: `(x0, x1)` its first column.
#[derive(Clone, Copy)]
struct M2<V> {
    x0: V,
    x1: V,
    y0: V,
    y1: V,
}

/// Whether lane `l` is in `b`.
#[inline(always)]
fn has(b: Bits, l: usize) -> bool {
    b & (1 << l) != 0
}

#[inline(always)]
unsafe fn blend<W: Wide>(a: V2<W>, b: V2<W>, m: W::B) -> V2<W> {
    unsafe {
        V2 {
            x: a.x.blend(b.x, m),
            y: a.y.blend(b.y, m),
        }
    }
}

#[inline(always)]
fn add<W: Wide>(a: V2<W>, b: V2<W>) -> V2<W> {
    V2 {
        x: a.x + b.x,
        y: a.y + b.y,
    }
}

#[inline(always)]
fn sub<W: Wide>(a: V2<W>, b: V2<W>) -> V2<W> {
    V2 {
        x: a.x - b.x,
        y: a.y - b.y,
    }
}

#[inline(always)]
fn scale<W: Wide>(a: V2<W>, s: W) -> V2<W> {
    V2 {
        x: a.x * s,
        y: a.y * s,
    }
}

/// glam's `dot`: `(a.x b.x) + (a.y b.y)`.
#[inline(always)]
fn dot<W: Wide>(a: V2<W>, b: V2<W>) -> W {
    a.x * b.x + a.y * b.y
}

/// glam's `perp_dot`: `(a.x b.y) - (a.y b.x)`.
#[inline(always)]
fn perp_dot<W: Wide>(a: V2<W>, b: V2<W>) -> W {
    a.x * b.y - a.y * b.x
}

/// glam's `DMat2 * DVec2`: `(x0 v.x) + (y0 v.y)`, `(x1 v.x) + (y1 v.y)`.
#[inline(always)]
fn mul_vec<W: Wide>(m: M2<W>, v: V2<W>) -> V2<W> {
    V2 {
        x: m.x0 * v.x + m.y0 * v.y,
        y: m.x1 * v.x + m.y1 * v.y,
    }
}

/// glam's `m.transpose() * v`.
#[inline(always)]
fn transpose_mul_vec<W: Wide>(m: M2<W>, v: V2<W>) -> V2<W> {
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
fn mul_mat<W: Wide>(a: M2<W>, b: M2<W>) -> M2<W> {
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
fn determinant<W: Wide>(m: M2<W>) -> W {
    m.x0 * m.y1 - m.x1 * m.y0
}

/// glam's `inverse`: through `1 / det`, the off-diagonal times `-(1 / det)`.
#[inline(always)]
unsafe fn inverse<W: Wide>(m: M2<W>) -> M2<W> {
    unsafe {
        let inv_det = W::splat(1.0) / determinant(m);
        let minus = inv_det.neg();
        M2 {
            x0: m.y1 * inv_det,
            x1: m.x1 * minus,
            y0: m.y0 * minus,
            y1: m.x0 * inv_det,
        }
    }
}

/// `ContourTable::next` of indices in [0, N): k + 1, N - 1 to 0.
#[inline(always)]
unsafe fn next_i<W: Wide>(k: W::I, n: i32) -> W::I {
    unsafe {
        let next = W::add_i(k, W::splat_i(1));
        let turn = W::splat_i(n);
        W::sub_i(next, W::where_i(W::equal_i(next, turn), turn))
    }
}

/// `ContourTable::previous` of indices in [0, N): k - 1, 0 to N - 1.
#[inline(always)]
unsafe fn previous_i<W: Wide>(k: W::I, n: i32) -> W::I {
    unsafe {
        let before = W::add_i(k, W::splat_i(-1));
        let below = W::greater_i(W::splat_i(0), before);
        W::add_i(before, W::where_i(below, W::splat_i(n)))
    }
}

/// `ContourTable::wrap` of indices within one turn of [0, N), [-N, 2N).
#[inline(always)]
unsafe fn wrap_i<W: Wide>(k: W::I, n: i32) -> W::I {
    unsafe {
        let turn = W::splat_i(n);
        let below = W::greater_i(W::splat_i(0), k);
        let beyond = W::greater_i(k, W::splat_i(n - 1));
        W::add_i(
            k,
            W::sub_i(W::where_i(below, turn), W::where_i(beyond, turn)),
        )
    }
}

/// Four consecutive nodes of the unit polygon in each lane, `start[l]` to `start[l] + 3`.
///
/// # Safety
/// Every `start[l]` lies in [-N, 2N - 3), so that the four nodes lie within the ring
/// (see [`grain_grain_lanes`] for why the kernel's do).
#[inline(always)]
unsafe fn ring4<W: Wide>(table: &ContourTable, start: W::I) -> [V2<W>; 4] {
    unsafe {
        let ring = table.vertex_ring().as_ptr();
        let nodes = table.nodes as isize;
        let at = W::add_i(start, W::splat_i(nodes as i32));
        W::load_quads(|l| {
            let k = W::index(at, l);
            debug_assert!(0 <= k && k + 3 < 3 * nodes);
            ring.offset(k).cast::<f64>()
        })
    }
}

/// The inside tests of `ContourTable::contains` that need no sector, as bit masks of the
/// lanes: inside the inscribed circle, and outside the circumscribed one (a point in the ring
/// between them, or a NaN, is in neither).
#[inline(always)]
unsafe fn inside_outside<W: Wide>(table: &ContourTable, u: V2<W>) -> (W::B, W::B) {
    unsafe {
        let r2 = dot(u, u);
        (
            r2.less(W::splat(table.apothem_squared)),
            r2.at_least(W::splat(1.0)),
        )
    }
}

/// Where a chain's end moved, by lanes (see [`end_moved`]).
#[derive(Clone, Copy)]
struct Moved<W: Wide> {
    back: W::B,
    stayed: W::B,
    on: W::B,
}

impl<W: Wide> Moved<W> {
    /// The lanes whose end moved by at most a node.
    #[inline(always)]
    fn settled(self) -> W::B {
        self.back | self.stayed | self.on
    }

    /// The offsets of the ends along their outward direction: -1, 0 or 1.
    #[inline(always)]
    unsafe fn offsets(self) -> W::I {
        unsafe { W::sub_i(W::ones_i(self.on), W::ones_i(self.back)) }
    }
}

/// The ends of one chain of last step (`end`, its chain running on from it against
/// `outward`): its nodes `end + c outward`, c = -1..=2, mapped into the other grain's frame
/// (`u = m v + t`), and where the end is now, as the one-pair path's `end_moved` settles it:
/// the lanes whose end moved back by a node, stayed, or moved on by one ([`Moved`]). A lane in
/// none of them moved further, or a node it tests lies in the ring between the inscribed and
/// circumscribed circles (where the inside test needs the node's sector).
#[inline(always)]
unsafe fn end_moved<W: Wide>(
    table: &ContourTable,
    m: M2<W>,
    t: V2<W>,
    end: W::I,
    outward: isize,
) -> ([V2<W>; 4], [V2<W>; 4], Moved<W>) {
    unsafe {
        // The four nodes lie together in memory: from end - 1 up for the hi end (outward
        // 1), from end - 2 up, in the reverse order, for the lo end.
        let raw = if outward == 1 {
            ring4::<W>(table, W::add_i(end, W::splat_i(-1)))
        } else {
            let [a, b, c, d] = ring4::<W>(table, W::add_i(end, W::splat_i(-2)));
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
        // (the node beyond came in, the one after it is out). The three exclude each other: a
        // node is not both in and out.
        let moved = Moved {
            back: at_end_outside & back_inside,
            stayed: at_end_inside & beyond_outside,
            on: at_end_inside & beyond_inside & further_outside,
        };
        (raw, nodes, moved)
    }
}

/// The chain's end node and the node beyond it, from [`end_moved`]'s nodes and where the end
/// moved.
#[inline(always)]
unsafe fn end_and_beyond<W: Wide>(nodes: &[V2<W>; 4], moved: Moved<W>) -> (V2<W>, V2<W>) {
    unsafe {
        (
            blend(blend(nodes[1], nodes[0], moved.back), nodes[2], moved.on),
            blend(blend(nodes[2], nodes[1], moved.back), nodes[3], moved.on),
        )
    }
}

/// b's unit-polygon edges `s[l]`: starts, ends and outward normals.
///
/// # Safety
/// Every `s[l]` lies in [0, N) (the guesses are hints checked to lie there, and `exit_near`
/// steps them round the polygon).
#[inline(always)]
unsafe fn edges<W: Wide>(table: &ContourTable, s: W::I) -> [V2<W>; 3] {
    unsafe {
        let edges = table.edges().as_ptr();
        let edge = |l: usize| {
            let k = W::index(s, l);
            debug_assert!(0 <= k && k < table.edges().len() as isize);
            // An edge is its start, end and normal, six f64s in this order (`repr(C)`).
            edges.offset(k).cast::<f64>()
        };
        let [start, end] = W::load_pairs(edge);
        let normal = W::load_points(|l| edge(l).add(4));
        [start, end, normal]
    }
}

/// Where a's edge from its node inside b (`p_in`, in b's reference coordinates) to the node
/// outside (`p_out`) leaves b's polygon, when it leaves through b's edge `guess` or a
/// neighbour of it: the exit parameter and b's edge, as the one-pair path's
/// `crossing_and_edge` finds them on its first or second try; `false` in `found` where that
/// path would try further, or search.
#[inline(always)]
unsafe fn exit_near<W: Wide>(
    table: &ContourTable,
    p_in: V2<W>,
    p_out: V2<W>,
    guess: W::I,
) -> (W, W::I, W::B, [V2<W>; 2]) {
    unsafe {
        let direction = sub(p_out, p_in);
        let apothem = W::splat(table.apothem);
        let (zero, one) = (W::splat(0.0), W::splat(1.0));
        let mut edge = guess;
        let mut t = zero;
        let mut found = W::no_lanes();
        // The lanes still looking.
        let mut open = W::all_lanes();
        let mut ends = [V2 { x: zero, y: zero }; 2];
        for _try in 0..2 {
            let [start, end, normal] = edges::<W>(table, edge);
            // The ends of each lane's edge (the first try's, or the second's where it tried
            // again): a chain of j runs between two of them.
            ends = [blend(ends[0], start, open), blend(ends[1], end, open)];
            let rate = dot(direction, normal);
            let t_try = (apothem - dot(p_in, normal)) / rate;
            let q = add(p_in, scale(direction, t_try));
            let rising = rate.greater(zero);
            let after_start = perp_dot(start, q).at_least(zero);
            let before_end = perp_dot(end, q).at_most(zero);
            // Within the edge of a (false for a NaN, as the one-pair path's test).
            let within = t_try.greater(zero) & t_try.at_most(one);
            // A lane whose edge of a does not rise through b's edge line stops, unfound.
            let hit = open & rising & after_start & before_end;
            found = found | (hit & within);
            t = t.blend(t_try, hit);
            open = open & rising & !hit;
            if W::none(open) {
                break;
            }
            // The next edge round where the crossing lies after this one's start, else the one
            // before.
            let turn = table.nodes as i32;
            let stepped = W::select_i(
                previous_i::<W>(edge, turn),
                next_i::<W>(edge, turn),
                after_start,
            );
            edge = W::select_i(edge, stepped, open);
        }
        (t, edge, found, ends)
    }
}

/// The crossing on a's edge from its node `v_in` to `v_out` (reference coordinates) at
/// parameter `t`, in global coordinates: `c + A R (v_in + (v_out - v_in) t)`.
#[inline(always)]
fn crossing<W: Wide>(center: V2<W>, map: M2<W>, v_in: V2<W>, v_out: V2<W>, t: W) -> V2<W> {
    add(center, mul_vec(map, add(v_in, scale(sub(v_out, v_in), t))))
}

/// The one-pair path's `cap_area_and_depth` for chains `lo..=hi` of a grain (`center`,
/// `map`): the area of its cap (from, chain, to) and the depth of its deepest node beyond
/// `origin` along `outward`, lane by lane in `depth[..LANES]`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn cap_area_and_depth<W: Wide>(
    table: &ContourTable,
    center: V2<W>,
    map: M2<W>,
    (lo, hi): (W::I, W::I),
    (vertex_lo, vertex_hi): (V2<W>, V2<W>),
    from: V2<W>,
    to: V2<W>,
    origin: V2<W>,
    outward: V2<W>,
    depth: &mut [f64; 8],
) -> W {
    unsafe {
        let first = mul_vec(map, vertex_lo);
        let last = mul_vec(map, vertex_hi);
        let (from, to) = (sub(from, center), sub(to, center));
        let spanned = W::from_indices(W::sub_i(hi, lo));
        let fan = spanned * determinant(map) * W::splat(table.sin_dbeta);
        let twice_area = perp_dot(from, first) + fan + perp_dot(last, to) + perp_dot(to, from);
        // The deepest node is one of the two or three around the chain's middle (see the
        // one-pair path); the last is repeated where there are fewer.
        let one = W::splat_i(1);
        let sum = W::add_i(lo, hi);
        // `>> 1` rounds down, as the one-pair path's on `isize`.
        let middle = W::half_i(sum);
        let start = W::max_i(W::add_i(W::sub_i(middle, one), W::and_i(sum, one)), lo);
        let count = W::add_i(W::sub_i(W::min_i(W::add_i(middle, one), hi), start), one);
        // The lanes with more than one node, and with more than two.
        let more = [
            W::lanes_i(W::greater_i(count, one)),
            W::lanes_i(W::greater_i(count, W::splat_i(2))),
        ];
        let support = transpose_mul_vec(map, outward);
        let around = ring4::<W>(table, start);
        let mut reach = dot(around[0], support);
        for (node, more) in around[1..3].iter().zip(more) {
            let r = dot(*node, support);
            reach = reach.blend(r, r.greater(reach) & more);
        }
        (dot(sub(center, origin), outward) + reach).write_lanes(depth);
        for d in depth.iter_mut().take(W::LANES) {
            *d = d.max(0.0);
        }
        W::splat(0.5) * twice_area
    }
}

/// A grain's centre, map and bounding radius, side i or j of each pair (lane `l` the source's
/// lane `first + l`).
#[inline(always)]
unsafe fn shapes<W: Wide, P: LanePairs>(
    pairs: &P,
    first: usize,
    second: bool,
) -> (V2<W>, M2<W>, W) {
    unsafe {
        let [center, radius] = W::load_pairs(|l| pairs.shape(first + l, second)[0]);
        let [x_axis, y_axis] = W::load_pairs(|l| pairs.shape(first + l, second)[1]);
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
}

/// The kernel of [`super::grain_grain_blocks`] over `W`'s lanes: the source's pairs
/// `first..first + LANES`, their contacts written to `out[..LANES / BLOCK]`, block `b` holding
/// lanes `4b..4b + 4`.
///
/// # Safety
/// `first + W::LANES` is at most [`super::PAIRS`], `out` holds `W::LANES / BLOCK` blocks, and
/// the caller is compiled for `W`'s instructions, which the processor has.
#[inline(always)]
pub(super) unsafe fn grain_grain_lanes<W: Wide, P: LanePairs>(
    table: &ContourTable,
    pairs: &P,
    first: usize,
    shifted: bool,
    out: &mut [BlockContacts],
) {
    debug_assert!(first + W::LANES <= super::PAIRS && out.len() == W::LANES / BLOCK);
    unsafe {
        let n = table.nodes as isize;
        let half = n / 2;
        let turn = n as i32;
        // Last step's chain of i inside j, unwrapped, and the guesses of j's edges the
        // crossings lie on: p_lo on j's edge (hi, hi + 1) of last step's chain of j, p_hi on
        // (lo - 1, lo).
        let [first_lo, first_hi, second_lo, second_hi] = W::hints(|l| pairs.hint(first + l));
        let chain_hi = W::add_i(
            first_hi,
            W::where_i(W::greater_i(first_lo, first_hi), W::splat_i(turn)),
        );
        // All four hints in [0, N), compared unsigned: a negative hint (NONE) wraps above N.
        let largest = W::max_unsigned_i(
            W::max_unsigned_i(first_lo, first_hi),
            W::max_unsigned_i(second_lo, second_hi),
        );
        let hints_in_turn = W::lanes_i(W::equal_i(
            W::min_unsigned_i(largest, W::splat_i(turn - 1)),
            largest,
        ));
        let short = W::lanes_i(W::greater_i(
            W::splat_i(half as i32),
            W::sub_i(chain_hi, first_lo),
        ));

        let (center_i, map_i, reach_i) = shapes::<W, P>(pairs, first, false);
        let (mut center_j, map_j, reach_j) = shapes::<W, P>(pairs, first, true);
        if shifted {
            center_j = add(center_j, W::load_points(|l| pairs.j_shift(first + l)));
        }
        // Lanes on the path so far; a lane that leaves it computes on with safe indices. The
        // ring is read without bounds checks (`ring4`), so every node index formed here lies
        // in [-N, 2N - 3) (N >= 8): a lane starts with hints in [0, N), checked above (a lane
        // without them takes node 0), and a chain shorter than N / 2; the ends' nodes reach
        // from lo - 2 to hi + 2, i's new chain keeps lo in [-1, N] and hi under lo + N / 2, and
        // j's chain runs within [0, 2N) with its middle under 3N / 2.
        let mut on_path = hints_in_turn & short;
        let zero_i = W::splat_i(0);
        let mut lo = W::select_i(zero_i, first_lo, on_path);
        let mut hi = W::select_i(zero_i, chain_hi, on_path);
        let guess_lo = W::select_i(zero_i, second_hi, on_path);
        let guess_hi = W::select_i(zero_i, previous_i::<W>(second_lo, turn), on_path);

        let branch = sub(center_i, center_j);
        let reach = reach_i + reach_j;
        let near = dot(branch, branch).less(reach * reach);
        let inv_j = inverse(map_j);
        let m = mul_mat(inv_j, map_i);
        let t = mul_vec(inv_j, branch);

        // The lo end runs outward to lower indices, the hi end to higher ones. Each end's
        // node and the node beyond it, picked at once so that its four nodes need not outlive
        // the other end's (fewer registers spilled): by the end's own offsets, since a lane
        // that leaves the path below may compute on with any values.
        let (raw_lo, nodes_lo, moved_lo) = end_moved(table, m, t, lo, -1);
        let (lo_in, lo_out) = end_and_beyond(&nodes_lo, moved_lo);
        // The same nodes in i's reference coordinates.
        let (vertex_lo, vertex_lo_out) = end_and_beyond(&raw_lo, moved_lo);
        let (raw_hi, nodes_hi, moved_hi) = end_moved(table, m, t, hi, 1);
        let (hi_in, hi_out) = end_and_beyond(&nodes_hi, moved_hi);
        let (vertex_hi, vertex_hi_out) = end_and_beyond(&raw_hi, moved_hi);
        // The lanes whose ends both moved by at most a node, into a chain still short: they
        // take the new ends; the others keep theirs and leave the path.
        let (new_lo, new_hi) = (
            W::sub_i(lo, moved_lo.offsets()),
            W::add_i(hi, moved_hi.offsets()),
        );
        let moved = moved_lo.settled()
            & moved_hi.settled()
            & near
            & !W::lanes_i(W::greater_i(new_lo, new_hi))
            & W::lanes_i(W::greater_i(
                W::splat_i(half as i32),
                W::sub_i(new_hi, new_lo),
            ));
        lo = W::select_i(lo, new_lo, moved);
        hi = W::select_i(hi, new_hi, moved);
        on_path = on_path & moved;

        let (t_lo, edge_lo, found_lo, ends_lo) = exit_near(table, lo_in, lo_out, guess_lo);
        let (t_hi, edge_hi, found_hi, ends_hi) = exit_near(table, hi_in, hi_out, guess_hi);
        let p_lo = crossing(center_i, map_i, vertex_lo, vertex_lo_out, t_lo);
        let p_hi = crossing(center_i, map_i, vertex_hi, vertex_hi_out, t_hi);
        // j's chain runs from the edge after p_hi's to p_lo's (none when both share an edge).
        on_path = on_path & found_lo & found_hi;
        let j_chain = on_path & !W::lanes_i(W::equal_i(edge_lo, edge_hi));
        let first = next_i::<W>(edge_hi, turn);
        let last = W::add_i(
            edge_lo,
            W::where_i(W::greater_i(first, edge_lo), W::splat_i(turn)),
        );
        let (j_lo, j_hi) = (
            W::select_i(zero_i, first, j_chain),
            W::select_i(zero_i, last, j_chain),
        );

        // The chord (the one-pair path's `Chord::between`).
        let chord = sub(p_hi, p_lo);
        let length = dot(chord, chord).sqrt();
        let normal = V2 {
            x: chord.y / length,
            y: (chord.x / length).neg(),
        };
        let point = scale(add(p_lo, p_hi), W::splat(0.5));

        let mut depth_i = [0.0; 8];
        let cap_area_i = cap_area_and_depth(
            table,
            center_i,
            map_i,
            (lo, hi),
            (vertex_lo, vertex_hi),
            p_lo,
            p_hi,
            point,
            normal,
            &mut depth_i,
        );
        let minus_normal = V2 {
            x: normal.x.neg(),
            y: normal.y.neg(),
        };
        let mut depth_j = [0.0; 8];
        let cap_area_j = cap_area_and_depth(
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
            &mut depth_j,
        );
        // A chord shorter than rounding is no contact (a NaN length stays, as in the one-pair
        // path's test).
        let shortest = W::splat(f64::EPSILON) * reach_i.min(reach_j);
        on_path = on_path & length.not_at_most(shortest);
        let on_path = W::bits(on_path);
        for (b, block) in out.iter_mut().enumerate() {
            block.on_path = (on_path >> (BLOCK * b)) & ((1 << BLOCK) - 1);
        }
        point.x.store(out, |c| &mut c.point[0]);
        point.y.store(out, |c| &mut c.point[1]);
        normal.x.store(out, |c| &mut c.normal[0]);
        normal.y.store(out, |c| &mut c.normal[1]);
        length.store(out, |c| &mut c.length);
        cap_area_i.store(out, |c| &mut c.cap_area_i);
        // Without a chain of j its cap and depth are zero.
        cap_area_j.keep(j_chain).store(out, |c| &mut c.cap_area_j);
        let j_chain_bits = W::bits(j_chain);
        for l in 0..W::LANES {
            let depth_j = if has(j_chain_bits, l) {
                depth_j[l]
            } else {
                0.0
            };
            out.get_unchecked_mut(l / BLOCK).normal_gap[l % BLOCK] = -0.5 * (depth_i[l] + depth_j);
        }
        // The next hints, pair by pair: without a chain of j its hint is none.
        let none = W::splat_i(ChainHint::NONE.lo);
        W::store_hints(
            [
                wrap_i::<W>(lo, turn),
                wrap_i::<W>(hi, turn),
                W::select_i(none, wrap_i::<W>(j_lo, turn), j_chain),
                W::select_i(none, wrap_i::<W>(j_hi, turn), j_chain),
            ],
            out,
        );
    }
}
