//! Contacts of exact ellipses: the contour polygons' limit as dbeta -> 0 (issue #16).
//!
//! SPEC §5 defines a contact on the two contours: the crossing points P, P', the chord, the caps
//! cut off by it and their depths. With `contact.resolution_deg: 0` the contours are the grains'
//! exact ellipses rather than their inscribed polygons ([`Contours::Exact`]). Like the closed
//! forms of [`circle`](super::circle), this is the limit of the polygon kernel of
//! [`intersection`](super::intersection): the two agree to the polygon's sagitta,
//! `R (1 - cos(dbeta / 2))`, and the exact contour has no discretisation left to converge.
//!
//! Grain i's contour is the image of the unit circle, `x(u) = c_i + A_i u` with |u| = 1. In
//! grain j's reference frame it is `g(u) = M u + t` (`M = A_j^-1 A_i`, `t = A_j^-1 (c_i - c_j)`)
//! and it lies inside j where `f(u) = |g(u)|^2 - 1 < 0`.
//!
//! - Along the rational parametrisation of the unit circle about the direction of j's centre,
//!   `u = ((1 - tau^2) e + 2 tau e') / (1 + tau^2)`, `(1 + tau^2)^2 f` is a quartic P in tau:
//!   no sine, cosine or square root inside the searches.
//! - Where the seed direction lies inside j (nearly every contact) it splits the two roots of
//!   P, which the quadratic model of P there places; otherwise the deepest point of i in j, the
//!   minimum of P by Newton's method on P', splits them, and its sign settles the contact (two
//!   convex contours whose interiors overlap cross unless one holds the other).
//! - The roots are polished by Halley's method, both sides in one loop; bisection takes over a
//!   side the iteration would leave.
//! - The caps are affine images of circular segments: i's cap is `det(A_i)` times the segment of
//!   the unit circle cut by the chord between the two crossing directions, and its depth beyond
//!   the chord along n is `(c_i - x_c) . n + |A_i^T n|` (the ellipse's support function).
//!
//! Nothing is carried from one step to the next: the result depends on the two shapes alone,
//! so a run resumed from a checkpoint takes the same steps bit for bit.
//!
//! Sign conventions as in [`intersection`](super::intersection): the normal points from the
//! first body towards the second (or the wall); gaps are negative when the bodies interpenetrate.

use super::circle::chord_segment_area;
use super::contour::{ContourTable, GrainShape};
use super::intersection::{
    Chord, ContactGeometry, Overlap, PairHint, grain_grain_hinted, grain_wall,
};
use glam::{DMat2, DVec2};

/// How the contacts see a grain's contour (SPEC §5): the polygon of nodes every dbeta, or the
/// exact ellipse (`resolution_deg = 0`).
#[derive(Debug, Clone)]
pub enum Contours {
    Polygon(ContourTable),
    Exact,
}

impl Contours {
    /// The contours of a contour resolution `resolution_deg` in degrees: 0 for the exact
    /// ellipses, else the polygon of that node spacing.
    pub fn new(resolution_deg: f64) -> Self {
        if resolution_deg == 0.0 {
            Contours::Exact
        } else {
            Contours::Polygon(ContourTable::new(resolution_deg))
        }
    }

    /// Nodes of a contour polygon; 0 for the exact ellipses.
    pub fn nodes(&self) -> usize {
        match self {
            Contours::Polygon(table) => table.nodes,
            Contours::Exact => 0,
        }
    }

    /// The angle between contour nodes, radians; 0 for the exact ellipses.
    pub fn dbeta(&self) -> f64 {
        match self {
            Contours::Polygon(table) => table.dbeta,
            Contours::Exact => 0.0,
        }
    }

    /// Whether the point `u` of a grain's reference frame (the unit circle's) lies strictly
    /// inside its contour.
    #[inline]
    pub fn contains(&self, u: DVec2) -> bool {
        match self {
            Contours::Polygon(table) => table.contains(u),
            Contours::Exact => u.length_squared() < 1.0,
        }
    }

    /// Contact of grains i and j, the polygons' search starting from `hint` (updated; the exact
    /// ellipses need none and leave it as it is).
    #[inline]
    pub fn grain_grain(&self, i: &GrainShape, j: &GrainShape, hint: &mut PairHint) -> Overlap {
        match self {
            Contours::Polygon(table) => grain_grain_hinted(table, i, j, hint),
            Contours::Exact => ellipse_ellipse(i, j),
        }
    }

