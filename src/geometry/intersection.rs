//! Contact geometry of two contour polygons, or of a contour polygon and a wall (SPEC §5).
//!
//! Both contours are convex, so their boundaries cross at two points P and P'. The arc of grain
//! i that lies inside grain j is one run of consecutive nodes ("chain"). Between two steps its
//! ends nearly always stay or move by one node, which four to six exact inside tests settle;
//! otherwise they are found by galloping and bisection from last step's ends (or, cold, from a
//! node near the deepest point of the smooth ellipse): O(log) exact inside tests, whatever the
//! resolution. The two crossing
//! points are cut on j's polygon from i's chain ends, and the j edges they lie on are j's chain
//! ends, so j's chain needs no search of its own. Cap areas and depths are O(1).
//!
//! Sign conventions: the contact normal `n` points from grain i towards grain j (or towards the
//! wall); gaps are negative when the contours interpenetrate.

use super::angle;
use super::contour::{ContourTable, GrainShape};
use glam::{DMat2, DVec2};

/// What two shapes do to each other.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Overlap {
    /// The contours do not cross.
    Separate,
    /// The contours cross at two points.
    Contact(ContactGeometry),
    /// One contour lies entirely inside the other (or a grain lies entirely beyond a wall): no
    /// crossing points exist and the contact law is undefined. A fatal instability (SPEC §9).
    Swallowed,
}

/// Local quantities of one contact (SPEC §5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactGeometry {
    /// `x_c = (P + P')/2`, the point of application of the contact force.
    pub point: DVec2,
    /// Unit normal, perpendicular to PP', from grain i towards grain j (or the wall).
    pub normal: DVec2,
    /// `L_c = |PP'|`.
    pub length: f64,
    /// `S_ij`: area of grain i's polygon on j's side of the line PP'.
    pub cap_area_i: f64,
    /// `S_ji`: area of grain j's polygon on i's side of PP' (0 for a wall).
    pub cap_area_j: f64,
    /// `delta_n <= 0`: mean depth of the two caps (grain–grain) or depth of the cap (grain–wall).
    pub normal_gap: f64,
}

/// Where the chain of one contour inside another was found in the previous step: the node
/// indices (in [0, N)) of its ends, or `NONE`. A hint only decides where the exact search
/// starts: a stale or wrong hint costs a few more tests, never a different result.
/// `repr(C)`, as [`PairHint`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(C)]
pub struct ChainHint {
    pub lo: i32,
    pub hi: i32,
}

impl ChainHint {
    pub const NONE: ChainHint = ChainHint { lo: -1, hi: -1 };
}

impl Default for ChainHint {
    fn default() -> Self {
        Self::NONE
    }
}

/// Hints for both sides of a grain–grain contact. `repr(C)`: four `i32`s in the order
/// first.lo, first.hi, second.lo, second.hi, which the contact lanes load and store as one
/// vector a pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(C)]
pub struct PairHint {
    pub first: ChainHint,
    pub second: ChainHint,
}

/// The nodes of one contour inside another polygon, `lo..=hi` (indices not yet wrapped), with
/// `lo` in [-1, N] and `hi` under `lo + N - 1`, so that `lo - 1..=hi + 1` lies within the ring
/// of [`ContourTable::vertex_near`].
#[derive(Debug, Clone, Copy)]
struct Chain {
    lo: isize,
    hi: isize,
}

impl Chain {
    /// The chain `lo..=hi` (any turn of the contour) with `lo` moved into [0, N): the same
    /// nodes.
    #[inline]
    fn from_ends(table: &ContourTable, lo: isize, hi: isize) -> Self {
        let lo_wrapped = table.wrap(lo) as isize;
        Self {
            lo: lo_wrapped,
            hi: hi + (lo_wrapped - lo),
        }
    }

    /// The hint for next step's search: the chain's ends wrapped into [0, N).
    #[inline(always)]
    fn hint(&self, table: &ContourTable) -> ChainHint {
        ChainHint {
            lo: table.wrap(self.lo) as i32,
            hi: table.wrap(self.hi) as i32,
        }
    }
}

enum ChainSearch {
    Empty,
    Found(Chain, ChainBorders),
    Whole,
}

/// A chain's end nodes and their outside neighbours (lo - 1 and hi + 1), mapped into the other
/// grain's reference coordinates: what the inside tests that settle the chain computed, and
/// what the two crossings are cut from.
#[derive(Debug, Clone, Copy)]
struct ChainBorders {
    lo_in: DVec2,
    lo_out: DVec2,
    hi_in: DVec2,
    hi_out: DVec2,
}

impl ChainBorders {
    #[inline(always)]
    fn of(table: &ContourTable, a_in_b: &RelativeMap, chain: Chain) -> Self {
        Self {
            lo_in: a_in_b.node_near(table, chain.lo),
            lo_out: a_in_b.node_near(table, chain.lo - 1),
            hi_in: a_in_b.node_near(table, chain.hi),
            hi_out: a_in_b.node_near(table, chain.hi + 1),
        }
    }
}

/// The affine map from `a`'s reference coordinates to `b`'s: `u_b = m u_a + t`.
#[derive(Debug, Clone, Copy)]
struct RelativeMap {
    m: DMat2,
    t: DVec2,
}

impl RelativeMap {
    #[inline]
    fn new(a: &GrainShape, b: &GrainShape) -> Self {
        let inv_map = b.inv_map();
        Self {
            m: inv_map * a.map,
            t: inv_map * (a.center - b.center),
        }
    }

    /// `a`'s node k in `b`'s reference coordinates.
    #[inline]
    fn node(&self, table: &ContourTable, k: isize) -> DVec2 {
        self.m * table.vertex_at(k) + self.t
    }

    /// [`node`](Self::node) for k in [-N, 2N) (see [`ContourTable::vertex_near`]).
    #[inline(always)]
    fn node_near(&self, table: &ContourTable, k: isize) -> DVec2 {
        self.m * table.vertex_near(k) + self.t
    }
}

/// A test on the nodes of a contour (inside another polygon, or beyond a wall) that the chain
/// searches probe. A trait rather than a closure so that the polygon test is inlined into
/// every probe (as a closure LLVM called it out of line, once per probe).
trait NodeTest {
    fn holds(&self, k: isize) -> bool;
}

impl<F: Fn(isize) -> bool> NodeTest for F {
    #[inline(always)]
    fn holds(&self, k: isize) -> bool {
        self(k)
    }
}

