//! Rigid frictionless walls: infinite straight lines with an inward unit normal.

use glam::DVec2;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Wall {
    /// A point of the wall line.
    pub point: DVec2,
    /// Unit normal pointing into the domain (towards the grains).
    pub normal: DVec2,
    /// Prescribed velocity of the wall.
    pub velocity: DVec2,
}

impl Wall {
    pub fn new(point: DVec2, normal: DVec2) -> Self {
        Self {
            point,
            normal: normal.normalize(),
            velocity: DVec2::ZERO,
        }
    }

    /// Where the wall's point is after it moves at its velocity for `dt` (the end of a step
    /// moves it there).
    #[inline]
    pub fn point_after(&self, dt: f64) -> DVec2 {
        self.point + self.velocity * dt
    }

    /// Signed distance of x from the wall, positive on the domain side.
    #[inline]
    pub fn height(&self, x: DVec2) -> f64 {
        (x - self.point).dot(self.normal)
    }

    /// Whether the axis-aligned box `[lo, hi]` lies wholly on the domain side, clear of the
    /// wall by far more than rounding: then every disc inside the box has
    /// `height(centre) >= radius`, and no grain whose bounding circle is in the box touches the
    /// wall. False for a normal that is not of unit length (the height is then no distance).
    #[inline]
    pub fn clears_box(&self, lo: DVec2, hi: DVec2) -> bool {
        let n = self.normal;
        if (n.length_squared() - 1.0).abs() > 1e-12 {
            return false;
        }
        // The box corner deepest towards the wall.
        let corner = DVec2::new(
            if n.x >= 0.0 { lo.x } else { hi.x },
            if n.y >= 0.0 { lo.y } else { hi.y },
        );
        let scale = lo.abs().max(hi.abs()).max(self.point.abs()).max_element();
        self.height(corner) > 1e-9 * scale
    }
}

/// Indices of the four walls of a box.
pub const LEFT: usize = 0;
pub const RIGHT: usize = 1;
pub const BOTTOM: usize = 2;
pub const TOP: usize = 3;

/// The four walls of the box `[x0, x1] x [y0, y1]`, in the order LEFT, RIGHT, BOTTOM, TOP.
pub fn box_walls(x0: f64, x1: f64, y0: f64, y1: f64) -> Vec<Wall> {
    vec![
        Wall::new(DVec2::new(x0, y0), DVec2::X),
        Wall::new(DVec2::new(x1, y0), -DVec2::X),
        Wall::new(DVec2::new(x0, y0), DVec2::Y),
        Wall::new(DVec2::new(x0, y1), -DVec2::Y),
    ]
}

/// Lower-left and upper-right corners of a box made by [`box_walls`].
pub fn box_corners(walls: &[Wall]) -> (DVec2, DVec2) {
    corners(|w| walls[w].point)
}

/// [`box_corners`] once every wall has moved by its velocity over `dt`
/// ([`Wall::point_after`]).
pub fn box_corners_after(walls: &[Wall], dt: f64) -> (DVec2, DVec2) {
    corners(|w| walls[w].point_after(dt))
}

fn corners(point: impl Fn(usize) -> DVec2) -> (DVec2, DVec2) {
    (
        DVec2::new(point(LEFT).x, point(BOTTOM).y),
        DVec2::new(point(RIGHT).x, point(TOP).y),
    )
}

/// Width and height of a box made by [`box_walls`].
pub fn box_size(walls: &[Wall]) -> (f64, f64) {
    (
        walls[RIGHT].point.x - walls[LEFT].point.x,
        walls[TOP].point.y - walls[BOTTOM].point.y,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_box_clears_a_wall_only_when_every_disc_in_it_is_off_the_wall() {
        // Expectation: a disc of centre c and radius r inside the box touches the wall iff
        // height(c) < r; the box clears the wall only when no such disc can. A grid of discs
        // that fill boxes on either side of, and across, each wall of a box with a tilted
        // wall added.
        let mut walls = box_walls(0.0, 2.0, 0.0, 1.0);
        walls.push(Wall::new(DVec2::new(1.0, 0.0), DVec2::new(-1.0, 1.0)));
        let boxes = [
            (DVec2::new(0.2, 0.2), DVec2::new(0.5, 0.5)),
            (DVec2::new(0.0, 0.2), DVec2::new(0.4, 0.6)),
            (DVec2::new(-0.1, 0.3), DVec2::new(0.3, 0.7)),
            (DVec2::new(1.5, 0.5), DVec2::new(2.0, 1.0)),
            (DVec2::new(1.7, 0.0), DVec2::new(1.9, 0.2)),
            (DVec2::new(0.8, 0.05), DVec2::new(0.9, 0.1)),
        ];
        for (lo, hi) in boxes {
            for wall in &walls {
                let clears = wall.clears_box(lo, hi);
                let mut some_touch = false;
                for a in 0..=10 {
                    for b in 0..=10 {
                        for r in [0.001, 0.01, 0.04] {
                            let x = lo.x + r + (hi.x - lo.x - 2.0 * r) * a as f64 / 10.0;
                            let y = lo.y + r + (hi.y - lo.y - 2.0 * r) * b as f64 / 10.0;
                            some_touch |= wall.height(DVec2::new(x, y)) < r;
                        }
                    }
                }
                assert!(!(clears && some_touch), "{wall:?} said clear of {lo}..{hi}");
                // The box touching the wall line or crossing it never clears it.
                let deepest = [lo, hi, DVec2::new(lo.x, hi.y), DVec2::new(hi.x, lo.y)]
                    .map(|c| wall.height(c))
                    .into_iter()
                    .fold(f64::INFINITY, f64::min);
                assert_eq!(clears, deepest > 1e-9 * 2.0, "{wall:?} and {lo}..{hi}");
            }
        }
        // A normal that is not unit length is never trusted.
        let skewed = Wall {
            normal: DVec2::new(0.5, 0.0),
            ..walls[0]
        };
        assert!(!skewed.clears_box(DVec2::new(1.0, 0.2), DVec2::new(1.2, 0.4)));
    }
}
