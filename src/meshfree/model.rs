//! One meshfree grain: field nodes, precomputed shape functions at the Gauss points,
//! total-Lagrangian internal forces, consistent tangent and consistent mass (appendix A).
//!
//! Degrees of freedom are the nodal displacements, `u[2 a + i]` for node a, direction i.
//! The internal force is `f_int[(a,i)] = sum_gp w P_iJ dPhi_a/dX_J` and the tangent
//! `K[(a,i),(b,k)] = sum_gp w dPhi_a/dX_J A_iJkL dPhi_b/dX_L` (A = dP/dF): the same matrices as
//! the paper's `B_t^T A B_t + G^T B_p`, written with the first Piola–Kirchhoff stress.

use super::MeshfreeError;
use super::discretization::{DiscNodes, IntegrationMesh, NodeDensity};
use super::material::Hyperelastic;
use super::rpim::Rpim;

/// A dense square matrix stored column-major (the layout faer factors in place).
#[derive(Debug, Clone, PartialEq)]
pub struct Dense {
    pub n: usize,
    pub data: Vec<f64>,
}

impl Dense {
    pub fn zeros(n: usize) -> Self {
        Self {
            n,
            data: vec![0.0; n * n],
        }
    }

    #[inline]
    pub fn get(&self, row: usize, col: usize) -> f64 {
        self.data[col * self.n + row]
    }

    #[inline]
    pub fn add(&mut self, row: usize, col: usize, v: f64) {
        self.data[col * self.n + row] += v;
    }

    pub fn fill_zero(&mut self) {
        self.data.iter_mut().for_each(|v| *v = 0.0);
    }

    /// `y = self * x`.
    pub fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.n];
        for (col, &xc) in x.iter().enumerate() {
            if xc != 0.0 {
                let c = &self.data[col * self.n..(col + 1) * self.n];
                for (yr, &v) in y.iter_mut().zip(c) {
                    *yr += v * xc;
                }
            }
        }
        y
    }

    /// `self += s * other`.
    pub fn add_scaled(&mut self, s: f64, other: &Dense) {
        for (a, b) in self.data.iter_mut().zip(&other.data) {
            *a += s * b;
        }
    }
}

/// Field nodes of one grain in the reference configuration: the first `boundary_count` are the
/// contour nodes, counter-clockwise, the others lie inside.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeSet {
    pub positions: Vec<[f64; 2]>,
    pub boundary_count: usize,
}

impl NodeSet {
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

impl From<DiscNodes> for NodeSet {
    fn from(d: DiscNodes) -> Self {
        Self {
            positions: d.positions,
            boundary_count: d.boundary_count,
        }
    }
}

/// The node pairs `(a, b)` that share at least one Gauss point: the nonzero 2 x 2 blocks of a
/// grain's tangent and mass, column-major (`b` outer, `a` inner, both increasing).
#[derive(Debug, Clone, PartialEq)]
pub struct BlockPattern {
    pub pairs: Vec<(u32, u32)>,
}

/// A meshfree grain ready to be solved: its field nodes (any star-shaped contour; a disc with
/// [`GrainModel::disc`]), shape functions at the Gauss points, mass, and the block pattern of
/// its tangent.
pub type DiscModel = GrainModel;

#[derive(Debug, Clone)]
pub struct GrainModel {
    pub nodes: NodeSet,
    pub mesh: IntegrationMesh,
    pub rpim: Rpim,
    pub material: Hyperelastic,
    /// Shape functions at the Gauss points, flattened: gauss point g uses entries
    /// `gp_offsets[g]..gp_offsets[g + 1]`.
    gp_offsets: Vec<usize>,
    gp_nodes: Vec<usize>,
    gp_phi: Vec<f64>,
    gp_dx: Vec<f64>,
    gp_dy: Vec<f64>,
    gp_weight: Vec<f64>,
    /// Scalar consistent mass `m_ab = sum_gp rho w Phi_a Phi_b` (the 2N x 2N mass is m ⊗ I2).
    pub scalar_mass: Dense,
    pub pattern: BlockPattern,
    /// `m_ab` on the pairs of `pattern`.
    pub pattern_mass: Vec<f64>,
}

impl GrainModel {
    /// Nodes, triangulation, shape functions and mass of a disc centred at the origin.
    pub fn disc(
        radius: f64,
        density: NodeDensity,
        material: Hyperelastic,
    ) -> Result<Self, MeshfreeError> {
        let nodes = DiscNodes::disc(radius, density)?;
        Self::from_nodes(nodes, material)
    }

