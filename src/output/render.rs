//! Pictures of a packing (`sdem render`): every grain drawn as its deformed contour, cut flat
//! along the chords of its contacts, filled with the colour of its mean stress, with a colour
//! bar — the kind of picture of the SDEM paper's figures 9 and 11.
//!
//! A grain's contour is the affine image of its reference circle (`center + A R u`); where two
//! contours cross, the paper's grains meet along the straight chord PP'. Each grain is drawn as
//! its contour polygon clipped by the line of each of its contacts (the part on its own side:
//! `(x - x_c) . n <= 0` for the first grain of a pair, `>= 0` for the second) and by each wall.
//! The chords come from the logged contacts; the contour resolution of the picture follows its
//! pixel size (the chords are exact whatever the resolution).
//!
//! A meshfree frame (`/contours`, see [`crate::output::mcap`]) holds each grain's deformed
//! contour itself: the polygon of its boundary nodes is drawn as it is, clipped by the walls
//! only, with the same colours.

use crate::boundary::walls::box_corners;
use crate::output::colour::stress_colour_max;
pub use crate::output::colour::viridis;
pub use crate::output::frame::outline::{clip_half_plane, frame_cuts, grain_outline};
use crate::output::frame::{Frame, FrameContour};
use glam::DVec2;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

/// DejaVu Sans, shipped so that text needs no system font (plotters' `ab_glyph` backend).
pub static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
/// The family name under which [`FONT`] is registered.
pub const FONT_FAMILY: &str = "sans-serif";

/// Registers the shipped font with plotters (once per process).
pub fn register_fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The font is a valid TTF compiled into the binary; a failure would leave text out of
        // the pictures, which plotters then reports as a drawing error.
        let _ = plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, FONT);
    });
}

/// How to draw a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    /// Pixels along the longer side of the box.
    pub size: u32,
    /// Top of the colour scale (compression positive); `None`: the frame's 99th percentile.
    pub stress_max: Option<f64>,
    /// First line of the caption (e.g. the scenario name).
    pub title: String,
    /// Part of the sample to show, `(lower left, upper right)`; `None`: the whole box.
    pub region: Option<(DVec2, DVec2)>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            size: 1200,
            stress_max: None,
            title: String::new(),
            region: None,
        }
    }
}

/// What was drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderInfo {
    pub width: u32,
    pub height: u32,
    pub grains: usize,
    pub stress_max: f64,
}

