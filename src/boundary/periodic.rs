//! The periodic cell (SPEC §14): a parallelogram spanned by the columns h1, h2 of the cell matrix
//! H, repeated over the plane, in place of walls.
//!
//! - Reduced coordinates `s = H^-1 (x - origin)`; a wrapped position has `s` in [0, 1)^2.
//! - A pair's branch vector is its minimum image `d = x_j - x_i - H round(H^-1 (x_j - x_i))`.
//!   Rounding in reduced coordinates finds the nearest image of every pair closer than half the
//!   smaller cell width (a width is measured across the cell, perpendicular to the other vector),
//!   so the interaction range (largest diameter + neighbour skin) must stay below it:
//!   [`PeriodicCell::check_range`].
//! - The cell deforms with a velocity gradient L: `dH/dt = L H`. An image shifted by `H n` (n a
//!   pair of integers) moves with the extra affine velocity `L H n`.
//! - Simple shear tilts h2 along h1 without end: once the tilt passes half a cell the cell is
//!   remapped to the equivalent cell of the same lattice ([`PeriodicCell::remap`]), which is what
//!   Lees–Edwards boundaries do.
//!
//! Units: lengths as the scenario's; L in 1/time. Stress tension positive, as SPEC §3.

use super::walls::{BOTTOM, LEFT, RIGHT, TOP, Wall, box_size};
use glam::{DMat2, DVec2};

/// Why a cell is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CellError {
    #[error(
        "the cell vectors ({h1:?}, {h2:?}) span no area or are left-handed (det H = {det:e}): give h1, h2 counter-clockwise"
    )]
    Degenerate { h1: DVec2, h2: DVec2, det: f64 },
    #[error(
        "the periodic cell is {width:.4e} wide across, under twice the interaction range {range:.4e} \
         (largest grain diameter + neighbour skin): a grain would meet two images of another; make the cell at least {:.4e} wide",
        2.0 * range
    )]
    TooNarrow { width: f64, range: f64 },
}

/// A periodic cell: origin (a corner) and cell matrix H, columns h1 and h2, with its inverse
/// (every reduced coordinate and minimum image needs it: it is computed once per cell).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeriodicCell {
    pub origin: DVec2,
    matrix: DMat2,
    inverse: DMat2,
    /// `H (0, 0)` as the product computes it (its zeros' signs follow H's entries): the shift
    /// of image (0, 0), which nearly every pair has, without the product.
    zero_shift: DVec2,
}

impl PeriodicCell {
    /// The cell spanned by `h1`, `h2` (counter-clockwise, non-degenerate) from `origin`.
    pub fn new(origin: DVec2, h1: DVec2, h2: DVec2) -> Result<Self, CellError> {
        let matrix = DMat2::from_cols(h1, h2);
        let det = matrix.determinant();
        if !(det > 0.0 && det.is_finite()) {
            return Err(CellError::Degenerate { h1, h2, det });
        }
        Ok(Self::from_matrix(origin, matrix))
    }

    /// The cell of matrix `matrix` (columns h1, h2), assumed non-degenerate.
    fn from_matrix(origin: DVec2, matrix: DMat2) -> Self {
        Self {
            origin,
            matrix,
            inverse: matrix.inverse(),
            zero_shift: matrix * DVec2::ZERO,
        }
    }

    /// The cell matrix H (columns h1, h2).
    pub fn matrix(&self) -> DMat2 {
        self.matrix
    }

    /// The axis-aligned cell `[x0, x0 + width] x [y0, y0 + height]`.
    pub fn rectangle(origin: DVec2, width: f64, height: f64) -> Result<Self, CellError> {
        Self::new(origin, DVec2::new(width, 0.0), DVec2::new(0.0, height))
    }

    pub fn h1(&self) -> DVec2 {
        self.matrix.x_axis
    }

    pub fn h2(&self) -> DVec2 {
        self.matrix.y_axis
    }

