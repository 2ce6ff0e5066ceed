//! Meshfree reference solver (MELODY-like, SPEC §10): RPIM shape functions, total-Lagrangian
//! hyperelasticity, wall contact with augmented Lagrangian, quasi-static and dynamic stepping.
//!
//! Field nodes of a disc on concentric rings ([`DiscNodes`]) or of any star-shaped contour
//! ([`shape`]), an integration mesh with 6 Gauss points per triangle ([`IntegrationMesh`]),
//! RPIM shape functions with supports of 20 neighbours ([`Rpim`]), plane-strain neo-Hookean or
//! Saint Venant–Kirchhoff material ([`Hyperelastic`]), internal forces, tangent and consistent
//! mass per grain ([`GrainModel`]), frictionless rigid walls ([`Wall`], appendix C).
//!
//! One grain (calibration, dense linear algebra): Newton nested in augmented-Lagrangian loops
//! ([`Problem`]) and the Bathe composite / trapezoidal dynamic schemes ([`Dynamics`]).
//!
//! Many grains ([`assembly`]): the two-pass smoothed node-to-segment element between grains
//! ([`nts`]), a global sparse tangent ([`sparse`]), the same nonlinear loops and schemes, and
//! sub-steps on non-convergence. Samples of star-shaped grains come from [`packing`].

pub mod assembly;
pub mod contact;
pub mod discretization;
pub mod friction;
pub mod material;
pub mod model;
pub mod nts;
pub mod packing;
pub mod rpim;
pub mod shape;
pub mod solver;
pub mod sparse;

pub use contact::{
    Multipliers, Wall, WallNodeElement, WallState, add_wall_contacts, contact_length,
    wall_node_element,
};
pub use discretization::{DiscNodes, GaussPoint, IntegrationMesh, NodeDensity};
pub use material::{Hyperelastic, HyperelasticLaw, StressResponse};
pub use model::{BlockPattern, Dense, DiscModel, GrainModel, NodeSet};
pub use rpim::{Rpim, SUPPORT_NEIGHBOURS, ShapeFunctions};
pub use solver::{
    DynamicState, DynamicTerms, Dynamics, Problem, SolveStats, SolverSettings, TimeScheme, lu_solve,
};

/// Failures of the meshfree solver.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshfreeError {
    #[error("invalid meshfree input: {0}")]
    BadInput(String),
    #[error(
        "node density too coarse: {nodes} field nodes where at least {needed} are needed \
         (each support must hold 20 neighbours); raise the number of boundary nodes"
    )]
    TooCoarse { nodes: usize, needed: usize },
    #[error(
        "material inverted at Gauss point ({:.4}, {:.4}): det F = {det:.3e}",
        position[0],
        position[1]
    )]
    Inverted { position: [f64; 2], det: f64 },
    #[error("singular tangent matrix (is a rigid-body motion unconstrained?)")]
    Singular,
    #[error("no convergence: {0}")]
    NotConverged(String),
}
