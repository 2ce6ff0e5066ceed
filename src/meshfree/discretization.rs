//! Field nodes of a disc, the integration triangulation and its Gauss points (SPEC §10).

use spade::{ConstrainedDelaunayTriangulation, DelaunayTriangulation, Point2, Triangulation};

use super::MeshfreeError;
use crate::geometry::angle::{cos, sin};

/// How densely a disc is filled with field nodes.
///
/// The boundary ring holds `boundary_nodes` nodes (a multiple of 4, so that the node set is
/// symmetric about both axes). Inside, the target spacing grows linearly from the boundary
/// spacing `s0 = 2 pi R / boundary_nodes` at the contour to `(1 + grading) s0` at the centre, so
/// refining `boundary_nodes` refines the whole disc in proportion (a true h-refinement).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeDensity {
    pub boundary_nodes: usize,
    pub grading: f64,
}

impl NodeDensity {
    pub fn new(boundary_nodes: usize) -> Self {
        Self {
            boundary_nodes,
            grading: 1.0,
        }
    }
}

/// Field nodes of a disc centred at the origin.
#[derive(Debug, Clone)]
pub struct DiscNodes {
    pub radius: f64,
    /// Reference positions; the first `boundary_count` are the contour, in counter-clockwise
    /// order starting at angle 0.
    pub positions: Vec<[f64; 2]>,
    pub boundary_count: usize,
}

