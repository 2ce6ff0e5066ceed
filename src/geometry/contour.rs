//! Contour polygons of deformed grains (SPEC §2).
//!
//! A grain of reference radius `R` is discretised by `N = 360°/dbeta` contour nodes placed on
//! its reference circle at angles `beta_k = k * dbeta`. Its current shape is the affine image of
//! that circle: `x_k = c + A R (cos beta_k, sin beta_k)` with `A = Q(theta) U`,
//! `U = I + Q(alpha) diag(eps1, eps2) Q(alpha)^T`.
//!
//! Every contact computation works in *reference coordinates* of one grain: `u = (A R)^-1 (x - c)`,
//! where that grain's polygon is the regular N-gon inscribed in the unit circle. Affine maps
//! preserve incidence, convexity and the order of the nodes, so "inside the polygon" and "where
//! does a segment leave the polygon" are answered exactly there, with a table of the N-gon.

use super::{affine, angle};
use crate::lanes::Real;
use glam::{DMat2, DVec2};

/// The unit regular polygon shared by every grain of a run: node directions and edge normals.
#[derive(Debug, Clone)]
pub struct ContourTable {
    /// Number of contour nodes per grain.
    pub nodes: usize,
    /// Angular step between nodes, radians.
    pub dbeta: f64,
    /// `(cos beta_k, sin beta_k)` for each node k.
    pub vertex: Vec<DVec2>,
    /// `vertex` three times over, so that `vertex_at(k)` needs no modulo for k in [-N, 2N),
    /// the range every chain search stays in.
    vertex_ring: Vec<DVec2>,
    /// Edge k (from node k to node k+1) with its unit outward normal, at angle
    /// `(k + 1/2) dbeta`: ends and normal side by side, so the hot loops that walk edges load
    /// one record (one bounds check) instead of three.
    edges: Vec<Edge>,
    /// Distance from the centre to every edge of the unit polygon: `cos(dbeta / 2)`.
    pub apothem: f64,
    /// `apothem^2`: points closer to the centre than this are inside for sure.
    pub apothem_squared: f64,
    /// `sin(dbeta)`: twice the area of the triangle (centre, node k, node k+1) of the unit polygon.
    pub sin_dbeta: f64,
}

impl ContourTable {
    /// Table for a contour resolution `dbeta_deg` (degrees). The node count is `round(360/dbeta)`
    /// (at least 8), so the effective step is `360° / nodes`.
    pub fn new(dbeta_deg: f64) -> Self {
        let nodes = ((360.0 / dbeta_deg).round() as usize).max(8);
        Self::with_nodes(nodes)
    }

    pub fn with_nodes(nodes: usize) -> Self {
        let dbeta = std::f64::consts::TAU / nodes as f64;
        let vertex = (0..nodes)
            .map(|k| {
                let (s, c) = angle::sin_cos(k as f64 * dbeta);
                DVec2::new(c, s)
            })
            .collect::<Vec<DVec2>>();
        let vertex_ring = vertex
            .iter()
            .chain(&vertex)
            .chain(&vertex)
            .copied()
            .collect();
        let apothem = angle::cos(0.5 * dbeta);
        let edges = (0..nodes)
            .map(|k| {
                let (s, c) = angle::sin_cos((k as f64 + 0.5) * dbeta);
                Edge {
                    start: vertex[k],
                    end: vertex[(k + 1) % nodes],
                    normal: DVec2::new(c, s),
                }
            })
            .collect();
        Self {
            nodes,
            dbeta,
            vertex,
            vertex_ring,
            edges,
            apothem,
            apothem_squared: apothem.powi(2),
            sin_dbeta: angle::sin(dbeta),
        }
    }

    /// Index k modulo N for any signed k.
    #[inline]
    pub fn wrap(&self, k: isize) -> usize {
        let n = self.nodes as isize;
        // Indices stay within one turn of [0, N) in every caller: skip the division.
        if (0..n).contains(&k) {
            k as usize
        } else if (-n..0).contains(&k) {
            (k + n) as usize
        } else if (n..2 * n).contains(&k) {
            (k - n) as usize
        } else {
            k.rem_euclid(n) as usize
        }
    }

