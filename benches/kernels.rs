//! Micro-benchmarks of the hot kernels: `cargo bench --bench kernels`.
//! The whole-step throughput on a dense packing is `sdem bench` (docs/performance.md).

use glam::DVec2;
use sdem::geometry::{
    ContourTable, GrainShape, PairHint, grain_grain, grain_grain_hinted, grain_wall,
};
use std::hint::black_box;

fn main() {
    divan::main();
}

/// Two sample-A grains overlapping by `depth` of a diameter, deformed and rotated.
fn pair(depth: f64) -> (GrainShape, GrainShape) {
    let i = GrainShape::new(DVec2::ZERO, 0.012, 0.3, 0.02, -0.03, 0.7);
    let j = GrainShape::new(
        DVec2::new(0.024 * (1.0 - depth), 0.001),
        0.012,
        -1.1,
        -0.01,
        0.02,
        2.0,
    );
    (i, j)
}

#[divan::bench(args = [0.01, 0.05, 0.15])]
fn grain_grain_cold(bencher: divan::Bencher, depth: f64) {
    let table = ContourTable::new(1.0);
    let (i, j) = pair(depth);
    bencher.bench(|| grain_grain(&table, black_box(&i), black_box(&j)));
}

#[divan::bench(args = [0.01, 0.05, 0.15])]
fn grain_grain_warm(bencher: divan::Bencher, depth: f64) {
    let table = ContourTable::new(1.0);
    let (i, j) = pair(depth);
    let mut hint = PairHint::default();
    grain_grain_hinted(&table, &i, &j, &mut hint);
    bencher.bench_local(|| grain_grain_hinted(&table, black_box(&i), black_box(&j), &mut hint));
}

/// The hinted kernel on a pair whose contact moves between calls, as a contact under load does
/// from step to step: grain j alternates between two positions half a node spacing (`R
/// dbeta / 2`) apart along the line of centres, so the crossings move by about 1.7, 0.8 and
/// 0.4 node spacings a call at the three depths (two circles' chord: `dy/dd = -d / 4y`).
#[divan::bench(args = [0.01, 0.05, 0.15])]
fn grain_grain_moving(bencher: divan::Bencher, depth: f64) {
    let table = ContourTable::new(1.0);
    let (i, j) = pair(depth);
    let mut j_moved = j;
    j_moved.center.x -= 0.5 * 0.012 * table.dbeta;
    let positions = [j, j_moved];
    let mut hint = PairHint::default();
    let mut call = 0usize;
    bencher.bench_local(|| {
        call += 1;
        grain_grain_hinted(
            &table,
            black_box(&i),
            black_box(&positions[call & 1]),
            &mut hint,
        )
    });
}

#[divan::bench]
fn grain_wall_contact(bencher: divan::Bencher) {
    let table = ContourTable::new(1.0);
    let g = GrainShape::new(DVec2::new(0.0, 0.011), 0.012, 0.3, 0.02, -0.03, 0.7);
    bencher.bench(|| grain_wall(&table, black_box(&g), DVec2::ZERO, DVec2::Y));
}

/// The exact ellipses' contacts (`resolution_deg: 0`, issue #16), at the same overlaps and
/// shapes as the polygons: no hint, so every call is cold.
#[divan::bench(args = [0.01, 0.05, 0.15])]
fn ellipse_ellipse(bencher: divan::Bencher, depth: f64) {
    let (i, j) = pair(depth);
    bencher.bench(|| sdem::geometry::ellipse_ellipse(black_box(&i), black_box(&j)));
}

#[divan::bench]
fn ellipse_wall(bencher: divan::Bencher) {
    let g = GrainShape::new(DVec2::new(0.0, 0.011), 0.012, 0.3, 0.02, -0.03, 0.7);
    bencher.bench(|| sdem::geometry::ellipse_wall(black_box(&g), DVec2::ZERO, DVec2::Y));
}

