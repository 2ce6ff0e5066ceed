//! The stacked-disc column of the multibody meshfree tests: equal neo-Hookean discs
//! (E = 1, radius [`RADIUS`]) touching in a column on x = 0, compressed between two walls.

use glam::DVec2;
use sdem::boundary::walls::Wall;
use sdem::meshfree::assembly::{Assembly, ContactMultipliers};
use sdem::meshfree::{
    DiscNodes, GrainModel, Hyperelastic, HyperelasticLaw, NodeDensity, NodeSet, SolverSettings,
};

/// The radius of every disc.
pub const RADIUS: f64 = 0.5;

/// A disc of radius [`RADIUS`] with `boundary_nodes` boundary nodes, centred on `centre`, of a
/// neo-Hookean material with E = 1, Poisson's ratio `nu` and density 1.
pub fn disc_at(centre: [f64; 2], boundary_nodes: usize, nu: f64) -> GrainModel {
    let material = Hyperelastic::new(HyperelasticLaw::NeoHookean, 1.0, nu, 1.0).unwrap();
    disc_of(RADIUS, centre, boundary_nodes, material)
}

/// A disc of radius `radius` with `boundary_nodes` boundary nodes, centred on `centre`, of
/// `material`.
pub fn disc_of(
    radius: f64,
    centre: [f64; 2],
    boundary_nodes: usize,
    material: Hyperelastic,
) -> GrainModel {
    let mut nodes: NodeSet = DiscNodes::disc(radius, NodeDensity::new(boundary_nodes))
        .unwrap()
        .into();
    for p in &mut nodes.positions {
        p[0] += centre[0];
        p[1] += centre[1];
    }
    GrainModel::from_nodes(nodes, material).unwrap()
}

/// The solver settings of the column.
pub fn settings() -> SolverSettings {
    SolverSettings {
        k0: 1.0 / RADIUS,
        alpha_k: 2.0,
        gap_tolerance: 1e-7,
        force_tolerance: 1e-12,
        max_newton: 40,
        max_augmentations: 40,
    }
}

/// What [`column`] measured along its loading.
#[derive(Debug, Default)]
pub struct Column {
    /// Force on the top wall after each load step.
    pub force: Vec<f64>,
    /// Largest momentum imbalance of the grain–grain forces relative to their magnitude.
    pub momentum: f64,
    /// Deepest penetration.
    pub penetration: f64,
    /// Newton iterations, all load steps together.
    pub newton: usize,
}

/// Force on the top wall along a quasi-static compression of a column of `discs` discs
/// (touching, centred on x = 0) between a bottom and a top wall, which each move in by
/// `approach / 2` over `steps` load steps. Also returns the largest momentum imbalance of the
/// grain–grain forces relative to their magnitude, and the deepest penetration.
pub fn column(discs: usize, boundary_nodes: usize, nu: f64, approach: f64, steps: usize) -> Column {
    let height = 2.0 * RADIUS * discs as f64;
    let grains: Vec<GrainModel> = (0..discs)
        .map(|k| disc_at([0.0, RADIUS * (2 * k + 1) as f64], boundary_nodes, nu))
        .collect();
    let walls = vec![
        Wall::new(DVec2::new(0.0, 0.0), DVec2::Y),
        Wall::new(DVec2::new(0.0, height), -DVec2::Y),
    ];
    let mut a = Assembly::new(grains, walls, [0.0, 0.0], (0.0, 0.0), settings()).unwrap();
    // The x DoF of each disc's top and bottom nodes (on the axis, zero by symmetry) hold the
    // rigid translation along x and the rotation that frictionless contacts leave free.
    let nb = boundary_nodes;
    a.fixed = (0..discs)
        .flat_map(|g| [nb / 4, 3 * nb / 4].map(|s| a.offset(g) + 2 * s))
        .collect();
    let mut u = vec![0.0; a.dofs()];
    let mut mult = ContactMultipliers::new();
    let mut out = Column::default();
    for step in 1..=steps {
        let d = 0.5 * approach * step as f64 / steps as f64;
        a.walls[0].point.y = d;
        a.walls[1].point.y = height - d;
        let (eval, stats) = a.solve_static(&mut u, &mut mult).unwrap();
        out.force.push(eval.wall_force(1)[1]);
        let (sum, mag) = eval.grain_contact_force_sum();
        if mag > 0.0 {
            out.momentum = out.momentum.max(sum[0].abs().max(sum[1].abs()) / mag);
        }
        out.penetration = out.penetration.max(stats.max_penetration);
        out.newton += stats.newton_iterations;
    }
    out
}