    /// Area of the cell (det H > 0).
    pub fn area(&self) -> f64 {
        self.matrix.determinant()
    }

    /// The widths across the cell: the distance between the two sides parallel to h2, and between
    /// the two sides parallel to h1.
    pub fn widths(&self) -> [f64; 2] {
        let area = self.area();
        [area / self.h2().length(), area / self.h1().length()]
    }

    /// Refuses a cell in which a pair closer than `range` could have two images within reach.
    pub fn check_range(&self, range: f64) -> Result<(), CellError> {
        let width = self.widths()[0].min(self.widths()[1]);
        if width < 2.0 * range {
            return Err(CellError::TooNarrow { width, range });
        }
        Ok(())
    }

    /// Reduced coordinates of a position.
    pub fn reduced(&self, x: DVec2) -> DVec2 {
        self.inverse * (x - self.origin)
    }

    /// The position of reduced coordinates `s`.
    pub fn position(&self, s: DVec2) -> DVec2 {
        self.origin + self.matrix * s
    }

    /// The image of `x` inside the cell and the image shift `n` it took: `x - H n`.
    #[inline]
    pub fn wrap(&self, x: DVec2) -> (DVec2, [i64; 2]) {
        let s = self.reduced(x);
        // Inside the cell, off its lower sides and off the axes (nearly every grain, every
        // step): the image is `x` itself, bit for bit, as below (`x - H (+0, +0)` is `x` for
        // any `x` that is not a zero).
        if s.x > 0.0 && s.x < 1.0 && s.y > 0.0 && s.y < 1.0 && x.x != 0.0 && x.y != 0.0 {
            return (x, [0, 0]);
        }
        let n = DVec2::new(floor_in_cell(s.x), floor_in_cell(s.y));
        let wrapped = x - self.matrix * n;
        if n.x == 0.0 && n.y == 0.0 {
            // Inside the cell, on a lower side or an axis: `wrapped` is `x` but for the sign of
            // a zero, its reduced coordinates are `s`'s, in [0, 1), and the fix of `shifted`
            // would add nothing.
            return (wrapped, [0, 0]);
        }
        self.shifted(wrapped, n)
    }

    /// The end of [`wrap`](Self::wrap) for a point that took an image shift `n` (now at
    /// `wrapped`): out of line, so that the pass that wraps every grain inlines only the common
    /// case.
    #[cold]
    #[inline(never)]
    fn shifted(&self, mut wrapped: DVec2, n: DVec2) -> (DVec2, [i64; 2]) {
        // Round-off can leave s = 1 - 1e-17 -> 1 after the shift: keep [0, 1).
        let again = self.reduced(wrapped);
        let fix = DVec2::new(
            if again.x >= 1.0 { 1.0 } else { 0.0 },
            if again.y >= 1.0 { 1.0 } else { 0.0 },
        );
        wrapped -= self.matrix * fix;
        let n = n + fix;
        (wrapped, [n.x as i64, n.y as i64])
    }

    /// The minimum image of the separation `d = x_j - x_i` and the image shift `n` it took:
    /// `(d - H n, n)`. The nearest image of every pair closer than half the cell's smaller width.
    pub fn minimum_image(&self, d: DVec2) -> (DVec2, [i64; 2]) {
        let n = (self.inverse * d).round();
        (d - self.matrix * n, [n.x as i64, n.y as i64])
    }

    /// [`minimum_image`](Self::minimum_image) for the candidates of a neighbour search, with
    /// [`nearest_integer`] in place of `round` (two library calls on the baseline x86-64 build:
    /// an eighth of a periodic list's build, issue #16). The two differ only at a tie, a
    /// separation with a reduced component of exactly one half, whose two images both lie at
    /// least half the cell's width away: beyond the range of any pair the list keeps (the cell
    /// is at least twice the range wide), so the pairs listed and their images are the same.
    #[inline]
    pub fn minimum_image_in_range(&self, d: DVec2) -> (DVec2, [i64; 2]) {
        let n = nearest_integer(self.inverse * d);
        (d - self.matrix * n, [n.x as i64, n.y as i64])
    }

