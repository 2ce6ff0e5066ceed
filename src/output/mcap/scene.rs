//! The Foxglove `/scene` channel of an SDEM log (JSON): grains as flat cylinders coloured by
//! mean stress, and the box.

use crate::boundary::walls::Wall;
use crate::integration::World;
use crate::output::colour::stress_colour_max;
use glam::DVec2;
use rayon::prelude::*;
use std::fmt::Write as _;

/// `{"sec":..,"nsec":..}` of a log time in ns.
fn json_time(out: &mut String, ns: u64) {
    let _ = write!(
        out,
        "{{\"sec\":{},\"nsec\":{}}}",
        ns / 1_000_000_000,
        ns % 1_000_000_000
    );
}

/// A finite number for JSON (non-finite values become 0).
#[inline]
fn num(v: f64) -> f64 {
    if v.is_finite() { v } else { 0.0 }
}

/// Decimals for lengths in `/scene`: 1/1000 of the smallest radius.
pub(super) fn length_decimals(min_radius: f64) -> usize {
    if min_radius.is_finite() && min_radius > 0.0 {
        (-(min_radius * 1e-3).log10()).ceil().clamp(0.0, 15.0) as usize
    } else {
        6
    }
}

/// The `/scene` message: one entity of cylinders (the grains: ellipses seen from +z, coloured
/// by mean stress) and one of lines (the box).
pub(super) fn encode_scene(out: &mut String, world: &World, log_time: u64) {
    out.clear();
    let grains = world.grains();
    let n = grains.len().max(1);
    let mean_radius = grains.iter().map(|g| g.radius).sum::<f64>() / n as f64;
    let min_radius = grains
        .iter()
        .map(|g| g.radius)
        .fold(f64::INFINITY, f64::min);
    let decimals = length_decimals(min_radius);
    let height = 0.2 * mean_radius;
    let mean_c: Vec<f64> = world
        .grain_stress
        .iter()
        .map(|s| -s.mean_external())
        .collect();
    let top = stress_colour_max(&mean_c);

    scene_grains_start(out, log_time, top, world.step);
    out.push_str("],\"arrows\":[],\"cubes\":[],\"spheres\":[],\"cylinders\":[");
    // Grains in parallel chunks, joined in order: the same bytes for any thread count.
    const CHUNK: usize = 2048;
    let parts: Vec<String> = grains
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(c, chunk)| {
            let mut s = String::with_capacity(chunk.len() * 200);
            for (k, g) in chunk.iter().enumerate() {
                let id = c * CHUNK + k;
                if id > 0 {
                    s.push(',');
                }
                let half = 0.5 * (g.theta + g.alpha);
                let (qz, qw) = half.sin_cos();
                let [r, gr, b] = stress_colour(mean_c[id], top);
                let _ = write!(
                    s,
                    "{{\"pose\":{{\"position\":{{\"x\":{:.d$},\"y\":{:.d$},\"z\":0}},\"orientation\":{{\"x\":0,\"y\":0,\"z\":{:.5},\"w\":{:.5}}}}},\"size\":{{\"x\":{:.d$},\"y\":{:.d$},\"z\":{:.d$}}},\"bottom_scale\":1,\"top_scale\":1,\"color\":{{\"r\":{:.3},\"g\":{:.3},\"b\":{:.3},\"a\":1}}}}",
                    num(g.center.x),
                    num(g.center.y),
                    num(qz),
                    num(qw),
                    num(2.0 * g.radius * (1.0 + g.eps1)),
                    num(2.0 * g.radius * (1.0 + g.eps2)),
                    height,
                    r as f64 / 255.0,
                    gr as f64 / 255.0,
                    b as f64 / 255.0,
                    d = decimals
                );
            }
            s
        })
        .collect();
    for p in &parts {
        out.push_str(p);
    }
    out.push_str("],\"lines\":[],\"triangles\":[],\"texts\":[],\"models\":[]}");
    encode_box(out, &world.walls, log_time, mean_radius, decimals);
    out.push_str("]}");
}

