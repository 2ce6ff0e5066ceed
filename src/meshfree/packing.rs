//! Initial samples of non-overlapping star-shaped grains in a box (SPEC §10b; the seed's
//! 100-grain "sand-like" example starts from grains that touch neither each other nor the walls).
//!
//! Random sequential placement, largest grain first (small grains fill the gaps left by large
//! ones; the other order jams early). Each trial draws a rotation, then a centre uniformly among
//! the positions that keep the rotated contour inside the box with the clearance, and is accepted
//! if the contour keeps the clearance from every grain already placed. The test is made on the
//! contour polygons (polygon vertices; 256 points of the radius function for smooth shapes,
//! with the clearance raised by a rigorous bound on how far the true curve bulges past the
//! chords), after a broad phase on circumscribed circles.

use std::f64::consts::TAU;

use rand::SeedableRng;

use super::MeshfreeError;
use super::shape::{StarShape, point_in_polygon, point_segment_distance, segment_intersection};
use crate::geometry::angle::sin_cos;
use crate::portable::hypot;

/// Where a grain was placed: its centre (the origin of its shape) and the rotation applied to
/// its shape (radians, counter-clockwise; see [`StarShape::rotated`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlacedGrain {
    pub centre: [f64; 2],
    pub rotation: f64,
}

/// Points of the outline of smooth contours used by the overlap test.
pub const OUTLINE_POINTS: usize = 256;

/// Trials per grain before [`place_grains`] gives up.
pub const MAX_ATTEMPTS_PER_GRAIN: usize = 20_000;

/// A contour in absolute coordinates with its bounding box.
struct Placed {
    centre: [f64; 2],
    radius: f64,
    /// Bound on the true contour's excursion beyond the polygon.
    excess: f64,
    polygon: Vec<[f64; 2]>,
    bbox: [f64; 4],
}

fn bbox(p: &[[f64; 2]]) -> [f64; 4] {
    let mut b = [f64::MAX, f64::MAX, f64::MIN, f64::MIN];
    for v in p {
        b[0] = b[0].min(v[0]);
        b[1] = b[1].min(v[1]);
        b[2] = b[2].max(v[0]);
        b[3] = b[3].max(v[1]);
    }
    b
}

fn boxes_apart(a: &[f64; 4], b: &[f64; 4], gap: f64) -> bool {
    a[0] >= b[2] + gap || b[0] >= a[2] + gap || a[1] >= b[3] + gap || b[1] >= a[3] + gap
}