    /// Contact of a grain with the wall through `wall_point` of inward unit normal `wall_normal`.
    #[inline]
    pub fn grain_wall(&self, grain: &GrainShape, wall_point: DVec2, wall_normal: DVec2) -> Overlap {
        match self {
            Contours::Polygon(table) => grain_wall(table, grain, wall_point, wall_normal),
            Contours::Exact => ellipse_wall(grain, wall_point, wall_normal),
        }
    }
}

/// Iterations before a search gives up (Halley's converges in 2–3 from its start).
const MAX_ITERATIONS: usize = 12;
/// A Newton step of the deepest-point search this small (in tan(beta / 2)) leaves an error of
/// its square: converged.
const CONVERGED_STEP: f64 = 1e-9;
/// A Halley step this small against the root's distance from the pivot leaves an error of
/// about its cube (times the ratio of P's curvature to its slope there, which that distance
/// bounds): converged.
const HALLEY_CONVERGED: f64 = 1e-5;
/// Largest step of the deepest-point search, in tan(beta / 2) (a turn of about 53 degrees).
const MAX_STEP: f64 = 0.5;

/// Grain i's contour in grain j's reference frame along the rational parametrisation of the
/// unit circle about the direction `e`: `u(tau) = ((1 - tau^2) e + 2 tau e') / (1 + tau^2)`,
/// `tau = tan(beta / 2)`, beta the angle from e (e' its quarter turn). Then
/// `(1 + tau^2) g(u(tau)) = a + b tau + c tau^2` with `a = M e + t`, `b = 2 M e'`, `c = t - M e`,
/// and `(1 + tau^2)^2 f = P(tau)`, the quartic below: P has f's sign, and its roots are the
/// crossings.
#[derive(Debug, Clone, Copy)]
struct Quartic {
    /// Coefficients of P, constant first.
    p: [f64; 5],
    e: DVec2,
    /// `M` and `t` of `g(u) = M u + t`.
    m: DMat2,
    t: DVec2,
}

impl Quartic {
    #[inline]
    fn new(i: &GrainShape, j: &GrainShape, e: DVec2) -> Self {
        let inv_map = j.inv_map();
        let m = inv_map * i.map;
        let t = inv_map * (i.center - j.center);
        let me = m * e;
        let (a, b, c) = (me + t, 2.0 * (m * e.perp()), t - me);
        Self {
            p: [
                a.length_squared() - 1.0,
                2.0 * a.dot(b),
                b.length_squared() + 2.0 * a.dot(c) - 2.0,
                2.0 * b.dot(c),
                c.length_squared() - 1.0,
            ],
            e,
            m,
            t,
        }
    }

    /// P and P' at tau (Horner).
    #[inline]
    fn value_and_slope(&self, tau: f64) -> (f64, f64) {
        let [p0, p1, p2, p3, p4] = self.p;
        let value = (((p4 * tau + p3) * tau + p2) * tau + p1) * tau + p0;
        let slope = ((4.0 * p4 * tau + 3.0 * p3) * tau + 2.0 * p2) * tau + p1;
        (value, slope)
    }

    /// P, P' and P'' at tau.
    #[inline]
    fn derivatives(&self, tau: f64) -> (f64, f64, f64) {
        let (value, slope) = self.value_and_slope(tau);
        let [_, _, p2, p3, p4] = self.p;
        let curvature = (12.0 * p4 * tau + 6.0 * p3) * tau + 2.0 * p2;
        (value, slope, curvature)
    }

    /// The point of i's unit circle at tau.
    #[inline]
    fn direction(&self, tau: f64) -> DVec2 {
        ((1.0 - tau * tau) * self.e + (2.0 * tau) * self.e.perp()) / (1.0 + tau * tau)
    }

    /// `g(u)`: where i's contour point u lies in j's reference frame.
    #[inline]
    fn image(&self, u: DVec2) -> DVec2 {
        self.m * u + self.t
    }
}

