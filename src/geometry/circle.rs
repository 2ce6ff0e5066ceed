//! Closed-form contacts of exact circles: discs (rigid grains, and grains at the volumetric
//! level, whose strains stay equal) need no contour polygon (issue #16).
//!
//! SPEC §5 defines a contact on the two contours: the crossing points P, P', the chord length
//! `L_c = |PP'|`, the point `x_c = (P + P')/2`, the caps cut off by the chord and their depths.
//! For two circles (or a circle and a wall) every one of these has a closed form, which is the
//! limit of the polygon kernel of [`intersection`](super::intersection) as dbeta -> 0: the same
//! law then costs a few square roots instead of chain searches. The polygon inscribed at dbeta
//! lies inside its circle by up to `R (1 - cos(dbeta / 2))` (3.8e-5 R at 1 degree), so the two
//! kernels agree to that order; on shallow contacts the closed form is the more accurate one.
//!
//! Sign conventions as in [`intersection`](super::intersection): the normal points from the
//! first body towards the second (or the wall); gaps are negative when the bodies interpenetrate.

use super::intersection::{ContactGeometry, Overlap};
use crate::lanes::Real;
use glam::DVec2;

/// Area of the segment cut off a circle of radius `radius` by a chord at signed distance
/// `distance` from the centre (towards the segment) whose half length is `half_chord`
/// (`distance^2 + half_chord^2 = radius^2`): `R^2 (theta - sin theta cos theta)`, theta the
/// chord's half angle at the centre, `sin theta = half_chord / R`, `cos theta = distance / R`.
///
/// Shallow caps (`sin theta <= 0.3`, a depth up to 4.6% of R: nearly every contact) take the
/// series `theta - sin theta cos theta = sum_k 2 C(2k, k) s^(2k+3) / (4^k (2k+3))` in
/// `s = sin theta`, 12 terms, relative error below 1e-14; it needs no atan2, which was a third of
/// a rigid step, and keeps full precision where the difference of the closed form cancels.
/// Deeper caps take the closed form.
#[inline]
pub fn chord_segment_area(radius: f64, distance: f64, half_chord: f64) -> f64 {
    let s = half_chord / radius;
    if shallow_cap(distance, s) {
        shallow_segment_area(radius, s)
    } else {
        let theta = libm::atan2(half_chord, distance);
        radius * radius * theta - distance * half_chord
    }
}

/// Whether a cap whose chord lies at `distance` from the centre, at `sin theta = s`, takes the
/// series of [`shallow_segment_area`].
#[inline(always)]
pub fn shallow_cap(distance: f64, s: f64) -> bool {
    (distance > 0.0) & (s <= 0.3)
}

/// The series branch of [`chord_segment_area`] at `s = sin theta = half_chord / radius`, for a
/// [`shallow_cap`]: `R^2 (theta - sin theta cos theta)`.
#[inline(always)]
pub fn shallow_segment_area<T: Real>(radius: T, s: T) -> T {
    // Coefficients 2 C(2k, k) / (4^k (2k + 3)), k = 0..11, summed in Estrin's order.
    const C: [f64; 12] = [
        2.0 / 3.0,
        1.0 / 5.0,
        3.0 / 28.0,
        5.0 / 72.0,
        35.0 / 704.0,
        63.0 / 1664.0,
        77.0 / 2560.0,
        429.0 / 17408.0,
        6435.0 / 311_296.0,
        12155.0 / 688_128.0,
        46189.0 / 3_014_656.0,
        88179.0 / 6_553_600.0,
    ];
    let u = s * s;
    let (u2, u4) = (u * u, u * u * u * u);
    let pair = |k: usize| T::splat(C[k]) + T::splat(C[k + 1]) * u;
    let low = pair(0) + pair(2) * u2;
    let middle = pair(4) + pair(6) * u2;
    let high = pair(8) + pair(10) * u2;
    let series = low + (middle + high * u4) * u4;
    radius * radius * s * u * series
}

/// The chord of two circles that overlap, at centre distance `distance` along `branch` (from
/// i's centre to j's): what [`disc_disc`] derives from the distance, written once for one pair
/// and for [lanes](crate::lanes) of pairs.
#[derive(Debug, Clone, Copy)]
pub struct DiscChord<T> {
    /// Unit normal from i towards j (x, y).
    pub normal: [T; 2],
    /// `R_i + R_j - d`.
    pub overlap: T,
    /// Depths of the two caps below the circles' outermost points along the normal.
    pub depth_i: T,
    pub depth_j: T,
    pub half_chord: T,
}