/// Node k of `a` lies strictly inside `b`'s polygon.
struct InsidePolygon<'a> {
    table: &'a ContourTable,
    a_in_b: &'a RelativeMap,
}

impl NodeTest for InsidePolygon<'_> {
    #[inline(always)]
    fn holds(&self, k: isize) -> bool {
        self.table.contains(self.a_in_b.node(self.table, k))
    }
}

/// Chain of `a`'s nodes strictly inside `b`'s polygon (`a_in_b` maps a's reference
/// coordinates into b's).
///
/// The nodes of a convex contour inside another convex polygon form one run. Its ends are found
/// by galloping from a seed node (offsets 1, 2, 4, ...) and bisecting: O(log) exact inside tests
/// instead of one per node. Galloping is exact while the run covers at most half the contour (a
/// probe within N/2 of the seed then always lands in the run or in the outside gap); longer runs
/// (grains nearly swallowed) are walked node by node.
#[inline(always)]
fn chain_inside(
    table: &ContourTable,
    a: &GrainShape,
    b: &GrainShape,
    a_in_b: &RelativeMap,
    hint: &mut ChainHint,
) -> ChainSearch {
    let n = table.nodes as isize;
    if let Some((chain, borders)) = last_chain_moved(table, a_in_b, hint, n) {
        *hint = chain.hint(table);
        return ChainSearch::Found(chain, borders);
    }
    chain_searched(table, a, b, a_in_b, hint)
}

/// [`chain_inside`] when last step's chain does not settle it: from the hint's ends or middle,
/// or cold from the deepest point. Out of line, so that the step-to-step path keeps its
/// registers.
#[inline(never)]
#[cold]
fn chain_searched(
    table: &ContourTable,
    a: &GrainShape,
    b: &GrainShape,
    a_in_b: &RelativeMap,
    hint: &mut ChainHint,
) -> ChainSearch {
    let inside = InsidePolygon { table, a_in_b };
    let n = table.nodes as isize;
    let half = n / 2;
    let ends = match hinted_ends(&inside, hint, n) {
        Some(ends) => ends,
        None => {
            let Some(seed) = deepest_inside_node(table, a, b, a_in_b, &inside) else {
                *hint = ChainHint::NONE;
                return ChainSearch::Empty;
            };
            match (
                find_end(&inside, seed, 1, half, None),
                find_end(&inside, seed, -1, half, None),
            ) {
                (Some(forward), Some(backward)) if forward + backward < half => {
                    Some((seed - backward, seed + forward))
                }
                _ => walk(&inside, seed, n),
            }
        }
    };
    let Some((lo, hi)) = ends else {
        *hint = ChainHint::NONE;
        return ChainSearch::Whole;
    };
    let chain = Chain::from_ends(table, lo, hi);
    *hint = chain.hint(table);
    ChainSearch::Found(chain, ChainBorders::of(table, a_in_b, chain))
}

/// Last step's chain, when each of its ends has moved by at most one node: its ends inside,
/// their outer neighbours outside, and shorter than half the contour. The inside nodes form one
/// run, and a run through both ends that leaves out the node before `lo` is `lo..=hi`: so these
/// are exactly the ends [`hinted_ends`] would find, found with four to six inside tests. They
/// settle nearly every contact between two steps, and the nodes they map are the crossings'
/// segments.
#[inline(always)]
fn last_chain_moved(
    table: &ContourTable,
    a_in_b: &RelativeMap,
    hint: &ChainHint,
    n: isize,
) -> Option<(Chain, ChainBorders)> {
    if hint.lo < 0 {
        return None;
    }
    let lo = hint.lo as isize;
    let mut hi = hint.hi as isize;
    if hi < lo {
        hi += n;
    }
    if hi - lo >= n / 2 {
        return None;
    }
    let node = |k: isize| a_in_b.node_near(table, k);
    let (lo, lo_in, lo_out) = end_moved(table, &node, lo, -1)?;
    let (hi, hi_in, hi_out) = end_moved(table, &node, hi, 1)?;
    if hi < lo || hi - lo >= n / 2 {
        return None;
    }
    Some((
        Chain { lo, hi },
        ChainBorders {
            lo_in,
            lo_out,
            hi_in,
            hi_out,
        },
    ))
}

/// Where one end of a chain lies now, when it has moved by at most one node from `end` (the
/// chain runs on from it in the direction `-outward`): the end, its node and the node beyond
/// it (outside), mapped; None when it moved further.
#[inline(always)]
fn end_moved(
    table: &ContourTable,
    node: &impl Fn(isize) -> DVec2,
    end: isize,
    outward: isize,
) -> Option<(isize, DVec2, DVec2)> {
    let (at_end, beyond) = (node(end), node(end + outward));
    if !table.contains(at_end) {
        let back = node(end - outward);
        return table
            .contains(back)
            .then_some((end - outward, back, at_end));
    }
    if !table.contains(beyond) {
        return Some((end, at_end, beyond));
    }
    let further = node(end + 2 * outward);
    (!table.contains(further)).then_some((end + outward, beyond, further))
}

/// Where `a`'s edge from node `k_in` (inside b) to `k_out` (outside b) leaves `b`'s polygon
/// (global coordinates), and the edge of b it leaves through; `p_in` and `p_out` are the two
/// nodes in b's reference coordinates.
///
/// The exit edge is looked for from a guess (last step's, or the inside node's sector): the
/// segment is cut with the guessed edge's line and the cut accepted only if it lies within that
/// edge's sector, which makes it the exit point exactly (the segment crosses the convex
/// boundary once). A cut outside the sector moves the guess one edge towards it; after a few
/// misses the exit is searched edge by edge from the inside node's sector.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn crossing_and_edge(
    table: &ContourTable,
    a: &GrainShape,
    k_in: isize,
    p_in: DVec2,
    k_out: isize,
    p_out: DVec2,
    guess: Option<usize>,
) -> (DVec2, usize) {
    let direction = p_out - p_in;
    let mut s = guess.unwrap_or_else(|| table.sector(p_in));
    let mut found = None;
    for _ in 0..4 {
        let edge = table.edge(s);
        let rate = direction.dot(edge.normal);
        if rate <= 0.0 {
            break;
        }
        let t = (table.apothem - p_in.dot(edge.normal)) / rate;
        let q = p_in + direction * t;
        let after_start = edge.start.perp_dot(q) >= 0.0;
        let before_end = edge.end.perp_dot(q) <= 0.0;
        if after_start && before_end {
            if t > 0.0 && t <= 1.0 {
                found = Some((t, s));
            }
            break;
        }
        s = if after_start {
            table.next(s)
        } else {
            table.previous(s)
        };
    }
    // The exit parameter along an edge is the same in both frames (affine maps keep ratios).
    let (t, edge) = found.unwrap_or_else(|| exit_searched(table, p_in, p_out));
    let (v_in, v_out) = (table.vertex_near(k_in), table.vertex_near(k_out));
    (a.center + a.map * (v_in + (v_out - v_in) * t), edge)
}

