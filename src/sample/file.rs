//! Samples read from a file: a CSV of grains, such as the `grains.csv` a run writes.
//!
//! # Format
//!
//! Comma-separated, one grain per line; blank lines and lines starting with `#` are skipped.
//! The first line is either a header naming the columns, or already a grain:
//!
//! * with a header, the columns are found by name: `x`, `y`, `radius` are required, `theta`,
//!   `eps1`, `eps2`, `alpha` are optional (0 when absent), and the other columns of sdem's own
//!   `grains.csv` (`id`, `stress_xx`, `stress_yy`, `stress_xy`, `mean_stress_c`, `contacts`) are
//!   ignored; any other name is an error (a typo would otherwise silently zero a DoF);
//! * without a header, the columns are `x,y,radius[,theta,eps1,eps2,alpha]` in that order.
//!
//! Grains start at rest (every rate zero). Lengths in the scenario's unit, angles in radians,
//! strains as in `grains.csv` (principal stretches minus one).
//!
//! # Checks
//!
//! [`read_grains`] checks each line: the number of fields, numbers that parse, finite values, a
//! radius > 0, strains > -1. [`check_packing`] then checks the grains against the box and each
//! other with the engine's own contact geometry: a centre outside the box, a contour wholly
//! beyond a wall, a grain swallowed by another, or an overlap (with a wall or a grain) outside the
//! domain of the contact law is an error; overlaps inside the law's domain are accepted (a
//! compacted state has them, and the run starts with their contact forces). Candidate pairs come
//! from the cell-list broad phase, so the check is O(N).

use crate::boundary::walls::box_walls;
use crate::contact::SecantLaw;
use crate::geometry::broadphase::NeighborList;
use crate::geometry::{Contours, GrainShape, Overlap, PairHint};
use crate::grain::Grain;
use glam::DVec2;
use std::path::Path;

/// Columns of a sample file that become a grain's degrees of freedom, in headerless order.
pub const COLUMNS: [&str; 7] = ["x", "y", "radius", "theta", "eps1", "eps2", "alpha"];
/// Columns of sdem's `grains.csv` that a sample file may have and that are not read.
pub const IGNORED_COLUMNS: [&str; 6] = [
    "id",
    "stress_xx",
    "stress_yy",
    "stress_xy",
    "mean_stress_c",
    "contacts",
];

/// Grains read from a file, with the line each came from (1-based).
#[derive(Debug, Clone, PartialEq)]
pub struct FileGrains {
    pub grains: Vec<Grain>,
    pub lines: Vec<usize>,
}

/// Why a sample file cannot be used. Every message names the file and, where there is one, the
/// line (`file:line:`), the column or value, and what is allowed.
#[derive(Debug, thiserror::Error)]
pub enum SampleFileError {
    /// The file could not be read (the reason is the `source`).
    #[error("cannot read the sample file {path}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    /// A problem on one line (or with the header).
    #[error("{path}:{line}: {message}")]
    Line {
        path: String,
        line: usize,
        message: String,
    },
    /// A problem of two grains together.
    #[error("{path}:{line} and line {other_line}: {message}")]
    Pair {
        path: String,
        line: usize,
        other_line: usize,
        message: String,
    },
    /// No grain at all.
    #[error(
        "{path}: the sample file has no grains (no data line); a sample needs at least one grain"
    )]
    Empty { path: String },
}

fn allowed_columns() -> String {
    format!(
        "x, y, radius (required), theta, eps1, eps2, alpha (optional, 0 when absent); ignored: {}",
        IGNORED_COLUMNS.join(", ")
    )
}

/// Reads the grains of a sample file and checks every line on its own (see the module docs).
pub fn read_grains(path: &Path) -> Result<FileGrains, SampleFileError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| SampleFileError::Io {
        path: name.clone(),
        source,
    })?;
    parse_grains(&text, &name)
}