/// The region shown: the box of the four walls, or the grains' extent.
fn view_bounds(frame: &Frame, region: Option<(DVec2, DVec2)>) -> (DVec2, DVec2) {
    if let Some((a, b)) = region {
        let (lo, hi) = (a.min(b), a.max(b));
        if lo.is_finite() && hi.is_finite() && (hi - lo).min_element() > 0.0 {
            return (lo, hi);
        }
    }
    if let Some(cell) = &frame.cell {
        let corners = [
            cell.origin,
            cell.origin + cell.h1(),
            cell.origin + cell.h2(),
            cell.origin + cell.h1() + cell.h2(),
        ];
        let lo = corners.iter().fold(corners[0], |a, b| a.min(*b));
        let hi = corners.iter().fold(corners[0], |a, b| a.max(*b));
        return (lo, hi);
    }
    // The first four walls are the box's; planes (a scenario's `planes`) follow them.
    if frame.walls.len() >= 4 {
        let (lo, hi) = box_corners(&frame.walls);
        if (hi - lo).min_element() > 0.0 && lo.is_finite() && hi.is_finite() {
            return (lo, hi);
        }
    }
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for p in frame.contours.iter().flatten().flat_map(|c| &c.points) {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    for g in &frame.grains {
        let r = g.radius * (1.0 + g.eps1.max(g.eps2).max(0.0));
        lo = lo.min(g.center - DVec2::splat(r));
        hi = hi.max(g.center + DVec2::splat(r));
    }
    if !(lo.is_finite() && hi.is_finite()) || (hi - lo).min_element() <= 0.0 {
        return (DVec2::ZERO, DVec2::ONE);
    }
    (lo, hi)
}

/// The segment of the line through `point` along `direction` inside the box `[lo, hi]`, if it
/// crosses it (Liang–Barsky clipping of the line's parameter).
fn line_in_box(point: DVec2, direction: DVec2, lo: DVec2, hi: DVec2) -> Option<(DVec2, DVec2)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for axis in 0..2 {
        let (p, d) = (point[axis], direction[axis]);
        if d == 0.0 {
            if p < lo[axis] || p > hi[axis] {
                return None;
            }
            continue;
        }
        let (a, b) = ((lo[axis] - p) / d, (hi[axis] - p) / d);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    (t0 < t1).then(|| (point + t0 * direction, point + t1 * direction))
}

/// Draws frame `frame` into `path` (PNG, or SVG if the name ends in `.svg`).
pub fn render_frame(
    frame: &Frame,
    path: &Path,
    options: &RenderOptions,
) -> Result<RenderInfo, String> {
    register_fonts();
    if frame.grain_count() == 0 {
        return Err("the frame has no grains".into());
    }
    frame.check()?;
    let (lo, hi) = view_bounds(frame, options.region);
    let extent = hi - lo;
    let size = options.size.clamp(100, 20_000) as f64;
    let scale = size / extent.max_element();
    let box_w = (extent.x * scale).round().max(1.0) as u32;
    let box_h = (extent.y * scale).round().max(1.0) as u32;
    let margin = 16u32;
    let caption_h = 64u32;
    let bar_w = 170u32;
    let width = margin + box_w + margin + bar_w;
    let height = caption_h + box_h + margin;
    let means: Vec<f64> = match &frame.contours {
        Some(contours) => contours.iter().map(|c| c.mean_stress_c).collect(),
        None => frame.grains.iter().map(|g| g.mean_stress_c()).collect(),
    };
    let stress_max = options
        .stress_max
        .filter(|v| v.is_finite() && *v > 0.0)
        .unwrap_or_else(|| stress_colour_max(&means));
    let layout = Layout {
        lo,
        hi,
        scale,
        origin: (margin as i32, caption_h as i32),
        box_h,
        box_w,
        stress_max,
    };
    let is_svg = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("svg"));
    if is_svg {
        let root = SVGBackend::new(path, (width, height)).into_drawing_area();
        draw(&root, frame, &means, &layout, options)?;
        root.present().map_err(|e| e.to_string())?;
    } else {
        let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
        draw(&root, frame, &means, &layout, options)?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(RenderInfo {
        width,
        height,
        grains: frame.grain_count(),
        stress_max,
    })
}

struct Layout {
    lo: DVec2,
    hi: DVec2,
    scale: f64,
    origin: (i32, i32),
    box_w: u32,
    box_h: u32,
    stress_max: f64,
}

impl Layout {
    fn pixel(&self, x: DVec2) -> (i32, i32) {
        let p = (x - self.lo) * self.scale;
        (
            self.origin.0 + p.x.round() as i32,
            self.origin.1 + self.box_h as i32 - p.y.round() as i32,
        )
    }
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    frame: &Frame,
    means: &[f64],
    layout: &Layout,
    options: &RenderOptions,
) -> Result<(), String> {
    root.fill(&WHITE).map_err(err)?;
    if let Some(contours) = &frame.contours {
        draw_contours(root, frame, contours, means, layout)?;
    } else {
        draw_ellipses(root, frame, means, layout)?;
    }
    draw_frame_decor(root, frame, layout, options)
}

/// The grain's colour for mean stress `mean` on the layout's scale.
fn stress_colour(mean: f64, layout: &Layout) -> RGBColor {
    let t = if layout.stress_max > 0.0 {
        mean / layout.stress_max
    } else {
        0.0
    };
    let [r, g, b] = viridis(t);
    RGBColor(r, g, b)
}

/// Fills `polygon` (model coordinates) with `fill` and outlines it when it is large enough.
fn draw_polygon<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    polygon: &[DVec2],
    fill: RGBColor,
    outlined: bool,
    layout: &Layout,
) -> Result<(), String> {
    let pixels: Vec<(i32, i32)> = polygon.iter().map(|&x| layout.pixel(x)).collect();
    root.draw(&Polygon::new(pixels.clone(), fill.filled()))
        .map_err(err)?;
    if outlined {
        let mut closed = pixels;
        closed.push(closed[0]);
        root.draw(&PathElement::new(
            closed,
            RGBColor(25, 25, 25).stroke_width(1),
        ))
        .map_err(err)?;
    }
    Ok(())
}