/// The exit of the segment from `p_in` (inside the unit polygon) to `p_out` (outside) searched
/// edge by edge, and the edge it leaves through: where the guesses of [`crossing_and_edge`]
/// missed. Out of line, like [`chain_searched`].
#[inline(never)]
#[cold]
fn exit_searched(table: &ContourTable, p_in: DVec2, p_out: DVec2) -> (f64, usize) {
    let sector_in = table.sector(p_in);
    let t = table.exit_parameter(
        p_in,
        sector_in,
        p_out,
        table.refine_sector(p_out, sector_in),
    );
    (t, table.sector(p_in + (p_out - p_in) * t))
}

/// A node of `a` inside `b` near the deepest point of `a`'s smooth contour into `b`: where
/// |p(beta)| is smallest in b's reference frame (up to the polygon's sagitta). Starts from the
/// direction of b seen from a, then two Newton steps on |p(beta)|^2.
fn deepest_inside_node(
    table: &ContourTable,
    a: &GrainShape,
    b: &GrainShape,
    a_in_b: &RelativeMap,
    inside: &impl NodeTest,
) -> Option<isize> {
    let RelativeMap { m, t } = *a_in_b;
    let toward_b = a.inv_map() * (b.center - a.center);
    let mut beta = angle::atan2(toward_b.y, toward_b.x);
    for _ in 0..2 {
        let (s, c) = angle::sin_cos(beta);
        let u = DVec2::new(c, s);
        let mu = m * u;
        let mdu = m * DVec2::new(-s, c);
        let g = mu + t;
        let slope = g.dot(mdu);
        let curvature = mdu.length_squared() - g.dot(mu);
        if curvature > 0.0 {
            beta -= slope / curvature;
        }
    }
    let k0 = table.nearest_node(beta);
    [0, -1, 1, -2, 2]
        .into_iter()
        .map(|dk| k0 + dk)
        .find(|&k| inside.holds(k))
}

/// The chain's ends searched from last step's: exact when the hint's ends, or its middle node,
/// are still inside (the run through them is the chain), None otherwise.
#[inline(always)]
fn hinted_ends(
    inside: &impl NodeTest,
    hint: &ChainHint,
    n: isize,
) -> Option<Option<(isize, isize)>> {
    if hint.lo < 0 {
        return None;
    }
    let lo = hint.lo as isize;
    let mut hi = hint.hi as isize;
    if hi < lo {
        hi += n;
    }
    let half = n / 2;
    if hi - lo >= half {
        return None;
    }
    if inside.holds(lo) && inside.holds(hi) {
        // Both of last step's ends are still inside, so the chain runs through lo..=hi (or it
        // covers more than half the contour, which the walk settles): extend it outwards.
        let room = half - (hi - lo);
        let forward = find_end(inside, hi, 1, room, None);
        let backward = find_end(inside, lo, -1, room, None);
        return Some(match (forward, backward) {
            (Some(f), Some(b)) if hi + f - (lo - b) < half => Some((lo - b, hi + f)),
            _ => walk(inside, lo, n),
        });
    }
    let seed = (lo + hi) / 2;
    if !inside.holds(seed) {
        return None;
    }
    let forward = find_end(inside, seed, 1, half, Some(hi - seed));
    let backward = find_end(inside, seed, -1, half, Some(seed - lo));
    Some(match (forward, backward) {
        (Some(f), Some(b)) if f + b < half => Some((seed - b, seed + f)),
        _ => walk(inside, seed, n),
    })
}

/// Largest d in [0, limit) such that the nodes `seed + dir*k` are inside for k = 0..=d, given
/// that the seed is inside; None when the search reaches `limit` still inside. With a guess of
/// d, gallops outwards from it (if inside) or inwards (if not), then bisects; without one,
/// gallops from the seed.
#[inline(always)]
fn find_end(
    inside: &impl NodeTest,
    seed: isize,
    dir: isize,
    limit: isize,
    guess: Option<isize>,
) -> Option<isize> {
    let (mut last_in, mut first_out);
    match guess {
        Some(g) if g > 0 && g < limit && !inside.holds(seed + dir * g) => {
            // The end lies before the guess: gallop back towards the seed.
            first_out = g;
            let mut step = 1;
            loop {
                let probe = (first_out - step).max(0);
                if probe == 0 || inside.holds(seed + dir * probe) {
                    last_in = probe;
                    break;
                }
                first_out = probe;
                step *= 2;
            }
        }
        _ => {
            last_in = match guess {
                Some(g) if g > 0 && g < limit => g,
                _ => 0,
            };
            let mut step = 1;
            loop {
                let probe = (last_in + step).min(limit);
                if inside.holds(seed + dir * probe) {
                    if probe == limit {
                        return None;
                    }
                    last_in = probe;
                    step *= 2;
                } else {
                    first_out = probe;
                    break;
                }
            }
        }
    }
    while first_out - last_in > 1 {
        let mid = (last_in + first_out) / 2;
        if inside.holds(seed + dir * mid) {
            last_in = mid;
        } else {
            first_out = mid;
        }
    }
    Some(last_in)
}

/// Node-by-node walk from the seed; None when every node is inside.
fn walk(inside: &impl NodeTest, seed: isize, nodes: isize) -> Option<(isize, isize)> {
    let mut hi = seed;
    while inside.holds(hi + 1) {
        hi += 1;
        if hi - seed >= nodes {
            return None;
        }
    }
    let mut lo = seed;
    while inside.holds(lo - 1) {
        lo -= 1;
    }
    if hi - lo + 1 >= nodes {
        None
    } else {
        Some((lo, hi))
    }
}