/// [`read_grains`] on text already read; `path` only names the file in errors.
pub fn parse_grains(text: &str, path: &str) -> Result<FileGrains, SampleFileError> {
    let at = |line: usize, message: String| SampleFileError::Line {
        path: path.to_string(),
        line,
        message,
    };
    // For each field of a line: the DoF it sets (index into COLUMNS), or None (ignored).
    let mut layout: Option<Vec<Option<usize>>> = None;
    let mut out = FileGrains {
        grains: Vec::new(),
        lines: Vec::new(),
    };
    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let content = raw.trim();
        if content.is_empty() || content.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = content.split(',').map(str::trim).collect();
        let fields_layout = match &layout {
            Some(l) => l,
            None => {
                let numbers = fields.iter().filter(|f| f.parse::<f64>().is_ok()).count();
                let is_header = numbers == 0;
                let l = if is_header {
                    header_layout(&fields).map_err(|m| at(line, m))?
                } else if numbers < fields.len() {
                    return Err(at(
                        line,
                        format!(
                            "the first line {content:?} is neither a header (column names) nor a \
                             grain (numbers only)"
                        ),
                    ));
                } else if (3..=COLUMNS.len()).contains(&fields.len()) {
                    (0..fields.len()).map(Some).collect()
                } else {
                    return Err(at(
                        line,
                        format!(
                            "{} fields without a header line: expected x,y,radius and optionally \
                             theta,eps1,eps2,alpha (3 to 7 fields), or a header naming the columns",
                            fields.len()
                        ),
                    ));
                };
                layout = Some(l);
                if is_header {
                    continue;
                }
                layout.as_ref().expect("just set")
            }
        };
        if fields.len() != fields_layout.len() {
            return Err(at(
                line,
                format!(
                    "{} fields, expected {} (one per column)",
                    fields.len(),
                    fields_layout.len()
                ),
            ));
        }
        let mut dof = [0.0f64; 7];
        for (field, slot) in fields.iter().zip(fields_layout) {
            let Some(c) = *slot else { continue };
            let value: f64 = field.parse().map_err(|_| {
                at(
                    line,
                    format!("`{}` = {field:?} is not a number", COLUMNS[c]),
                )
            })?;
            dof[c] = value;
        }
        let [x, y, radius, theta, eps1, eps2, alpha] = dof;
        for (c, v) in dof.iter().enumerate() {
            if !v.is_finite() {
                return Err(at(
                    line,
                    format!("`{}` = {v}: must be a finite number", COLUMNS[c]),
                ));
            }
        }
        if radius <= 0.0 {
            return Err(at(line, format!("`radius` = {radius}: must be > 0")));
        }
        for (c, v) in [(4, eps1), (5, eps2)] {
            if v <= -1.0 {
                return Err(at(
                    line,
                    format!(
                        "`{}` = {v}: must be > -1 (a principal stretch 1 + eps > 0)",
                        COLUMNS[c]
                    ),
                ));
            }
        }
        out.grains.push(Grain {
            radius,
            center: DVec2::new(x, y),
            theta,
            eps1,
            eps2,
            alpha,
            ..Default::default()
        });
        out.lines.push(line);
    }
    if out.grains.is_empty() {
        return Err(SampleFileError::Empty {
            path: path.to_string(),
        });
    }
    Ok(out)
}

/// The layout of a header line.
fn header_layout(names: &[&str]) -> Result<Vec<Option<usize>>, String> {
    let mut layout = Vec::with_capacity(names.len());
    for (k, name) in names.iter().enumerate() {
        if names[..k].contains(name) {
            return Err(format!("column `{name}` appears twice in the header"));
        }
        if let Some(c) = COLUMNS.iter().position(|c| c == name) {
            layout.push(Some(c));
        } else if IGNORED_COLUMNS.contains(name) {
            layout.push(None);
        } else {
            return Err(format!(
                "unknown column `{name}` in the header; the columns are {}",
                allowed_columns()
            ));
        }
    }
    for required in &COLUMNS[..3] {
        if !names.contains(required) {
            return Err(format!(
                "the header has no `{required}` column; the columns are {}",
                allowed_columns()
            ));
        }
    }
    Ok(layout)
}

/// The box `[x0, x1] x [y0, y1]` a sample must fit in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxBounds {
    pub x0: f64,
    pub x1: f64,
    pub y0: f64,
    pub y1: f64,
}

fn num(x: f64) -> String {
    format!("{x:.6e}")
}

