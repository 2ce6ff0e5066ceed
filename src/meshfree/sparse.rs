//! Sparse LU for assemblies of meshfree grains (a block per grain plus contact couplings).
//!
//! The dense LU of [`super::lu_solve`] costs O(n³) in the total number of DoF, which is
//! fine for one grain but not for hundreds; a multi-grain tangent is block sparse and, because
//! of the contact terms, not symmetric, so this module wraps faer's sparse LU (COLAMD column
//! ordering, partial pivoting by rows, simplicial or supernodal chosen by faer).
//!
//! Newton iterations reassemble the tangent with the same triplet sequence until the contact
//! set changes, so [`SparseSolver`] keeps the triplet-to-CSC map and the symbolic analysis as
//! long as the row/column arrays are identical to the previous call's (compared in full: a
//! false "unchanged" would silently factorize the wrong pattern).
//!
//! Determinism: duplicates are summed in triplet order, and faer is always called with
//! `Par::Seq`, so the result depends only on the input, never on the rayon thread count.
//! faer's parallel supernodal path is not bitwise reproducible: with `Par::rayon(0)`, 1 and
//! 2 threads give different bits from about 3,000 DoF up (measured on the synthetic
//! multi-grain matrices below; the thread test uses such a size so that it would catch it).
//! Parallelism belongs to the caller (e.g. assembling grains concurrently).

use std::fmt;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::lu::{LuSymbolicParams, NumericLu, SymbolicLu, factorize_symbolic_lu};
use faer::sparse::linalg::{LuError, SupernodalThreshold};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par};

use super::MeshfreeError;
use crate::geometry::angle::{cos, sin};

/// Collects the nonzeros of a square matrix as (row, col, value) triplets in the caller's
/// order; duplicates are summed (in triplet order) when the matrix is factorized.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TripletMatrix {
    pub n: usize,
    rows: Vec<usize>,
    cols: Vec<usize>,
    values: Vec<f64>,
}

impl TripletMatrix {
    pub fn new(n: usize) -> Self {
        Self {
            n,
            ..Default::default()
        }
    }

    /// Empties the matrix but keeps the allocations, so that reassembling every Newton
    /// iteration does not reallocate.
    pub fn clear(&mut self) {
        self.rows.clear();
        self.cols.clear();
        self.values.clear();
    }

    /// Appends `value` at (`row`, `col`).
    ///
    /// # Panics
    /// If `row` or `col` is not below `n` (an assembly bug, caught where it happens rather
    /// than at factorization).
    #[inline]
    pub fn push(&mut self, row: usize, col: usize, value: f64) {
        assert!(
            row < self.n && col < self.n,
            "triplet ({row}, {col}) outside a {n}×{n} matrix",
            n = self.n
        );
        self.rows.push(row);
        self.cols.push(col);
        self.values.push(value);
    }

    /// Number of triplets (duplicates counted separately).
    pub fn len(&self) -> usize {
        self.values.len()
    }

    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Row indices in push order.
    pub fn rows(&self) -> &[usize] {
        &self.rows
    }

    /// Column indices in push order.
    pub fn cols(&self) -> &[usize] {
        &self.cols
    }

    /// Values in push order.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// `A x` (for tests and residual checks).
    ///
    /// # Panics
    /// If `x.len() != n`.
    pub fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        assert_eq!(
            x.len(),
            self.n,
            "vector length differs from the matrix size"
        );
        let mut y = vec![0.0; self.n];
        for ((&r, &c), &v) in self.rows.iter().zip(&self.cols).zip(&self.values) {
            y[r] += v * x[c];
        }
        y
    }
}

/// What depends only on the triplet index sequence: the CSC structure, where each triplet
/// lands in it, faer's symbolic LU and the scratch sizes derived from it.
struct Analysis {
    n: usize,
    /// Copies of the triplet indices the analysis was built from (the reuse key).
    rows: Vec<usize>,
    cols: Vec<usize>,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// CSC position of each triplet (duplicates share a position).
    slot: Vec<usize>,
    symbolic: SymbolicLu<usize>,
    factor_scratch: MemBuffer,
    solve_scratch: MemBuffer,
}

impl Analysis {
    fn matches(&self, a: &TripletMatrix) -> bool {
        self.n == a.n && self.rows == a.rows && self.cols == a.cols
    }