impl DiscNodes {
    /// Concentric rings of nodes. Ring k has a multiple of 4 nodes, at angles `j 2pi/n` or
    /// `(j + 1/2) 2pi/n` (alternating), which keeps the set symmetric about both axes.
    pub fn disc(radius: f64, density: NodeDensity) -> Result<Self, MeshfreeError> {
        let nb = density.boundary_nodes;
        if !(radius.is_finite() && radius > 0.0) {
            return Err(MeshfreeError::BadInput(format!(
                "disc radius must be positive and finite, got {radius}"
            )));
        }
        if nb < 8 || !nb.is_multiple_of(4) {
            return Err(MeshfreeError::BadInput(format!(
                "boundary_nodes must be a multiple of 4 and at least 8, got {nb}"
            )));
        }
        if !(density.grading.is_finite() && density.grading >= 0.0) {
            return Err(MeshfreeError::BadInput(format!(
                "grading must be >= 0, got {}",
                density.grading
            )));
        }
        let s0 = 2.0 * std::f64::consts::PI * radius / nb as f64;
        let spacing = |r: f64| s0 * (1.0 + density.grading * (radius - r) / radius);
        let mut positions = Vec::new();
        let mut r = radius;
        let mut ring = 0usize;
        loop {
            let s = spacing(r);
            let n = if ring == 0 {
                nb
            } else {
                4 * ((2.0 * std::f64::consts::PI * r / s / 4.0).round() as usize).max(1)
            };
            let offset = if ring.is_multiple_of(2) { 0.0 } else { 0.5 };
            for j in 0..n {
                let t = 2.0 * std::f64::consts::PI * (j as f64 + offset) / n as f64;
                positions.push([r * cos(t), r * sin(t)]);
            }
            ring += 1;
            let step = 0.5 * 3f64.sqrt() * spacing(r - 0.5 * s);
            let next = r - step;
            if next < 0.6 * spacing(next.max(0.0)) {
                break;
            }
            r = next;
        }
        positions.push([0.0, 0.0]);
        Ok(Self {
            radius,
            positions,
            boundary_count: nb,
        })
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

/// One Gauss point of the integration mesh, in the reference configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussPoint {
    pub position: [f64; 2],
    /// Quadrature weight times the triangle area.
    pub weight: f64,
}

/// Delaunay triangulation of the field nodes (only used for integration).
#[derive(Debug, Clone)]
pub struct IntegrationMesh {
    pub triangles: Vec<[usize; 3]>,
    pub gauss_points: Vec<GaussPoint>,
    pub area: f64,
}

/// 6-point, degree-4 rule on a triangle (Dunavant): barycentric coordinates and weights
/// (the weights sum to 1).
const GAUSS6: [([f64; 3], f64); 6] = {
    const A: f64 = 0.445_948_490_915_965;
    const B: f64 = 0.091_576_213_509_771;
    const WA: f64 = 0.223_381_589_678_011;
    const WB: f64 = 0.109_951_743_655_322;
    [
        ([A, A, 1.0 - 2.0 * A], WA),
        ([A, 1.0 - 2.0 * A, A], WA),
        ([1.0 - 2.0 * A, A, A], WA),
        ([B, B, 1.0 - 2.0 * B], WB),
        ([B, 1.0 - 2.0 * B, B], WB),
        ([1.0 - 2.0 * B, B, B], WB),
    ]
};

impl IntegrationMesh {
    /// Delaunay triangulation of the nodes (it covers their convex hull, the polygon of the
    /// contour nodes for a disc) with 6 Gauss points per triangle.
    pub fn delaunay(positions: &[[f64; 2]]) -> Result<Self, MeshfreeError> {
        let points: Vec<Point2<f64>> = positions.iter().map(|p| Point2::new(p[0], p[1])).collect();
        let dt = DelaunayTriangulation::<Point2<f64>>::bulk_load_stable(points)
            .map_err(|e| MeshfreeError::BadInput(format!("triangulation failed: {e:?}")))?;
        if dt.num_vertices() != positions.len() {
            return Err(MeshfreeError::BadInput(
                "triangulation dropped duplicate field nodes".into(),
            ));
        }
        let mut triangles = Vec::with_capacity(dt.num_inner_faces());
        for face in dt.inner_faces() {
            let v = face.vertices();
            triangles.push([v[0].fix().index(), v[1].fix().index(), v[2].fix().index()]);
        }
        // Deterministic order independent of spade's internals.
        for t in &mut triangles {
            t.sort_unstable();
        }
        triangles.sort_unstable();
        // Slivers from cocircular nodes on the hull have zero area: skipped.
        Ok(Self::with_gauss_points(positions, triangles))
    }
}

impl IntegrationMesh {
    /// Triangulation of the field nodes restricted to the inside of the boundary polygon
    /// (nodes `0..boundary_count`, counter-clockwise), with 6 Gauss points per triangle as in
    /// [`delaunay`](Self::delaunay).
    ///
    /// Why: a plain Delaunay triangulation covers the convex hull, so for a non-convex grain it
    /// would integrate over the empty bays of the contour. Here the boundary edges are
    /// constraints of a constrained Delaunay triangulation and only the triangles inside the
    /// boundary polygon are kept (every triangle is either wholly inside or wholly outside, so
    /// its centroid decides). For a convex node set this gives the same area as `delaunay`.
    /// Triangles are listed with sorted vertex indices, in sorted order (deterministic).
    ///
    /// Fails (`BadInput`) if the boundary polygon self-intersects or is clockwise, if nodes
    /// coincide, or if a node lies outside the boundary polygon (it would carry no Gauss point).
    pub fn inside_boundary(
        positions: &[[f64; 2]],
        boundary_count: usize,
    ) -> Result<Self, MeshfreeError> {
        use super::shape::{first_crossing, point_in_polygon, polygon_area};
        if boundary_count < 3 || boundary_count > positions.len() {
            return Err(MeshfreeError::BadInput(format!(
                "boundary_count must be in 3..={}, got {boundary_count}",
                positions.len()
            )));
        }
        if positions
            .iter()
            .any(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(MeshfreeError::BadInput("non-finite node position".into()));
        }
        let boundary = &positions[..boundary_count];
        if let Some((e1, e2, at)) = first_crossing(boundary) {
            return Err(MeshfreeError::BadInput(format!(
                "boundary polygon self-intersects: edge {e1}-{} and edge {e2}-{} meet at \
                 ({:.6}, {:.6})",
                (e1 + 1) % boundary_count,
                (e2 + 1) % boundary_count,
                at[0],
                at[1]
            )));
        }
        if polygon_area(boundary) <= 0.0 {
            return Err(MeshfreeError::BadInput(
                "boundary nodes must be counter-clockwise (the polygon has area <= 0)".into(),
            ));
        }
        if let Some(i) =
            (boundary_count..positions.len()).find(|&i| !point_in_polygon(positions[i], boundary))
        {
            return Err(MeshfreeError::BadInput(format!(
                "interior node {i} at ({:.6}, {:.6}) is not inside the boundary polygon",
                positions[i][0], positions[i][1]
            )));
        }
        let points: Vec<Point2<f64>> = positions.iter().map(|p| Point2::new(p[0], p[1])).collect();
        let edges: Vec<[usize; 2]> = (0..boundary_count)
            .map(|i| [i, (i + 1) % boundary_count])
            .collect();
        let mut conflicts = 0usize;
        let cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::try_bulk_load_cdt(
            points,
            edges,
            |_| conflicts += 1,
        )
        .map_err(|e| MeshfreeError::BadInput(format!("triangulation failed: {e:?}")))?;
        if cdt.num_vertices() != positions.len() {
            return Err(MeshfreeError::BadInput(
                "triangulation dropped duplicate field nodes".into(),
            ));
        }
        if conflicts > 0 {
            return Err(MeshfreeError::BadInput(format!(
                "{conflicts} boundary edges could not be constrained (a node lies on the contour \
                 between two boundary nodes?)"
            )));
        }
        let mut triangles = Vec::with_capacity(cdt.num_inner_faces());
        for face in cdt.inner_faces() {
            let v = face.vertices();
            let t = [v[0].fix().index(), v[1].fix().index(), v[2].fix().index()];
            let c = [0, 1].map(|k| t.iter().map(|&i| positions[i][k]).sum::<f64>() / 3.0);
            if point_in_polygon(c, boundary) {
                triangles.push(t);
            }
        }
        for t in &mut triangles {
            t.sort_unstable();
        }
        triangles.sort_unstable();
        Ok(Self::with_gauss_points(positions, triangles))
    }