    /// A disc's nodes (or any convex node set) with the Delaunay mesh of their convex hull.
    pub fn from_nodes(
        nodes: impl Into<NodeSet>,
        material: Hyperelastic,
    ) -> Result<Self, MeshfreeError> {
        let nodes = nodes.into();
        if nodes.len() <= super::SUPPORT_NEIGHBOURS {
            return Err(MeshfreeError::TooCoarse {
                nodes: nodes.len(),
                needed: super::SUPPORT_NEIGHBOURS + 1,
            });
        }
        let mesh = IntegrationMesh::delaunay(&nodes.positions)?;
        Self::from_parts(nodes, mesh, material)
    }

    /// A grain from its nodes and an integration mesh covering its inside.
    pub fn from_parts(
        nodes: NodeSet,
        mesh: IntegrationMesh,
        material: Hyperelastic,
    ) -> Result<Self, MeshfreeError> {
        if nodes.boundary_count < 3 || nodes.boundary_count > nodes.len() {
            return Err(MeshfreeError::BadInput(format!(
                "a grain needs at least 3 contour nodes among its field nodes, got {} of {}",
                nodes.boundary_count,
                nodes.len()
            )));
        }
        let rpim = Rpim::new(&nodes.positions)?;
        let mut gp_offsets = vec![0];
        let (mut gp_nodes, mut gp_phi, mut gp_dx, mut gp_dy, mut gp_weight) =
            (vec![], vec![], vec![], vec![], vec![]);
        for g in &mesh.gauss_points {
            let sf = rpim.shape_functions(g.position)?;
            gp_nodes.extend_from_slice(&sf.nodes);
            gp_phi.extend_from_slice(&sf.value);
            gp_dx.extend_from_slice(&sf.dx);
            gp_dy.extend_from_slice(&sf.dy);
            gp_offsets.push(gp_nodes.len());
            gp_weight.push(g.weight);
        }
        let n = nodes.len();
        let mut scalar_mass = Dense::zeros(n);
        for g in 0..gp_weight.len() {
            let r = gp_offsets[g]..gp_offsets[g + 1];
            let w = material.density * gp_weight[g];
            for (pb, &b) in gp_phi[r.clone()].iter().zip(&gp_nodes[r.clone()]) {
                for (pa, &a) in gp_phi[r.clone()].iter().zip(&gp_nodes[r.clone()]) {
                    scalar_mass.add(a, b, w * pa * pb);
                }
            }
        }
        let mut coupled = vec![false; n * n];
        for g in 0..gp_weight.len() {
            let r = gp_offsets[g]..gp_offsets[g + 1];
            for &b in &gp_nodes[r.clone()] {
                for &a in &gp_nodes[r.clone()] {
                    coupled[b * n + a] = true;
                }
            }
        }
        let mut pairs = Vec::new();
        let mut pattern_mass = Vec::new();
        for b in 0..n {
            for a in 0..n {
                if coupled[b * n + a] {
                    pairs.push((a as u32, b as u32));
                    pattern_mass.push(scalar_mass.get(a, b));
                }
            }
        }
        Ok(Self {
            nodes,
            mesh,
            rpim,
            material,
            gp_offsets,
            gp_nodes,
            gp_phi,
            gp_dx,
            gp_dy,
            gp_weight,
            scalar_mass,
            pattern: BlockPattern { pairs },
            pattern_mass,
        })
    }

    /// The 2 x 2 blocks of a dense 2N x 2N matrix on the pattern's pairs,
    /// `[K_ax,bx, K_ay,bx, K_ax,by, K_ay,by]` (column-major within the block).
    pub fn pattern_blocks(&self, k: &Dense, out: &mut Vec<[f64; 4]>) {
        out.clear();
        out.extend(self.pattern.pairs.iter().map(|&(a, b)| {
            let (a, b) = (a as usize, b as usize);
            [
                k.get(2 * a, 2 * b),
                k.get(2 * a + 1, 2 * b),
                k.get(2 * a, 2 * b + 1),
                k.get(2 * a + 1, 2 * b + 1),
            ]
        }));
    }

    /// Current area and area centroid of the contour polygon (boundary nodes at `X + u`).
    pub fn contour_area_centroid(&self, u: &[f64]) -> (f64, [f64; 2]) {
        let nb = self.nodes.boundary_count;
        let (mut a2, mut cx, mut cy) = (0.0, 0.0, 0.0);
        for s in 0..nb {
            let p = self.position(u, s);
            let q = self.position(u, (s + 1) % nb);
            let cross = p[0] * q[1] - q[0] * p[1];
            a2 += cross;
            cx += (p[0] + q[0]) * cross;
            cy += (p[1] + q[1]) * cross;
        }
        (0.5 * a2, [cx / (3.0 * a2), cy / (3.0 * a2)])
    }

