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

/// A meshfree disc ready to be solved.
#[derive(Debug, Clone)]
pub struct DiscModel {
    pub nodes: DiscNodes,
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
}

impl DiscModel {
    /// Nodes, triangulation, shape functions and mass of a disc centred at the origin.
    pub fn disc(
        radius: f64,
        density: NodeDensity,
        material: Hyperelastic,
    ) -> Result<Self, MeshfreeError> {
        let nodes = DiscNodes::disc(radius, density)?;
        Self::from_nodes(nodes, material)
    }

    pub fn from_nodes(nodes: DiscNodes, material: Hyperelastic) -> Result<Self, MeshfreeError> {
        let rpim = Rpim::new(&nodes.positions)?;
        let mesh = IntegrationMesh::delaunay(&nodes.positions)?;
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
        })
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

    /// Elastic energy, internal forces (added to `force`) and, if asked, the tangent (added to
    /// `tangent`). Fails if a Gauss point is inverted (`det F <= 0`).
    pub fn internal(
        &self,
        u: &[f64],
        force: &mut [f64],
        mut tangent: Option<&mut Dense>,
    ) -> Result<f64, MeshfreeError> {
        let mut energy = 0.0;
        let mut t = Vec::new();
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
                for kb in r.clone() {
                    let b = self.gp_nodes[kb];
                    let gb = [self.gp_dx[kb], self.gp_dy[kb]];
                    for kk in 0..2 {
                        let col = &mut kmat.data[(2 * b + kk) * n..(2 * b + kk + 1) * n];
                        for (la, ka) in r.clone().enumerate() {
                            let a = self.gp_nodes[ka];
                            let ta = &t[la * 8..la * 8 + 8];
                            col[2 * a] += ta[kk * 2] * gb[0] + ta[kk * 2 + 1] * gb[1];
                            col[2 * a + 1] += ta[4 + kk * 2] * gb[0] + ta[4 + kk * 2 + 1] * gb[1];
                        }
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