/// Area of the cap polygon (from, chain nodes lo..=hi, to) and the largest distance of a chain
/// node beyond the chord, along `outward`, measured from `origin` (a point of the chord).
///
/// Both in O(1): consecutive nodes of the affine image of the regular N-gon span triangles of
/// the same area `det(A R) sin(dbeta) / 2` about the centre, so the shoelace sum over the chain
/// is that times (hi - lo). The deepest node maximises `v_k . (A R)^T n`, i.e. it is the node
/// nearest the direction of `(A R)^T n`; in reference coordinates that direction is
/// perpendicular to the chord, whose ends lie on the edges (lo-1, lo) and (hi, hi+1), so it
/// points within half a node (plus the sagitta's tilt of the chord, under 1/8 node once the
/// chain has two nodes) of the middle angle `(lo + hi) / 2`: the deepest node is one of the two
/// or three nodes around the middle of the chain.
#[inline(always)]
fn cap_area_and_depth(
    table: &ContourTable,
    shape: &GrainShape,
    chain: (isize, isize),
    from: DVec2,
    to: DVec2,
    origin: DVec2,
    outward: DVec2,
) -> (f64, f64) {
    let (lo, hi) = chain;
    let first = shape.map * table.vertex_near(lo);
    let last = shape.map * table.vertex_near(hi);
    let (from, to) = (from - shape.center, to - shape.center);
    let fan = (hi - lo) as f64 * shape.map.determinant() * table.sin_dbeta;
    let twice_area = from.perp_dot(first) + fan + last.perp_dot(to) + to.perp_dot(from);

    let support = shape.map.transpose() * outward;
    let sum = lo + hi;
    let middle = sum >> 1; // floor((lo + hi) / 2), also for negative indices
    let start = (middle - 1 + (sum & 1)).max(lo);
    let end = (middle + 1).min(hi);
    let mut reach = table.vertex_near(start).dot(support);
    let mut k = start + 1;
    while k <= end {
        let r = table.vertex_near(k).dot(support);
        if r > reach {
            reach = r;
        }
        k += 1;
    }
    let depth = (shape.center - origin).dot(outward) + reach;
    (0.5 * twice_area, depth.max(0.0))
}

/// The chord PP' of a grain–grain contact.
pub(super) struct Chord {
    pub length: f64,
    /// Right-hand normal of i's chord, from `p_lo` to `p_hi` (the order of i's contour): i's
    /// cap lies on this side, towards j.
    pub normal: DVec2,
    /// `x_c`, the chord's middle.
    pub point: DVec2,
}

impl Chord {
    /// The chord between the crossing points of grains i and j; None when it is shorter than
    /// rounding (the contours only touch).
    #[inline]
    pub fn between(p_lo: DVec2, p_hi: DVec2, i: &GrainShape, j: &GrainShape) -> Option<Self> {
        let chord = p_hi - p_lo;
        let length = chord.length();
        if length <= f64::EPSILON * i.bounding_radius.min(j.bounding_radius) {
            return None;
        }
        let tangent = chord / length;
        Some(Self {
            length,
            normal: DVec2::new(tangent.y, -tangent.x),
            point: 0.5 * (p_lo + p_hi),
        })
    }
}

/// Whether the smooth ellipses of i and j lie apart along the line of their centres: then so do
/// their inscribed polygons, and both cold chain searches would find no node inside the other
/// contour. The test for a pair that was not in contact last step (its hints are empty): pairs
/// whose bounding circles overlap but whose contours do not touch would otherwise take the
/// two cold searches every step.
///
/// The extent of an ellipse `x = c + M u`, `|u| = 1`, along the branch vector `d` is
/// `|M^T d| / |d|`, so the ellipses lie apart when `|M_i^T d| + |M_j^T d| < |d|^2`. With
/// `a = |M_i^T d|^2`, `b = |M_j^T d|^2` and `s = |d|^4 - a - b`, that is `s > 0` and
/// `4 a b < s^2`: no square root and no division.
#[inline]
fn ellipses_apart(i: &GrainShape, j: &GrainShape) -> bool {
    let branch = j.center - i.center;
    let a = (i.map.transpose() * branch).length_squared();
    let b = (j.map.transpose() * branch).length_squared();
    let distance_squared = branch.length_squared();
    let slack = distance_squared * distance_squared - a - b;
    slack > 0.0 && 4.0 * a * b < slack * slack
}

/// Contact between the contour polygons of grains i and j.
pub fn grain_grain(table: &ContourTable, i: &GrainShape, j: &GrainShape) -> Overlap {
    grain_grain_hinted(table, i, j, &mut PairHint::default())
}

/// [`grain_grain`] starting from last step's chains (`hint`, updated in place).
pub fn grain_grain_hinted(
    table: &ContourTable,
    i: &GrainShape,
    j: &GrainShape,
    hint: &mut PairHint,
) -> Overlap {
    let reach = i.bounding_radius + j.bounding_radius;
    if i.center.distance_squared(j.center) >= reach * reach
        || (hint.first.lo < 0 && hint.second.lo < 0 && ellipses_apart(i, j))
    {
        *hint = PairHint::default();
        return Overlap::Separate;
    }
    let i_in_j = RelativeMap::new(i, j);
    let chain_i = match chain_inside(table, i, j, &i_in_j, &mut hint.first) {
        ChainSearch::Whole => return Overlap::Swallowed,
        ChainSearch::Empty => None,
        ChainSearch::Found(c, borders) => Some((c, borders)),
    };
    // Crossing points in the order of grain i's contour (counter-clockwise): i's chain runs from
    // `p_lo` to `p_hi`; j's chain runs the other way, so p_lo lies on j's edge (hi, hi+1) and
    // p_hi on j's edge (lo-1, lo). When i has nodes inside j, the two crossings are found on
    // j's polygon from i's side, and the j edges they lie on give j's chain without a search.
    let (p_lo, p_hi, chain_j) = match chain_i {
        Some((ci, borders)) => {
            let last = (hint.second.lo >= 0).then_some(hint.second);
            let (p_lo, edge_lo) = crossing_and_edge(
                table,
                i,
                ci.lo,
                borders.lo_in,
                ci.lo - 1,
                borders.lo_out,
                last.map(|h| h.hi as usize),
            );
            let (p_hi, edge_hi) = crossing_and_edge(
                table,
                i,
                ci.hi,
                borders.hi_in,
                ci.hi + 1,
                borders.hi_out,
                last.map(|h| table.previous(h.lo as usize)),
            );
            let chain_j = if edge_lo == edge_hi {
                // Both crossings on one edge of j: none of j's nodes is inside i (all of them
                // would put j inside i, leaving no node of i inside j).
                None
            } else {
                let lo = table.next(edge_hi) as isize;
                let hi = edge_lo as isize;
                Some(Chain {
                    lo,
                    hi: if hi < lo {
                        hi + table.nodes as isize
                    } else {
                        hi
                    },
                })
            };
            hint.second = chain_j.map_or(ChainHint::NONE, |c| c.hint(table));
            (p_lo, p_hi, chain_j)
        }
        None => {
            let j_in_i = RelativeMap::new(j, i);
            let (cj, borders) = match chain_inside(table, j, i, &j_in_i, &mut hint.second) {
                ChainSearch::Whole => return Overlap::Swallowed,
                ChainSearch::Empty => return Overlap::Separate,
                ChainSearch::Found(c, borders) => (c, borders),
            };
            let (hi, lo) = (cj.hi, cj.lo);
            (
                crossing_and_edge(table, j, hi, borders.hi_in, hi + 1, borders.hi_out, None).0,
                crossing_and_edge(table, j, lo, borders.lo_in, lo - 1, borders.lo_out, None).0,
                Some(cj),
            )
        }
    };
    let Some(Chord {
        length,
        normal,
        point,
    }) = Chord::between(p_lo, p_hi, i, j)
    else {
        return Overlap::Separate;
    };
    let (cap_area_i, depth_i) = match chain_i {
        Some((c, _)) => cap_area_and_depth(table, i, (c.lo, c.hi), p_lo, p_hi, point, normal),
        None => (0.0, 0.0),
    };
    let (cap_area_j, depth_j) = match chain_j {
        Some(c) => cap_area_and_depth(table, j, (c.lo, c.hi), p_hi, p_lo, point, -normal),
        None => (0.0, 0.0),
    };
    Overlap::Contact(ContactGeometry {
        point,
        normal,
        length,
        cap_area_i,
        cap_area_j,
        normal_gap: -0.5 * (depth_i + depth_j),
    })
}