/// Checks grains read from `path` against the box and each other (see the module docs), with the
/// run's contact law and contour resolution.
pub fn check_packing(
    path: &str,
    sample: &FileGrains,
    bounds: BoxBounds,
    law: &SecantLaw,
    resolution_deg: f64,
) -> Result<(), SampleFileError> {
    let contours = Contours::new(resolution_deg);
    let shapes: Vec<GrainShape> = sample.grains.iter().map(Grain::shape).collect();
    let at = |g: usize, message: String| SampleFileError::Line {
        path: path.to_string(),
        line: sample.lines[g],
        message,
    };
    let walls = box_walls(bounds.x0, bounds.x1, bounds.y0, bounds.y1);
    let wall_names = [
        format!("left wall x = {}", bounds.x0),
        format!("right wall x = {}", bounds.x1),
        format!("bottom wall y = {}", bounds.y0),
        format!("top wall y = {}", bounds.y1),
    ];
    let box_text = format!(
        "the box [{}, {}] x [{}, {}] (sample.origin, sample.box_width, sample.box_height)",
        bounds.x0, bounds.x1, bounds.y0, bounds.y1
    );
    for (g, shape) in shapes.iter().enumerate() {
        let c = shape.center;
        if !(c.x > bounds.x0 && c.x < bounds.x1 && c.y > bounds.y0 && c.y < bounds.y1) {
            return Err(at(
                g,
                format!("grain centre ({}, {}) is outside {box_text}", c.x, c.y),
            ));
        }
        for (w, wall) in walls.iter().enumerate() {
            match contours.grain_wall(shape, wall.point, wall.normal) {
                Overlap::Separate => {}
                Overlap::Swallowed => {
                    return Err(at(
                        g,
                        format!(
                            "the grain (radius {}) lies wholly beyond the {} of {box_text}",
                            sample.grains[g].radius, wall_names[w]
                        ),
                    ));
                }
                Overlap::Contact(contact) => {
                    if let Err(exit) = law.response(contact.length, contact.normal_gap) {
                        return Err(at(
                            g,
                            format!(
                                "the grain (radius {}) crosses the {} of {box_text} by {}, \
                                 beyond the domain of the contact law (L_c = {}, delta_n = {}: \
                                 a L_c + (b-1) delta_n must stay above contact.domain_floor x a L_c); \
                                 move it inside or enlarge the box",
                                sample.grains[g].radius,
                                wall_names[w],
                                num(-exit.normal_gap),
                                num(exit.length),
                                num(exit.normal_gap)
                            ),
                        ));
                    }
                }
            }
        }
    }
    let centers: Vec<DVec2> = shapes.iter().map(|s| s.center).collect();
    let reach: Vec<f64> = shapes.iter().map(|s| s.bounding_radius).collect();
    let mut list = NeighborList::new(0.0);
    list.build(&centers, &reach);
    for &[i, j] in &list.pairs {
        let (i, j) = (i as usize, j as usize);
        let pair = |message: String| SampleFileError::Pair {
            path: path.to_string(),
            line: sample.lines[i],
            other_line: sample.lines[j],
            message,
        };
        // A centre inside the other grain's contour: far deeper than any packing gets (a cap
        // reaching past the centre), and two copies of one grain, whose contours lie on each
        // other and cross nowhere, are caught here too.
        let inside =
            |a: &GrainShape, b: &GrainShape| contours.contains(b.inv_map() * (a.center - b.center));
        if inside(&shapes[i], &shapes[j]) || inside(&shapes[j], &shapes[i]) {
            return Err(pair(format!(
                "the grains (radii {} and {}, centres {} apart) overlap so much that a centre \
                 lies inside the other grain{}",
                sample.grains[i].radius,
                sample.grains[j].radius,
                num(centers[i].distance(centers[j])),
                if centers[i] == centers[j] {
                    " (the same centre: a duplicated line?)"
                } else {
                    ""
                }
            )));
        }
        match contours.grain_grain(&shapes[i], &shapes[j], &mut PairHint::default()) {
            Overlap::Separate => {}
            Overlap::Swallowed => {
                return Err(pair(format!(
                    "one grain lies inside the other (radii {} and {}, centres {} apart): their \
                     contours do not cross, the contact law is undefined",
                    sample.grains[i].radius,
                    sample.grains[j].radius,
                    num(centers[i].distance(centers[j]))
                )));
            }
            Overlap::Contact(contact) => {
                if let Err(exit) = law.response(contact.length, contact.normal_gap) {
                    return Err(pair(format!(
                        "the grains (radii {} and {}) overlap beyond the domain of the contact \
                         law (L_c = {}, delta_n = {}: a L_c + (b-1) delta_n must stay above \
                         contact.domain_floor x a L_c); overlaps of a compacted packing are \
                         accepted, this one is too deep",
                        sample.grains[i].radius,
                        sample.grains[j].radius,
                        num(exit.length),
                        num(exit.normal_gap)
                    )));
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headerless_and_named_columns() {
        let a = parse_grains("0.5,0.5,0.1,0\n\n# c\n0.2, 0.3, 0.05, 1.0\n", "a").unwrap();
        assert_eq!(a.lines, vec![1, 4]);
        assert_eq!(a.grains[1].theta, 1.0);
        let b = parse_grains("id,radius,y,x,eps2\n0,0.1,0.3,0.2,-0.1\n", "b").unwrap();
        let g = b.grains[0];
        assert_eq!(
            (g.center.x, g.center.y, g.radius, g.eps2),
            (0.2, 0.3, 0.1, -0.1)
        );
        assert_eq!(b.lines, vec![2]);
    }
}