    /// Reference direction of node k (any signed k).
    #[inline]
    pub fn vertex_at(&self, k: isize) -> DVec2 {
        // Below -N the shifted index wraps to a huge usize and misses the ring as well.
        match self.vertex_ring.get((k + self.nodes as isize) as usize) {
            Some(&v) => v,
            None => self.vertex[self.wrap(k)],
        }
    }

    /// Reference direction of node k for k in [-N, 2N), the range of a chain whose first node
    /// lies in [0, N) (and of its neighbours): one load from the ring, where [`vertex_at`]
    /// chooses between the ring and a wrapped index. Panics outside that range.
    ///
    /// [`vertex_at`]: Self::vertex_at
    #[inline(always)]
    pub fn vertex_near(&self, k: isize) -> DVec2 {
        self.vertex_ring[(k + self.nodes as isize) as usize]
    }

    /// The vertices three times over: node k (k in [-N, 2N)) at index k + N, so that a
    /// kernel loads consecutive nodes as one block of memory.
    #[inline(always)]
    pub fn vertex_ring(&self) -> &[DVec2] {
        &self.vertex_ring
    }

    /// Node index nearest to the reference angle `beta` (radians, any range).
    #[inline]
    pub fn nearest_node(&self, beta: f64) -> isize {
        (beta / self.dbeta).round() as isize
    }

    /// The edge (sector) of the unit polygon that the ray from the centre through `u` crosses:
    /// `s` with `angle(u)` in `[s dbeta, (s+1) dbeta)`.
    ///
    /// The angle comes from a polynomial arctangent (error < 2e-5 rad, well under any sector
    /// width in use) and `refine_sector` settles the exact sector with cross products, so the
    /// result is exact.
    #[inline]
    pub fn sector(&self, u: DVec2) -> usize {
        let mut phi = fast_atan2(u.y, u.x);
        if phi < 0.0 {
            phi += std::f64::consts::TAU;
        }
        let s = ((phi / self.dbeta) as usize).min(self.nodes - 1);
        self.refine_sector(u, s)
    }

    /// Moves a sector guess `s` to the sector that holds `u`, one edge at a time: O(1) when the
    /// guess is close, as it is for consecutive nodes of a walk along a contour.
    #[inline]
    pub fn refine_sector(&self, u: DVec2, mut s: usize) -> usize {
        let n = self.nodes;
        for _ in 0..n {
            let edge = self.edge(s);
            if edge.start.perp_dot(u) < 0.0 {
                s = self.previous(s);
            } else if edge.end.perp_dot(u) >= 0.0 {
                s = self.next(s);
            } else {
                break;
            }
        }
        s
    }

    /// Edge k (k in [0, N)).
    #[inline(always)]
    pub fn edge(&self, k: usize) -> &Edge {
        &self.edges[k]
    }

    /// The unit polygon's edges, edge k from node k to node k + 1.
    #[inline(always)]
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// Index k + 1 modulo N, for k in [0, N): no division on the hot path.
    #[inline]
    pub fn next(&self, k: usize) -> usize {
        if k + 1 == self.nodes { 0 } else { k + 1 }
    }

    /// Index k - 1 modulo N, for k in [0, N).
    #[inline]
    pub fn previous(&self, k: usize) -> usize {
        if k == 0 { self.nodes - 1 } else { k - 1 }
    }

    /// Gauge (Minkowski functional) of the unit polygon at `u`, given the sector that holds `u`:
    /// `< 1` strictly inside, `1` on the boundary, `> 1` outside.
    #[inline]
    pub fn gauge(&self, u: DVec2, sector: usize) -> f64 {
        u.dot(self.edge(sector).normal) / self.apothem
    }

    /// Whether `u` lies strictly inside the unit polygon. The inscribed circle (radius =
    /// apothem) and the circumscribed one (radius 1) settle almost every point with one dot
    /// product; only points in the thin ring between them need their sector.
    #[inline(always)]
    pub fn contains(&self, u: DVec2) -> bool {
        let r2 = u.length_squared();
        if r2 < self.apothem_squared {
            true
        } else if r2 >= 1.0 {
            false
        } else {
            self.contains_in_ring(u)
        }
    }