/// [`DiscChord`] of the circles of radii `radius_i` and `radius_j` (`reach` their sum) whose
/// centres lie `distance = |branch|` apart.
#[inline(always)]
pub fn disc_chord<T: Real>(
    branch: [T; 2],
    distance: T,
    radius_i: T,
    radius_j: T,
    reach: T,
) -> DiscChord<T> {
    let normal = [branch[0] / distance, branch[1] / distance];
    let overlap = reach - distance;
    // Depths of the two caps below the circles' outermost points along the normal, each
    // written as a product so that shallow contacts keep their precision:
    // `R_i - a = overlap (d + R_j - R_i) / (2 d)`, a the chord's distance from i's centre.
    let inv_two_distance = T::splat(0.5) / distance;
    let depth_i = overlap * (distance + radius_j - radius_i) * inv_two_distance;
    let depth_j = overlap * (distance + radius_i - radius_j) * inv_two_distance;
    let half_chord = (depth_i * (T::splat(2.0) * radius_i - depth_i))
        .max(T::splat(0.0))
        .sqrt();
    DiscChord {
        normal,
        overlap,
        depth_i,
        depth_j,
        half_chord,
    }
}

/// Whether circles whose centres lie `sqrt(distance_squared)` apart and whose radii sum to
/// `reach` do not overlap.
#[inline(always)]
pub fn discs_apart(distance_squared: f64, reach: f64) -> bool {
    distance_squared >= reach * reach
}

/// Whether one of two circles (radii `radius_i`, `radius_j`, centres `distance` apart) lies
/// inside the other: no crossing points (SPEC §9).
#[inline(always)]
pub fn disc_swallowed(distance: f64, radius_i: f64, radius_j: f64) -> bool {
    distance <= (radius_i - radius_j).abs()
}

/// Whether a chord of half length `half_chord` is too short to be a contact of circles of
/// radii summing to `reach` (its crossing points coincide to rounding).
#[inline(always)]
pub fn degenerate_chord(half_chord: f64, reach: f64) -> bool {
    half_chord <= 0.5 * f64::EPSILON * reach
}

/// Contact of the circle (centre `center_i`, radius `radius_i`) with the circle
/// (`center_j`, `radius_j`): the normal from i towards j, the chord of the two crossing points,
/// the two circular caps cut off by it and their depths, whose mean is
/// `delta_n = -(R_i + R_j - d) / 2`.
#[inline]
pub fn disc_disc(center_i: DVec2, radius_i: f64, center_j: DVec2, radius_j: f64) -> Overlap {
    let branch = center_j - center_i;
    let distance_squared = branch.length_squared();
    let reach = radius_i + radius_j;
    if discs_apart(distance_squared, reach) {
        return Overlap::Separate;
    }
    let distance = distance_squared.sqrt();
    if disc_swallowed(distance, radius_i, radius_j) {
        return Overlap::Swallowed;
    }
    let chord = disc_chord(branch.into(), distance, radius_i, radius_j, reach);
    let half_chord = chord.half_chord;
    if degenerate_chord(half_chord, reach) {
        return Overlap::Separate;
    }
    let normal = DVec2::from(chord.normal);
    let (distance_i, distance_j) = (radius_i - chord.depth_i, radius_j - chord.depth_j);
    Overlap::Contact(ContactGeometry {
        point: center_i + distance_i * normal,
        normal,
        length: 2.0 * half_chord,
        cap_area_i: chord_segment_area(radius_i, distance_i, half_chord),
        cap_area_j: chord_segment_area(radius_j, distance_j, half_chord),
        normal_gap: -0.5 * chord.overlap,
    })
}