/// The closed-form contacts of rigid discs (issue #16), at the same overlaps as the polygons.
#[divan::bench(args = [0.01, 0.05, 0.15])]
fn disc_disc(bencher: divan::Bencher, depth: f64) {
    let (ci, cj) = (DVec2::ZERO, DVec2::new(0.024 * (1.0 - depth), 0.001));
    bencher
        .bench(|| sdem::geometry::circle::disc_disc(black_box(ci), 0.012, black_box(cj), 0.0121));
}

#[divan::bench]
fn disc_wall(bencher: divan::Bencher) {
    let c = DVec2::new(0.0, 0.011);
    bencher.bench(|| sdem::geometry::circle::disc_wall(black_box(c), 0.012, DVec2::ZERO, DVec2::Y));
}

#[divan::bench(args = [1000, 10000], sample_count = 20)]
fn step_dense_packing(bencher: divan::Bencher, grains: usize) {
    time_steps(bencher, sdem::run::bench::dense_packing(grains, 1.0));
}

/// Times `world.step()`, counted in grain-steps, after one untimed step.
fn time_steps(bencher: divan::Bencher, mut world: sdem::integration::World) {
    world.step().unwrap();
    bencher
        .counter(divan::counter::ItemsCount::new(world.grains().len()))
        .bench_local(|| {
            world.step().unwrap();
        });
}

/// The sparse LU of a 100-grain tangent (20,000 DoF: 100 blocks of 200 DoF, 40 neighbours
/// per node, 300 one-sided contacts): `cold` is analysis + numeric factorization, `warm` the
/// numeric factorization alone (same pattern), `solve` the triangular solves.
mod sparse_lu {
    use sdem::meshfree::sparse::{SparseSolver, TripletMatrix, synthetic_multi_grain};

    fn matrix() -> TripletMatrix {
        synthetic_multi_grain(100, 200, 40, 300, 1)
    }

    #[divan::bench(sample_count = 5, sample_size = 1)]
    fn cold(bencher: divan::Bencher) {
        let a = matrix();
        bencher.bench_local(|| {
            let mut s = SparseSolver::new();
            s.factorize(&a).unwrap();
            s
        });
    }

    #[divan::bench(sample_count = 5, sample_size = 1)]
    fn warm(bencher: divan::Bencher) {
        let a = matrix();
        let mut s = SparseSolver::new();
        s.factorize(&a).unwrap();
        bencher.bench_local(|| s.factorize(&a).unwrap());
    }

    #[divan::bench(sample_count = 20)]
    fn solve(bencher: divan::Bencher) {
        let a = matrix();
        let mut s = SparseSolver::new();
        s.factorize(&a).unwrap();
        let b: Vec<f64> = (0..a.n).map(|i| (i % 7) as f64 - 3.0).collect();
        let mut x = b.clone();
        bencher.bench_local(|| {
            x.copy_from_slice(&b);
            s.solve_factored(&mut x).unwrap();
        });
    }
}

/// The whole step with every grain a rigid disc (closed-form contacts).
#[divan::bench(args = [1000, 10000], sample_count = 20)]
fn step_dense_packing_rigid(bencher: divan::Bencher, grains: usize) {
    let mut world = sdem::run::bench::dense_packing(grains, 1.0);
    sdem::run::bench::with_model(&mut world, sdem::grain::ModelLevel::Rigid);
    time_steps(bencher, world);
}

/// The whole step of rigid discs in a periodic cell: the dense packing with its box as the
/// cell's sides (issue #16, seventeenth and eighteenth sessions: the carry and wrap in the
/// grain pass, the chunked periodic list build). The lattice leaves a gap of a grain at the
/// cell's sides, which its grains close during the timed steps, crossing the sides.
#[divan::bench(args = [1000, 10000], sample_count = 20)]
fn step_dense_packing_rigid_periodic(bencher: divan::Bencher, grains: usize) {
    let mut world = sdem::run::bench::dense_packing(grains, 1.0)
        .with_periodic(sdem::boundary::periodic::PeriodicBoundary::default());
    sdem::run::bench::with_model(&mut world, sdem::grain::ModelLevel::Rigid);
    time_steps(bencher, world);
}