    /// [`contains`](Self::contains) for a point in the ring between the inscribed and the
    /// circumscribed circles: out of line, so that the two one-comparison cases inline into
    /// the chain searches.
    #[inline(never)]
    fn contains_in_ring(&self, u: DVec2) -> bool {
        self.gauge(u, self.sector(u)) < 1.0
    }

    /// Where the segment from `inside` (gauge < 1) to `outside` (gauge >= 1) leaves the unit
    /// polygon, as the parameter t in (0, 1]. The polygon is convex and contains the origin, so
    /// its gauge is the maximum over edges of `u . n_s / apothem`; along the segment the exit is
    /// the smallest t at which an edge's constraint becomes active. Only the edges swept between
    /// the two endpoints' sectors can be the exit edge.
    pub fn exit_parameter(
        &self,
        inside: DVec2,
        sector_inside: usize,
        outside: DVec2,
        sector_outside: usize,
    ) -> f64 {
        let n = self.nodes;
        let d = outside - inside;
        // Walk from the inside sector to the outside one along the shorter way round.
        let forward = if sector_outside >= sector_inside {
            sector_outside - sector_inside
        } else {
            sector_outside + n - sector_inside
        };
        let backward = n - forward;
        let (steps, step_forward) = if forward <= backward {
            (forward, true)
        } else {
            (backward, false)
        };
        let mut best = 1.0_f64;
        let mut s = sector_inside;
        for _ in 0..=steps {
            let normal = self.edge(s).normal;
            let rate = d.dot(normal);
            if rate > 0.0 {
                let t = (self.apothem - inside.dot(normal)) / rate;
                if t < best {
                    best = t;
                }
            }
            s = if step_forward {
                self.next(s)
            } else {
                self.previous(s)
            };
        }
        best.clamp(0.0, 1.0)
    }
}

/// One edge of the unit polygon: from node k to node k+1, with its outward normal (in this
/// order in memory, where a kernel loads them together).
#[derive(Debug, Clone, Copy)]
#[repr(C)]
pub struct Edge {
    pub start: DVec2,
    pub end: DVec2,
    pub normal: DVec2,
}

/// `atan2(y, x)` to within 2e-5 rad (1.15e-5 measured): a minimax polynomial for atan on [0, 1] with octant
/// reduction. Only ever used as a first guess that exact tests then correct.
#[inline]
pub fn fast_atan2(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let (num, den) = if ay > ax { (ax, ay) } else { (ay, ax) };
    if den == 0.0 {
        return 0.0;
    }
    let t = num / den;
    let t2 = t * t;
    // atan(t) on [0, 1], max error 1.15e-5.
    let mut a = t
        * (0.999_866_0
            + t2 * (-0.330_299_5 + t2 * (0.180_141_0 + t2 * (-0.085_133_0 + t2 * 0.020_835_1))));
    if ay > ax {
        a = FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    if y < 0.0 { -a } else { a }
}

/// The current shape of one grain, as needed by the contact kernels.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GrainShape {
    /// Centre of mass.
    pub center: DVec2,
    /// `A R`: maps the unit reference circle onto the current contour (relative to the centre).
    pub map: DMat2,
    /// Radius of a circle about the centre that contains the whole contour:
    /// `R max(1 + eps1, 1 + eps2)`.
    pub bounding_radius: f64,
    /// The shape is the circle of radius `bounding_radius`, laid unrotated (`map` is that
    /// radius times the identity): a frame's circle (see `Frame::circle`), whose inverse map is
    /// `1 / radius` times the identity.
    pub circle: bool,
}

/// The deformation gradient `A = Q(theta) U` of SPEC §2 (paper eq. 49–53).
pub fn deformation_gradient(theta: f64, eps1: f64, eps2: f64, alpha: f64) -> DMat2 {
    let stretch = principal_stretch(eps1, eps2, alpha);
    angle::rotation_by(theta) * stretch
}

/// The rotation `Q` by the angle whose sine and cosine are given (what `DMat2::from_angle`
/// builds, for callers that already hold the sine and cosine).
#[inline]
pub fn rotation(sin: f64, cos: f64) -> DMat2 {
    affine::rotation(sin, cos).to_glam()
}

