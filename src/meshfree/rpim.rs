//! Radial point interpolation (RPIM, paper eq. 1–10) with a Gaussian RBF and the quadratic
//! polynomial basis `[1, x, y, x^2, y^2, xy]`.
//!
//! Node `j` has a circular support of radius `D_j`, the distance to its 20th nearest other node
//! (found with an R*-tree), and the RBF `r_j(X) = exp(-(3 d / D_j)^2)` for `d = |X - X_j| <= D_j`.
//! At a point X the shape functions of the nodes whose supports contain X solve
//!
//! ```text
//! [R0 P; P^T 0]^T [Phi; psi] = [R(X); p(X)]      R0[i][j] = r_j(X_i),  P[i][k] = p_k(X_i)
//! ```
//!
//! The paper writes `[R0 P; P^T 0]^{-1}` without the transpose; R0 is not symmetric when the
//! support radii differ from node to node, and only the transposed system gives interpolating
//! shape functions (`Phi_i(X_k) = delta_ik`). The polynomial part is written in coordinates
//! centred at X and scaled by the mean support radius, which spans the same space (so quadratic
//! fields are reproduced exactly) and keeps the system well conditioned.

use rstar::RTree;
use rstar::primitives::GeomWithData;

use super::MeshfreeError;
use crate::portable::exp;

/// Number of other nodes in each support (SPEC §10).
pub const SUPPORT_NEIGHBOURS: usize = 20;

/// Support radii and RBF of a node set.
#[derive(Debug, Clone)]
pub struct Rpim {
    pub positions: Vec<[f64; 2]>,
    /// `D_j` of each node.
    pub support_radius: Vec<f64>,
}

/// Shape functions at one point: the contributing nodes, values and gradients.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ShapeFunctions {
    pub nodes: Vec<usize>,
    pub value: Vec<f64>,
    pub dx: Vec<f64>,
    pub dy: Vec<f64>,
}

impl ShapeFunctions {
    /// Interpolates nodal values `f[node]` at the point.
    pub fn interpolate(&self, f: impl Fn(usize) -> f64) -> (f64, f64, f64) {
        let mut out = (0.0, 0.0, 0.0);
        for (k, &j) in self.nodes.iter().enumerate() {
            let v = f(j);
            out.0 += self.value[k] * v;
            out.1 += self.dx[k] * v;
            out.2 += self.dy[k] * v;
        }
        out
    }
}

impl Rpim {
    /// Support radii from the k-nearest neighbours; fails if there are not enough nodes.
    pub fn new(positions: &[[f64; 2]]) -> Result<Self, MeshfreeError> {
        if positions.len() < SUPPORT_NEIGHBOURS + 1 {
            return Err(MeshfreeError::TooCoarse {
                nodes: positions.len(),
                needed: SUPPORT_NEIGHBOURS + 1,
            });
        }
        if positions
            .iter()
            .any(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(MeshfreeError::BadInput("non-finite node position".into()));
        }
        let tree: RTree<GeomWithData<[f64; 2], usize>> = RTree::bulk_load(
            positions
                .iter()
                .enumerate()
                .map(|(i, p)| GeomWithData::new(*p, i))
                .collect(),
        );
        let mut support_radius = Vec::with_capacity(positions.len());
        for (i, p) in positions.iter().enumerate() {
            // The iterator starts with the node itself (distance 0): skip it by index.
            let mut d2: Vec<f64> = tree
                .nearest_neighbor_iter(*p)
                .filter(|g| g.data != i)
                .take(SUPPORT_NEIGHBOURS)
                .map(|g| dist2(*g.geom(), *p))
                .collect();
            d2.sort_by(f64::total_cmp);
            let d = d2[SUPPORT_NEIGHBOURS - 1].sqrt();
            if d <= 0.0 {
                return Err(MeshfreeError::BadInput(format!(
                    "field node {i} coincides with 20 other nodes"
                )));
            }
            // A hair larger so that the 20th neighbour is inside despite rounding.
            support_radius.push(d * (1.0 + 1e-9));
        }
        Ok(Self {
            positions: positions.to_vec(),
            support_radius,
        })
    }

    /// RBF of node j at distance d (0 outside its support).
    #[inline]
    fn rbf(&self, j: usize, d: f64) -> f64 {
        let dj = self.support_radius[j];
        if d <= dj {
            let s = 3.0 * d / dj;
            exp(-s * s)
        } else {
            0.0
        }
    }

    /// Nodes whose support contains `x`, in increasing index order.
    pub fn support_nodes(&self, x: [f64; 2]) -> Vec<usize> {
        (0..self.positions.len())
            .filter(|&j| dist2(self.positions[j], x).sqrt() <= self.support_radius[j])
            .collect()
    }