/// The whole step on the dense packing spread apart by 15% (φ about 0.68), every grain a rigid
/// disc at rest: no contacts, so what is timed is the per-grain work of a loose gas (frames,
/// the neighbour list's rebuild test, open candidate pairs, the grain pass), which is where
/// the gas half of `scenarios/isotropic_100k.ron` spends its time.
#[divan::bench(args = [1000, 10000], sample_count = 20)]
fn step_loose_rigid(bencher: divan::Bencher, grains: usize) {
    let mut world = sdem::run::bench::dense_packing(grains, 1.0);
    sdem::run::bench::with_model(&mut world, sdem::grain::ModelLevel::Rigid);
    for g in world.grains_mut() {
        g.center *= 1.15;
    }
    for wall in &mut world.walls {
        wall.point *= 1.15;
    }
    world.step().unwrap();
    assert_eq!(world.totals.contacts, 0, "a loose packing without contacts");
    time_steps(bencher, world);
}

/// The adaptive level on the dense packing of 10,000 grains with one grain in `ONE_IN` at the
/// full level and the others rigid (levels held fixed), as in the burst at the end of
/// `isotropic_100k.ron`'s fast compaction (up to one grain in twenty deforming): plain steps
/// of the full level's step h (`multi_rate = false`) against multi-rate cycles of 2h
/// (`true`), where the rigid grains out of the deforming grains' reach take one step of 2h.
/// Counted in grain-steps of h, so that the two throughputs compare the same simulated time.
/// The pairs of a deforming grain take the polygon kernel in both halves of a cycle: what a
/// cycle saves is the rigid pairs' and grains' second substep.
#[divan::bench(consts = [100, 20], args = [false, true], sample_count = 30)]
fn step_mixed_adaptive<const ONE_IN: usize>(bencher: divan::Bencher, multi_rate: bool) {
    use sdem::grain::{AdaptiveSettings, GrainLevel, ModelLevel};
    use sdem::integration::parameters::{Adaptive, ModeSettings};
    let mut world = sdem::run::bench::dense_packing(10_000, 1.0);
    let min_radius = world
        .grains()
        .iter()
        .map(|g| g.radius)
        .fold(f64::MAX, f64::min);
    let p = &mut world.params;
    p.adaptive = Some(Adaptive {
        multi_rate,
        ..Adaptive::fraction_of_critical(
            AdaptiveSettings::HELD,
            0.4,
            &p.material,
            &p.law,
            min_radius,
            ModeSettings::default(),
        )
    });
    let levels: Vec<GrainLevel> = (0..world.grains().len())
        .map(|g| {
            GrainLevel::new(if g % ONE_IN == 0 {
                ModelLevel::Full
            } else {
                ModelLevel::Rigid
            })
        })
        .collect();
    world.set_levels(&levels);
    // The lattice's release first: while its grains fly apart, the cycles' reach (from the
    // fastest grain) rebuilds the neighbour list in two cycles of three.
    for _ in 0..200 {
        world.step().unwrap();
    }
    assert_eq!(
        world.cycle_substep().is_some(),
        multi_rate,
        "cycles are taken when asked for"
    );
    world.step().unwrap();
    let substeps = if multi_rate { 2 } else { 1 };
    bencher
        .counter(divan::counter::ItemsCount::new(
            substeps * world.grains().len(),
        ))
        .bench_local(|| {
            world.step().unwrap();
        });
}

/// A neighbour-list build on the dense packing's centres (skin 0.2 of the mean radius, as
/// the step uses): the binning, the pair search and the per-grain index.
#[divan::bench(args = [10000, 100000], sample_count = 10)]
fn neighbor_list_build(bencher: divan::Bencher, grains: usize) {
    let world = sdem::run::bench::dense_packing(grains, 1.0);
    time_builds(bencher, &world, |list, centers, reach| {
        list.build(centers, reach)
    });
}