/// Contact of the circle (`center`, `radius`) with the infinite wall through `wall_point` whose
/// unit normal `wall_normal` points into the domain: the chord lies on the wall, the cap is the
/// part of the disc beyond it and `delta_n` its depth.
#[inline]
pub fn disc_wall(center: DVec2, radius: f64, wall_point: DVec2, wall_normal: DVec2) -> Overlap {
    let height = (center - wall_point).dot(wall_normal);
    if height >= radius {
        return Overlap::Separate;
    }
    if height <= -radius {
        return Overlap::Swallowed;
    }
    let depth = radius - height;
    let half_chord = (depth * (2.0 * radius - depth)).sqrt();
    if half_chord <= 0.5 * f64::EPSILON * radius {
        return Overlap::Separate;
    }
    Overlap::Contact(ContactGeometry {
        point: center - height * wall_normal,
        normal: -wall_normal,
        length: 2.0 * half_chord,
        cap_area_i: chord_segment_area(radius, height, half_chord),
        cap_area_j: 0.0,
        normal_gap: -depth,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::intersection::tests::{contact, segment_area as direct_segment_area};
    use crate::geometry::{ContourTable, GrainShape, grain_grain, grain_wall};
    use std::f64::consts::PI;

    /// [`chord_segment_area`] of the cap of depth `depth` (`0 <= depth <= 2 radius`).
    fn segment_area(radius: f64, depth: f64) -> f64 {
        let half_chord = (depth * (2.0 * radius - depth)).max(0.0).sqrt();
        chord_segment_area(radius, radius - depth, half_chord)
    }

    #[test]
    fn segment_area_matches_the_direct_formula_and_the_half_disc() {
        // Expectation: R^2 acos(1 - h/R) - (R - h) sqrt(h (2R - h)), exact for a half disc
        // (h = R: pi R^2 / 2) and the whole disc (h = 2R); the series branch joins the direct one.
        let r = 1.7;
        assert!((segment_area(r, r) - 0.5 * PI * r * r).abs() < 1e-14);
        assert!((segment_area(r, 2.0 * r) - PI * r * r).abs() < 1e-13);
        for depth in [1e-3, 4e-3, 1e-2, 0.1, 0.5, 1.2, 3.0] {
            let direct = direct_segment_area(r, depth);
            let rel = (segment_area(r, depth) - direct).abs() / direct;
            assert!(
                rel < 1e-9,
                "depth {depth}: {} vs {direct}",
                segment_area(r, depth)
            );
        }
        // The series (sin theta <= 0.3) and the closed form meet at the switch: both against
        // R^2 asin(s) - d h, whose cancellation costs at most 7e-14 from s = 0.05 up.
        for s in [0.05, 0.15, 0.299_999, 0.300_001, 0.5] {
            let (half, distance) = (r * s, r * (1.0 - s * s).sqrt());
            let direct = r * r * s.asin() - distance * half;
            let rel = (chord_segment_area(r, distance, half) - direct).abs() / direct;
            assert!(rel < 1e-12, "s = {s}: relative difference {rel}");
        }
        // Shallow caps: A -> (4/3) sqrt(2 R) h^(3/2).
        let h: f64 = 1e-10;
        let limit = 4.0 / 3.0 * (2.0 * r).sqrt() * h.powf(1.5);
        assert!((segment_area(r, h) / limit - 1.0).abs() < 1e-9);
    }

    #[test]
    fn disc_disc_is_the_limit_of_the_polygon_kernel() {
        // Expectation: the polygon kernel converges to the closed form as dbeta -> 0, with an
        // error of the order of the polygon's sagitta s = R (1 - cos(dbeta / 2)) ~ R dbeta^2 / 8.
        // The polygon lies up to s inside the circle, so a crossing point moves along the chord
        // by up to s R / h (h the half chord: the chord meets the circle at an angle whose sine
        // is h / R); `bound` allows both.
        let (ri, rj) = (1.0, 0.7);
        let ci = DVec2::new(0.2, -0.1);
        for (angle, overlap) in [(0.3, 0.05), (2.0, 0.2), (-1.1, 0.4)] {
            let cj = ci + (ri + rj - overlap) * DVec2::from_angle(angle);
            let exact = contact(disc_disc(ci, ri, cj, rj));
            assert!((exact.normal_gap + 0.5 * overlap).abs() < 1e-15);
            let mut last_error = f64::INFINITY;
            for degrees in [2.0, 0.5, 0.125] {
                let table = ContourTable::new(degrees);
                let c = contact(grain_grain(
                    &table,
                    &GrainShape::disc(ci, ri),
                    &GrainShape::disc(cj, rj),
                ));
                let sagitta = ri * (1.0 - (0.5 * table.dbeta).cos());
                let bound = 4.0 * sagitta * (1.0 + 2.0 * ri / exact.length);
                let error = [
                    (c.length - exact.length).abs(),
                    (c.normal_gap - exact.normal_gap).abs(),
                    (c.point - exact.point).length(),
                    (c.cap_area_i - exact.cap_area_i).abs() / exact.length,
                    (c.cap_area_j - exact.cap_area_j).abs() / exact.length,
                ]
                .into_iter()
                .fold(0.0, f64::max);
                assert!(
                    error < bound,
                    "{degrees} deg: error {error}, sagitta {sagitta}"
                );
                assert!((c.normal - exact.normal).length() < 1e-3 * degrees);
                assert!(error < last_error);
                last_error = error;
            }
        }
    }

    #[test]
    fn disc_wall_is_the_limit_of_the_polygon_kernel() {
        // Expectation as for two discs; the chord lies on the wall, and the depth is off by at
        // most the sagitta (the deepest node lies within dbeta / 2 of the deepest point).
        let (r, center) = (0.8, DVec2::new(1.0, 0.3));
        let normal = DVec2::from_angle(0.7);
        for depth in [0.02, 0.3] {
            let point = center - (r - depth) * normal;
            let exact = contact(disc_wall(center, r, point, normal));
            assert!((exact.normal_gap + depth).abs() < 1e-15);
            assert_eq!(exact.normal, -normal);
            for degrees in [1.0, 0.25] {
                let table = ContourTable::new(degrees);
                let c = contact(grain_wall(
                    &table,
                    &GrainShape::disc(center, r),
                    point,
                    normal,
                ));
                let sagitta = r * (1.0 - (0.5 * table.dbeta).cos());
                let bound = 4.0 * sagitta * (1.0 + 2.0 * r / exact.length);
                assert!((c.length - exact.length).abs() < bound);
                assert!((c.normal_gap - exact.normal_gap).abs() <= sagitta * (1.0 + 1e-9));
                assert!((c.point - exact.point).length() < bound);
                assert!((c.cap_area_i - exact.cap_area_i).abs() < bound * exact.length);
            }
        }
    }

    #[test]
    fn disc_disc_is_symmetric_under_exchange() {
        // Expectation: swapping i and j reverses the normal, swaps the caps, keeps the rest.
        let (ci, cj) = (DVec2::new(0.0, 0.0), DVec2::new(0.9, 0.4));
        let a = contact(disc_disc(ci, 0.6, cj, 0.5));
        let b = contact(disc_disc(cj, 0.5, ci, 0.6));
        assert!((a.normal + b.normal).length() < 1e-15);
        assert!((a.point - b.point).length() < 1e-15);
        assert!((a.length - b.length).abs() < 1e-15);
        assert!((a.cap_area_i - b.cap_area_j).abs() < 1e-15);
        assert!((a.cap_area_j - b.cap_area_i).abs() < 1e-15);
        assert_eq!(a.normal_gap, b.normal_gap);
    }

    #[test]
    fn separate_touching_and_swallowed_cases() {
        let c = DVec2::new(0.5, 0.5);
        assert_eq!(
            disc_disc(c, 1.0, c + DVec2::X * 2.0, 1.0),
            Overlap::Separate
        );
        assert_eq!(
            disc_disc(c, 1.0, c + DVec2::X * 2.5, 1.0),
            Overlap::Separate
        );
        assert_eq!(
            disc_disc(c, 1.0, c + DVec2::X * 0.1, 0.5),
            Overlap::Swallowed
        );
        assert_eq!(disc_disc(c, 1.0, c, 1.0), Overlap::Swallowed);
        assert_eq!(
            disc_wall(c, 1.0, DVec2::new(0.0, -0.5), DVec2::Y),
            Overlap::Separate
        );
        assert_eq!(
            disc_wall(c, 1.0, DVec2::new(0.0, 1.6), DVec2::Y),
            Overlap::Swallowed
        );
        // Two equal discs half overlapping: the chord is the perpendicular bisector.
        let g = contact(disc_disc(DVec2::ZERO, 1.0, DVec2::X, 1.0));
        assert!((g.length - 3f64.sqrt()).abs() < 1e-15);
        assert!((g.point - DVec2::new(0.5, 0.0)).length() < 1e-15);
        let lens_half = (PI / 3.0 - 3f64.sqrt() / 4.0) * 1.0;
        assert!((g.cap_area_i - lens_half).abs() < 1e-14);
    }
}