    /// The shift `H n` of image `n`.
    #[inline]
    pub fn image_shift(&self, n: [i64; 2]) -> DVec2 {
        if n == [0, 0] {
            self.zero_shift
        } else {
            self.matrix * DVec2::new(n[0] as f64, n[1] as f64)
        }
    }

    /// The tilt of h2 along h1 in units of |h1|: 0 for a rectangle, ±1/2 at the remap.
    pub fn tilt(&self) -> f64 {
        self.h1().dot(self.h2()) / self.h1().length_squared()
    }

    /// Once the tilt passes ±1/2, replaces h2 by `h2 - k h1` (k the nearest integer to the tilt):
    /// the same lattice of images, the least skewed cell. Returns whether it changed; positions
    /// must be wrapped again after a remap.
    pub fn remap(&mut self) -> bool {
        let k = self.tilt().round();
        if k == 0.0 {
            return false;
        }
        let mut matrix = self.matrix;
        matrix.y_axis -= k * self.h1();
        *self = Self::from_matrix(self.origin, matrix);
        true
    }
}

/// A world's periodic boundary. The loading program drives the cell as it drives a box: through
/// the velocities of four virtual walls (in the order of [`super::walls::box_walls`]), which
/// meet no grain; they give the cell's origin (left, bottom), its width along x and its height
/// along y. The shear of the cell is kept here: `h2 = (tilt, height)`, sheared at `shear_rate`
/// (the velocity gradient's `L_xy`, set by a shear phase).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PeriodicBoundary {
    /// x component of h2 (length).
    pub tilt: f64,
    /// `L_xy = d v_x / d y` of the affine field (1/time).
    pub shear_rate: f64,
    /// Shear strain `∫ L_xy dt` since the start of the run, remaps not undone.
    pub shear_strain: f64,
}

impl PeriodicBoundary {
    /// The cell that `walls` and the tilt describe.
    pub fn cell(&self, walls: &[Wall]) -> PeriodicCell {
        let (width, height) = box_size(walls);
        PeriodicCell::from_matrix(
            DVec2::new(walls[LEFT].point.x, walls[BOTTOM].point.y),
            DMat2::from_cols(DVec2::new(width, 0.0), DVec2::new(self.tilt, height)),
        )
    }

    /// Turns the left and right virtual walls along h2, so that the four walls are the cell's
    /// sides (as the MCAP log records them; the loop reads only their positions).
    pub fn orient_walls(&self, walls: &mut [Wall]) {
        let height = walls[TOP].point.y - walls[BOTTOM].point.y;
        let inward = DVec2::new(height, -self.tilt).normalize();
        walls[LEFT].normal = inward;
        walls[RIGHT].normal = -inward;
    }

    /// The cell whose four sides are `walls` (as [`orient_walls`](Self::orient_walls) leaves
    /// them): an error for walls that are not the sides of a cell.
    pub fn cell_of_sides(walls: &[Wall]) -> Result<PeriodicCell, String> {
        if walls.len() != 4 {
            return Err(format!(
                "{} sides for a periodic cell (4 expected)",
                walls.len()
            ));
        }
        let (width, height) = box_size(walls);
        let n = walls[LEFT].normal;
        if !(n.x > 0.0 && width > 0.0 && height > 0.0) {
            return Err(format!(
                "the sides (width {width}, height {height}, left normal {n:?}) make no cell"
            ));
        }
        // The left side runs along h2 = (tilt, height), perpendicular to its normal.
        let tilt = -n.y / n.x * height;
        Ok(PeriodicBoundary {
            tilt,
            ..Default::default()
        }
        .cell(walls))
    }

