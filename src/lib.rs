//! # sdem — the Soft Discrete Element Method in 2D
//!
//! Each grain is an ellipse with six degrees of freedom (x, y, rotation, two principal strains
//! and their orientation). Contacts are found by intersecting contour polygons, the normal force
//! follows the a/b secant law, the grain stress comes from its constitutive law and from the
//! Love–Weber stress of its contact forces, and an explicit solver integrates it all.
//!
//! Conventions: 2D, consistent units (the shipped scenarios use E = 1, rho = 1); stress and
//! strain are **tension positive** inside the library. Reports for users (CSV) state their sign
//! in the column names.
//!
//! Layout: [`geometry`] (contours, intersections, broad phase), [`contact`] (laws),
//! [`grain`] (state, constitutive laws), [`integration`] (the time step), [`boundary`] (walls,
//! loading programs), [`sample`] (initial packings), [`scenario`] (RON input), [`output`]
//! (measures, CSV files, MCAP logs, pictures and plots), [`run`] (a scenario from start to end,
//! checkpoints, the bench), [`meshfree`] (the single-grain meshfree reference solver) and
//! [`calibration`] (fitting the contact law to it); [`huge_pages`], the command line's
//! allocator.

pub mod boundary;
pub mod calibration;
pub mod contact;
pub mod geometry;
pub mod grain;
pub mod huge_pages;
pub mod integration;
pub mod lanes;
pub mod meshfree;
pub mod output;
pub mod portable;
pub mod run;
pub mod sample;
pub mod scenario;