/// `J`, the rotation by 90 degrees: a rigid spin omega has the velocity gradient `omega J`.
pub const QUARTER_TURN: DMat2 = DMat2::from_cols(DVec2::new(0.0, 1.0), DVec2::new(-1.0, 0.0));

/// The symmetric stretch `U = I + Q(alpha) diag(eps1, eps2) Q(alpha)^T`.
pub fn principal_stretch(eps1: f64, eps2: f64, alpha: f64) -> DMat2 {
    let (s, c) = angle::sin_cos(alpha);
    affine::stretch(eps1, eps2, s, c).to_glam()
}

impl GrainShape {
    pub fn new(center: DVec2, radius: f64, theta: f64, eps1: f64, eps2: f64, alpha: f64) -> Self {
        Self::from_deformation(
            center,
            radius,
            deformation_gradient(theta, eps1, eps2, alpha),
            eps1,
            eps2,
        )
    }

    /// The shape for a deformation gradient `A` already built from the grain's angles.
    #[inline]
    pub fn from_deformation(
        center: DVec2,
        radius: f64,
        deformation: DMat2,
        eps1: f64,
        eps2: f64,
    ) -> Self {
        Self::from_map(center, deformation * radius, radius, eps1, eps2)
    }

    /// The shape whose map `A R` is already built, of a grain of reference radius `radius`.
    #[inline]
    pub fn from_map(center: DVec2, map: DMat2, radius: f64, eps1: f64, eps2: f64) -> Self {
        Self {
            center,
            map,
            bounding_radius: Self::bounding_radius_of(radius, eps1, eps2),
            circle: false,
        }
    }

    /// [`GrainShape::bounding_radius`] of a grain of reference radius `radius` and strains
    /// `eps1`, `eps2`: of one grain, or of lanes of grains (the grain pass's blocks). Over
    /// `f64` it gives `f64::max`'s bits: the two maxima differ at most in a zero's sign, which
    /// `1 +` erases.
    #[inline(always)]
    pub fn bounding_radius_of<T: Real>(radius: T, eps1: T, eps2: T) -> T {
        radius * (T::splat(1.0) + eps1.max(eps2))
    }

    /// `(A R)^-1`: current coordinates (relative to the centre) to reference coordinates.
    /// Computed where it is needed rather than stored: a contact of two polygons needs one
    /// grain's inverse on its common path, and the shapes are built for each pair from the
    /// frames (issue #16).
    #[inline]
    pub fn inv_map(&self) -> DMat2 {
        if self.circle {
            DMat2::from_diagonal(DVec2::splat(1.0 / self.bounding_radius))
        } else {
            self.map.inverse()
        }
    }

    /// A rigid disc.
    pub fn disc(center: DVec2, radius: f64) -> Self {
        Self::new(center, radius, 0.0, 0.0, 0.0, 0.0)
    }

    /// Position of contour node k (relative to the grain centre).
    #[inline]
    pub fn node_offset(&self, table: &ContourTable, k: usize) -> DVec2 {
        self.map * table.vertex[k]
    }

    /// Position of contour node k.
    #[inline]
    pub fn node(&self, table: &ContourTable, k: usize) -> DVec2 {
        self.center + self.node_offset(table, k)
    }

    /// Area of the full contour polygon: `N/2 sin(dbeta) det(A R)`.
    pub fn polygon_area(&self, table: &ContourTable) -> f64 {
        0.5 * table.nodes as f64 * table.sin_dbeta * self.map.determinant()
    }
}