    /// The velocity gradient L of the affine field: the walls' strain rates on the diagonal,
    /// the shear rate above it.
    pub fn velocity_gradient(&self, walls: &[Wall]) -> DMat2 {
        let (width, height) = box_size(walls);
        let l_xx = (walls[RIGHT].velocity.x - walls[LEFT].velocity.x) / width;
        let l_yy = (walls[TOP].velocity.y - walls[BOTTOM].velocity.y) / height;
        DMat2::from_cols(DVec2::new(l_xx, 0.0), DVec2::new(self.shear_rate, l_yy))
    }

    /// One step of the cell: the walls move by their velocity × dt (as in a box), h2's tilt
    /// follows `dH/dt = L H`, and past a tilt of half the width the cell is remapped to the
    /// equivalent lattice cell. Returns the motion, whose `remapped` says that the images of
    /// the pairs changed.
    pub fn advance(&mut self, walls: &mut [Wall], dt: f64) -> CellMotion {
        let before = self.cell(walls);
        let velocity_gradient = self.velocity_gradient(walls);
        self.tilt +=
            dt * (velocity_gradient.x_axis.x * self.tilt + self.shear_rate * before.h2().y);
        self.shear_strain += self.shear_rate * dt;
        for wall in walls.iter_mut() {
            wall.point += wall.velocity * dt;
        }
        let mut current = self.cell(walls);
        let map = current.matrix * before.inverse;
        let remapped = current.remap();
        self.tilt = current.h2().x;
        self.orient_walls(walls);
        CellMotion {
            before,
            current,
            map,
            velocity_gradient,
            remapped,
        }
    }
}

/// How the cell moved over one step ([`PeriodicBoundary::advance`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellMotion {
    pub before: PeriodicCell,
    /// The cell after the step (and its remap, if any: the same lattice, the same origin).
    pub current: PeriodicCell,
    /// `H_after H_before^-1` (H_after before any remap): a point of the affine field moves
    /// from x to `current.origin + map (x - before.origin)`.
    pub map: DMat2,
    pub velocity_gradient: DMat2,
    /// The cell was remapped after the step (the pairs' images are stale).
    pub remapped: bool,
}

impl CellMotion {
    /// Where the affine field carries a point over the step (its reduced coordinates kept).
    #[inline]
    pub fn carry(&self, x: DVec2) -> DVec2 {
        self.current.origin + self.map * (x - self.before.origin)
    }
}

/// The nearest integers to `v`'s components (ties to even), for components of magnitude below
/// 2^51: adding and subtracting 1.5 * 2^52 leaves the rounded value, in two additions where
/// `f64::round` is a library call on x86-64 without SSE4.1 (the neighbour list's rebuild test
/// calls it for every grain and step of a periodic cell). Only the choice of lattice shift rests
/// on it.
#[inline(always)]
pub(crate) fn nearest_integer(v: DVec2) -> DVec2 {
    const SHIFT: f64 = 6_755_399_441_055_744.0;
    DVec2::new((v.x + SHIFT) - SHIFT, (v.y + SHIFT) - SHIFT)
}

/// `v.floor()`, without the call where `v` lies in `[-0, 1)` (a grain inside the cell, as nearly
/// every grain is after each step's wrap): there the floor is the zero of `v`'s sign. The
/// baseline x86-64 build has no rounding instruction, and the two calls a grain cost the
/// periodic step 27 instructions a grain-step (callgrind).
#[inline(always)]
pub(crate) fn floor_in_cell(v: f64) -> f64 {
    if (0.0..1.0).contains(&v) {
        0.0f64.copysign(v)
    } else {
        v.floor()
    }
}