/// [`neighbor_list_build`] in a periodic cell, the packing's box: the pairs across the cell's
/// sides are listed with the image of their second grain.
#[divan::bench(args = [10000, 100000], sample_count = 10)]
fn neighbor_list_build_periodic(bencher: divan::Bencher, grains: usize) {
    let world = sdem::run::bench::dense_packing(grains, 1.0)
        .with_periodic(sdem::boundary::periodic::PeriodicBoundary::default());
    let cell = world.cell().expect("a periodic world");
    time_builds(bencher, &world, |list, centers, reach| {
        list.build_periodic(centers, reach, black_box(&cell))
    });
}

/// Times `build` on the world's centres and radii, counted in grains.
fn time_builds(
    bencher: divan::Bencher,
    world: &sdem::integration::World,
    build: impl Fn(&mut sdem::geometry::broadphase::NeighborList, &[DVec2], &[f64]),
) {
    let centers: Vec<DVec2> = world.grains().iter().map(|g| g.center).collect();
    let reach: Vec<f64> = world.grains().iter().map(|g| g.radius).collect();
    let mut list = sdem::geometry::broadphase::NeighborList::new(0.2 * 0.012);
    bencher
        .counter(divan::counter::ItemsCount::new(centers.len()))
        .bench_local(|| build(&mut list, black_box(&centers), black_box(&reach)));
}

/// Eight pairs of rigid discs at once (issue #16, tenth session): the lane kernel of the pair
/// pass, with the vector instructions the processor has, against the same eight pairs one by
/// one through `disc_disc`, the law and the dashpot (the one-pair path). Counted in pairs.
mod disc_pairs {
    use glam::DVec2;
    use sdem::contact::law::{SecantLaw, damped_normal_force};
    use sdem::geometry::Overlap;
    use sdem::integration::pairs::{
        DiscLanes, DiscPairForces, DiscPairs, LANES, PairLanes, disc_pair_forces_dispatch,
    };
    use std::hint::black_box;

    fn pairs() -> DiscPairs<PairLanes> {
        let lanes = |f: fn(usize) -> f64| PairLanes::from_fn(f);
        DiscPairs {
            first: DiscLanes {
                center: [lanes(|l| 0.03 * l as f64), lanes(|_| 0.0)],
                radius: lanes(|_| 0.012),
                mass: lanes(|_| 4.5e-4),
                velocity: [lanes(|l| 1e-3 * l as f64), lanes(|_| 0.0)],
                omega: lanes(|_| 0.1),
                // Rigid discs: no dilation.
                dilation: lanes(|_| 0.0),
            },
            second: DiscLanes {
                center: [
                    lanes(|l| 0.03 * l as f64 + 0.0238 - 1e-4 * l as f64),
                    lanes(|l| 1e-3 * l as f64),
                ],
                radius: lanes(|_| 0.0121),
                mass: lanes(|_| 4.6e-4),
                velocity: [lanes(|_| 0.0), lanes(|l| -1e-3 * l as f64)],
                omega: lanes(|_| -0.2),
                dilation: lanes(|_| 0.0),
            },
            affine_rate: [lanes(|_| 0.0), lanes(|_| 0.0)],
        }
    }

    #[divan::bench]
    fn eight_in_lanes(bencher: divan::Bencher) {
        let (input, law) = (pairs(), SecantLaw::new(1.0, 0.58, 2.0));
        let mut out = DiscPairForces::default();
        bencher
            .counter(divan::counter::ItemsCount::new(LANES))
            .bench_local(|| disc_pair_forces_dispatch(black_box(&input), &law, 1.0, &mut out));
    }

