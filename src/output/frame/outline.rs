//! The deformed outline of an SDEM grain: its contour polygon cut flat along its contacts'
//! chords and the walls it crosses (what `render` draws and the VTK export writes).

use super::{Frame, FrameGrain};
use glam::DVec2;

/// Clips a convex polygon to the half-plane `(x - point) . normal <= 0` (Sutherland–Hodgman).
pub fn clip_half_plane(polygon: &[DVec2], point: DVec2, normal: DVec2) -> Vec<DVec2> {
    let n = polygon.len();
    let mut out = Vec::with_capacity(n + 2);
    for k in 0..n {
        let a = polygon[k];
        let b = polygon[(k + 1) % n];
        let da = (a - point).dot(normal);
        let db = (b - point).dot(normal);
        if da <= 0.0 {
            out.push(a);
        }
        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
            out.push(a + (b - a) * (da / (da - db)));
        }
    }
    out
}

/// The outline of a grain: its contour polygon with `nodes` nodes, cut by each `(point,
/// normal)` half-plane `(x - point) . normal <= 0`.
pub fn grain_outline(grain: &FrameGrain, nodes: usize, cuts: &[(DVec2, DVec2)]) -> Vec<DVec2> {
    let shape = grain.shape();
    let nodes = nodes.max(8);
    let mut polygon: Vec<DVec2> = (0..nodes)
        .map(|k| {
            let (s, c) = (k as f64 * std::f64::consts::TAU / nodes as f64).sin_cos();
            shape.center + shape.map * DVec2::new(c, s)
        })
        .collect();
    for &(point, normal) in cuts {
        if polygon.len() < 3 {
            break;
        }
        polygon = clip_half_plane(&polygon, point, normal);
    }
    polygon
}

/// The cuts of every grain of a frame: its contacts' chords and the walls it crosses. In a
/// periodic cell a contact with an image of a grain is logged where the images meet: its chord
/// is moved by the lattice vector that brings it to the grain itself, and the cell's sides cut
/// nothing.
pub fn frame_cuts(frame: &Frame) -> Vec<Vec<(DVec2, DVec2)>> {
    let mut cuts: Vec<Vec<(DVec2, DVec2)>> = vec![Vec::new(); frame.grains.len()];
    let near = |point: DVec2, g: usize| match &frame.cell {
        Some(cell) => frame.grains[g].center + cell.minimum_image(point - frame.grains[g].center).0,
        None => point,
    };
    for c in &frame.contacts {
        let (i, j) = (c.first as usize, c.second as usize);
        if i < cuts.len() && j < cuts.len() && c.normal.is_finite() && c.point.is_finite() {
            cuts[i].push((near(c.point, i), c.normal));
            cuts[j].push((near(c.point, j), -c.normal));
        }
    }
    if frame.cell.is_some() {
        return cuts;
    }
    for (g, list) in frame.grains.iter().zip(cuts.iter_mut()) {
        let reach = g.radius * (1.0 + g.eps1.max(g.eps2));
        for w in &frame.walls {
            if w.height(g.center) < reach {
                list.push((w.point, -w.normal));
            }
        }
    }
    cuts
}