/// `sym(a ⊗ b)` as (xx, yy, xy). A contact's share of the cell stress (SPEC §14, tension
/// positive) is `sym(f_i ⊗ d_ij) / A`: f_i the force on grain i from j, d_ij the branch vector
/// from i to j (minimum image); a pair pressed together gives a negative stress. The kinetic
/// stress is `-sym(m v ⊗ v) / A`.
#[inline]
pub fn symmetric_dyad(a: DVec2, b: DVec2) -> [f64; 3] {
    [a.x * b.x, a.y * b.y, 0.5 * (a.x * b.y + a.y * b.x)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_integer_matches_round_except_at_ties() {
        // Expectation: the nearest integer, as f64::round gives it wherever the two roundings
        // agree (everywhere but exact halves), negative values and large magnitudes included.
        let mut x = -3.7e9;
        while x < 3.7e9 {
            for v in [x, x * 1e-9, -x * 1e-7, x + 0.49, x - 0.51] {
                let got = nearest_integer(DVec2::new(v, -v));
                assert_eq!((got.x, got.y), (v.round(), (-v).round()), "{v}");
            }
            x += 1.234567e7;
        }
        // Ties go to the even neighbour; either is a valid lattice shift there.
        assert_eq!(
            nearest_integer(DVec2::new(0.5, -2.5)),
            DVec2::new(0.0, -2.0)
        );
    }

    #[test]
    fn wrap_inside_the_cell_gives_the_full_formula_to_the_bit() {
        // Expectation: the shortcut for a point inside the cell returns the bits of the full
        // wrap (the floor's shift, then the second reduction and fix of `shifted`, for every
        // point), on zeros of either sign, points on the axes, the origin, a point just inside
        // the far side and points inside and outside, in a sheared cell with negative entries as
        // in a rectangle.
        let full = |cell: &PeriodicCell, x: DVec2| {
            let s = cell.reduced(x);
            let n = DVec2::new(s.x.floor(), s.y.floor());
            cell.shifted(x - cell.matrix * n, n)
        };
        let cells = [
            PeriodicCell::rectangle(DVec2::ZERO, 2.0, 1.5).unwrap(),
            PeriodicCell::new(
                DVec2::new(-0.3, 0.2),
                DVec2::new(1.7, -0.4),
                DVec2::new(-0.6, 1.2),
            )
            .unwrap(),
            // Both entries of each row negative: `H (+0, +0)` is (-0, -0), which changes the
            // sign of a point's zero coordinate.
            PeriodicCell::new(
                DVec2::new(0.8, 1.2),
                DVec2::new(-1.0, -1.0),
                DVec2::new(-0.5, -1.5),
            )
            .unwrap(),
        ];
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for cell in &cells {
            let mut points = vec![
                DVec2::new(0.0, -0.0),
                DVec2::new(-0.0, -0.0),
                cell.origin,
                cell.position(DVec2::new(1.0 - f64::EPSILON, 0.5)),
            ];
            for _ in 0..20_000 {
                points.push(cell.position(DVec2::new(3.0 * next() - 1.0, 3.0 * next() - 1.0)));
            }
            // Points on the axes, inside the cell or not: zeros of either sign.
            for _ in 0..2_000 {
                let p = cell.position(DVec2::new(next(), next()));
                for zero in [0.0, -0.0] {
                    points.extend([DVec2::new(zero, p.y), DVec2::new(p.x, zero)]);
                }
            }
            for x in points {
                let (got, image) = cell.wrap(x);
                let (want, want_image) = full(cell, x);
                assert_eq!(image, want_image, "{x}");
                assert_eq!(
                    (got.x.to_bits(), got.y.to_bits()),
                    (want.x.to_bits(), want.y.to_bits()),
                    "{x}"
                );
            }
        }
    }

    #[test]
    fn minimum_image_in_range_is_the_minimum_image_within_half_a_width() {
        // Expectation: wherever the reduced separation is not a tie, the same image and
        // separation as `minimum_image`, to the bit.
        let cell =
            PeriodicCell::new(DVec2::ZERO, DVec2::new(1.3, 0.2), DVec2::new(-0.5, 0.9)).unwrap();
        for k in 0..40_000 {
            let s = DVec2::new((k % 200) as f64 / 99.7 - 1.0, (k / 200) as f64 / 99.3 - 1.0);
            let d = cell.matrix * s;
            let (a, na) = cell.minimum_image(d);
            let (b, nb) = cell.minimum_image_in_range(d);
            assert_eq!(na, nb, "{d}");
            assert_eq!(
                (a.x.to_bits(), a.y.to_bits()),
                (b.x.to_bits(), b.y.to_bits())
            );
        }
    }

    #[test]
    fn floor_in_cell_is_floor_to_the_bit() {
        // Expectation: the shortcut inside [-0, 1) returns the very bits of `f64::floor`,
        // signed zeros and values next to the ends included, and leaves the rest to it.
        let values = [
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            1e-300,
            0.5,
            1.0 - f64::EPSILON / 2.0,
            1.0,
            -f64::MIN_POSITIVE,
            -1e-17,
            -0.5,
            1.5,
            -1.5,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for v in values {
            assert_eq!(floor_in_cell(v).to_bits(), v.floor().to_bits(), "{v:e}");
        }
        assert!(floor_in_cell(f64::NAN).is_nan());
    }

    fn sheared() -> PeriodicCell {
        PeriodicCell::new(
            DVec2::new(0.3, -0.2),
            DVec2::new(2.0, 0.1),
            DVec2::new(0.7, 1.5),
        )
        .unwrap()
    }

    /// Every image of `d` within `reach` images, by brute force: the nearest.
    fn nearest_by_search(cell: &PeriodicCell, d: DVec2) -> DVec2 {
        let mut best = d;
        for i in -3..=3 {
            for j in -3..=3 {
                let c = d - cell.image_shift([i, j]);
                if c.length() < best.length() {
                    best = c;
                }
            }
        }
        best
    }

    #[test]
    fn the_minimum_image_is_the_nearest_image_within_half_a_width() {
        // Expectation: for separations whose nearest image is closer than half the smaller
        // width, rounding in reduced coordinates finds the same image as a brute-force search.
        let cell = sheared();
        let half = 0.5 * cell.widths()[0].min(cell.widths()[1]);
        let mut checked = 0;
        for k in 0..2000 {
            let t = k as f64 * 0.6180339887;
            let d = DVec2::new(5.0 * (t.fract() - 0.5), 5.0 * ((t * 7.3).fract() - 0.5));
            let nearest = nearest_by_search(&cell, d);
            if nearest.length() < half * 0.999 {
                let (image, n) = cell.minimum_image(d);
                assert!(
                    (image - nearest).length() < 1e-12,
                    "{d:?}: {image:?} vs {nearest:?}"
                );
                assert!((d - cell.image_shift(n) - image).length() < 1e-12);
                checked += 1;
            }
        }
        assert!(checked > 100, "only {checked} separations tested");
    }

    #[test]
    fn the_shift_of_image_zero_keeps_the_products_signed_zeros() {
        // Expectation: `H (0, 0)` as the product gives it. In a cell turned past a half turn
        // both x entries of H are negative, so the shift's x is -0.0 (+0.0 would move a centre
        // at -0.0 to +0.0 where the product leaves it).
        let cell =
            PeriodicCell::new(DVec2::ZERO, DVec2::new(-1.0, 0.2), DVec2::new(-0.3, -1.0)).unwrap();
        let shift = cell.image_shift([0, 0]);
        assert_eq!(
            (shift.x.to_bits(), shift.y.to_bits()),
            ((-0.0_f64).to_bits(), 0.0_f64.to_bits())
        );
        let rectangle = PeriodicCell::rectangle(DVec2::ZERO, 2.0, 3.0).unwrap();
        let shift = rectangle.image_shift([0, 0]);
        assert_eq!((shift.x.to_bits(), shift.y.to_bits()), (0, 0));
        assert_eq!(rectangle.image_shift([1, -2]), DVec2::new(2.0, -6.0));
    }

    #[test]
    fn wrapping_puts_a_point_in_the_cell_by_a_lattice_shift() {
        let cell = sheared();
        for k in 0..500 {
            let t = k as f64 * 0.7548776662;
            let x = DVec2::new(20.0 * (t.fract() - 0.5), 20.0 * ((t * 3.1).fract() - 0.5));
            let (w, n) = cell.wrap(x);
            let s = cell.reduced(w);
            assert!(
                (0.0..1.0).contains(&s.x) && (0.0..1.0).contains(&s.y),
                "{s:?}"
            );
            assert!((x - cell.image_shift(n) - w).length() < 1e-12);
            // Wrapping a wrapped point changes nothing.
            assert_eq!(cell.wrap(w).1, [0, 0]);
        }
    }

    #[test]
    fn remapping_keeps_the_lattice_and_bounds_the_tilt() {
        // Expectation: a simple shear to a tilt of 1.3 remaps to a tilt in [-1/2, 1/2], the
        // same area, and the same set of images (each new cell vector is a lattice vector of the
        // old cell with an integer inverse).
        let mut cell =
            PeriodicCell::new(DVec2::ZERO, DVec2::new(1.0, 0.0), DVec2::new(1.3, 1.0)).unwrap();
        let old = cell;
        assert!(cell.remap());
        assert!(cell.tilt().abs() <= 0.5, "{}", cell.tilt());
        assert!((cell.area() - old.area()).abs() < 1e-15);
        let in_old = old.matrix.inverse() * cell.matrix;
        for v in in_old.to_cols_array() {
            assert!((v - v.round()).abs() < 1e-12, "{in_old:?}");
        }
        assert!(!cell.remap());
        // A pair closer than half of either cell's smaller width: the same nearest image.
        let d = DVec2::new(0.9, 0.05);
        let (a, b) = (old.minimum_image(d).0, cell.minimum_image(d).0);
        assert!((a - b).length() < 1e-12 && (a - DVec2::new(-0.1, 0.05)).length() < 1e-12);
    }

    #[test]
    fn a_narrow_or_degenerate_cell_is_refused() {
        let cell = PeriodicCell::rectangle(DVec2::ZERO, 1.0, 0.1).unwrap();
        let e = cell.check_range(0.06).unwrap_err();
        assert!(e.to_string().contains("at least 1.2000e-1"), "{e}");
        assert!(cell.check_range(0.05).is_ok());
        assert!(matches!(
            PeriodicCell::new(DVec2::ZERO, DVec2::X, DVec2::X * 2.0),
            Err(CellError::Degenerate { .. })
        ));
        assert!(PeriodicCell::new(DVec2::ZERO, DVec2::Y, DVec2::X).is_err());
    }

    /// The cell stress of one contact, `sym(f ⊗ d) / A`, as a matrix.
    fn contact_stress(force: DVec2, branch: DVec2, area: f64) -> DMat2 {
        let [xx, yy, xy] = symmetric_dyad(force, branch).map(|v| v / area);
        DMat2::from_cols(DVec2::new(xx, xy), DVec2::new(xy, yy))
    }

    #[test]
    fn cell_stress_is_objective_and_compressive_for_a_pressed_pair() {
        // Expectation: a pair pressed together (force on i pointing away from j) gives a
        // negative normal stress along the branch; rotating forces and branches by R rotates the
        // stress to R sigma R^T.
        let branch = DVec2::new(0.02, 0.01);
        let force = -3.0 * branch.normalize();
        let sigma = contact_stress(force, branch, 0.5);
        let n = branch.normalize();
        assert!(n.dot(sigma * n) < 0.0);
        let rotation = DMat2::from_angle(0.7);
        let rotated = contact_stress(rotation * force, rotation * branch, 0.5);
        let expected = rotation * sigma * rotation.transpose();
        for (a, b) in rotated.to_cols_array().iter().zip(expected.to_cols_array()) {
            assert!((a - b).abs() < 1e-12);
        }
    }
}