    #[divan::bench]
    fn eight_one_by_one(bencher: divan::Bencher) {
        let (input, law) = (pairs(), SecantLaw::new(1.0, 0.58, 2.0));
        bencher
            .counter(divan::counter::ItemsCount::new(LANES))
            .bench(|| {
                let input = black_box(&input);
                let mut forces = [0.0; LANES];
                for (l, force) in forces.iter_mut().enumerate() {
                    let at = |v: &PairLanes| v.0[l];
                    let (ci, cj) = (
                        DVec2::new(at(&input.first.center[0]), at(&input.first.center[1])),
                        DVec2::new(at(&input.second.center[0]), at(&input.second.center[1])),
                    );
                    let contact = sdem::geometry::circle::disc_disc(
                        ci,
                        at(&input.first.radius),
                        cj,
                        at(&input.second.radius),
                    );
                    if let Overlap::Contact(c) = contact {
                        let r = law.response(c.length, c.normal_gap).unwrap();
                        let vi =
                            DVec2::new(at(&input.first.velocity[0]), at(&input.first.velocity[1]));
                        let vj = DVec2::new(
                            at(&input.second.velocity[0]),
                            at(&input.second.velocity[1]),
                        );
                        let (mi, mj) = (at(&input.first.mass), at(&input.second.mass));
                        let gap_rate = (vj - vi).dot(c.normal);
                        *force = damped_normal_force(
                            r.force,
                            r.stiffness,
                            mi * mj / (mi + mj),
                            1.0,
                            gap_rate,
                        );
                    }
                }
                forces
            });
    }
}

/// The polygon contact's common path eight pairs at a time (`grain_grain_blocks`, by each
/// kernel the processor runs: AVX a block at a time, AVX-512) against the one-pair path four
/// times, on four pairs (twice over in the eight lanes) at depths 0.01 to 0.15 of a diameter
/// whose j moves back and forth by a tenth of a node spacing along the line of centres from
/// call to call (a contact under load from step to step; a dense step moves a grain by far
/// less). Each call takes the hints the last left.
mod polygon_lanes {
    use super::pair;
    use sdem::geometry::intersection_lanes::{
        BLOCK, BLOCKS, BlockContacts, BlockKernel, LanePair, OwnedLaneShape, PAIRS,
        grain_grain_blocks,
    };
    use sdem::geometry::{ContourTable, GrainShape, PairHint, grain_grain_hinted};
    use std::hint::black_box;

    /// The four pairs at both positions of j, and their hints after a first call.
    fn moving_pairs(
        table: &ContourTable,
    ) -> ([[(GrainShape, GrainShape); 2]; BLOCK], [PairHint; BLOCK]) {
        let mut hints = [PairHint::default(); BLOCK];
        let pairs = std::array::from_fn(|l| {
            let (i, j) = pair([0.01, 0.05, 0.15, 0.08][l]);
            let mut j_moved = j;
            j_moved.center.x -= 0.1 * 0.012 * table.dbeta;
            grain_grain_hinted(table, &i, &j, &mut hints[l]);
            [(i, j), (i, j_moved)]
        });
        (pairs, hints)
    }

    /// The kernels by name (`divan`'s arguments are values it can print).
    fn kernel(name: &str) -> Option<BlockKernel> {
        BlockKernel::available()
            .into_iter()
            .find(|k| k.name() == name)
    }

    #[divan::bench(args = ["AVX", "AVX-512"])]
    fn eight_in_lanes(bencher: divan::Bencher, name: &str) {
        let Some(kernel) = kernel(name) else {
            return;
        };
        let table = ContourTable::new(1.0);
        let (pairs, four_hints) = moving_pairs(&table);
        let mut hints = [four_hints, four_hints].concat();
        let shapes =
            pairs.map(|at| at.map(|(i, j)| [OwnedLaneShape::of(&i), OwnedLaneShape::of(&j)]));
        let mut contacts = [BlockContacts::default(); BLOCKS];
        let mut call = 0usize;
        let mut on_path = 0;
        bencher
            .counter(divan::counter::ItemsCount::new(PAIRS))
            .bench_local(|| {
                call += 1;
                let block: [LanePair; PAIRS] = std::array::from_fn(|l| {
                    let [i, j] = &shapes[l % BLOCK][call & 1];
                    LanePair {
                        i: i.lane_shape(),
                        j: j.lane_shape(),
                        hint: hints[l],
                        ..Default::default()
                    }
                });
                grain_grain_blocks(
                    kernel,
                    &table,
                    black_box(&block),
                    false,
                    PAIRS,
                    &mut contacts,
                );
                for (l, hint) in hints.iter_mut().enumerate() {
                    match contacts[l / BLOCK].lane(l % BLOCK) {
                        Some((_, next)) => {
                            *hint = next;
                            on_path += 1;
                        }
                        None => {
                            let (i, j) = &pairs[l % BLOCK][call & 1];
                            grain_grain_hinted(&table, i, j, hint);
                        }
                    }
                }
                black_box(&contacts);
            });
        // What the bench means to time: every lane on the path.
        assert_eq!(on_path, PAIRS * call, "lanes left the path");
    }