/// The half-planes of the view's edges (no drawing outside the picture's box).
fn view_cuts(layout: &Layout) -> [(DVec2, DVec2); 4] {
    [
        (layout.lo, -DVec2::X),
        (layout.lo, -DVec2::Y),
        (layout.hi, DVec2::X),
        (layout.hi, DVec2::Y),
    ]
}

/// Meshfree grains: each contour as logged, clipped by the walls and the view.
fn draw_contours<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    frame: &Frame,
    contours: &[FrameContour],
    means: &[f64],
    layout: &Layout,
) -> Result<(), String> {
    let cuts: Vec<(DVec2, DVec2)> = frame
        .walls
        .iter()
        .map(|w| (w.point, -w.normal))
        .chain(view_cuts(layout))
        .collect();
    for (k, c) in contours.iter().enumerate() {
        if c.points.len() < 3 || !c.points.iter().all(|p| p.is_finite()) {
            continue;
        }
        let r_px = c.equivalent_radius() * layout.scale;
        draw_clipped(root, c.points.clone(), &cuts, means[k], r_px >= 4.0, layout)?;
    }
    Ok(())
}

/// Clips a grain's outline by half planes (walls, the view's edges) and draws it in its stress
/// colour, outlined when large enough for the outline to show.
fn draw_clipped<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    mut polygon: Vec<DVec2>,
    cuts: &[(DVec2, DVec2)],
    mean_stress: f64,
    outlined: bool,
    layout: &Layout,
) -> Result<(), String> {
    for &(point, normal) in cuts {
        if polygon.len() < 3 {
            break;
        }
        polygon = clip_half_plane(&polygon, point, normal);
    }
    if polygon.len() < 3 {
        return Ok(());
    }
    draw_polygon(
        root,
        &polygon,
        stress_colour(mean_stress, layout),
        outlined,
        layout,
    )
}

/// SDEM grains: ellipses cut along their contact chords and by the walls and the view.
fn draw_ellipses<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    frame: &Frame,
    means: &[f64],
    layout: &Layout,
) -> Result<(), String> {
    let cuts = frame_cuts(frame);
    // The view's edges cut every grain too (no drawing outside the picture's box).
    let view = view_cuts(layout);
    // In a periodic cell, each grain and its images next to the cell (the view is the cell's
    // bounding box, so a grain across a side shows on both).
    let images: Vec<DVec2> = match &frame.cell {
        Some(cell) => (-1..=1)
            .flat_map(|a| (-1..=1).map(move |b| cell.image_shift([a, b])))
            .collect(),
        None => vec![DVec2::ZERO],
    };
    for (k, g) in frame.grains.iter().enumerate() {
        let reach = g.radius * (1.0 + g.eps1.max(g.eps2));
        let r_px = reach * layout.scale;
        if !r_px.is_finite() {
            continue;
        }
        // Contour nodes: about one per 2 pixels of perimeter, at most 360.
        let nodes = (std::f64::consts::PI * r_px).clamp(12.0, 360.0) as usize;
        let mut polygon = None;
        for shift in &images {
            let center = g.center + *shift;
            if (center - center.clamp(layout.lo, layout.hi)).length() > reach {
                continue;
            }
            let outline = polygon.get_or_insert_with(|| grain_outline(g, nodes, &cuts[k]));
            let moved: Vec<DVec2> = outline.iter().map(|x| *x + *shift).collect();
            draw_clipped(root, moved, &view, means[k], r_px >= 4.0, layout)?;
        }
    }
    Ok(())
}