/// The box entity of `/scene` (after a comma): a line loop through the corners of the four
/// walls (a periodic cell's sides: a parallelogram), `0.25 * mean_radius` thick; nothing
/// unless there are at least four walls (planes after the box's four are not drawn).
pub(super) fn encode_box(
    out: &mut String,
    walls: &[Wall],
    log_time: u64,
    mean_radius: f64,
    decimals: usize,
) {
    if walls.len() >= 4 {
        use crate::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP};
        let (x0, x1) = (walls[LEFT].point.x, walls[RIGHT].point.x);
        let (y0, y1) = (walls[BOTTOM].point.y, walls[TOP].point.y);
        out.push_str(",{\"timestamp\":");
        json_time(out, log_time);
        out.push_str(",\"frame_id\":\"sdem\",\"id\":\"box\",\"lifetime\":{\"sec\":0,\"nsec\":0},\"frame_locked\":false,\"metadata\":[],\"arrows\":[],\"cubes\":[],\"spheres\":[],\"cylinders\":[],\"lines\":[");
        // Sides along h2 = (tilt, height) in a sheared periodic cell.
        let n = walls[LEFT].normal;
        let shift = if n.y != 0.0 {
            -n.y / n.x * (y1 - y0)
        } else {
            0.0
        };
        let corners =
            [(x0, y0), (x1, y0), (x1 + shift, y1), (x0 + shift, y1)].map(|(x, y)| DVec2::new(x, y));
        json_line_loop(out, &corners, 0.25 * mean_radius, decimals);
        out.push_str("],\"triangles\":[],\"texts\":[],\"models\":[]}");
    }
}

/// The identity pose of a `/scene` primitive.
pub(super) const IDENTITY_POSE: &str = "\"pose\":{\"position\":{\"x\":0,\"y\":0,\"z\":0},\"orientation\":{\"x\":0,\"y\":0,\"z\":0,\"w\":1}}";

/// Starts a `/scene` message: up to the metadata of its `grains` entity (colour scale from 0
/// to `top`, step), which the caller may extend before it closes them.
pub(super) fn scene_grains_start(out: &mut String, log_time: u64, top: f64, step: u64) {
    out.push_str("{\"deletions\":[],\"entities\":[{\"timestamp\":");
    json_time(out, log_time);
    out.push_str(
        ",\"frame_id\":\"sdem\",\"id\":\"grains\",\"lifetime\":{\"sec\":0,\"nsec\":0},\"frame_locked\":false,\"metadata\":[",
    );
    let _ = write!(
        out,
        "{{\"key\":\"colour\",\"value\":\"mean grain stress, compression positive, viridis from 0 to {top:.4e}\"}},{{\"key\":\"step\",\"value\":\"{step}\"}}"
    );
}

/// The colour of a grain of mean stress `mean_stress_c` (compression positive): viridis over
/// `[0, top]` (the low end when `top` is not positive).
pub(super) fn stress_colour(mean_stress_c: f64, top: f64) -> [u8; 3] {
    let t = if top > 0.0 {
        (mean_stress_c / top).clamp(0.0, 1.0)
    } else {
        0.0
    };
    crate::output::colour::viridis(t)
}

/// A point of a `/scene` primitive, in the plane z = 0, with `decimals` decimals.
pub(super) fn json_point(out: &mut String, p: DVec2, decimals: usize) {
    let _ = write!(
        out,
        "{{\"x\":{:.d$},\"y\":{:.d$},\"z\":0}}",
        num(p.x),
        num(p.y),
        d = decimals
    );
}

/// A dark grey line loop through `points`, `thickness` thick, as a `/scene` line primitive.
pub(super) fn json_line_loop(out: &mut String, points: &[DVec2], thickness: f64, decimals: usize) {
    out.push_str("{\"type\":1,");
    out.push_str(IDENTITY_POSE);
    let _ = write!(
        out,
        ",\"thickness\":{thickness:.decimals$},\"scale_invariant\":false,\"points\":["
    );
    for (k, &p) in points.iter().enumerate() {
        if k > 0 {
            out.push(',');
        }
        json_point(out, p, decimals);
    }
    out.push_str(
        "],\"color\":{\"r\":0.1,\"g\":0.1,\"b\":0.1,\"a\":1},\"colors\":[],\"indices\":[]}",
    );
}