    /// Gauss points of a list of triangles; zero-area slivers (collinear nodes) are skipped.
    fn with_gauss_points(positions: &[[f64; 2]], triangles: Vec<[usize; 3]>) -> Self {
        let mut gauss_points = Vec::with_capacity(6 * triangles.len());
        let mut area = 0.0;
        for t in &triangles {
            let [a, b, c] = t.map(|i| positions[i]);
            let tri_area =
                0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])).abs();
            if tri_area <= 1e-14 * (1.0 + area) {
                continue;
            }
            area += tri_area;
            for (bary, w) in GAUSS6 {
                gauss_points.push(GaussPoint {
                    position: [
                        bary[0] * a[0] + bary[1] * b[0] + bary[2] * c[0],
                        bary[0] * a[1] + bary[1] * b[1] + bary[2] * c[1],
                    ],
                    weight: w * tri_area,
                });
            }
        }
        Self {
            triangles,
            gauss_points,
            area,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disc_nodes_are_symmetric_and_mesh_covers_the_polygon() {
        let nodes = DiscNodes::disc(0.5, NodeDensity::new(32)).unwrap();
        // Every node has its mirror images about both axes.
        for p in &nodes.positions {
            for q in [[-p[0], p[1]], [p[0], -p[1]]] {
                assert!(
                    nodes
                        .positions
                        .iter()
                        .any(|r| (r[0] - q[0]).abs() < 1e-12 && (r[1] - q[1]).abs() < 1e-12)
                );
            }
        }
        let mesh = IntegrationMesh::delaunay(&nodes.positions).unwrap();
        let n = 32.0;
        let polygon = 0.5 * n * 0.25 * (2.0 * std::f64::consts::PI / n).sin();
        assert!(
            (mesh.area - polygon).abs() < 1e-12,
            "{} vs {}",
            mesh.area,
            polygon
        );
        let wsum: f64 = mesh.gauss_points.iter().map(|g| g.weight).sum();
        assert!((wsum - polygon).abs() < 1e-12);
    }

    #[test]
    fn inside_boundary_covers_only_the_grain() {
        use crate::meshfree::shape::{StarShape, place_nodes, polygon_area};
        // A non-convex star: plain Delaunay fills the convex hull, inside_boundary the star.
        let vertices: Vec<[f64; 2]> = (0..10)
            .map(|k| {
                let t = std::f64::consts::PI * k as f64 / 5.0;
                let r = if k % 2 == 0 { 1.0 } else { 0.45 };
                [r * t.cos(), r * t.sin()]
            })
            .collect();
        let star = StarShape::Polygon { vertices };
        let nodes = place_nodes(&star, 0.1, 1.0).unwrap();
        let exact = polygon_area(nodes.boundary());
        let mesh =
            IntegrationMesh::inside_boundary(&nodes.positions, nodes.boundary_count).unwrap();
        let wsum: f64 = mesh.gauss_points.iter().map(|g| g.weight).sum();
        assert!((wsum - exact).abs() < 1e-12, "{wsum} vs {exact}");
        assert!((mesh.area - exact).abs() < 1e-12);
        let hull = IntegrationMesh::delaunay(&nodes.positions).unwrap();
        assert!(hull.area > exact + 0.3, "{} vs {exact}", hull.area);
        // Every node is used by some triangle.
        let mut used = vec![false; nodes.len()];
        mesh.triangles
            .iter()
            .flatten()
            .for_each(|&i| used[i] = true);
        assert!(used.iter().all(|&u| u));
        // Deterministic.
        let again =
            IntegrationMesh::inside_boundary(&nodes.positions, nodes.boundary_count).unwrap();
        assert_eq!(mesh.triangles, again.triangles);

        // Convex node set (disc): the same area as plain Delaunay.
        let disc = DiscNodes::disc(0.5, NodeDensity::new(32)).unwrap();
        let a = IntegrationMesh::inside_boundary(&disc.positions, disc.boundary_count).unwrap();
        let b = IntegrationMesh::delaunay(&disc.positions).unwrap();
        assert!((a.area - b.area).abs() < 1e-12);
        assert_eq!(a.gauss_points.len(), b.gauss_points.len());

        // A node outside the boundary is refused.
        let mut bad = nodes.positions.clone();
        bad.push([0.9, 0.5]);
        assert!(IntegrationMesh::inside_boundary(&bad, nodes.boundary_count).is_err());
    }
}
