//! Geometry: the affine map of a deformed grain and its velocity gradient, contour polygons of
//! deformed grains, their intersections with each other and with walls, the closed forms of
//! the same contacts for exact circles (rigid discs), and the broad phase that finds the
//! candidate pairs; with exact contours, the same contacts of the grains' ellipses.

pub mod affine;
pub mod angle;
pub mod broadphase;
pub mod circle;
pub mod contour;
pub mod ellipse;
pub mod intersection;
pub mod intersection_lanes;

pub use contour::{ContourTable, GrainShape};
pub use ellipse::{Contours, ellipse_ellipse, ellipse_wall};
pub use intersection::{
    ChainHint, ContactGeometry, Overlap, PairHint, grain_grain, grain_grain_hinted, grain_wall,
};