/// Contact between a grain and an infinite straight wall through `wall_point` whose unit normal
/// `wall_normal` points into the domain (the side where grains belong).
pub fn grain_wall(
    table: &ContourTable,
    grain: &GrainShape,
    wall_point: DVec2,
    wall_normal: DVec2,
) -> Overlap {
    let height = |x: DVec2| (x - wall_point).dot(wall_normal);
    let center_height = height(grain.center);
    if center_height >= grain.bounding_radius {
        return Overlap::Separate;
    }
    let node_height =
        |k: isize| center_height + grain.node_offset(table, table.wrap(k)).dot(wall_normal);
    // The deepest point of the smooth contour: reference direction -(A R)^T n.
    let deepest = -(grain.map.transpose() * wall_normal);
    let k0 = table.nearest_node(angle::atan2(deepest.y, deepest.x));
    let Some(k_seed) = [0, -1, 1]
        .into_iter()
        .map(|dk| k0 + dk)
        .find(|&k| node_height(k) < 0.0)
    else {
        return Overlap::Separate;
    };
    let n = table.nodes as isize;
    let beyond = |k: isize| node_height(k) < 0.0;
    let (lo, hi) = match (
        find_end(&beyond, k_seed, 1, n / 2, None),
        find_end(&beyond, k_seed, -1, n / 2, None),
    ) {
        (Some(forward), Some(backward)) if forward + backward < n / 2 => {
            (k_seed - backward, k_seed + forward)
        }
        _ => match walk(&beyond, k_seed, n) {
            Some(ends) => ends,
            None => return Overlap::Swallowed,
        },
    };
    let Chain { lo, hi } = Chain::from_ends(table, lo, hi);
    let crossing = |k_in: isize, k_out: isize| {
        let (h_in, h_out) = (node_height(k_in), node_height(k_out));
        let x_in = grain.node(table, table.wrap(k_in));
        let x_out = grain.node(table, table.wrap(k_out));
        x_in + (x_out - x_in) * (h_in / (h_in - h_out))
    };
    let p_lo = crossing(lo, lo - 1);
    let p_hi = crossing(hi, hi + 1);
    let length = p_lo.distance(p_hi);
    if length <= f64::EPSILON * grain.bounding_radius {
        return Overlap::Separate;
    }
    let point = 0.5 * (p_lo + p_hi);
    // The chord lies on the wall, so the contact normal is exactly the wall's, reversed.
    let normal = -wall_normal;
    let (cap_area, depth) = cap_area_and_depth(table, grain, (lo, hi), p_lo, p_hi, point, normal);
    Overlap::Contact(ContactGeometry {
        point,
        normal,
        length,
        cap_area_i: cap_area,
        cap_area_j: 0.0,
        normal_gap: -depth,
    })
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The contact geometry of an overlap that must be a contact (for the geometry tests).
    pub(in crate::geometry) fn contact(o: Overlap) -> ContactGeometry {
        match o {
            Overlap::Contact(c) => c,
            other => panic!("expected a contact, got {other:?}"),
        }
    }

    /// Circular segment of a circle of radius r cut at distance r - h from its centre.
    pub(in crate::geometry) fn segment_area(r: f64, h: f64) -> f64 {
        let d = r - h;
        r * r * (d / r).acos() - d * (r * r - d * d).sqrt()
    }

    #[test]
    fn equal_discs_match_the_analytic_chord_and_segments() {
        // Expectation: two circles of radius r at distance d cross on a chord of half-length
        // sqrt(r^2 - (d/2)^2); each loses a circular segment of height r - d/2.
        let r: f64 = 1.0;
        let d = 1.8;
        let half_chord = (r * r - 0.25 * d * d).sqrt();
        let seg = segment_area(r, r - 0.5 * d);
        let mut previous_error = f64::INFINITY;
        for deg in [4.0, 2.0, 1.0, 0.5, 0.25] {
            let table = ContourTable::new(deg);
            let i = GrainShape::disc(DVec2::new(0.3, -0.2), r);
            let j = GrainShape::disc(DVec2::new(0.3 + d, -0.2), r);
            let c = contact(grain_grain(&table, &i, &j));
            let length_error = (c.length - 2.0 * half_chord).abs() / (2.0 * half_chord);
            let area_error = (c.cap_area_i - seg).abs() / seg;
            assert!((c.cap_area_i - c.cap_area_j).abs() < 1e-12 * seg);
            assert!((c.normal - DVec2::X).length() < 1e-12);
            assert!(c.normal_gap < 0.0);
            let error = length_error.max(area_error);
            assert!(
                error < 0.5 * previous_error + 1e-12,
                "{deg}: {error} vs {previous_error}"
            );
            previous_error = error;
        }
        assert!(previous_error < 1e-4);
    }

    #[test]
    fn unequal_discs_converge_under_refinement() {
        // Expectation: chord where the circles |x| = r1 and |x - d| = r2 cross, at
        // x = (d^2 + r1^2 - r2^2) / (2d); the caps are segments of each circle cut by that line.
        let (r1, r2, d): (f64, f64, f64) = (1.0, 0.3, 1.2);
        let x = (d * d + r1 * r1 - r2 * r2) / (2.0 * d);
        let half = (r1 * r1 - x * x).sqrt();
        let seg1 = segment_area(r1, r1 - x);
        let seg2 = segment_area(r2, r2 - (d - x));
        let table = ContourTable::new(0.25);
        let dir = DVec2::from_angle(0.7);
        let i = GrainShape::disc(DVec2::ZERO, r1);
        let j = GrainShape::disc(dir * d, r2);
        let c = contact(grain_grain(&table, &i, &j));
        assert!((c.length - 2.0 * half).abs() / (2.0 * half) < 1e-4);
        assert!((c.cap_area_i - seg1).abs() / seg1 < 1e-3);
        assert!((c.cap_area_j - seg2).abs() / seg2 < 1e-3);
        assert!((c.normal - dir).length() < 1e-6);
    }

    #[test]
    fn disc_against_a_wall_gives_the_chord_and_segment() {
        // Expectation: a disc of radius r at height r - h over a wall loses a segment of height h
        // on a chord of length 2 sqrt(r^2 - (r-h)^2).
        let r: f64 = 0.5;
        let h = 0.05;
        let exact_length = 2.0 * (r * r - (r - h) * (r - h)).sqrt();
        let exact_area = segment_area(r, h);
        let mut previous = f64::INFINITY;
        for deg in [2.0, 1.0, 0.5, 0.25] {
            let table = ContourTable::new(deg);
            let grain = GrainShape::disc(DVec2::new(0.1, r - h), r);
            let c = contact(grain_wall(&table, &grain, DVec2::ZERO, DVec2::Y));
            let error = ((c.length - exact_length).abs() / exact_length)
                .max((c.cap_area_i - exact_area).abs() / exact_area);
            assert!(error < 0.5 * previous + 1e-12);
            previous = error;
            assert!(c.normal_gap <= 0.0 && c.normal_gap > -h);
            assert_eq!(c.normal, -DVec2::Y);
            assert!(c.point.y.abs() < 1e-12);
        }
        assert!(previous < 1e-3);
    }

    #[test]
    fn wall_caps_match_the_polygon_clipped_by_the_wall_at_any_depth_and_angle() {
        // Expectation: the cap is the part of the contour polygon beyond the wall line (its
        // area by clipping the polygon node by node, its depth the deepest node's), whatever
        // the grain's orientation and strain and however deep it lies, up to more than half
        // of it beyond the wall (the walked chains, whose ends lie far from the seed).
        let table = ContourTable::new(1.0);
        let mut next = unit_randoms(3);
        let mut contacts = 0;
        for _ in 0..3000 {
            let (theta, alpha) = (40.0 * next() - 20.0, 40.0 * next() - 20.0);
            let (eps1, eps2) = (0.6 * next() - 0.3, 0.6 * next() - 0.3);
            let grain = GrainShape::new(DVec2::new(0.3, -0.2), 1.0, theta, eps1, eps2, alpha);
            let normal = DVec2::from_angle(40.0 * next() - 20.0);
            let wall_point = grain.center - normal * (grain.bounding_radius * (1.9 * next() - 0.9));
            let height = |x: DVec2| (x - wall_point).dot(normal);
            let nodes: Vec<DVec2> = (0..table.nodes).map(|k| grain.node(&table, k)).collect();
            // Sutherland–Hodgman against the half-plane height < 0.
            let mut clipped = Vec::new();
            for k in 0..nodes.len() {
                let (a, b) = (nodes[k], nodes[(k + 1) % nodes.len()]);
                let (ha, hb) = (height(a), height(b));
                if ha < 0.0 {
                    clipped.push(a);
                }
                if (ha < 0.0) != (hb < 0.0) {
                    clipped.push(a + (b - a) * (ha / (ha - hb)));
                }
            }
            let area: f64 = (0..clipped.len())
                .map(|k| clipped[k].perp_dot(clipped[(k + 1) % clipped.len()]))
                .sum::<f64>()
                * 0.5;
            let depth = nodes.iter().map(|&x| -height(x)).fold(0.0, f64::max);
            match grain_wall(&table, &grain, wall_point, normal) {
                Overlap::Contact(c) => {
                    assert!(
                        (c.cap_area_i - area).abs() < 1e-10,
                        "{} vs {area}",
                        c.cap_area_i
                    );
                    assert!((c.normal_gap + depth).abs() < 1e-10);
                    contacts += 1;
                }
                Overlap::Separate => assert!(depth < 1e-3, "missed a cap {depth} deep"),
                Overlap::Swallowed => assert!(nodes.iter().all(|&x| height(x) < 0.0)),
            }
        }
        assert!(contacts > 2000, "{contacts}");
    }

    #[test]
    fn contact_is_symmetric_under_swapping_the_grains() {
        let table = ContourTable::new(1.0);
        let i = GrainShape::new(DVec2::new(0.0, 0.0), 1.0, 0.3, 0.1, -0.05, 0.4);
        let j = GrainShape::new(DVec2::new(1.7, 0.6), 0.8, -1.0, -0.1, 0.05, 1.1);
        let a = contact(grain_grain(&table, &i, &j));
        let b = contact(grain_grain(&table, &j, &i));
        assert!((a.length - b.length).abs() < 1e-12);
        assert!((a.normal + b.normal).length() < 1e-12);
        assert!((a.point - b.point).length() < 1e-12);
        assert!((a.cap_area_i - b.cap_area_j).abs() < 1e-12);
        assert!((a.normal_gap - b.normal_gap).abs() < 1e-12);
    }

    #[test]
    fn separated_touching_and_swallowed_cases() {
        let table = ContourTable::new(1.0);
        let i = GrainShape::disc(DVec2::ZERO, 1.0);
        assert_eq!(
            grain_grain(&table, &i, &GrainShape::disc(DVec2::new(2.5, 0.0), 1.0)),
            Overlap::Separate
        );
        // Within the bounding circles but outside the polygons (gap of 1e-3 R).
        assert_eq!(
            grain_grain(&table, &i, &GrainShape::disc(DVec2::new(2.001, 0.0), 1.0)),
            Overlap::Separate
        );
        assert_eq!(
            grain_grain(&table, &i, &GrainShape::disc(DVec2::new(0.1, 0.0), 0.2)),
            Overlap::Swallowed
        );
        // A tiny overlap far below the sagitta of i's edges: a node of j pokes through the middle
        // of one edge of i while no node of i lies inside j.
        let mid_edge = DVec2::from_angle(0.5 * table.dbeta);
        let tiny = GrainShape::disc(mid_edge * (table.apothem + 0.1 - 1e-5), 0.1);
        let c = contact(grain_grain(&table, &i, &tiny));
        assert!(c.length > 0.0 && c.length < 0.01);
        assert!(c.normal_gap < 0.0);
    }

    #[test]
    fn deep_overlap_area_of_a_large_and_small_disc() {
        // Sample B's radius ratio (~10) with a deep overlap, against the analytic lens.
        let (r1, r2, d) = (0.038, 0.004, 0.037);
        let table = ContourTable::new(1.0);
        let i = GrainShape::disc(DVec2::ZERO, r1);
        let j = GrainShape::disc(DVec2::new(0.0, d), r2);
        let c = contact(grain_grain(&table, &i, &j));
        let x = (d * d + r1 * r1 - r2 * r2) / (2.0 * d);
        let half = (r1 * r1 - x * x).sqrt();
        assert!((c.length - 2.0 * half).abs() / (2.0 * half) < 2e-3);
        let seg2 = segment_area(r2, r2 - (d - x));
        assert!(
            (c.cap_area_j - seg2).abs() / seg2 < 2e-3,
            "{} {}",
            c.cap_area_j,
            seg2
        );
        assert!(c.cap_area_j < PI * r2 * r2);
    }

    /// Uniform numbers in [0, 1) from a seeded stream (the random cases of these tests).
    pub(in crate::geometry) fn unit_randoms(seed: u64) -> impl FnMut() -> f64 {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(seed);
        move || crate::sample::unit_random(&mut rng)
    }

    /// For each node of `a`, whether it lies strictly inside `b`'s polygon: node by node, the
    /// exact gauge of its sector.
    fn nodes_inside(table: &ContourTable, a: &GrainShape, b: &GrainShape) -> Vec<bool> {
        (0..table.nodes)
            .map(|k| {
                let u = b.inv_map() * (a.node(table, k) - b.center);
                table.gauge(u, table.sector(u)) < 1.0
            })
            .collect()
    }

    /// Brute force over every node of both contours: the crossing points from the edges whose
    /// ends lie on both sides, the cap polygons node by node.
    fn brute_force(
        table: &ContourTable,
        i: &GrainShape,
        j: &GrainShape,
    ) -> Option<(f64, f64, f64, f64)> {
        let (in_i, in_j) = (nodes_inside(table, i, j), nodes_inside(table, j, i));
        if !in_i.iter().any(|&b| b) && !in_j.iter().any(|&b| b) {
            return None;
        }
        // Cap of a: its inside nodes, with the chord through the two crossings.
        let cap = |a: &GrainShape,
                   inside: &[bool],
                   chord: (DVec2, DVec2),
                   outward: DVec2|
         -> (f64, f64) {
            let mid = 0.5 * (chord.0 + chord.1);
            let n = table.nodes;
            let Some(start) = (0..n).find(|&k| inside[k] && !inside[(k + n - 1) % n]) else {
                return (0.0, 0.0);
            };
            let mut pts = vec![chord.0 - mid];
            let mut depth: f64 = 0.0;
            let mut k = start;
            while inside[k] {
                let x = a.node(table, k) - mid;
                depth = depth.max(x.dot(outward));
                pts.push(x);
                k = (k + 1) % n;
            }
            pts.push(chord.1 - mid);
            let area: f64 = pts.windows(2).map(|w| w[0].perp_dot(w[1])).sum::<f64>() * 0.5;
            (area, depth)
        };
        let c = match grain_grain(table, i, j) {
            Overlap::Contact(c) => c,
            _ => return None,
        };
        let tangent = c.normal.perp();
        let p_lo = c.point - tangent * (0.5 * c.length);
        let p_hi = c.point + tangent * (0.5 * c.length);
        let (area_i, depth_i) = cap(i, &in_i, (p_lo, p_hi), c.normal);
        let (area_j, depth_j) = cap(j, &in_j, (p_hi, p_lo), -c.normal);
        Some((area_i, area_j, depth_i, depth_j))
    }

    /// Brute force crossing points: every edge of `a` whose ends lie on both sides of `b`,
    /// intersected with `b`'s polygon edge by edge (the exit is the smallest parameter).
    fn brute_crossings(
        table: &ContourTable,
        a: &GrainShape,
        b: &GrainShape,
        inside: &[bool],
    ) -> Vec<DVec2> {
        let n = table.nodes;
        let mut points = Vec::new();
        for k in 0..n {
            let next = (k + 1) % n;
            if inside[k] == inside[next] {
                continue;
            }
            let (k_in, k_out) = if inside[k] { (k, next) } else { (next, k) };
            let to_b = |x: DVec2| b.inv_map() * (x - b.center);
            let (p_in, p_out) = (to_b(a.node(table, k_in)), to_b(a.node(table, k_out)));
            let d = p_out - p_in;
            let t = (0..n)
                .filter_map(|s| {
                    let normal = table.edge(s).normal;
                    let rate = d.dot(normal);
                    (rate > 0.0).then(|| (table.apothem - p_in.dot(normal)) / rate)
                })
                .fold(1.0_f64, f64::min);
            let (x_in, x_out) = (a.node(table, k_in), a.node(table, k_out));
            points.push(x_in + (x_out - x_in) * t);
        }
        points
    }

    /// A random pair of ellipses in any overlap, from deep to barely touching: i of radius 1 at
    /// the origin, j of radius `rj` in [0.1, 1.6] (returned) around it; strains up to 20%.
    fn random_pair(next: &mut impl FnMut() -> f64) -> (GrainShape, GrainShape, f64) {
        let i = GrainShape::new(
            DVec2::ZERO,
            1.0,
            6.0 * next(),
            0.4 * next() - 0.2,
            0.4 * next() - 0.2,
            6.0 * next(),
        );
        let rj = 0.1 + 1.5 * next();
        let direction = DVec2::from_angle(6.3 * next());
        let j = GrainShape::new(
            direction * (1.0 + rj) * (0.75 + 0.3 * next()),
            rj,
            6.0 * next(),
            0.3 * next() - 0.15,
            0.3 * next() - 0.15,
            6.0 * next(),
        );
        (i, j, rj)
    }

    #[test]
    fn hints_never_change_the_contact() {
        // Expectation: a hint only chooses where the exact search starts, so any hint (last
        // step's chains, shifted ones, random ones, swapped ones) gives the cold result bit for
        // bit.
        let table = ContourTable::new(1.0);
        let n = table.nodes as i32;
        let mut next = unit_randoms(7);
        let mut compared = 0;
        for _ in 0..300 {
            let (i, j, _) = random_pair(&mut next);
            let mut exact_hint = PairHint::default();
            let cold = grain_grain_hinted(&table, &i, &j, &mut exact_hint);
            let shift = |h: ChainHint, d_lo: i32, d_hi: i32| ChainHint {
                lo: (h.lo + d_lo).rem_euclid(n),
                hi: (h.hi + d_hi).rem_euclid(n),
            };
            let mut hints = vec![exact_hint];
            if exact_hint.first.lo >= 0 && exact_hint.second.lo >= 0 {
                for d in [-3, -1, 1, 2, 5] {
                    hints.push(PairHint {
                        first: shift(exact_hint.first, d, -d),
                        second: shift(exact_hint.second, -d, d),
                    });
                }
                // Each end moved on its own, by up to two nodes: what the search from last
                // step's ends (`last_chain_moved`) settles or hands on.
                for d_lo in -2..=2 {
                    for d_hi in -2..=2 {
                        hints.push(PairHint {
                            first: shift(exact_hint.first, d_lo, d_hi),
                            second: shift(exact_hint.second, d_hi, d_lo),
                        });
                    }
                }
                hints.push(PairHint {
                    first: exact_hint.second,
                    second: exact_hint.first,
                });
            }
            for _ in 0..4 {
                let mut random = || ChainHint {
                    lo: (next() * n as f64) as i32 % n,
                    hi: (next() * n as f64) as i32 % n,
                };
                hints.push(PairHint {
                    first: random(),
                    second: random(),
                });
            }
            for mut hint in hints {
                assert_eq!(grain_grain_hinted(&table, &i, &j, &mut hint), cold);
                compared += 1;
            }
        }
        assert!(compared > 2000, "{compared}");
    }

    #[test]
    fn ellipses_apart_only_where_no_node_of_either_polygon_is_inside_the_other() {
        // Expectation: each polygon is inscribed in its ellipse, so ellipses that lie apart along
        // the line of centres leave no node of either polygon inside the other (node-by-node
        // test); and the cold contact is then Separate, with empty hints.
        let table = ContourTable::new(1.0);
        let mut next = unit_randoms(5);
        let (mut apart, mut touching) = (0, 0);
        for sample in 0..2000 {
            // Within 1% of where the ellipses touch along the line of centres. Every other pair
            // is of two circles, for which the test is sharp (the projections overlap exactly
            // when the discs do, and the polygons then have nodes inside); the others are
            // ellipses with strains up to 20%.
            let strain = if sample % 2 == 0 { 0.0 } else { 0.2 };
            let grain = |radius: f64, next: &mut dyn FnMut() -> f64| {
                let (theta, alpha) = (6.3 * next(), 6.3 * next());
                let eps1 = strain * (2.0 * next() - 1.0);
                let eps2 = strain * (2.0 * next() - 1.0);
                GrainShape::new(DVec2::ZERO, radius, theta, eps1, eps2, alpha)
            };
            let i = grain(1.0, &mut next);
            let radius_j = 0.2 + 1.3 * next();
            let mut j = grain(radius_j, &mut next);
            let along = DVec2::from_angle(6.3 * next());
            let extents =
                (i.map.transpose() * along).length() + (j.map.transpose() * along).length();
            j.center = along * extents * (0.99 + 0.02 * next());
            let separate = !nodes_inside(&table, &i, &j).contains(&true)
                && !nodes_inside(&table, &j, &i).contains(&true);
            if ellipses_apart(&i, &j) {
                assert!(separate);
                let mut hint = PairHint::default();
                assert_eq!(
                    grain_grain_hinted(&table, &i, &j, &mut hint),
                    Overlap::Separate
                );
                assert_eq!(hint, PairHint::default());
                apart += 1;
            } else if !separate {
                touching += 1;
            }
        }
        assert!(
            apart > 200 && touching > 200,
            "{apart} apart, {touching} touching"
        );
    }

    #[test]
    fn fast_caps_match_a_node_by_node_computation() {
        // Expectation: the O(1) cap area and depth and the galloping chain search give what a
        // node-by-node pass over the whole contour gives, for random ellipses in any overlap.
        let table = ContourTable::new(1.0);
        let mut next = unit_randoms(99);
        let mut checked = 0;
        for _ in 0..400 {
            let (i, j, rj) = random_pair(&mut next);
            let Overlap::Contact(c) = grain_grain(&table, &i, &j) else {
                continue;
            };
            let (area_i, area_j, depth_i, depth_j) = brute_force(&table, &i, &j).unwrap();
            // The crossing points, from whichever contour has nodes inside the other.
            let in_i = nodes_inside(&table, &i, &j);
            let points = if in_i.contains(&true) {
                brute_crossings(&table, &i, &j, &in_i)
            } else {
                brute_crossings(&table, &j, &i, &nodes_inside(&table, &j, &i))
            };
            assert_eq!(points.len(), 2);
            let tangent = c.normal.perp();
            let ends = [
                c.point - tangent * (0.5 * c.length),
                c.point + tangent * (0.5 * c.length),
            ];
            for p in points {
                let miss = ends
                    .iter()
                    .map(|e| e.distance(p))
                    .fold(f64::INFINITY, f64::min);
                assert!(miss < 1e-12 * (1.0 + rj), "crossing off by {miss}");
            }
            let scale = c.length * c.length;
            assert!(
                (c.cap_area_i - area_i).abs() < 1e-9 * scale,
                "{} vs {area_i}",
                c.cap_area_i
            );
            assert!(
                (c.cap_area_j - area_j).abs() < 1e-9 * scale,
                "{} vs {area_j}",
                c.cap_area_j
            );
            assert!((c.normal_gap + 0.5 * (depth_i + depth_j)).abs() < 1e-9 * c.length);
            checked += 1;
        }
        assert!(checked > 200, "only {checked} contacts");
    }
}