/// The minimum of P near tau = 0 (the seed direction): Newton's method on P', with bounded
/// steps downhill where P is not convex. Returns tau, P and P'' there.
fn deepest_point(quartic: &Quartic) -> (f64, f64, f64) {
    let mut tau = 0.0;
    for _ in 0..MAX_ITERATIONS {
        let (_, slope, curvature) = quartic.derivatives(tau);
        let step = if curvature > 0.0 {
            (-slope / curvature).clamp(-MAX_STEP, MAX_STEP)
        } else {
            -MAX_STEP * slope.signum()
        };
        tau += step;
        if step.abs() <= CONVERGED_STEP * (1.0 + tau.abs()) {
            break;
        }
    }
    let (value, _, curvature) = quartic.derivatives(tau);
    (tau, value, curvature)
}

/// The two roots of P either side of `pivot` (P < 0 there, and P > 0 far out: `p4 > 0`), from
/// the guesses `lo < pivot < hi`: Halley's method (P'' is one more Horner line; cubic
/// convergence takes a guess good to 1e-2 to rounding in two steps), both sides in one loop
/// (two independent chains keep the pipeline busy), bisection for a side the iteration loses.
fn crossings(quartic: &Quartic, pivot: f64, guesses: [f64; 2]) -> (f64, f64) {
    let mut roots = guesses;
    let mut done = [false; 2];
    for _ in 0..MAX_ITERATIONS {
        for (side, (root, done)) in roots.iter_mut().zip(done.iter_mut()).enumerate() {
            if *done {
                continue;
            }
            let (value, slope, curvature) = quartic.derivatives(*root);
            let step = -2.0 * value * slope / (2.0 * slope * slope - value * curvature);
            let next = *root + step;
            // On its side P grows away from the pivot: a slope the other way, or a root that
            // crossed the pivot, means the iteration has lost it.
            let upward = side == 1;
            if (slope > 0.0) != upward || (next > pivot) != upward || !step.is_finite() {
                *root = bisect_crossing(quartic, pivot, upward);
                *done = true;
                continue;
            }
            *root = next;
            *done = step.abs() <= HALLEY_CONVERGED * (next - pivot).abs();
        }
        if done[0] && done[1] {
            return (roots[0], roots[1]);
        }
    }
    (
        if done[0] {
            roots[0]
        } else {
            bisect_crossing(quartic, pivot, false)
        },
        if done[1] {
            roots[1]
        } else {
            bisect_crossing(quartic, pivot, true)
        },
    )
}

/// The root of P beyond `pivot` (P < 0) on the side of increasing tau (`upward`) or the other:
/// brackets it by doubling the distance until P > 0, then bisects. Slow and sure, for the
/// contours Halley's iteration cannot follow.
#[cold]
fn bisect_crossing(quartic: &Quartic, pivot: f64, upward: bool) -> f64 {
    let direction = if upward { 1.0 } else { -1.0 };
    let mut inside = pivot;
    let mut distance = 1e-3;
    let mut outside = pivot + direction * distance;
    // P > 0 for large |tau| (p4 > 0), so the doubling ends.
    while quartic.value_and_slope(outside).0 < 0.0 {
        inside = outside;
        distance *= 2.0;
        outside = pivot + direction * distance;
    }
    for _ in 0..200 {
        let middle = 0.5 * (inside + outside);
        if middle == inside || middle == outside {
            break;
        }
        if quartic.value_and_slope(middle).0 < 0.0 {
            inside = middle;
        } else {
            outside = middle;
        }
    }
    0.5 * (inside + outside)
}

/// Area of the unit disc's segment bounded by the chord from `from` to `to` (unit vectors) and
/// the arc that runs counter-clockwise from `from` to `to`.
#[inline]
fn unit_segment_area(from: DVec2, to: DVec2) -> f64 {
    let half_chord = 0.5 * (to - from).length();
    let middle = 0.5 * (to + from).length();
    // The arc is the minor one when `to` lies counter-clockwise of `from`: the segment is then
    // on the far side of the chord from the centre.
    let distance = if from.perp_dot(to) >= 0.0 {
        middle
    } else {
        -middle
    };
    chord_segment_area(1.0, distance, half_chord)
}