/// Distance between segments `ab` and `cd` (0 if they touch or cross).
fn segment_distance(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> f64 {
    if segment_intersection(a, b, c, d).is_some() {
        return 0.0;
    }
    point_segment_distance(a, c, d)
        .min(point_segment_distance(b, c, d))
        .min(point_segment_distance(c, a, b))
        .min(point_segment_distance(d, a, b))
}

/// Whether two closed polygons (simple) are at least `gap` apart: neither contains a vertex of
/// the other and no two edges come closer than `gap`.
pub(crate) fn polygons_apart(
    a: &[[f64; 2]],
    ba: &[f64; 4],
    b: &[[f64; 2]],
    bb: &[f64; 4],
    gap: f64,
) -> bool {
    if boxes_apart(ba, bb, gap) {
        return true;
    }
    if point_in_polygon(a[0], b) || point_in_polygon(b[0], a) {
        return false;
    }
    // Only edges that reach into the other polygon's box (grown by the gap) can be close.
    let near = |p: [f64; 2], q: [f64; 2], o: &[f64; 4]| {
        let e = [
            p[0].min(q[0]),
            p[1].min(q[1]),
            p[0].max(q[0]),
            p[1].max(q[1]),
        ];
        !boxes_apart(&e, o, gap)
    };
    let edges = |poly: &[[f64; 2]], other: &[f64; 4]| -> Vec<([f64; 2], [f64; 2], [f64; 4])> {
        let n = poly.len();
        (0..n)
            .map(|i| (poly[i], poly[(i + 1) % n]))
            .filter(|&(p, q)| near(p, q, other))
            .map(|(p, q)| {
                (
                    p,
                    q,
                    [
                        p[0].min(q[0]),
                        p[1].min(q[1]),
                        p[0].max(q[0]),
                        p[1].max(q[1]),
                    ],
                )
            })
            .collect()
    };
    let ea = edges(a, bb);
    let eb = edges(b, ba);
    for &(p, q, bp) in &ea {
        for &(r, s, br) in &eb {
            if !boxes_apart(&bp, &br, gap) && segment_distance(p, q, r, s) < gap {
                return false;
            }
        }
    }
    // With a zero gap, touching edges give distance 0, which is not < 0: treat crossing edges
    // as overlap explicitly.
    if gap == 0.0 {
        for &(p, q, _) in &ea {
            for &(r, s, _) in &eb {
                if segment_intersection(p, q, r, s).is_some() {
                    return false;
                }
            }
        }
    }
    true
}

fn unit(rng: &mut rand_chacha::ChaCha8Rng) -> f64 {
    super::shape::unit_f64(rng)
}

/// Places `shapes` (in the order given; the result is in the same order) without overlap in
/// the box `bounds = [x0, x1, y0, y1]`, with a clearance `gap` from each other and from the
/// walls, by random sequential placement from a ChaCha8 generator seeded with `seed`, largest
/// grain first, each with a random orientation (deterministic for a seed).
///
/// Fails with `BadInput` for invalid input (naming the grain whose shape is invalid) or when a
/// grain cannot be placed within [`MAX_ATTEMPTS_PER_GRAIN`] trials (naming the grain and the
/// packing fraction reached: enlarge the box, or use fewer or smaller grains).
pub fn place_grains(
    shapes: &[StarShape],
    bounds: [f64; 4],
    gap: f64,
    seed: u64,
) -> Result<Vec<PlacedGrain>, MeshfreeError> {
    let [x0, x1, y0, y1] = bounds;
    if !(bounds.iter().all(|b| b.is_finite()) && x1 > x0 && y1 > y0) {
        return Err(MeshfreeError::BadInput(format!(
            "box bounds [x0, x1, y0, y1] must be finite with x1 > x0 and y1 > y0, got {bounds:?}"
        )));
    }
    if !(gap.is_finite() && gap >= 0.0) {
        return Err(MeshfreeError::BadInput(format!(
            "gap must be finite and >= 0, got {gap}"
        )));
    }
    for (i, s) in shapes.iter().enumerate() {
        s.validate()
            .map_err(|e| MeshfreeError::BadInput(format!("grain {i}: {e}")))?;
    }
    let box_area = (x1 - x0) * (y1 - y0);
    let radii: Vec<f64> = shapes.iter().map(StarShape::max_radius).collect();
    let mut order: Vec<usize> = (0..shapes.len()).collect();
    order.sort_by(|&a, &b| radii[b].total_cmp(&radii[a]).then(a.cmp(&b)));

    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut placed: Vec<Placed> = Vec::with_capacity(shapes.len());
    let mut result = vec![
        PlacedGrain {
            centre: [f64::NAN; 2],
            rotation: 0.0
        };
        shapes.len()
    ];
    let mut placed_area = 0.0;
    for (rank, &i) in order.iter().enumerate() {
        let shape = &shapes[i];
        let outline = shape.outline(OUTLINE_POINTS);
        let excess = shape.outline_error(OUTLINE_POINTS);
        let mut done = false;
        for _ in 0..MAX_ATTEMPTS_PER_GRAIN {
            let rotation = TAU * unit(&mut rng);
            let (s, c) = sin_cos(rotation);
            let rotated: Vec<[f64; 2]> = outline
                .iter()
                .map(|v| [c * v[0] - s * v[1], s * v[0] + c * v[1]])
                .collect();
            let b = bbox(&rotated);
            let clear = gap + excess;
            let (lo_x, hi_x) = (x0 + clear - b[0], x1 - clear - b[2]);
            let (lo_y, hi_y) = (y0 + clear - b[1], y1 - clear - b[3]);
            // Draw the centre even when the range is empty, so the stream does not depend on it.
            let (u, v) = (unit(&mut rng), unit(&mut rng));
            if lo_x > hi_x || lo_y > hi_y {
                continue;
            }
            let centre = [lo_x + u * (hi_x - lo_x), lo_y + v * (hi_y - lo_y)];
            let polygon: Vec<[f64; 2]> = rotated
                .iter()
                .map(|p| [p[0] + centre[0], p[1] + centre[1]])
                .collect();
            let pb = bbox(&polygon);
            let free = placed.iter().all(|q| {
                let d = hypot(centre[0] - q.centre[0], centre[1] - q.centre[1]);
                d >= radii[i] + q.radius + gap
                    || polygons_apart(&polygon, &pb, &q.polygon, &q.bbox, gap + excess + q.excess)
            });
            if free {
                placed.push(Placed {
                    centre,
                    radius: radii[i],
                    excess,
                    polygon,
                    bbox: pb,
                });
                placed_area += shape.area();
                result[i] = PlacedGrain { centre, rotation };
                done = true;
                break;
            }
        }
        if !done {
            return Err(MeshfreeError::BadInput(format!(
                "could not place grain {i} (circumscribed radius {:.4}, the {}th largest) after \
                 {MAX_ATTEMPTS_PER_GRAIN} trials: {rank} of {} grains placed, packing fraction \
                 {:.3} of the box {bounds:?} with gap {gap}; enlarge the box or use fewer or \
                 smaller grains (random sequential placement jams near 0.5)",
                radii[i],
                rank + 1,
                shapes.len(),
                placed_area / box_area
            )));
        }
    }
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::meshfree::discretization::IntegrationMesh;
    use crate::meshfree::shape::{place_nodes, polygon_area, sand_like_sample};

    /// Fine outline of the true contour of a placed grain, in absolute coordinates.
    fn fine_contour(shape: &StarShape, g: &PlacedGrain, n: usize) -> Vec<[f64; 2]> {
        let s = shape.rotated(g.rotation);
        let pts = match &s {
            StarShape::Polygon { vertices } => {
                // Subdivide each edge so that the check samples edges too.
                let m = vertices.len();
                (0..m)
                    .flat_map(|k| {
                        let (a, b) = (vertices[k], vertices[(k + 1) % m]);
                        (0..16).map(move |j| {
                            let t = j as f64 / 16.0;
                            [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
                        })
                    })
                    .collect()
            }
            _ => s.outline(n),
        };
        pts.iter()
            .map(|p| [p[0] + g.centre[0], p[1] + g.centre[1]])
            .collect()
    }

    /// Independent check: no point of one true contour within `gap` of the other's inside,
    /// using the exact radius function of the other (not the placement's polygons), and no
    /// crossing of the fine polygons.
    fn check_sample(shapes: &[StarShape], placed: &[PlacedGrain], bounds: [f64; 4], gap: f64) {
        let contours: Vec<Vec<[f64; 2]>> = shapes
            .iter()
            .zip(placed)
            .map(|(s, g)| fine_contour(s, g, 1024))
            .collect();
        for c in &contours {
            for p in c {
                assert!(p[0] >= bounds[0] + gap - 1e-12 && p[0] <= bounds[1] - gap + 1e-12);
                assert!(p[1] >= bounds[2] + gap - 1e-12 && p[1] <= bounds[3] - gap + 1e-12);
            }
        }
        for i in 0..shapes.len() {
            for j in 0..shapes.len() {
                if i == j {
                    continue;
                }
                let d = (placed[i].centre[0] - placed[j].centre[0])
                    .hypot(placed[i].centre[1] - placed[j].centre[1]);
                if d > shapes[i].max_radius() + shapes[j].max_radius() + gap {
                    continue;
                }
                let sj = shapes[j].rotated(placed[j].rotation);
                for p in &contours[i] {
                    let q = [p[0] - placed[j].centre[0], p[1] - placed[j].centre[1]];
                    // Grown by the gap (to first order): inside the contour of j dilated by gap.
                    let t = q[1].atan2(q[0]);
                    assert!(
                        q[0].hypot(q[1]) > sj.radius_at(t),
                        "grain {i} point {p:?} inside grain {j}"
                    );
                }
                if i < j {
                    let (a, b) = (&contours[i], &contours[j]);
                    let (ba, bb) = (bbox(a), bbox(b));
                    // Slightly below the gap: the fine polygons are inscribed in the contours.
                    assert!(
                        polygons_apart(a, &ba, b, &bb, 0.99 * gap),
                        "grains {i} and {j} closer than the gap"
                    );
                }
            }
        }
    }

    #[test]
    fn placed_grains_do_not_overlap_and_are_deterministic() {
        let mut shapes = sand_like_sample(30, 1.0, 0.2, 3);
        let star: Vec<[f64; 2]> = (0..10)
            .map(|k| {
                let t = std::f64::consts::PI * k as f64 / 5.0;
                let r = if k % 2 == 0 { 1.2 } else { 0.6 };
                [r * t.cos(), r * t.sin()]
            })
            .collect();
        shapes.push(StarShape::Polygon { vertices: star });
        shapes.push(StarShape::Disc { radius: 0.9 });
        let bounds = [0.0, 16.0, -2.0, 14.0];
        let gap = 0.05;
        let a = place_grains(&shapes, bounds, gap, 11).unwrap();
        check_sample(&shapes, &a, bounds, gap);
        assert_eq!(a, place_grains(&shapes, bounds, gap, 11).unwrap());
        assert_ne!(a, place_grains(&shapes, bounds, gap, 12).unwrap());

        // The overlap test itself: two squares, apart, closer than the gap, overlapping, nested.
        let sq = |x: f64, y: f64, h: f64| {
            vec![
                [x - h, y - h],
                [x + h, y - h],
                [x + h, y + h],
                [x - h, y + h],
            ]
        };
        let t =
            |a: &[[f64; 2]], b: &[[f64; 2]], g: f64| polygons_apart(a, &bbox(a), b, &bbox(b), g);
        assert!(t(&sq(0.0, 0.0, 1.0), &sq(2.5, 0.3, 0.4), 0.1));
        assert!(!t(&sq(0.0, 0.0, 1.0), &sq(1.45, 0.3, 0.4), 0.1));
        assert!(!t(&sq(0.0, 0.0, 1.0), &sq(1.2, 0.9, 0.4), 0.0));
        assert!(!t(&sq(0.0, 0.0, 1.0), &sq(0.1, 0.1, 0.2), 0.0));
    }

    #[test]
    fn impossible_packing_fails_clearly() {
        let shapes = vec![StarShape::Disc { radius: 1.0 }; 10];
        let e = place_grains(&shapes, [0.0, 4.0, 0.0, 4.0], 0.0, 1)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("could not place grain") && e.contains("packing fraction"),
            "{e}"
        );
        let e = place_grains(&shapes, [0.0, -1.0, 0.0, 4.0], 0.0, 1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("bounds"), "{e}");
        assert!(place_grains(&shapes, [0.0, 40.0, 0.0, 40.0], -0.1, 1).is_err());
    }

    /// The seed paper's example: 100 sand-like grains, ~100 field nodes each (at least 30), in
    /// a square box without contacts.
    #[test]
    fn paper_sample_of_100_sand_like_grains() {
        let started = std::time::Instant::now();
        let shapes = sand_like_sample(100, 1.0, 0.2, 2016);
        let area: f64 = shapes.iter().map(StarShape::area).sum();
        let side = (area / 0.45).sqrt();
        let bounds = [0.0, side, 0.0, side];
        let placed = place_grains(&shapes, bounds, 0.02, 7).unwrap();
        let t_place = started.elapsed();
        check_sample(&shapes, &placed, bounds, 0.02);
        let t_check = started.elapsed();
        let spacing = 0.17;
        let mut counts = Vec::new();
        for s in &shapes {
            let nodes = place_nodes(s, spacing, 1.0).unwrap();
            let mesh =
                IntegrationMesh::inside_boundary(&nodes.positions, nodes.boundary_count).unwrap();
            assert!((mesh.area - polygon_area(nodes.boundary())).abs() < 1e-12);
            counts.push(nodes.len());
        }
        let mean = counts.iter().sum::<usize>() as f64 / counts.len() as f64;
        let min = *counts.iter().min().unwrap();
        eprintln!(
            "100 grains: packing {:.3}, box side {side:.2}, nodes mean {mean:.1} min {min} max {}, \
             placement {t_place:?}, check until {t_check:?}, total {:?}",
            area / (side * side),
            counts.iter().max().unwrap(),
            started.elapsed()
        );
        assert!(min >= 30, "min {min}");
        assert!((80.0..=120.0).contains(&mean), "mean {mean}");
    }
}