    /// Integral of the Cauchy stress over the current grain, `sum_gp w P F^T` (tension
    /// positive; `sigma J = P F^T` and `dA = J dA_0`). Divided by the current area it is the
    /// grain's mean stress tensor.
    pub fn stress_integral(&self, u: &[f64]) -> Result<[[f64; 2]; 2], MeshfreeError> {
        let mut out = [[0.0; 2]; 2];
        for g in 0..self.gp_weight.len() {
            let f = self.deformation_gradient(g, u);
            let resp = self.material.response(f).ok_or(MeshfreeError::Inverted {
                position: self.mesh.gauss_points[g].position,
                det: f[0][0] * f[1][1] - f[0][1] * f[1][0],
            })?;
            let w = self.gp_weight[g];
            for (i, row) in out.iter_mut().enumerate() {
                for (j, v) in row.iter_mut().enumerate() {
                    *v += w * (resp.p[i][0] * f[j][0] + resp.p[i][1] * f[j][1]);
                }
            }
        }
        Ok(out)
    }

    /// `M v` with the mass stored on the pattern (cheap for large grains).
    pub fn pattern_mass_mul(&self, v: &[f64], out: &mut [f64]) {
        for (&(a, b), &m) in self.pattern.pairs.iter().zip(&self.pattern_mass) {
            let (a, b) = (a as usize, b as usize);
            out[2 * a] += m * v[2 * b];
            out[2 * a + 1] += m * v[2 * b + 1];
        }
    }

    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    pub fn dofs(&self) -> usize {
        2 * self.nodes.len()
    }

    pub fn gauss_count(&self) -> usize {
        self.gp_weight.len()
    }

    /// Current position of node a.
    #[inline]
    pub fn position(&self, u: &[f64], a: usize) -> [f64; 2] {
        let x = self.nodes.positions[a];
        [x[0] + u[2 * a], x[1] + u[2 * a + 1]]
    }

    /// Deformation gradient at Gauss point g.
    pub fn deformation_gradient(&self, g: usize, u: &[f64]) -> [[f64; 2]; 2] {
        let mut f = [[1.0, 0.0], [0.0, 1.0]];
        for k in self.gp_offsets[g]..self.gp_offsets[g + 1] {
            let a = self.gp_nodes[k];
            let (gx, gy) = (self.gp_dx[k], self.gp_dy[k]);
            f[0][0] += u[2 * a] * gx;
            f[0][1] += u[2 * a] * gy;
            f[1][0] += u[2 * a + 1] * gx;
            f[1][1] += u[2 * a + 1] * gy;
        }
        f
    }

    /// Whether `det F > 0` at every Gauss point.
    pub fn all_points_valid(&self, u: &[f64]) -> bool {
        (0..self.gp_weight.len()).all(|g| {
            let f = self.deformation_gradient(g, u);
            let j = f[0][0] * f[1][1] - f[0][1] * f[1][0];
            j > 0.0 && j.is_finite()
        })
    }

    /// Reference position and weight of Gauss point g.
    pub fn gauss_point(&self, g: usize) -> ([f64; 2], f64) {
        (self.mesh.gauss_points[g].position, self.gp_weight[g])
    }

    /// Mass-weighted body force vector for an acceleration field `b` (e.g. gravity).
    pub fn body_force(&self, b: [f64; 2]) -> Vec<f64> {
        let mut f = vec![0.0; self.dofs()];
        for g in 0..self.gp_weight.len() {
            let w = self.material.density * self.gp_weight[g];
            for k in self.gp_offsets[g]..self.gp_offsets[g + 1] {
                let a = self.gp_nodes[k];
                f[2 * a] += w * self.gp_phi[k] * b[0];
                f[2 * a + 1] += w * self.gp_phi[k] * b[1];
            }
        }
        f
    }

    /// `M v` for the consistent mass.
    pub fn mass_mul(&self, v: &[f64]) -> Vec<f64> {
        let n = self.node_count();
        let mut out = vec![0.0; 2 * n];
        for b in 0..n {
            let (vx, vy) = (v[2 * b], v[2 * b + 1]);
            if vx == 0.0 && vy == 0.0 {
                continue;
            }
            let col = &self.scalar_mass.data[b * n..(b + 1) * n];
            for (a, &m) in col.iter().enumerate() {
                out[2 * a] += m * vx;
                out[2 * a + 1] += m * vy;
            }
        }
        out
    }