/// Contact of the exact ellipses of grains i and j (SPEC §5 on smooth contours).
pub fn ellipse_ellipse(i: &GrainShape, j: &GrainShape) -> Overlap {
    let reach = i.bounding_radius + j.bounding_radius;
    if i.center.distance_squared(j.center) >= reach * reach {
        return Overlap::Separate;
    }
    // j's centre in i's reference frame: the direction the parametrisation is laid about.
    let toward_j = i.inv_map() * (j.center - i.center);
    let distance = toward_j.length();
    if distance == 0.0 {
        // Concentric: one contour holds the other (or they cross four times).
        return Overlap::Swallowed;
    }
    let quartic = Quartic::new(i, j, toward_j / distance);
    if quartic.p[4] <= 0.0 {
        // i's far side (tau -> infinity) inside j: i lies (mostly) inside j.
        return Overlap::Swallowed;
    }
    let [p0, p1, p2, _, _] = quartic.p;
    // i's arc inside j runs counter-clockwise (increasing tau) from `tau_lo` to `tau_hi`.
    let (tau_lo, tau_hi) = if p0 < 0.0 && p2 > 0.0 {
        // The seed direction lies inside j (nearly every contact): it splits the two roots,
        // which the quadratic model p0 + p1 tau + p2 tau^2 places.
        let root = (p1 * p1 - 4.0 * p0 * p2).sqrt();
        let far = -0.5 * (p1 + root.copysign(p1));
        let (a, b) = (far / p2, p0 / far);
        crossings(&quartic, 0.0, [a.min(b), a.max(b)])
    } else {
        let (deepest, depth_value, curvature) = deepest_point(&quartic);
        if depth_value >= 0.0 {
            // i's contour nowhere enters j: apart, or j lies inside i.
            return if distance < 1.0 {
                Overlap::Swallowed
            } else {
                Overlap::Separate
            };
        }
        if curvature <= 0.0 {
            return Overlap::Swallowed;
        }
        let guess = (-2.0 * depth_value / curvature).sqrt();
        crossings(&quartic, deepest, [deepest - guess, deepest + guess])
    };
    let (u_lo, u_hi) = (quartic.direction(tau_lo), quartic.direction(tau_hi));
    let (p_lo, p_hi) = (i.center + i.map * u_lo, i.center + i.map * u_hi);
    let Some(chord) = Chord::between(p_lo, p_hi, i, j) else {
        return Overlap::Separate;
    };
    // The caps' depths beyond the chord: the ellipses' support functions along the normal.
    let outermost = |shape: &GrainShape, direction: DVec2| {
        (shape.center - chord.point).dot(direction) + (shape.map.transpose() * direction).length()
    };
    let (depth_i, depth_j) = (outermost(i, chord.normal), outermost(j, -chord.normal));
    // i's cap: the arc of angle 2 (atan tau_hi - atan tau_lo) < 2 pi, whose half angle has
    // the sine and cosine below (no cancellation for shallow caps).
    let norm = ((1.0 + tau_lo * tau_lo) * (1.0 + tau_hi * tau_hi)).sqrt();
    let (half_sin, half_cos) = ((tau_hi - tau_lo) / norm, (1.0 + tau_lo * tau_hi) / norm);
    let cap_area_i = i.map.determinant() * chord_segment_area(1.0, half_cos, half_sin);
    // j's arc inside i runs the other way, from P' to P; both points on j's unit circle (to
    // the roots' rounding).
    let (w_lo, w_hi) = (quartic.image(u_lo), quartic.image(u_hi));
    let cap_area_j = j.map.determinant() * unit_segment_area(w_hi, w_lo);
    Overlap::Contact(ContactGeometry {
        point: chord.point,
        normal: chord.normal,
        length: chord.length,
        cap_area_i,
        cap_area_j,
        normal_gap: -0.5 * (depth_i.max(0.0) + depth_j.max(0.0)),
    })
}

