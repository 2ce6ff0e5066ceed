//! Contact geometry of two contour polygons, or of a contour polygon and a wall (SPEC §5).
//!
//! Both contours are convex, so their boundaries cross at two points P and P'. The arc of grain
//! i that lies inside grain j is one run of consecutive nodes ("chain"): we find one node of it
//! near the deepest point of the smooth ellipse, then walk outwards until a node leaves j. Only
//! those nodes (plus one on each side) are ever computed: the cost of a contact grows with the
//! length of its overlap arc, not with the contour resolution.
//!
//! Sign conventions: the contact normal `n` points from grain i towards grain j (or towards the
//! wall); gaps are negative when the contours interpenetrate.

use super::contour::{ContourTable, GrainShape};
use glam::DVec2;

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

/// The nodes of one contour inside another polygon, `lo..=hi` (indices not yet wrapped), and
/// the two points where the contour leaves that polygon: on edge (lo-1, lo) and on (hi, hi+1).
#[derive(Debug, Clone, Copy)]
struct Chain {
    lo: isize,
    hi: isize,
    exit_lo: DVec2,
    exit_hi: DVec2,
}

enum ChainSearch {
    Empty,
    Found(Chain),
    Whole,
}

/// Chain of `a`'s nodes strictly inside `b`'s polygon.
fn chain_inside(table: &ContourTable, a: &GrainShape, b: &GrainShape) -> ChainSearch {
    // a's node k in b's reference coordinates: p_k = M v_k + t.
    let m = b.inv_map * a.map;
    let t = b.inv_map * (a.center - b.center);
    let node_in_b = |k: isize| m * table.vertex[table.wrap(k)] + t;

    // Seed: the point of a's smooth contour nearest to b's centre in b's reference frame,
    // where |p(beta)| is smallest (the deepest point, up to the polygon's sagitta). Start
    // from the direction of b seen from a, then two Newton steps on |p(beta)|^2.
    let toward_b = a.inv_map * (b.center - a.center);
    let mut beta = toward_b.y.atan2(toward_b.x);
    for _ in 0..2 {
        let (s, c) = beta.sin_cos();
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

    let mut seed = None;
    for dk in [0, -1, 1, -2, 2] {
        let p = node_in_b(k0 + dk);
        let s = table.sector(p);
        if table.gauge(p, s) < 1.0 {
            seed = Some((k0 + dk, p, s));
            break;
        }
    }
    let Some((k_seed, p_seed, s_seed)) = seed else {
        return ChainSearch::Empty;
    };

    let n = table.nodes as isize;
    // Walk forwards: last inside node `hi`, first outside node `hi + 1`.
    let (mut hi, mut p_hi, mut s_hi) = (k_seed, p_seed, s_seed);
    let (p_out_hi, s_out_hi) = loop {
        let p = node_in_b(hi + 1);
        let s = table.refine_sector(p, s_hi);
        if table.gauge(p, s) >= 1.0 {
            break (p, s);
        }
        hi += 1;
        (p_hi, s_hi) = (p, s);
        if hi - k_seed >= n {
            return ChainSearch::Whole;
        }
    };
    let (mut lo, mut p_lo, mut s_lo) = (k_seed, p_seed, s_seed);
    let (p_out_lo, s_out_lo) = loop {
        let p = node_in_b(lo - 1);
        let s = table.refine_sector(p, s_lo);
        if table.gauge(p, s) >= 1.0 {
            break (p, s);
        }
        lo -= 1;
        (p_lo, s_lo) = (p, s);
    };
    if hi - lo + 1 >= n {
        return ChainSearch::Whole;
    }

    // The exit parameter along an edge is the same in both frames (affine maps keep ratios).
    let t_hi = table.exit_parameter(p_hi, s_hi, p_out_hi, s_out_hi);
    let t_lo = table.exit_parameter(p_lo, s_lo, p_out_lo, s_out_lo);
    let edge_point = |k_in: isize, k_out: isize, t: f64| {
        let v_in = table.vertex[table.wrap(k_in)];
        let v_out = table.vertex[table.wrap(k_out)];
        a.center + a.map * (v_in + (v_out - v_in) * t)
    };
    ChainSearch::Found(Chain {
        lo,
        hi,
        exit_lo: edge_point(lo, lo - 1, t_lo),
        exit_hi: edge_point(hi, hi + 1, t_hi),
    })
}

/// Area of the cap polygon (from, chain nodes lo..=hi, to) and the largest distance of a chain
/// node beyond the chord along `outward`. Coordinates are taken relative to `origin` (a point on
/// the chord) to keep the shoelace sum free of cancellation.
fn cap_area_and_depth(
    table: &ContourTable,
    shape: &GrainShape,
    chain: (isize, isize),
    from: DVec2,
    to: DVec2,
    origin: DVec2,
    outward: DVec2,
) -> (f64, f64) {
    let offset = shape.center - origin;
    let mut previous = from - origin;
    let mut twice_area = 0.0;
    let mut depth = 0.0_f64;
    for k in chain.0..=chain.1 {
        let node = offset + shape.node_offset(table, table.wrap(k));
        twice_area += previous.perp_dot(node);
        depth = depth.max(node.dot(outward));
        previous = node;
    }
    let last = to - origin;
    twice_area += previous.perp_dot(last);
    // The closing chord (to -> from) passes through the origin: it adds nothing.
    (0.5 * twice_area, depth)
}

/// Contact between the contour polygons of grains i and j.
pub fn grain_grain(table: &ContourTable, i: &GrainShape, j: &GrainShape) -> Overlap {
    let reach = i.bounding_radius + j.bounding_radius;
    if i.center.distance_squared(j.center) >= reach * reach {
        return Overlap::Separate;
    }
    let chain_i = match chain_inside(table, i, j) {
        ChainSearch::Whole => return Overlap::Swallowed,
        ChainSearch::Empty => None,
        ChainSearch::Found(c) => Some(c),
    };
    let chain_j = match chain_inside(table, j, i) {
        ChainSearch::Whole => return Overlap::Swallowed,
        ChainSearch::Empty => None,
        ChainSearch::Found(c) => Some(c),
    };
    // Crossing points in the order of grain i's contour (counter-clockwise): i's chain runs from
    // `p_lo` to `p_hi`; j's chain runs the other way.
    let (p_lo, p_hi) = match (&chain_i, &chain_j) {
        (Some(c), _) => (c.exit_lo, c.exit_hi),
        (None, Some(c)) => (c.exit_hi, c.exit_lo),
        (None, None) => return Overlap::Separate,
    };
    let chord = p_hi - p_lo;
    let length = chord.length();
    if length <= f64::EPSILON * i.bounding_radius.min(j.bounding_radius) {
        return Overlap::Separate;
    }
    let tangent = chord / length;
    // Right-hand normal of i's chord: i's cap lies on this side, towards j.
    let normal = DVec2::new(tangent.y, -tangent.x);
    let point = 0.5 * (p_lo + p_hi);
    let (cap_area_i, depth_i) = match chain_i {
        Some(c) => cap_area_and_depth(table, i, (c.lo, c.hi), p_lo, p_hi, point, normal),
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
    let k0 = table.nearest_node(deepest.y.atan2(deepest.x));
    let Some(k_seed) = [0, -1, 1]
        .into_iter()
        .map(|dk| k0 + dk)
        .find(|&k| node_height(k) < 0.0)
    else {
        return Overlap::Separate;
    };
    let n = table.nodes as isize;
    let mut hi = k_seed;
    while node_height(hi + 1) < 0.0 {
        hi += 1;
        if hi - k_seed >= n {
            return Overlap::Swallowed;
        }
    }
    let mut lo = k_seed;
    while node_height(lo - 1) < 0.0 {
        lo -= 1;
    }
    if hi - lo + 1 >= n {
        return Overlap::Swallowed;
    }
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
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn contact(o: Overlap) -> ContactGeometry {
        match o {
            Overlap::Contact(c) => c,
            other => panic!("expected a contact, got {other:?}"),
        }
    }

    /// Circular segment of a circle of radius r cut at distance r - h from its centre.
    fn segment_area(r: f64, h: f64) -> f64 {
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
}