    fn new(a: &TripletMatrix, threshold: SupernodalThreshold) -> Result<Self, MeshfreeError> {
        let n = a.n;
        let nnz = a.len();
        // Two stable counting sorts (by row, then by column) give the triplets in CSC order
        // with sorted row indices, in O(nnz + n).
        let mut by_row = vec![0usize; nnz];
        counting_sort(&a.rows, n, 0..nnz, &mut by_row);
        let mut order = vec![0usize; nnz];
        counting_sort(&a.cols, n, by_row.iter().copied(), &mut order);

        let mut col_ptr = vec![0usize; n + 1];
        let mut row_idx = Vec::with_capacity(nnz);
        let mut slot = vec![0usize; nnz];
        let mut prev = (usize::MAX, usize::MAX);
        for &k in &order {
            let key = (a.cols[k], a.rows[k]);
            if key != prev {
                row_idx.push(key.1);
                col_ptr[key.0 + 1] += 1;
                prev = key;
            }
            slot[k] = row_idx.len() - 1;
        }
        for j in 0..n {
            col_ptr[j + 1] += col_ptr[j];
        }

        let pattern = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let params = LuSymbolicParams {
            supernodal_flop_ratio_threshold: threshold,
            ..Default::default()
        };
        let symbolic = factorize_symbolic_lu(pattern, params)
            .map_err(|e| MeshfreeError::BadInput(format!("sparse LU analysis failed: {e:?}")))?;
        let factor_scratch = MemBuffer::new(
            symbolic.factorize_numeric_lu_scratch::<f64>(Par::Seq, Default::default()),
        );
        let solve_scratch = MemBuffer::new(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
        Ok(Self {
            n,
            rows: a.rows.clone(),
            cols: a.cols.clone(),
            col_ptr,
            row_idx,
            slot,
            symbolic,
            factor_scratch,
            solve_scratch,
        })
    }
}

/// Writes `items` into `out` ordered by `key[item]` (stable; keys below `n`).
fn counting_sort(
    key: &[usize],
    n: usize,
    items: impl Iterator<Item = usize> + Clone,
    out: &mut [usize],
) {
    let mut start = vec![0usize; n + 1];
    for i in items.clone() {
        start[key[i] + 1] += 1;
    }
    for j in 0..n {
        start[j + 1] += start[j];
    }
    for i in items {
        let s = &mut start[key[i]];
        out[*s] = i;
        *s += 1;
    }
}

/// Sparse LU of a (generally non-symmetric) square matrix given as triplets, with the
/// symbolic analysis (column ordering and elimination structure) and the triplet-to-CSC map
/// reused while the triplets' index sequence is unchanged, recomputed automatically otherwise.
pub struct SparseSolver {
    analysis: Option<Analysis>,
    /// CSC values of the last factorized matrix.
    values: Vec<f64>,
    numeric: NumericLu<usize, f64>,
    /// Whether `numeric` holds a factorization of `analysis`'s pattern.
    factorized: bool,
    threshold: SupernodalThreshold,
    symbolic_count: usize,
    numeric_count: usize,
}

impl fmt::Debug for SparseSolver {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SparseSolver")
            .field("n", &self.analysis.as_ref().map(|a| a.n))
            .field("nnz", &self.values.len())
            .field("factorized", &self.factorized)
            .field("symbolic_count", &self.symbolic_count)
            .field("numeric_count", &self.numeric_count)
            .finish()
    }
}

impl Default for SparseSolver {
    fn default() -> Self {
        Self::new()
    }
}

impl SparseSolver {
    pub fn new() -> Self {
        Self::with_threshold(SupernodalThreshold::AUTO)
    }

    /// Forces faer's simplicial or supernodal variant (tests cover both; faer picks by flop
    /// count otherwise).
    fn with_threshold(threshold: SupernodalThreshold) -> Self {
        Self {
            analysis: None,
            values: Vec::new(),
            numeric: NumericLu::new(),
            factorized: false,
            threshold,
            symbolic_count: 0,
            numeric_count: 0,
        }
    }