/// The box, the caption and the colour bar.
fn draw_frame_decor<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    frame: &Frame,
    layout: &Layout,
    options: &RenderOptions,
) -> Result<(), String> {
    // The box; for a periodic cell, its bounding box in grey and the cell's sides in black.
    let (x0, y0) = layout.origin;
    let box_colour = if frame.cell.is_some() {
        RGBColor(170, 170, 170)
    } else {
        BLACK
    };
    root.draw(&Rectangle::new(
        [
            (x0, y0),
            (x0 + layout.box_w as i32, y0 + layout.box_h as i32),
        ],
        box_colour.stroke_width(2),
    ))
    .map_err(err)?;
    if let Some(cell) = &frame.cell {
        let corners = [
            cell.origin,
            cell.origin + cell.h1(),
            cell.origin + cell.h1() + cell.h2(),
            cell.origin + cell.h2(),
            cell.origin,
        ];
        let pixels: Vec<(i32, i32)> = corners.iter().map(|&x| layout.pixel(x)).collect();
        root.draw(&PathElement::new(pixels, BLACK.stroke_width(2)))
            .map_err(err)?;
    }
    // Planes (walls after the box's four), as their segment inside the view.
    if frame.cell.is_none() {
        for wall in frame.walls.iter().skip(4) {
            if let Some((a, b)) = line_in_box(wall.point, wall.normal.perp(), layout.lo, layout.hi)
            {
                root.draw(&PathElement::new(
                    vec![layout.pixel(a), layout.pixel(b)],
                    BLACK.stroke_width(2),
                ))
                .map_err(err)?;
            }
        }
    }

    // Caption.
    let font = |size: u32| (FONT_FAMILY, size).into_font().color(&BLACK);
    let mut line2 = format!("step {}   t = {:.4e}", frame.step, frame.time);
    if let Some(m) = &frame.measures {
        line2.push_str(&format!(
            "   φ = {:.4}   p_c = {:.3e}   z = {:.2}   contacts {}",
            m.phi, m.p_c, m.z, m.contacts
        ));
    }
    let title = if options.title.is_empty() {
        format!("{} grains", frame.grain_count())
    } else {
        format!("{} — {} grains", options.title, frame.grain_count())
    };
    root.draw_text(&title, &font(22), (x0, 8)).map_err(err)?;
    root.draw_text(&line2, &font(17), (x0, 36)).map_err(err)?;

    // Colour bar.
    let bar_x = x0 + layout.box_w as i32 + 24;
    let bar_top = y0 + 40;
    let bar_h = (layout.box_h as i32 - 60).max(100);
    let bar_w = 26;
    let steps = 256;
    for s in 0..steps {
        let t0 = s as f64 / steps as f64;
        let ya = bar_top + bar_h - ((s + 1) as f64 / steps as f64 * bar_h as f64).round() as i32;
        let yb = bar_top + bar_h - (t0 * bar_h as f64).round() as i32;
        let [r, g, b] = viridis(t0 + 0.5 / steps as f64);
        root.draw(&Rectangle::new(
            [(bar_x, ya), (bar_x + bar_w, yb)],
            RGBColor(r, g, b).filled(),
        ))
        .map_err(err)?;
    }
    root.draw(&Rectangle::new(
        [(bar_x, bar_top), (bar_x + bar_w, bar_top + bar_h)],
        BLACK.stroke_width(1),
    ))
    .map_err(err)?;
    root.draw_text("mean stress", &font(15), (bar_x - 14, y0))
        .map_err(err)?;
    root.draw_text("(compression +)", &font(13), (bar_x - 14, y0 + 18))
        .map_err(err)?;
    let ticks = 5;
    for k in 0..=ticks {
        let f = k as f64 / ticks as f64;
        let y = bar_top + bar_h - (f * bar_h as f64).round() as i32;
        root.draw(&PathElement::new(
            vec![(bar_x + bar_w, y), (bar_x + bar_w + 5, y)],
            BLACK.stroke_width(1),
        ))
        .map_err(err)?;
        let value = f * layout.stress_max;
        let label = if k == ticks && layout.stress_max > 0.0 {
            format!("≥ {value:.2e}")
        } else {
            format!("{value:.2e}")
        };
        root.draw_text(&label, &font(14), (bar_x + bar_w + 8, y - 7))
            .map_err(err)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::frame::FrameGrain;

    #[test]
    fn a_plane_is_drawn_as_its_chord_of_the_view() {
        let (lo, hi) = (DVec2::ZERO, DVec2::ONE);
        // x + y = 1 crosses the unit square from (1, 0) to (0, 1) (in either order).
        let (a, b) = line_in_box(DVec2::new(0.5, 0.5), DVec2::new(-1.0, 1.0), lo, hi).unwrap();
        let ends = [a, b];
        assert!(
            ends.iter()
                .any(|e| e.distance(DVec2::new(1.0, 0.0)) < 1e-12)
        );
        assert!(
            ends.iter()
                .any(|e| e.distance(DVec2::new(0.0, 1.0)) < 1e-12)
        );
        // A horizontal line inside, and one outside the view.
        let (a, b) = line_in_box(DVec2::new(0.3, 0.25), DVec2::X, lo, hi).unwrap();
        assert_eq!((a.x.min(b.x), a.x.max(b.x), a.y), (0.0, 1.0, 0.25));
        assert!(line_in_box(DVec2::new(0.0, 2.0), DVec2::X, lo, hi).is_none());
    }

    #[test]
    fn clipping_a_square_by_a_half_plane() {
        let square = [
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        let cut = clip_half_plane(&square, DVec2::new(0.5, 0.0), DVec2::X);
        let area = |p: &[DVec2]| {
            0.5 * (0..p.len())
                .map(|k| p[k].perp_dot(p[(k + 1) % p.len()]))
                .sum::<f64>()
        };
        assert!((area(&cut) - 0.5).abs() < 1e-12);
        assert!(cut.iter().all(|x| x.x <= 0.5 + 1e-12));
    }

    #[test]
    fn two_touching_discs_share_a_flat_chord() {
        // Two unit discs 1.8 apart: cut at x = 0.9, both outlines end on the chord line.
        let a = FrameGrain {
            radius: 1.0,
            ..Default::default()
        };
        let b = FrameGrain {
            center: DVec2::new(1.8, 0.0),
            ..a
        };
        let point = DVec2::new(0.9, 0.0);
        let pa = grain_outline(&a, 360, &[(point, DVec2::X)]);
        let pb = grain_outline(&b, 360, &[(point, -DVec2::X)]);
        let max_a = pa.iter().map(|p| p.x).fold(f64::MIN, f64::max);
        let min_b = pb.iter().map(|p| p.x).fold(f64::MAX, f64::min);
        assert!((max_a - 0.9).abs() < 1e-12 && (min_b - 0.9).abs() < 1e-12);
        // The flat segment is the chord: half-length sqrt(1 - 0.81).
        let on_chord: Vec<f64> = pa
            .iter()
            .filter(|p| (p.x - 0.9).abs() < 1e-12)
            .map(|p| p.y)
            .collect();
        let half = (1.0f64 - 0.81).sqrt();
        let span = on_chord.iter().fold(f64::MIN, |m, &y| m.max(y))
            - on_chord.iter().fold(f64::MAX, |m, &y| m.min(y));
        assert!((span - 2.0 * half).abs() < 1e-3, "{span}");
    }

    #[test]
    fn viridis_ends() {
        assert_eq!(viridis(0.0), [68, 1, 84]);
        assert_eq!(viridis(1.0), [253, 231, 37]);
        assert_eq!(viridis(f64::NAN), [68, 1, 84]);
    }
}