    #[divan::bench]
    fn four_one_by_one(bencher: divan::Bencher) {
        let table = ContourTable::new(1.0);
        let (pairs, mut hints) = moving_pairs(&table);
        let mut call = 0usize;
        bencher
            .counter(divan::counter::ItemsCount::new(BLOCK))
            .bench_local(|| {
                call += 1;
                for (l, hint) in hints.iter_mut().enumerate() {
                    let (i, j) = &pairs[l][call & 1];
                    black_box(grain_grain_hinted(&table, black_box(i), black_box(j), hint));
                }
            });
    }
}

/// Angles of grains that have turned for a while (tens of radians, as in a run's jammed state),
/// in random order: what the frames' sines and cosines see.
fn turned_angles(count: usize) -> Vec<f64> {
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    (0..count)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            60.0 * ((state >> 11) as f64 / (1u64 << 53) as f64) - 30.0
        })
        .collect()
}

/// `libm`'s sincos one angle at a time, against [`sdem::geometry::angle::sin_cos_lanes`] four
/// at a time (the grain pass's way), on 4,096 angles.
#[divan::bench(args = [false, true])]
fn sin_cos_of_turned_grains(bencher: divan::Bencher, lanes: bool) {
    use sdem::geometry::angle::{sin_cos, sin_cos_lanes};
    use sdem::lanes::Lanes;
    let angles = turned_angles(4096);
    bencher.bench(|| {
        let mut total = 0.0;
        if lanes {
            for four in angles.chunks_exact(4) {
                let (s, c) = sin_cos_lanes(&Lanes([four[0], four[1], four[2], four[3]]));
                total += s.0[0] + c.0[3];
            }
        } else {
            for &x in &angles {
                let (s, c) = sin_cos(black_box(x));
                total += s + c;
            }
        }
        black_box(total)
    });
}

/// The frames and principal directions of 4,096 deforming grains: one at a time
/// (`Frame::of_grain_and_direction`) against blocks of four (`Frame::write_full_block`, the
/// grain pass's way).
#[divan::bench(args = [false, true])]
fn frames_of_deforming_grains(bencher: divan::Bencher, blocks: bool) {
    use sdem::grain::Grain;
    use sdem::integration::{FRAME_LANES, Frame};
    let angles = turned_angles(2 * 4096);
    let grains: Vec<Grain> = (0..4096)
        .map(|k| Grain {
            theta: angles[2 * k],
            alpha: angles[2 * k + 1],
            eps1: 0.02,
            eps2: -0.015,
            eps1_rate: 1e-3,
            eps2_rate: -2e-3,
            alpha_rate: 0.1,
            omega: 0.3,
            ..Grain::at_rest(DVec2::new(k as f64, 0.0), 0.012)
        })
        .collect();
    let mut frames = vec![Frame::default(); grains.len()];
    let mut directions = vec![DVec2::ZERO; grains.len()];
    bencher.bench_local(|| {
        if blocks {
            for first in (0..grains.len()).step_by(FRAME_LANES) {
                let block = std::array::from_fn(|l| first + l);
                Frame::write_full_block(&mut frames, &mut directions, &grains, block, 1.0);
            }
        } else {
            for ((frame, direction), grain) in frames.iter_mut().zip(&mut directions).zip(&grains) {
                (*frame, *direction) = Frame::of_grain_and_direction(grain, 1.0);
            }
        }
        black_box((&frames, &directions));
    });
}