    /// Factorizes the matrix and solves `A x = b` in place. Results are bitwise identical
    /// whatever the rayon thread count.
    ///
    /// Errors: [`MeshfreeError::Singular`] on a (structurally or numerically) singular matrix
    /// or a non-finite solution; [`MeshfreeError::BadInput`] if `b.len() != a.n`.
    pub fn solve(&mut self, a: &TripletMatrix, b: &mut [f64]) -> Result<(), MeshfreeError> {
        if b.len() != a.n {
            return Err(MeshfreeError::BadInput(format!(
                "right-hand side of length {} for a {}×{} matrix",
                b.len(),
                a.n,
                a.n
            )));
        }
        self.factorize(a)?;
        self.solve_factored(b)
    }

    /// Factorizes `a` (reusing the symbolic analysis when its index sequence is unchanged),
    /// for several right-hand sides through [`Self::solve_factored`].
    pub fn factorize(&mut self, a: &TripletMatrix) -> Result<(), MeshfreeError> {
        self.factorized = false;
        if !self.analysis.as_ref().is_some_and(|an| an.matches(a)) {
            // Drop the old analysis first: on failure nothing stale may be reused.
            self.analysis = None;
            self.analysis = Some(Analysis::new(a, self.threshold)?);
            self.symbolic_count += 1;
        }
        let an = self.analysis.as_mut().expect("analysis was just built");
        if an.n == 0 {
            self.factorized = true;
            return Ok(());
        }
        self.values.clear();
        self.values.resize(an.row_idx.len(), 0.0);
        for (&s, &v) in an.slot.iter().zip(&a.values) {
            self.values[s] += v;
        }
        let pattern =
            SymbolicSparseColMatRef::new_checked(an.n, an.n, &an.col_ptr, None, &an.row_idx);
        let mat = SparseColMatRef::new(pattern, &self.values);
        an.symbolic
            .factorize_numeric_lu(
                &mut self.numeric,
                mat,
                Par::Seq,
                MemStack::new(&mut an.factor_scratch),
                Default::default(),
            )
            .map_err(|e| match e {
                LuError::SymbolicSingular { .. } => MeshfreeError::Singular,
                LuError::Generic(e) => {
                    MeshfreeError::BadInput(format!("sparse LU factorization failed: {e:?}"))
                }
            })?;
        self.numeric_count += 1;
        self.factorized = true;
        Ok(())
    }

    /// Solves `A x = b` in place with the last successful [`Self::factorize`].
    ///
    /// Errors: [`MeshfreeError::Singular`] on a non-finite solution (a zero or tiny pivot);
    /// [`MeshfreeError::BadInput`] without a factorization or on a length mismatch.
    pub fn solve_factored(&mut self, b: &mut [f64]) -> Result<(), MeshfreeError> {
        let an = match (&mut self.analysis, self.factorized) {
            (Some(an), true) => an,
            _ => {
                return Err(MeshfreeError::BadInput(
                    "no sparse factorization to solve with".into(),
                ));
            }
        };
        if b.len() != an.n {
            return Err(MeshfreeError::BadInput(format!(
                "right-hand side of length {} for a {}×{} matrix",
                b.len(),
                an.n,
                an.n
            )));
        }
        if an.n == 0 {
            return Ok(());
        }
        let lu = faer::sparse::linalg::lu::LuRef::new_unchecked(&an.symbolic, &self.numeric);
        lu.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(b, an.n, 1),
            Par::Seq,
            MemStack::new(&mut an.solve_scratch),
        );
        if b.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(MeshfreeError::Singular)
        }
    }

    /// Symbolic analyses done (for reports: how often the pattern changed).
    pub fn symbolic_count(&self) -> usize {
        self.symbolic_count
    }

    /// Numeric factorizations done.
    pub fn numeric_count(&self) -> usize {
        self.numeric_count
    }
}

