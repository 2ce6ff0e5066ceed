//! Spatial numbering of a generated sample: grains along a Hilbert curve (issue #16); and the
//! check that warns when a sample file's numbering is scattered in space
//! ([`numbering_warning`]).
//!
//! The step reads each pair's two grains and gathers each grain's contacts by index. With the
//! random numbering of random sequential addition, those reads land anywhere in memory; numbered
//! along a space-filling curve, neighbours sit close in every array and the caches serve them.
//! On the dense bench packing at 10^5 grains a random numbering steps 2.5 (full level) to 3.3
//! (rigid) times slower on one thread than a spatial one. A compaction moves grains little
//! relative to their neighbours, so the numbering stays good for the whole run.

use crate::grain::Grain;

/// Samples of this many grains and more are checked by [`numbering_warning`]: in smaller ones
/// the caches hold every grain whatever the order.
pub const NUMBERING_CHECK_GRAINS: usize = 10_000;

/// The median step of a numbering (see [`median_step_in_radii`]) above which it counts as
/// scattered: a spatial one steps about two radii (one diameter) in a packing.
pub const SCATTERED_STEP_RADII: f64 = 8.0;

/// The median distance between grains numbered one after the other, in mean radii: about 2 in
/// a packing numbered along a space-filling curve or row by row, a fair part of the box over a
/// radius in a random numbering. 0 for fewer than two grains.
pub fn median_step_in_radii(grains: &[Grain]) -> f64 {
    if grains.len() < 2 {
        return 0.0;
    }
    let mean_radius = grains.iter().map(|g| g.radius).sum::<f64>() / grains.len() as f64;
    let mut steps: Vec<f64> = grains
        .windows(2)
        .map(|pair| pair[0].center.distance(pair[1].center))
        .collect();
    let middle = steps.len() / 2;
    let (_, median, _) = steps.select_nth_unstable_by(middle, f64::total_cmp);
    *median / mean_radius
}

/// What both warnings about a file's order ask of the user.
const SORT_ROWS: &str = "The order changes no physics, only the rounding of sums: sort the \
                         file's rows, strip by strip, with `sdem sort-sample FILE SORTED.csv` \
                         and name the sorted file";

/// A warning for a sample file (`field`: the scenario field that names it) of at least
/// [`NUMBERING_CHECK_GRAINS`] grains whose numbering is scattered in space, or `None`. The
/// step reads each pair's grains and gathers each grain's contacts by number: LAMMPS's packing
/// of 10^5 discs in a random order stepped 0.51 times as fast as in its own (binned) order, on
/// one thread and on two (issue #16, thirty-third session). sdem keeps a file's numbering (its
/// outputs name grains by it), so the warning asks the user to sort the file.
pub fn numbering_warning(field: &str, grains: &[Grain]) -> Option<String> {
    if grains.len() < NUMBERING_CHECK_GRAINS {
        return None;
    }
    let step = median_step_in_radii(grains);
    (step > SCATTERED_STEP_RADII).then(|| {
        format!(
            "{field}: grains numbered one after the other lie {step:.0} mean radii apart \
             (median; about 2 in a spatial order): the file's order is scattered in space, \
             and SDEM steps such a sample about half as fast as the same grains in a spatial \
             order. {SORT_ROWS} (sdem keeps a file's numbering, which its outputs use)"
        )
    })
}

/// A warning for a sample file (`field`: the scenario field that names it) of at least
/// [`NUMBERING_CHECK_GRAINS`] grains whose numbering is spatial piece by piece but whose pieces
/// meet across the numbering, or `None`: rows written one piece of the box after another, as
/// LAMMPS's `write_data` writes each MPI process's atoms in turn, put grains next to grains of
/// the other half of the numbering. On two threads the step's sweep then takes its pair and
/// grain passes one after the other, as [`sweep_plan_of`](crate::integration::sweep_plan_of)
/// (the sweep's own rule) tells from the grains' candidate pairs (with `skin`, the run's
/// neighbour skin): LAMMPS's 10^5 packing as written by two processes stepped 3–19% slower on
/// two threads than in strips, 8% in the median of nine paired rounds over four sittings
/// (2.31–2.58e7 against 2.61–2.91e7 grain-steps/s; issue #16, thirty-fourth session).
pub fn threads_wait_warning(field: &str, grains: &[Grain], skin: f64) -> Option<String> {
    if grains.len() < NUMBERING_CHECK_GRAINS {
        return None;
    }
    let centers: Vec<glam::DVec2> = grains.iter().map(|g| g.center).collect();
    let reach: Vec<f64> = grains.iter().map(|g| g.shape().bounding_radius).collect();
    let mut list = crate::geometry::broadphase::NeighborList::new(skin);
    list.build(&centers, &reach);
    let plan = crate::integration::sweep_plan_of(&list, grains.len(), 2);
    (!plan.fused).then(|| {
        format!(
            "{field}: grains meet grains far back in the file's numbering ({} of {} chunks of \
             {} grains would wait on two threads: rows written piece by piece, as LAMMPS writes \
             each MPI process's atoms in turn), and SDEM's step on two threads or more then \
             takes its pair and grain passes one after the other (8% slower on LAMMPS's 10^5 \
             packing, the median of nine paired rounds). {SORT_ROWS}",
            plan.waiting,
            plan.chunks,
            crate::integration::GRAIN_CHUNK
        )
    })
}

