//! Broad phase: a Verlet neighbour list with a skin, built on a uniform cell grid.
//!
//! Two grains are candidates when their bounding circles, inflated by the skin, overlap. The
//! list stays valid while every grain has moved plus grown by less than half the skin since
//! it was built: a pair not in the list cannot then have closed the gap. Everything here is
//! ordered (a stable counting sort into cells, pairs sorted by (i, j)), so the list and every
//! sum over it are the same whatever the thread count.

use glam::DVec2;
use rayon::prelude::*;

#[derive(Debug, Clone, Default)]
pub struct NeighborList {
    /// Extra distance added to the bounding circles, in length units.
    pub skin: f64,
    /// Candidate pairs (i, j), i < j, sorted.
    pub pairs: Vec<[u32; 2]>,
    /// For grain g, `grain_pairs[grain_offsets[g]..grain_offsets[g + 1]]` lists the indices of
    /// the pairs that contain g, in increasing order.
    pub grain_offsets: Vec<u32>,
    pub grain_pairs: Vec<u32>,
    reference_centers: Vec<DVec2>,
    reference_reach: Vec<f64>,
    /// Number of builds so far (a diagnostic).
    pub builds: u64,
}

impl NeighborList {
    pub fn new(skin: f64) -> Self {
        Self {
            skin,
            ..Default::default()
        }
    }

    /// Whether some grain moved or grew enough since the last build that a pair may be missing.
    pub fn needs_rebuild(&self, centers: &[DVec2], reach: &[f64]) -> bool {
        if self.reference_centers.len() != centers.len() {
            return true;
        }
        let limit = 0.5 * self.skin;
        centers
            .par_iter()
            .zip(reach.par_iter())
            .zip(
                self.reference_centers
                    .par_iter()
                    .zip(self.reference_reach.par_iter()),
            )
            .any(|((c, r), (c0, r0))| c.distance(*c0) + (r - r0).max(0.0) >= limit)
    }

    /// Rebuilds the list for grains with the given centres and bounding radii.
    pub fn build(&mut self, centers: &[DVec2], reach: &[f64]) {
        let n = centers.len();
        self.builds += 1;
        self.reference_centers.clear();
        self.reference_centers.extend_from_slice(centers);
        self.reference_reach.clear();
        self.reference_reach.extend_from_slice(reach);
        self.pairs.clear();
        self.grain_pairs.clear();
        self.grain_offsets.clear();
        self.grain_offsets.resize(n + 1, 0);
        if n == 0 {
            return;
        }
        let max_reach = reach.iter().cloned().fold(0.0, f64::max);
        let cell = (2.0 * max_reach + self.skin).max(f64::MIN_POSITIVE);
        let (mut lo, mut hi) = (centers[0], centers[0]);
        for c in centers {
            lo = lo.min(*c);
            hi = hi.max(*c);
        }
        let cols = (((hi.x - lo.x) / cell) as usize + 1).min(1 << 15);
        let rows = (((hi.y - lo.y) / cell) as usize + 1).min(1 << 15);
        let cell_of = |c: DVec2| -> (usize, usize) {
            let cx = (((c.x - lo.x) / cell) as usize).min(cols - 1);
            let cy = (((c.y - lo.y) / cell) as usize).min(rows - 1);
            (cx, cy)
        };
        // Stable counting sort of the grains into cells.
        let mut cell_start = vec![0u32; cols * rows + 1];
        for c in centers {
            let (cx, cy) = cell_of(*c);
            cell_start[cy * cols + cx + 1] += 1;
        }
        for k in 0..cols * rows {
            cell_start[k + 1] += cell_start[k];
        }
        let mut fill = cell_start.clone();
        let mut cell_grains = vec![0u32; n];
        for (g, c) in centers.iter().enumerate() {
            let (cx, cy) = cell_of(*c);
            let slot = &mut fill[cy * cols + cx];
            cell_grains[*slot as usize] = g as u32;
            *slot += 1;
        }
        let skin = self.skin;
        let neighbours: Vec<Vec<u32>> = (0..n)
            .into_par_iter()
            .with_min_len(256)
            .map(|i| {
                let ci = centers[i];
                let (cx, cy) = cell_of(ci);
                let mut found = Vec::new();
                for ny in cy.saturating_sub(1)..=(cy + 1).min(rows - 1) {
                    for nx in cx.saturating_sub(1)..=(cx + 1).min(cols - 1) {
                        let k = ny * cols + nx;
                        for &j in &cell_grains[cell_start[k] as usize..cell_start[k + 1] as usize] {
                            if (j as usize) <= i {
                                continue;
                            }
                            let limit = reach[i] + reach[j as usize] + skin;
                            if ci.distance_squared(centers[j as usize]) < limit * limit {
                                found.push(j);
                            }
                        }
                    }
                }
                found.sort_unstable();
                found
            })
            .collect();
        for (i, list) in neighbours.iter().enumerate() {
            self.pairs.extend(list.iter().map(|&j| [i as u32, j]));
        }
        // Transpose: the pairs of each grain, in increasing pair order.
        for [i, j] in &self.pairs {
            self.grain_offsets[*i as usize + 1] += 1;
            self.grain_offsets[*j as usize + 1] += 1;
        }
        for g in 0..n {
            self.grain_offsets[g + 1] += self.grain_offsets[g];
        }
        self.grain_pairs.resize(self.grain_offsets[n] as usize, 0);
        let mut fill: Vec<u32> = self.grain_offsets[..n].to_vec();
        for (p, [i, j]) in self.pairs.iter().enumerate() {
            for g in [*i as usize, *j as usize] {
                self.grain_pairs[fill[g] as usize] = p as u32;
                fill[g] += 1;
            }
        }
    }

    /// Indices of the pairs that contain grain g.
    #[inline]
    pub fn pairs_of(&self, g: usize) -> &[u32] {
        &self.grain_pairs[self.grain_offsets[g] as usize..self.grain_offsets[g + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_exactly_the_pairs_of_a_brute_force_search() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(12345);
        let mut next = || crate::sample::unit_random(&mut rng);
        let centers: Vec<DVec2> = (0..500)
            .map(|_| DVec2::new(next() * 3.0, next() * 2.0))
            .collect();
        let reach: Vec<f64> = (0..500).map(|_| 0.02 + 0.05 * next()).collect();
        let mut list = NeighborList::new(0.01);
        list.build(&centers, &reach);
        let mut brute = Vec::new();
        for i in 0..500 {
            for j in i + 1..500 {
                let limit = reach[i] + reach[j] + 0.01;
                if centers[i].distance_squared(centers[j]) < limit * limit {
                    brute.push([i as u32, j as u32]);
                }
            }
        }
        assert_eq!(list.pairs, brute);
        for g in 0..500 {
            for &p in list.pairs_of(g) {
                assert!(list.pairs[p as usize].contains(&(g as u32)));
            }
        }
        assert!(!list.needs_rebuild(&centers, &reach));
        let mut moved = centers.clone();
        moved[7].x += 0.006;
        assert!(list.needs_rebuild(&moved, &reach));
    }
}