/// Twice the signed area of the triangle (o, a, b), i.e. the cross product (a - o) x (b - o).
#[inline]
pub fn cross(o: DVec2, a: DVec2, b: DVec2) -> f64 {
    (a - o).perp_dot(b - o)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sector_and_gauge_of_the_unit_polygon() {
        let table = ContourTable::new(10.0);
        // A vertex lies on the boundary; the mid-edge point at the apothem too.
        for k in 0..table.nodes {
            let v = table.vertex[k] * 0.999_999_999;
            let s = table.sector(v);
            assert!(table.gauge(v, s) < 1.0);
            let mid = table.edge(k).normal * table.apothem;
            let s = table.sector(mid);
            assert_eq!(s, k);
            assert!((table.gauge(mid, s) - 1.0).abs() < 1e-12);
        }
        // refine_sector from a wrong guess reaches the same sector.
        let u = DVec2::new(-0.3, -0.8);
        assert_eq!(table.refine_sector(u, 0), table.sector(u));
    }

    #[test]
    fn edges_join_consecutive_nodes_with_their_outward_normal() {
        // Expectation: edge k runs from node k to node k+1 (node 0 after the last), its normal
        // is perpendicular to it, and the edge lies at the apothem along that normal.
        for nodes in [8, 13, 360] {
            let table = ContourTable::with_nodes(nodes);
            for k in 0..nodes {
                let edge = table.edge(k);
                assert_eq!(edge.start, table.vertex[k]);
                assert_eq!(edge.end, table.vertex[table.next(k)]);
                assert!((edge.end - edge.start).dot(edge.normal).abs() < 1e-12);
                assert!((edge.start.dot(edge.normal) - table.apothem).abs() < 1e-12);
                assert!((edge.end.dot(edge.normal) - table.apothem).abs() < 1e-12);
            }
        }
    }
    #[test]
    fn fast_atan2_is_within_2e_5_of_atan2_everywhere() {
        for k in 0..100_000 {
            let phi = -3.2 + 6.4 * k as f64 / 100_000.0;
            for r in [1e-3, 1.0, 1e3] {
                let (y, x) = (r * phi.sin(), r * phi.cos());
                assert!((fast_atan2(y, x) - y.atan2(x)).abs() < 2e-5, "{phi}");
            }
        }
    }

    #[test]
    fn sector_agrees_with_the_exact_angle_at_every_resolution() {
        for deg in [0.25, 1.0, 5.0] {
            let table = ContourTable::new(deg);
            for k in 0..20_000 {
                let u = DVec2::from_angle(k as f64 * 0.000_314_159_3 + 1e-9) * 0.9;
                let mut phi = u.y.atan2(u.x);
                if phi < 0.0 {
                    phi += std::f64::consts::TAU;
                }
                let s = table.sector(u);
                assert!(
                    table.vertex[s].perp_dot(u) >= 0.0
                        && table.vertex[(s + 1) % table.nodes].perp_dot(u) < 0.0
                );
                let approx = ((phi / table.dbeta) as usize).min(table.nodes - 1);
                assert!(
                    s == approx
                        || (s as isize - approx as isize).abs() == 1
                        || (s == 0 || approx == 0)
                );
            }
        }
    }

    #[test]
    fn exit_parameter_finds_the_boundary() {
        let table = ContourTable::new(7.0);
        let inside = DVec2::new(0.1, 0.2);
        for k in 0..50 {
            let dir = DVec2::from_angle(k as f64 * 0.37);
            let outside = dir * 1.5;
            let t =
                table.exit_parameter(inside, table.sector(inside), outside, table.sector(outside));
            let p = inside + (outside - inside) * t;
            let g = table.gauge(p, table.sector(p));
            assert!((g - 1.0).abs() < 1e-12, "gauge {g} at exit");
        }
    }

    #[test]
    fn polygon_area_of_an_ellipse_converges_to_pi_a_b() {
        // Expectation: the inscribed polygon's area tends to pi a b as dbeta -> 0, with error
        // O(dbeta^2) (relative error 1 - sin(dbeta)/dbeta ~ dbeta^2/6).
        let shape = GrainShape::new(DVec2::ZERO, 2.0, 0.3, 0.2, -0.1, 0.7);
        let exact = std::f64::consts::PI * 4.0 * 1.2 * 0.9;
        for deg in [4.0, 2.0, 1.0] {
            let table = ContourTable::new(deg);
            let rel = (exact - shape.polygon_area(&table)) / exact;
            let expected = table.dbeta * table.dbeta / 6.0;
            assert!(
                (rel - expected).abs() < 0.01 * expected,
                "{deg}: {rel} vs {expected}"
            );
        }
    }
}