/// Bits per axis of the Hilbert grid: 2^16 cells across the longer side of the box.
const HILBERT_BITS: u32 = 16;

/// Position of the cell `(x, y)` along the Hilbert curve that fills the `2^bits x 2^bits` grid
/// (x, y < 2^bits): consecutive positions are cells that share a side.
pub fn hilbert_index(bits: u32, mut x: u32, mut y: u32) -> u64 {
    let n: u32 = 1 << bits;
    let mut index = 0u64;
    let mut s = n / 2;
    while s > 0 {
        let rx = u32::from(x & s > 0);
        let ry = u32::from(y & s > 0);
        index += u64::from(s) * u64::from(s) * u64::from((3 * rx) ^ ry);
        // Turn the quadrant so that the curve inside it runs the standard way.
        if ry == 0 {
            if rx == 1 {
                x = n - 1 - x;
                y = n - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
        s /= 2;
    }
    index
}

/// The order in which to number points `(x, y)` of the box `[0, width] x [0, height]` so that
/// they follow a Hilbert curve (ties keep their given order): the k-th grain of the new
/// numbering is `points[order[k]]`.
pub fn hilbert_order(points: &[(f64, f64)], width: f64, height: f64) -> Vec<usize> {
    let cells = f64::from(1u32 << HILBERT_BITS);
    let side = width.max(height);
    let cell_of = |v: f64| -> u32 {
        // NaN and points outside the box go to the nearest edge cell.
        ((v / side * cells).max(0.0) as u32).min((1 << HILBERT_BITS) - 1)
    };
    let keys: Vec<u64> = points
        .iter()
        .map(|&(x, y)| hilbert_index(HILBERT_BITS, cell_of(x), cell_of(y)))
        .collect();
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by_key(|&k| keys[k]);
    order
}

/// The order in which to number grains of mean radius `mean_radius` centred at `points` so that
/// they run strip by strip, each strip one mean diameter wide and as long as the shorter side of
/// their bounding box, back and forth (ties keep their given order): the k-th grain of the new
/// numbering is `points[order[k]]`. A grain's neighbours then lie in its own strip or the next,
/// at most about one strip's grains apart in number.
///
/// For the step's sweep this beats a Hilbert curve where several threads share it: a thread's
/// run of grains meets the runs before it along one strip, where a Hilbert curve's piece of
/// the box meets them along much of its outline, and a grain that meets an earlier run waits
/// for a second round (`integration::sweep`). LAMMPS's packing of 10^5 discs, two threads
/// (issue #16, thirty-fourth session): 6 of 391 chunks waited in strips, 41 along a Hilbert
/// curve, and the step ran 2.63e7 and 2.67e7 against 2.41e7 and 2.48e7 grain-steps/s.
pub fn strip_order(points: &[(f64, f64)], mean_radius: f64) -> Vec<usize> {
    let (mut low, mut high) = (
        (f64::INFINITY, f64::INFINITY),
        (f64::NEG_INFINITY, f64::NEG_INFINITY),
    );
    for &(x, y) in points {
        low = (low.0.min(x), low.1.min(y));
        high = (high.0.max(x), high.1.max(y));
    }
    // Strips along the shorter side: more strips, each of fewer grains.
    let along_x = high.0 - low.0 <= high.1 - low.1;
    let width = 2.0 * mean_radius;
    let key = |&(x, y): &(f64, f64)| {
        let (along, across) = if along_x {
            (x - low.0, y - low.1)
        } else {
            (y - low.1, x - low.0)
        };
        // A sample file's centres are finite; a NaN would go to the first strip.
        let strip = (across / width).max(0.0).min(u32::MAX as f64) as u64;
        let along = if strip.is_multiple_of(2) {
            along
        } else {
            -along
        };
        (strip, along)
    };
    let keys: Vec<(u64, f64)> = points.iter().map(key).collect();
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| {
        keys[a]
            .0
            .cmp(&keys[b].0)
            .then(keys[a].1.total_cmp(&keys[b].1))
    });
    order
}

/// A sample file's text with its grains' lines in [`strip_order`] (`sdem sort-sample`): the
/// order [`numbering_warning`] asks for. Each grain's line is kept as written, so the sorted file
/// holds the same grains to the last digit; the lines that are not grains (the header, comments)
/// come first, in their order, and blank lines go. `path` names the file in errors: the text
/// must be a sample file ([`parse_grains`](crate::sample::file::parse_grains)).
pub fn sort_sample_text(
    text: &str,
    path: &str,
) -> Result<SortedSample, crate::sample::file::SampleFileError> {
    let parsed = crate::sample::file::parse_grains(text, path)?;
    let lines: Vec<&str> = text.lines().collect();
    let points: Vec<(f64, f64)> = parsed
        .grains
        .iter()
        .map(|g| (g.center.x, g.center.y))
        .collect();
    let mean_radius =
        parsed.grains.iter().map(|g| g.radius).sum::<f64>() / parsed.grains.len().max(1) as f64;
    let order = strip_order(&points, mean_radius);
    let mut grain_line = vec![false; lines.len()];
    for &line in &parsed.lines {
        grain_line[line - 1] = true;
    }
    let mut sorted = String::with_capacity(text.len() + 1);
    for (k, line) in lines.iter().enumerate() {
        if !grain_line[k] && !line.trim().is_empty() {
            sorted.push_str(line);
            sorted.push('\n');
        }
    }
    for &k in &order {
        sorted.push_str(lines[parsed.lines[k] - 1]);
        sorted.push('\n');
    }
    let sorted_grains: Vec<Grain> = order.iter().map(|&k| parsed.grains[k]).collect();
    Ok(SortedSample {
        text: sorted,
        grains: parsed.grains.len(),
        step_before: median_step_in_radii(&parsed.grains),
        step_after: median_step_in_radii(&sorted_grains),
    })
}

/// What [`sort_sample_text`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct SortedSample {
    /// The sorted file.
    pub text: String,
    pub grains: usize,
    /// [`median_step_in_radii`] of the file's numbering and of the sorted one.
    pub step_before: f64,
    pub step_after: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    #[test]
    fn a_scattered_numbering_of_a_large_sample_draws_the_warning_and_a_spatial_one_does_not() {
        // Expectation: a 100 x 100 grid of touching discs numbered row by row steps one
        // diameter (2 radii) but at each row's end; numbered along a Hilbert curve, about the
        // same; numbered by a scattering permutation (k -> 7919 k mod n), some 57 radii (far
        // more than 8). Only the scattered one of the large sample is warned about, and a small
        // sample never is.
        let side = 100;
        let radius = 0.01;
        let rows: Vec<Grain> = (0..side * side)
            .map(|k| {
                let (i, j) = (k % side, k / side);
                let center = DVec2::new((2 * i + 1) as f64 * radius, (2 * j + 1) as f64 * radius);
                Grain::at_rest(center, radius)
            })
            .collect();
        assert!((median_step_in_radii(&rows) - 2.0).abs() < 1e-9);
        let points: Vec<(f64, f64)> = rows.iter().map(|g| (g.center.x, g.center.y)).collect();
        let width = 2.0 * side as f64 * radius;
        let hilbert: Vec<Grain> = hilbert_order(&points, width, width)
            .into_iter()
            .map(|k| rows[k])
            .collect();
        assert!(median_step_in_radii(&hilbert) <= 2.0 + 1e-9);
        let n = rows.len();
        let scattered: Vec<Grain> = (0..n).map(|k| rows[k * 7919 % n]).collect();
        assert!(median_step_in_radii(&scattered) > 5.0 * SCATTERED_STEP_RADII);

        assert_eq!(numbering_warning("sample.file", &rows), None);
        assert_eq!(numbering_warning("sample.file", &hilbert), None);
        let warning = numbering_warning("sample.file", &scattered).expect("a warning");
        assert!(warning.starts_with("sample.file: ") && warning.contains("sort the file's rows"));
        assert_eq!(numbering_warning("sample.file", &scattered[..5000]), None);
    }

    #[test]
    fn the_hilbert_curve_visits_every_cell_once_through_neighbouring_cells() {
        // Expectation: on a 2^k grid the index is a bijection onto 0..4^k, and cells with
        // consecutive indices share a side (the defining property of the curve).
        for bits in 1..=5 {
            let n = 1u32 << bits;
            let mut cell_at = vec![None; (n * n) as usize];
            for x in 0..n {
                for y in 0..n {
                    let d = hilbert_index(bits, x, y) as usize;
                    assert!(cell_at[d].is_none(), "index {d} twice");
                    cell_at[d] = Some((x as i64, y as i64));
                }
            }
            let cells: Vec<(i64, i64)> = cell_at.into_iter().map(Option::unwrap).collect();
            for w in cells.windows(2) {
                let step = (w[0].0 - w[1].0).abs() + (w[0].1 - w[1].1).abs();
                assert_eq!(step, 1, "{bits} bits: {:?} -> {:?}", w[0], w[1]);
            }
        }
    }

    #[test]
    fn the_order_is_a_permutation_that_keeps_neighbours_close() {
        // Expectation: a permutation; and along it, consecutive points of a 64 x 64 lattice
        // (listed row by row, then shuffled) are lattice neighbours.
        let side = 64;
        let mut points: Vec<(f64, f64)> = (0..side * side)
            .map(|k| ((k % side) as f64 + 0.5, (k / side) as f64 + 0.5))
            .collect();
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
        rand::seq::SliceRandom::shuffle(&mut points[..], &mut rng);
        let order = hilbert_order(&points, side as f64, side as f64);
        let mut seen = vec![false; points.len()];
        for &k in &order {
            assert!(!std::mem::replace(&mut seen[k], true));
        }
        for w in order.windows(2) {
            let (a, b) = (points[w[0]], points[w[1]]);
            assert!(((a.0 - b.0).abs() + (a.1 - b.1).abs() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn strips_run_back_and_forth_one_diameter_wide_along_the_shorter_side() {
        // Expectation: a 40 x 10 lattice of unit spacing (radius 0.5: one strip a column of the
        // shorter side's 10 points), shuffled, comes back as a permutation that walks each
        // strip, then steps to the next at the same end: every step of the order is one
        // lattice spacing, and the strips are the lattice's columns (the box is wider than
        // tall, so the strips run along y).
        let (wide, tall) = (40, 10);
        let mut points: Vec<(f64, f64)> = (0..wide * tall)
            .map(|k| ((k % wide) as f64, (k / wide) as f64))
            .collect();
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(2);
        rand::seq::SliceRandom::shuffle(&mut points[..], &mut rng);
        let order = strip_order(&points, 0.5);
        let mut seen = vec![false; points.len()];
        for &k in &order {
            assert!(!std::mem::replace(&mut seen[k], true));
        }
        for w in order.windows(2) {
            let (a, b) = (points[w[0]], points[w[1]]);
            assert_eq!((a.0 - b.0).abs() + (a.1 - b.1).abs(), 1.0, "{a:?} -> {b:?}");
        }
        for (k, &p) in order.iter().enumerate() {
            assert_eq!(points[p].0, (k / tall) as f64, "point {k} of the order");
        }
    }

    #[test]
    fn a_sorted_sample_file_keeps_every_line_as_written() {
        // Expectation: `sort_sample_text` puts the header and comments first, drops blank
        // lines, and writes every grain's line once, unchanged, strip by strip; a sorted file
        // sorts to itself; a line that is not a grain is the error `parse_grains` gives.
        let text = "# a comment\nx,y,radius\n3.0,0.0,0.5\n\n0.0,0.0,0.5\n# another\n\
                    2.0,0.0,0.5\n1.0,0.0,0.5\n";
        let sorted = sort_sample_text(text, "s.csv").unwrap();
        assert_eq!(
            sorted.text,
            "# a comment\nx,y,radius\n# another\n0.0,0.0,0.5\n1.0,0.0,0.5\n2.0,0.0,0.5\n\
             3.0,0.0,0.5\n"
        );
        assert_eq!(sorted.grains, 4);
        assert_eq!((sorted.step_before, sorted.step_after), (4.0, 2.0));
        assert_eq!(
            sort_sample_text(&sorted.text, "t.csv").unwrap().text,
            sorted.text
        );
        let error = sort_sample_text("x,y,radius\n1.0,2.0\n", "bad.csv").unwrap_err();
        assert!(error.to_string().starts_with("bad.csv:2:"), "{error}");
    }
}
