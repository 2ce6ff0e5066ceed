//! The periodic cell (SPEC §14): contacts across the boundary, the affine deformation of the
//! cell, the cell stress, objectivity, and runs with checkpoints.

mod common;

use glam::DVec2;
use sdem::boundary::periodic::PeriodicBoundary;
use sdem::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP, box_walls};
use sdem::grain::Grain;
use sdem::integration::World;
use sdem::scenario::Scenario;

const SMALL_PERIODIC: &str = r#"
Scenario(
    name: "small_periodic",
    sample: (count: 200, box_width: 0.45, box_height: 0.45,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    boundary: Periodic,
    loading: [
        Isotropic(rate: Constant(5e-2), until: PackingFraction(0.86)),
        Relax(until: Steps(1000)),
    ],
    output: (every: 50),
)
"#;

fn small_periodic() -> Scenario {
    let s = Scenario::parse(SMALL_PERIODIC, "small_periodic.ron").unwrap();
    s.validate().unwrap();
    s
}

/// Expectation: at every step of a compaction, every pair of grains whose bounding circles
/// overlap (minimum image, brute force over all pairs) is in the neighbour list with that
/// image: the Verlet criterion of a deforming cell misses no pair.
#[test]
fn the_neighbour_list_of_a_compressed_cell_misses_no_pair() {
    let scenario = small_periodic();
    let mut world = sdem::run::build_world(&scenario).unwrap();
    let n = world.grains.len();
    let rate = 5e-2;
    for step in 0..6000 {
        let (w, h) = sdem::boundary::walls::box_size(&world.walls);
        world.walls[LEFT].velocity.x = 0.5 * rate * w;
        world.walls[RIGHT].velocity.x = -0.5 * rate * w;
        world.walls[BOTTOM].velocity.y = 0.5 * rate * h;
        world.walls[TOP].velocity.y = -0.5 * rate * h;
        world.step().unwrap_or_else(|e| panic!("step {step}: {e}"));
        let cell = world.cell().unwrap();
        let shapes: Vec<_> = world
            .grains
            .iter()
            .map(|g| g.shape_and_velocity_gradient().0)
            .collect();
        for i in 0..n {
            for j in i + 1..n {
                let (d, [m1, m2]) = cell.minimum_image(shapes[j].center - shapes[i].center);
                let image = [-m1, -m2];
                if d.length() < shapes[i].bounding_radius + shapes[j].bounding_radius {
                    let k = world
                        .neighbors
                        .pairs
                        .iter()
                        .position(|p| *p == [i as u32, j as u32])
                        .unwrap_or_else(|| panic!("step {step}: pair {i} {j} missing"));
                    assert_eq!(
                        world.neighbors.images[k], image,
                        "step {step}: pair {i} {j}"
                    );
                }
            }
        }
    }
}