/// A synthetic multi-grain matrix for tests and benchmarks: `blocks` grains of
/// `dofs_per_block` DoF (2 per node, nodes at random in a disc), each node coupled with its
/// `neighbours` nearest nodes through random symmetric positive 2×2 blocks (a matrix-weighted
/// graph Laplacian, assembled edge by edge so that diagonal entries arrive as duplicates),
/// plus a small diagonal shift; then `contacts` one-sided (hence non-symmetric) 2×2
/// couplings between random nodes of random pairs of distinct grains.
///
/// # Panics
/// If `dofs_per_block` is odd or `neighbours` is not below the number of nodes per block,
/// or if `contacts > 0` with fewer than two blocks.
pub fn synthetic_multi_grain(
    blocks: usize,
    dofs_per_block: usize,
    neighbours: usize,
    contacts: usize,
    seed: u64,
) -> TripletMatrix {
    use rand::SeedableRng;
    assert!(dofs_per_block.is_multiple_of(2), "2 DoF per node");
    let nodes = dofs_per_block / 2;
    assert!(neighbours < nodes, "more neighbours than nodes in a block");
    assert!(contacts == 0 || blocks >= 2, "contacts need two grains");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut u = move || crate::sample::unit_random(&mut rng);
    let mut a = TripletMatrix::new(blocks * dofs_per_block);
    let push2 = |a: &mut TripletMatrix, ni: usize, nj: usize, m: [[f64; 2]; 2]| {
        for (r, row) in m.iter().enumerate() {
            for (c, &v) in row.iter().enumerate() {
                a.push(2 * ni + r, 2 * nj + c, v);
            }
        }
    };
    for blk in 0..blocks {
        let base = blk * nodes;
        let pts: Vec<[f64; 2]> = (0..nodes)
            .map(|_| {
                let (r, t) = (u().sqrt(), std::f64::consts::TAU * u());
                [r * cos(t), r * sin(t)]
            })
            .collect();
        // Symmetrized k-nearest-neighbour graph, each edge once (i < j), in a fixed order.
        let mut adj = vec![vec![false; nodes]; nodes];
        for i in 0..nodes {
            let mut d: Vec<(f64, usize)> = (0..nodes)
                .filter(|&j| j != i)
                .map(|j| {
                    (
                        (pts[i][0] - pts[j][0]).powi(2) + (pts[i][1] - pts[j][1]).powi(2),
                        j,
                    )
                })
                .collect();
            d.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            for &(_, j) in &d[..neighbours] {
                adj[i][j] = true;
                adj[j][i] = true;
            }
        }
        for (i, row) in adj.iter().enumerate() {
            for j in (i + 1..nodes).filter(|&j| row[j]) {
                // Random SPD 2×2: diagonal dominant with a random off-diagonal.
                let (p, q) = (0.5 + u(), 0.5 + u());
                let o = (u() - 0.5) * (p.min(q));
                let s = [[p, o], [o, q]];
                let neg = [[-p, -o], [-o, -q]];
                push2(&mut a, base + i, base + i, s);
                push2(&mut a, base + j, base + j, s);
                push2(&mut a, base + i, base + j, neg);
                push2(&mut a, base + j, base + i, neg);
            }
        }
        for i in 0..nodes {
            push2(&mut a, base + i, base + i, [[0.05, 0.0], [0.0, 0.05]]);
        }
    }
    for _ in 0..contacts {
        let bi = ((u() * blocks as f64) as usize).min(blocks - 1);
        let mut bj = ((u() * (blocks - 1) as f64) as usize).min(blocks - 2);
        if bj >= bi {
            bj += 1;
        }
        let ni = bi * nodes + ((u() * nodes as f64) as usize).min(nodes - 1);
        let nj = bj * nodes + ((u() * nodes as f64) as usize).min(nodes - 1);
        // A penalty-like term acting on grain i only: rows of i get C (u_i − u_j).
        let c = [[1.0 + u(), u() - 0.5], [u() - 0.5, 1.0 + u()]];
        push2(&mut a, ni, ni, c);
        push2(&mut a, ni, nj, [[-c[0][0], -c[0][1]], [-c[1][0], -c[1][1]]]);
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::meshfree::model::Dense;
    use crate::meshfree::solver::lu_solve;

    fn to_dense(a: &TripletMatrix) -> Dense {
        let mut d = Dense::zeros(a.n);
        for ((&r, &c), &v) in a.rows.iter().zip(&a.cols).zip(&a.values) {
            d.add(r, c, v);
        }
        d
    }

    fn rhs(n: usize, seed: u64) -> Vec<f64> {
        (0..n)
            .map(|i| ((i as u64 * 2654435761 + seed) % 1000) as f64 / 500.0 - 1.0)
            .collect()
    }

    fn inf_norm(v: &[f64]) -> f64 {
        v.iter().fold(0.0, |m: f64, x| m.max(x.abs()))
    }

    /// ‖A x − b‖∞ / (‖A‖∞ ‖x‖∞): the backward error of the solve.
    fn relative_residual(a: &TripletMatrix, x: &[f64], b: &[f64]) -> f64 {
        let ax = a.mul_vec(x);
        let r: Vec<f64> = ax.iter().zip(b).map(|(p, q)| p - q).collect();
        let mut row_abs = vec![0.0; a.n];
        for (&r, &v) in a.rows.iter().zip(&a.values) {
            row_abs[r] += v.abs();
        }
        inf_norm(&r) / (inf_norm(&row_abs) * inf_norm(x))
    }

    fn all_variants() -> [SparseSolver; 3] {
        [
            SparseSolver::new(),
            SparseSolver::with_threshold(SupernodalThreshold::FORCE_SIMPLICIAL),
            SparseSolver::with_threshold(SupernodalThreshold::FORCE_SUPERNODAL),
        ]
    }

    /// Checks `solver` on `a` against the dense LU: small backward error and agreement.
    fn check_against_dense(solver: &mut SparseSolver, a: &TripletMatrix, seed: u64) {
        let b = rhs(a.n, seed);
        let mut x = b.clone();
        solver.solve(a, &mut x).unwrap();
        let res = relative_residual(a, &x, &b);
        assert!(res < 1e-12, "relative residual {res:e}");
        let mut xd = b.clone();
        lu_solve(&mut to_dense(a), &mut xd).unwrap();
        let diff: Vec<f64> = x.iter().zip(&xd).map(|(p, q)| p - q).collect();
        let rel = inf_norm(&diff) / inf_norm(&xd);
        assert!(rel < 1e-9, "sparse and dense solutions differ by {rel:e}");
    }

    #[test]
    fn matches_dense_lu_on_non_symmetric_blocks() {
        let a = synthetic_multi_grain(2, 200, 40, 30, 1);
        // The test matrix must really be non-symmetric.
        let d = to_dense(&a);
        let asym = (0..a.n)
            .flat_map(|i| (0..a.n).map(move |j| (i, j)))
            .map(|(i, j)| (d.get(i, j) - d.get(j, i)).abs())
            .fold(0.0, f64::max);
        assert!(asym > 0.1, "matrix is symmetric");
        for mut s in all_variants() {
            check_against_dense(&mut s, &a, 7);
        }
    }

    #[test]
    fn duplicates_summed_and_order_free() {
        // [[4, 1, 0], [2, 5, 1], [0, 3, 6]] given shuffled, with entries split in pieces.
        let mut a = TripletMatrix::new(3);
        for &(r, c, v) in &[
            (2, 2, 6.0),
            (1, 0, 1.5),
            (0, 1, 1.0),
            (1, 1, 2.0),
            (0, 0, 3.0),
            (2, 1, 3.0),
            (1, 2, 1.0),
            (1, 0, 0.5),
            (0, 0, 1.0),
            (1, 1, 3.0),
        ] {
            a.push(r, c, v);
        }
        let x_true = [1.0, -2.0, 0.5];
        let mut b = a.mul_vec(&x_true);
        assert_eq!(b, vec![2.0, -7.5, -3.0]);
        let mut s = SparseSolver::new();
        s.solve(&a, &mut b).unwrap();
        for (p, q) in b.iter().zip(&x_true) {
            assert!((p - q).abs() < 1e-14, "{b:?}");
        }
    }

    #[test]
    fn symbolic_analysis_reused_until_pattern_changes() {
        let a = synthetic_multi_grain(2, 200, 40, 30, 2);
        for mut s in all_variants() {
            check_against_dense(&mut s, &a, 1);
            assert_eq!((s.symbolic_count(), s.numeric_count()), (1, 1));

            // Same index sequence, new values: numeric only.
            let mut a2 = TripletMatrix::new(a.n);
            for ((&r, &c), &v) in a.rows.iter().zip(&a.cols).zip(&a.values) {
                a2.push(r, c, if r == c { v * 1.5 } else { v * 0.9 });
            }
            check_against_dense(&mut s, &a2, 2);
            assert_eq!((s.symbolic_count(), s.numeric_count()), (1, 2));

            // A new contact coupling between the two grains: new analysis.
            let mut a3 = a2.clone();
            a3.push(10, 300, -0.7);
            a3.push(300, 300, 0.7);
            check_against_dense(&mut s, &a3, 3);
            assert_eq!((s.symbolic_count(), s.numeric_count()), (2, 3));

            // Same length, one index moved: the full comparison must see it.
            let mut a4 = a3.clone();
            *a4.cols.last_mut().unwrap() = 301;
            *a4.rows.last_mut().unwrap() = 301;
            check_against_dense(&mut s, &a4, 4);
            assert_eq!((s.symbolic_count(), s.numeric_count()), (3, 4));

            // Back to a3 (cleared and refilled, as in a Newton loop): analysed again, correct.
            let mut a5 = TripletMatrix::new(a.n);
            a5.clone_from(&a3);
            a5.clear();
            assert!(a5.is_empty());
            for ((&r, &c), &v) in a3.rows.iter().zip(&a3.cols).zip(&a3.values) {
                a5.push(r, c, v);
            }
            check_against_dense(&mut s, &a5, 5);
            check_against_dense(&mut s, &a5, 6);
            assert_eq!((s.symbolic_count(), s.numeric_count()), (4, 6));
        }
    }

    #[test]
    fn singular_matrices_rejected() {
        let base = synthetic_multi_grain(2, 60, 12, 5, 3);
        let b = rhs(base.n, 0);

        // Structurally singular: DoF 7 appears in no triplet (empty row and column).
        let mut a = TripletMatrix::new(base.n);
        for ((&r, &c), &v) in base.rows.iter().zip(&base.cols).zip(&base.values) {
            if r != 7 && c != 7 {
                a.push(r, c, v);
            }
        }
        for mut s in all_variants() {
            let mut x = b.clone();
            assert_eq!(s.solve(&a, &mut x), Err(MeshfreeError::Singular));
        }

        // Numerically singular, structurally regular: rows 0 and 1 are proportional on the
        // 2×2 block that remains once column 3 is eliminated, so whatever the column order
        // and pivoting the LU meets an exactly zero pivot.
        let mut a = TripletMatrix::new(4);
        for &(r, c, v) in &[
            (0, 0, 1.0),
            (0, 1, 2.0),
            (1, 0, 2.0),
            (1, 1, 4.0),
            (2, 2, 1.0),
            (3, 3, 1.0),
            (0, 3, 1.0),
        ] {
            a.push(r, c, v);
        }
        for mut s in all_variants() {
            let mut x = vec![1.0, 0.0, 2.0, 3.0];
            assert_eq!(s.solve(&a, &mut x), Err(MeshfreeError::Singular));
            // A later regular matrix with the same pattern still works.
            let mut a2 = a.clone();
            a2.values[3] = 5.0;
            let mut x = vec![1.0, 0.0, 2.0, 3.0];
            s.solve(&a2, &mut x).unwrap();
            assert!(relative_residual(&a2, &x, &[1.0, 0.0, 2.0, 3.0]) < 1e-15);
        }
    }

    #[test]
    fn bad_input_and_empty() {
        let a = synthetic_multi_grain(2, 20, 4, 2, 4);
        let mut s = SparseSolver::new();
        assert!(matches!(
            s.solve_factored(&mut [0.0; 40]),
            Err(MeshfreeError::BadInput(_))
        ));
        assert!(matches!(
            s.solve(&a, &mut [0.0; 39]),
            Err(MeshfreeError::BadInput(_))
        ));
        let mut empty: [f64; 0] = [];
        s.solve(&TripletMatrix::new(0), &mut empty).unwrap();
    }

    #[test]
    fn bitwise_identical_across_thread_counts() {
        // 3,200 DoF with many contacts: the smallest of the sizes tried where faer's
        // parallel path (`Par::Seq` instead of `Par::Seq`) does give different bits
        // with 1 and 2 threads, so this test catches a switch to it.
        let a = synthetic_multi_grain(16, 200, 40, 800, 5);
        let b = rhs(a.n, 9);
        let variants = [
            SupernodalThreshold::AUTO,
            SupernodalThreshold::FORCE_SUPERNODAL,
        ];
        for threshold in variants {
            let run = |threads: usize| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| {
                    let mut s = SparseSolver::with_threshold(threshold);
                    let mut x = b.clone();
                    s.solve(&a, &mut x).unwrap();
                    x.iter().map(|v| v.to_bits()).collect::<Vec<u64>>()
                })
            };
            assert_eq!(run(1), run(2), "threshold {}", threshold.0);
        }
    }
}
