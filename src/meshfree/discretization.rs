//! Field nodes of a disc, the integration triangulation and its Gauss points (SPEC §10).

use spade::{DelaunayTriangulation, Point2, Triangulation};

use super::MeshfreeError;

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
        if nb < 8 || nb % 4 != 0 {
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
            let offset = if ring % 2 == 0 { 0.0 } else { 0.5 };
            for j in 0..n {
                let t = 2.0 * std::f64::consts::PI * (j as f64 + offset) / n as f64;
                positions.push([r * t.cos(), r * t.sin()]);
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
        let mut gauss_points = Vec::with_capacity(6 * triangles.len());
        let mut area = 0.0;
        for t in &triangles {
            let [a, b, c] = t.map(|i| positions[i]);
            let tri_area =
                0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])).abs();
            if tri_area <= 1e-14 * (1.0 + area) {
                continue; // sliver from cocircular nodes on the hull: contributes nothing
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
        Ok(Self {
            triangles,
            gauss_points,
            area,
        })
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
}