/// Contact of a grain's exact ellipse with the infinite wall through `wall_point` whose unit
/// normal `wall_normal` points into the domain: the chord lies on the wall, the cap is the part
/// of the ellipse beyond it and `delta_n` its depth. In closed form: the contour point u lies at
/// the height `H + s . u` above the wall (`H` the centre's height, `s = A^T n`), so the
/// crossings are the two unit vectors with `s . u = -H`.
pub fn ellipse_wall(grain: &GrainShape, wall_point: DVec2, wall_normal: DVec2) -> Overlap {
    let height = (grain.center - wall_point).dot(wall_normal);
    if height >= grain.bounding_radius {
        return Overlap::Separate;
    }
    let s = grain.map.transpose() * wall_normal;
    let reach = s.length();
    if height >= reach {
        return Overlap::Separate;
    }
    if height <= -reach {
        return Overlap::Swallowed;
    }
    let depth = reach - height;
    let axis = s / reach;
    // The crossings lie at the angle gamma either side of `axis`, cos gamma = -H / |s|; the cap
    // is the arc around -axis, counter-clockwise from `u_lo` to `u_hi`.
    let cos = -height / reach;
    let sin = (depth * (reach + height)).sqrt() / reach;
    let (u_lo, u_hi) = (
        cos * axis + sin * axis.perp(),
        cos * axis - sin * axis.perp(),
    );
    let (p_lo, p_hi) = (
        grain.center + grain.map * u_lo,
        grain.center + grain.map * u_hi,
    );
    let length = p_lo.distance(p_hi);
    if length <= f64::EPSILON * grain.bounding_radius {
        return Overlap::Separate;
    }
    Overlap::Contact(ContactGeometry {
        point: 0.5 * (p_lo + p_hi),
        normal: -wall_normal,
        length,
        cap_area_i: grain.map.determinant() * chord_segment_area(1.0, height / reach, sin),
        cap_area_j: 0.0,
        normal_gap: -depth,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::circle::{disc_disc, disc_wall};
    use crate::geometry::intersection::tests::contact;
    use crate::geometry::{ContourTable, grain_grain};
    use std::f64::consts::PI;

    /// A deformed grain: radius 1 (or `radius`), strains and angles as given.
    fn ellipse(
        center: DVec2,
        radius: f64,
        theta: f64,
        eps1: f64,
        eps2: f64,
        alpha: f64,
    ) -> GrainShape {
        GrainShape::new(center, radius, theta, eps1, eps2, alpha)
    }

    /// Places j beyond i along `direction` d: j's outermost point along -d at i's outermost
    /// point along d, moved back by `overlap`. The two contours then share the normal d there
    /// and overlap by `overlap` along it.
    fn placed(
        i: &GrainShape,
        j_at_origin: &GrainShape,
        direction: DVec2,
        overlap: f64,
    ) -> GrainShape {
        let support = |shape: &GrainShape, d: DVec2| {
            let s = shape.map.transpose() * d;
            shape.map * (s / s.length())
        };
        let touching = i.center + support(i, direction) - overlap * direction;
        GrainShape {
            center: touching - support(j_at_origin, -direction),
            ..*j_at_origin
        }
    }

    /// The largest difference of two contacts in length units (areas over the chord length).
    fn difference(a: &ContactGeometry, b: &ContactGeometry) -> f64 {
        [
            (a.length - b.length).abs(),
            (a.normal_gap - b.normal_gap).abs(),
            (a.point - b.point).length(),
            (a.cap_area_i - b.cap_area_i).abs() / b.length,
            (a.cap_area_j - b.cap_area_j).abs() / b.length,
        ]
        .into_iter()
        .fold(0.0, f64::max)
    }

    #[test]
    fn circles_give_the_closed_form_disc_contact() {
        // Expectation: an ellipse of equal semi-axes is a circle, whose contact has the closed
        // form of `disc_disc`, from the deepest overlaps down to a millionth of a radius.
        let ci = DVec2::new(0.3, -0.2);
        for (ri, rj) in [(1.0, 1.0), (1.0, 0.6), (0.7, 1.3)] {
            for (angle, overlap) in [(0.4, 0.3), (2.5, 0.05), (-1.9, 1e-3), (0.0, 1e-6)] {
                let cj = ci + (ri + rj - overlap) * DVec2::from_angle(angle);
                let (i, j) = (GrainShape::disc(ci, ri), GrainShape::disc(cj, rj));
                let exact = contact(ellipse_ellipse(&i, &j));
                let closed = contact(disc_disc(ci, ri, cj, rj));
                // A shallow crossing is ill-conditioned: f's slope at the root is ~ the chord,
                // so a rounding of f moves the root by ~ eps R / overlap relative to the chord.
                let tolerance = 1e-12 + 1e-15 / overlap;
                let relative = |a: f64, b: f64| (a / b - 1.0).abs();
                assert!(
                    relative(exact.length, closed.length) < tolerance
                        && relative(exact.cap_area_i, closed.cap_area_i) < 3.0 * tolerance
                        && relative(exact.cap_area_j, closed.cap_area_j) < 3.0 * tolerance
                        && (exact.point - closed.point).length() < 1e-14
                        && (exact.normal - closed.normal).length() < tolerance,
                    "{ri} {rj} {angle} {overlap}: {exact:?} against {closed:?}"
                );
                let relative_gap = relative(exact.normal_gap, closed.normal_gap);
                assert!(relative_gap < 1e-8, "gap off by {relative_gap}");
            }
        }
    }

    #[test]
    fn the_polygon_kernel_converges_to_the_exact_ellipses() {
        // Expectation: the polygon inscribed at dbeta lies inside the ellipse by up to its
        // sagitta s ~ R_max dbeta^2 / 8, so every quantity of the polygon kernel lies within a
        // few s (a crossing point slides along the chord by s R / h) of the exact contact, and
        // the error falls with dbeta.
        let i = ellipse(DVec2::new(0.1, 0.2), 1.0, 0.3, 0.12, -0.1, 0.4);
        let j_shape = ellipse(DVec2::ZERO, 0.8, -1.2, -0.05, 0.2, 2.1);
        for (angle, overlap) in [(0.5, 0.08), (2.4, 0.25), (-1.3, 0.02)] {
            let j = placed(&i, &j_shape, DVec2::from_angle(angle), overlap);
            let exact = contact(ellipse_ellipse(&i, &j));
            let mut last_error = f64::INFINITY;
            for degrees in [2.0, 0.5, 0.125] {
                let table = ContourTable::new(degrees);
                let polygon = contact(grain_grain(&table, &i, &j));
                let sagitta = 1.2 * (1.0 - (0.5 * table.dbeta).cos());
                let bound = 4.0 * sagitta * (1.0 + 2.4 / exact.length);
                let error = difference(&polygon, &exact);
                assert!(error < bound, "{degrees} deg: error {error}, bound {bound}");
                assert!((polygon.normal - exact.normal).length() < 1e-3 * degrees);
                assert!(
                    error < 0.25 * last_error,
                    "{degrees} deg: {error} after {last_error}"
                );
                last_error = error;
            }
        }
    }

    #[test]
    fn random_pairs_agree_with_a_fine_polygon() {
        // Expectation: over deformed pairs of every orientation and overlaps from 1e-4 to a
        // third of a radius, the exact contact is the limit of the polygon kernel (within the
        // sagitta bound of a 0.05-degree polygon), and the contact found either way is the same.
        let table = ContourTable::new(0.05);
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut uniform = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut contacts, mut separate) = (0, 0);
        for case in 0..200 {
            let mut draw = |lo: f64, hi: f64| lo + (hi - lo) * uniform();
            let i = ellipse(
                DVec2::new(draw(-1.0, 1.0), draw(-1.0, 1.0)),
                draw(0.6, 1.4),
                draw(-PI, PI),
                draw(-0.25, 0.3),
                draw(-0.25, 0.3),
                draw(-PI, PI),
            );
            let j_shape = ellipse(
                DVec2::ZERO,
                draw(0.6, 1.4),
                draw(-PI, PI),
                draw(-0.25, 0.3),
                draw(-0.25, 0.3),
                draw(-PI, PI),
            );
            let overlap = 10f64.powf(draw(-4.0, -0.5));
            let j = placed(&i, &j_shape, DVec2::from_angle(draw(-PI, PI)), overlap);
            let (exact, polygon) = match (ellipse_ellipse(&i, &j), grain_grain(&table, &i, &j)) {
                (Overlap::Contact(e), Overlap::Contact(p)) => (e, p),
                (Overlap::Separate, Overlap::Separate) => {
                    separate += 1;
                    continue;
                }
                other => panic!("case {case}: {other:?}"),
            };
            contacts += 1;
            let largest = i.bounding_radius.max(j.bounding_radius);
            let sagitta = largest * (1.0 - (0.5 * table.dbeta).cos());
            let bound = 4.0 * sagitta * (1.0 + 2.0 * largest / exact.length);
            let error = difference(&polygon, &exact);
            assert!(
                error < bound,
                "case {case}: error {error}, bound {bound}, overlap {overlap}"
            );
            // Exchanging the grains: the same chord, the normal reversed, the caps swapped.
            let swapped = contact(ellipse_ellipse(&j, &i));
            let scale = exact.length;
            assert!(
                (swapped.point - exact.point).length() < 1e-9 * scale,
                "case {case}"
            );
            assert!(
                (swapped.length - exact.length).abs() < 1e-9 * scale,
                "case {case}"
            );
            assert!(
                (swapped.normal + exact.normal).length() < 1e-9,
                "case {case}"
            );
            assert!((swapped.cap_area_i - exact.cap_area_j).abs() < 1e-9 * scale * scale);
            assert!((swapped.cap_area_j - exact.cap_area_i).abs() < 1e-9 * scale * scale);
            assert!((swapped.normal_gap - exact.normal_gap).abs() < 1e-9 * overlap);
        }
        assert!(
            contacts > 150 && separate < 20,
            "{contacts} contacts, {separate} apart"
        );
    }

    #[test]
    fn newton_and_bisection_find_the_same_crossings() {
        // Expectation: the bisection that backs Newton's method up converges to the same roots
        // of P (to rounding), both lie on j's contour, and the quartic is f (1 + tau^2)^2.
        let i = ellipse(DVec2::ZERO, 1.0, 0.8, 0.25, -0.2, -0.6);
        let j = placed(
            &i,
            &ellipse(DVec2::ZERO, 0.7, 0.1, -0.2, 0.25, 0.3),
            DVec2::from_angle(1.1),
            0.2,
        );
        let seed = i.inv_map() * (j.center - i.center);
        let quartic = Quartic::new(&i, &j, seed / seed.length());
        for tau in [-3.0, -0.4, 0.0, 0.1, 2.5] {
            let f = quartic.image(quartic.direction(tau)).length_squared() - 1.0;
            let p = quartic.value_and_slope(tau).0;
            assert!((p - f * (1.0 + tau * tau).powi(2)).abs() < 1e-12 * (1.0 + tau.powi(4)));
        }
        let (deepest, value, curvature) = deepest_point(&quartic);
        assert!(value < 0.0 && curvature > 0.0);
        let guess = (-2.0 * value / curvature).sqrt();
        let (lo, hi) = crossings(&quartic, deepest, [deepest - guess, deepest + guess]);
        for (newton, upward) in [(lo, false), (hi, true)] {
            let bisection = bisect_crossing(&quartic, deepest, upward);
            assert!(
                (newton - bisection).abs() < 1e-13,
                "{newton} against {bisection}"
            );
            let on_j = quartic.image(quartic.direction(newton)).length_squared() - 1.0;
            assert!(on_j.abs() < 1e-14, "{on_j}");
        }
        assert!(lo < deepest && deepest < hi);
    }

    #[test]
    fn an_ellipse_on_a_wall_cuts_the_elliptic_segment() {
        // Expectation: an ellipse of semi-axes a (along x) and b on the wall y = -b + h loses
        // the segment a b (gamma - sin gamma cos gamma), cos gamma = 1 - h / b, on a chord of
        // length 2 a sin gamma centred below its centre, h deep.
        let (a, b) = (1.3, 0.8);
        let grain = ellipse(DVec2::new(0.4, 0.0), 1.0, 0.0, 0.3, -0.2, 0.0);
        for h in [1e-6, 0.01, 0.3, 1.1] {
            let c = contact(ellipse_wall(&grain, DVec2::new(0.0, -b + h), DVec2::Y));
            let gamma = (1.0 - h / b).acos();
            let area = a * b * (gamma - gamma.sin() * gamma.cos());
            assert!((c.cap_area_i / area - 1.0).abs() < 1e-9, "h {h}");
            assert!(
                (c.length / (2.0 * a * gamma.sin()) - 1.0).abs() < 1e-9,
                "h {h}"
            );
            assert!((c.normal_gap + h).abs() < 1e-15);
            assert!((c.point - DVec2::new(0.4, -b + h)).length() < 1e-15);
            assert_eq!(c.normal, -DVec2::Y);
        }
        // A tilted wall and a turned ellipse: the limit of the polygon kernel.
        let grain = ellipse(DVec2::new(1.0, 0.3), 0.9, 0.7, 0.2, -0.15, -0.4);
        let normal = DVec2::from_angle(2.0);
        for depth in [0.02, 0.3] {
            let point = grain.center - ((grain.map.transpose() * normal).length() - depth) * normal;
            let exact = contact(ellipse_wall(&grain, point, normal));
            assert!((exact.normal_gap + depth).abs() < 1e-14);
            for degrees in [1.0, 0.25] {
                let table = ContourTable::new(degrees);
                let c = contact(grain_wall(&table, &grain, point, normal));
                let sagitta = grain.bounding_radius * (1.0 - (0.5 * table.dbeta).cos());
                let bound = 4.0 * sagitta * (1.0 + 2.0 * grain.bounding_radius / exact.length);
                assert!(difference(&c, &exact) < bound, "{degrees} deg");
            }
        }
        // A disc on a wall: the closed form of `disc_wall`.
        let center = DVec2::new(0.2, 0.5);
        let c = contact(ellipse_wall(
            &GrainShape::disc(center, 0.7),
            DVec2::ZERO,
            DVec2::Y,
        ));
        let d = contact(disc_wall(center, 0.7, DVec2::ZERO, DVec2::Y));
        assert!(difference(&c, &d) < 1e-14);
    }

    #[test]
    fn separate_and_swallowed_contours_are_told_apart() {
        let big = ellipse(DVec2::ZERO, 1.0, 0.2, 0.3, -0.1, 0.5);
        // A small grain inside a big one, in either order, and off its centre.
        let small = ellipse(DVec2::new(0.2, -0.1), 0.3, 1.0, 0.1, -0.1, 0.0);
        assert_eq!(ellipse_ellipse(&big, &small), Overlap::Swallowed);
        assert_eq!(ellipse_ellipse(&small, &big), Overlap::Swallowed);
        assert_eq!(ellipse_ellipse(&big, &big), Overlap::Swallowed);
        // Two thin ellipses, parallel and side by side: their bounding circles overlap deeply,
        // their contours do not meet (and the polygon kernel agrees).
        let thin = |y: f64| ellipse(DVec2::new(0.0, y), 1.0, 0.0, 0.3, -0.6, 0.0);
        let (a, b) = (thin(0.0), thin(0.85));
        assert!(a.center.distance(b.center) < a.bounding_radius + b.bounding_radius);
        assert_eq!(ellipse_ellipse(&a, &b), Overlap::Separate);
        assert_eq!(
            grain_grain(&ContourTable::new(1.0), &a, &b),
            Overlap::Separate
        );
        // ... and overlapping by 0.05 once closer.
        let c = contact(ellipse_ellipse(&a, &thin(0.75)));
        assert!((c.normal_gap + 0.025).abs() < 1e-12, "{c:?}");
        assert!((c.normal - DVec2::Y).length() < 1e-12);
        // A grain beyond a wall, and one clear of it.
        assert_eq!(
            ellipse_wall(&big, DVec2::new(0.0, 2.0), DVec2::Y),
            Overlap::Swallowed
        );
        assert_eq!(
            ellipse_wall(&big, DVec2::new(0.0, -2.0), DVec2::Y),
            Overlap::Separate
        );
    }

    #[test]
    fn contours_dispatch_to_the_polygon_or_the_exact_kernel() {
        // Expectation: resolution 0 means the exact ellipses; any other the polygon of that node
        // spacing, whose result the dispatch returns unchanged (hint included).
        let i = ellipse(DVec2::ZERO, 1.0, 0.3, 0.1, -0.05, 0.2);
        let j = placed(
            &i,
            &ellipse(DVec2::ZERO, 0.9, 0.0, 0.0, 0.1, 1.0),
            DVec2::X,
            0.05,
        );
        assert_eq!(Contours::new(0.0).nodes(), 0);
        let mut hint = PairHint::default();
        assert_eq!(
            Contours::new(0.0).grain_grain(&i, &j, &mut hint),
            ellipse_ellipse(&i, &j)
        );
        assert_eq!(hint, PairHint::default());
        let polygon = Contours::new(1.0);
        assert_eq!(polygon.nodes(), 360);
        let table = ContourTable::new(1.0);
        let mut expected_hint = PairHint::default();
        assert_eq!(
            polygon.grain_grain(&i, &j, &mut hint),
            grain_grain_hinted(&table, &i, &j, &mut expected_hint)
        );
        assert_eq!(hint, expected_hint);
        let wall = (DVec2::new(0.0, -0.9), DVec2::Y);
        assert_eq!(
            Contours::new(0.0).grain_wall(&i, wall.0, wall.1),
            ellipse_wall(&i, wall.0, wall.1)
        );
        assert_eq!(
            polygon.grain_wall(&i, wall.0, wall.1),
            grain_wall(&table, &i, wall.0, wall.1)
        );
    }
}