    /// Adds `s M` to a 2N x 2N matrix.
    pub fn add_mass(&self, s: f64, k: &mut Dense) {
        let n = self.node_count();
        for b in 0..n {
            for a in 0..n {
                let m = s * self.scalar_mass.get(a, b);
                k.add(2 * a, 2 * b, m);
                k.add(2 * a + 1, 2 * b + 1, m);
            }
        }
    }

    /// Elastic energy, internal forces (added to `force`) and, if asked, the tangent (written
    /// over `tangent`'s content). Fails if a Gauss point is inverted (`det F <= 0`).
    ///
    /// The tangent is symmetric (hyperelastic laws: `A_iJkL = A_kLiJ`), so only the blocks
    /// `(a, b)` with `a <= b` are integrated and the others are mirrored: half the work of the
    /// Gauss-point loop, which dominates the cost of a Newton iteration.
    pub fn internal(
        &self,
        u: &[f64],
        force: &mut [f64],
        mut tangent: Option<&mut Dense>,
    ) -> Result<f64, MeshfreeError> {
        let mut energy = 0.0;
        let mut t = Vec::new();
        if let Some(k) = tangent.as_deref_mut() {
            k.fill_zero();
        }
        for g in 0..self.gp_weight.len() {
            let f = self.deformation_gradient(g, u);
            let resp = self
                .material
                .response(f)
                .ok_or_else(|| MeshfreeError::Inverted {
                    position: self.mesh.gauss_points[g].position,
                    det: f[0][0] * f[1][1] - f[0][1] * f[1][0],
                })?;
            let w = self.gp_weight[g];
            energy += w * resp.energy;
            let r = self.gp_offsets[g]..self.gp_offsets[g + 1];
            for k in r.clone() {
                let a = self.gp_nodes[k];
                let (gx, gy) = (self.gp_dx[k], self.gp_dy[k]);
                force[2 * a] += w * (resp.p[0][0] * gx + resp.p[0][1] * gy);
                force[2 * a + 1] += w * (resp.p[1][0] * gx + resp.p[1][1] * gy);
            }
            if let Some(kmat) = tangent.as_deref_mut() {
                let aa = resp.a;
                // t[a][i][k][L] = w sum_J g_a[J] A[2i+J][2k+L]
                let ne = r.len();
                t.clear();
                t.resize(ne * 8, 0.0);
                for (la, k) in r.clone().enumerate() {
                    let ga = [self.gp_dx[k], self.gp_dy[k]];
                    for i in 0..2 {
                        for kk in 0..2 {
                            for l in 0..2 {
                                t[la * 8 + i * 4 + kk * 2 + l] = w
                                    * (ga[0] * aa[2 * i][2 * kk + l]
                                        + ga[1] * aa[2 * i + 1][2 * kk + l]);
                            }
                        }
                    }
                }
                let n = kmat.n;
                // The support lists are in increasing node order: la <= lb is a <= b.
                for (lb, kb) in r.clone().enumerate() {
                    let b = self.gp_nodes[kb];
                    let gb = [self.gp_dx[kb], self.gp_dy[kb]];
                    for kk in 0..2 {
                        let col = &mut kmat.data[(2 * b + kk) * n..(2 * b + kk + 1) * n];
                        for (la, ka) in r.clone().take(lb + 1).enumerate() {
                            let a = self.gp_nodes[ka];
                            let ta = &t[la * 8..la * 8 + 8];
                            col[2 * a] += ta[kk * 2] * gb[0] + ta[kk * 2 + 1] * gb[1];
                            col[2 * a + 1] += ta[4 + kk * 2] * gb[0] + ta[4 + kk * 2 + 1] * gb[1];
                        }
                    }
                }
            }
        }
        if let Some(k) = tangent {
            let n = k.n;
            for col in 0..n {
                for row in 0..n {
                    if row / 2 > col / 2 {
                        k.data[col * n + row] = k.data[row * n + col];
                    }
                }
            }
        }
        Ok(energy)
    }

    /// Tangent stiffness of the undeformed disc, `K_i0`.
    pub fn initial_stiffness(&self) -> Result<Dense, MeshfreeError> {
        let mut k = Dense::zeros(self.dofs());
        let mut f = vec![0.0; self.dofs()];
        self.internal(&vec![0.0; self.dofs()], &mut f, Some(&mut k))?;
        Ok(k)
    }
}
