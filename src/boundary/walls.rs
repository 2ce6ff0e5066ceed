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

    /// Signed distance of x from the wall, positive on the domain side.
    #[inline]
    pub fn height(&self, x: DVec2) -> f64 {
        (x - self.point).dot(self.normal)
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

/// Width and height of a box made by [`box_walls`].
pub fn box_size(walls: &[Wall]) -> (f64, f64) {
    (
        walls[RIGHT].point.x - walls[LEFT].point.x,
        walls[TOP].point.y - walls[BOTTOM].point.y,
    )
}