    /// Shape functions and their gradients at `x` (eq. 4, 9, 10 with the transpose).
    pub fn shape_functions(&self, x: [f64; 2]) -> Result<ShapeFunctions, MeshfreeError> {
        let nodes = self.support_nodes(x);
        let n = nodes.len();
        if n < 6 {
            return Err(MeshfreeError::TooCoarse {
                nodes: n,
                needed: 6,
            });
        }
        let scale = nodes.iter().map(|&j| self.support_radius[j]).sum::<f64>() / n as f64;
        let poly = |p: [f64; 2]| {
            let u = (p[0] - x[0]) / scale;
            let v = (p[1] - x[1]) / scale;
            [1.0, u, v, u * u, v * v, u * v]
        };
        let m = n + 6;
        // G^T with G = [R0 P; P^T 0], R0[i][j] = r_j(X_i): G^T[i][j] = r_i(|X_i - X_j|).
        let mut gt = vec![0.0; m * m];
        for (a, &i) in nodes.iter().enumerate() {
            for (b, &j) in nodes.iter().enumerate() {
                let d = dist2(self.positions[i], self.positions[j]).sqrt();
                gt[a * m + b] = self.rbf(i, d);
            }
            let p = poly(self.positions[i]);
            for k in 0..6 {
                gt[a * m + n + k] = p[k];
                gt[(n + k) * m + a] = p[k];
            }
        }
        // Right-hand sides: values, d/dx, d/dy of [R(X); p(X)].
        let mut rhs = vec![0.0; 3 * m];
        for (a, &j) in nodes.iter().enumerate() {
            let dx = x[0] - self.positions[j][0];
            let dy = x[1] - self.positions[j][1];
            let d = (dx * dx + dy * dy).sqrt();
            let r = self.rbf(j, d);
            let dj = self.support_radius[j];
            let c = -18.0 / (dj * dj);
            rhs[a] = r;
            rhs[m + a] = r * c * dx;
            rhs[2 * m + a] = r * c * dy;
        }
        rhs[n] = 1.0; // p(X) in local coordinates: [1, 0, 0, 0, 0, 0]
        rhs[m + n + 1] = 1.0 / scale;
        rhs[2 * m + n + 2] = 1.0 / scale;
        solve_dense(m, &mut gt, &mut rhs, 3).ok_or_else(|| {
            MeshfreeError::BadInput(format!(
                "singular RPIM moment matrix at ({:.6}, {:.6}): nodes are degenerate",
                x[0], x[1]
            ))
        })?;
        Ok(ShapeFunctions {
            value: rhs[..n].to_vec(),
            dx: rhs[m..m + n].to_vec(),
            dy: rhs[2 * m..2 * m + n].to_vec(),
            nodes,
        })
    }
}

#[inline]
fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

/// Solves `A X = B` in place for a small dense row-major `A` (m x m) and `nrhs` right-hand
/// sides stored one after the other in `b` (Gaussian elimination, partial pivoting). Returns
/// `None` when a pivot vanishes.
pub(crate) fn solve_dense(m: usize, a: &mut [f64], b: &mut [f64], nrhs: usize) -> Option<()> {
    let norm = a.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    for col in 0..m {
        let mut piv = col;
        let mut best = a[col * m + col].abs();
        for row in col + 1..m {
            let v = a[row * m + col].abs();
            if v > best {
                best = v;
                piv = row;
            }
        }
        if best.is_nan() || best <= 1e-14 * norm {
            return None;
        }
        if piv != col {
            for k in 0..m {
                a.swap(col * m + k, piv * m + k);
            }
            for r in 0..nrhs {
                b.swap(r * m + col, r * m + piv);
            }
        }
        let inv = 1.0 / a[col * m + col];
        for row in col + 1..m {
            let f = a[row * m + col] * inv;
            if f != 0.0 {
                for k in col + 1..m {
                    a[row * m + k] -= f * a[col * m + k];
                }
                for r in 0..nrhs {
                    b[r * m + row] -= f * b[r * m + col];
                }
            }
        }
    }
    for r in 0..nrhs {
        for row in (0..m).rev() {
            let mut s = b[r * m + row];
            for k in row + 1..m {
                s -= a[row * m + k] * b[r * m + k];
            }
            b[r * m + row] = s / a[row * m + row];
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dense_solver_solves_a_small_system() {
        let mut a = vec![0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let mut b = vec![3.0, 2.0, 4.0];
        solve_dense(3, &mut a, &mut b, 1).unwrap();
        for (x, e) in b.iter().zip([1.0, 1.0, 1.0]) {
            assert!((x - e).abs() < 1e-14);
        }
    }
}
