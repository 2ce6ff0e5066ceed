//! VTK export for ParaView: one XML PolyData file (`.vtp`) per frame and per part, and one
//! ParaView Data collection (`.pvd`) per part listing them with their simulated times.
//!
//! `DIR/grains.pvd`, `DIR/contacts.pvd` (SDEM frames only) and `DIR/boundary.pvd` each open in
//! ParaView as a time series (File > Open, no plugin); the `.vtp` files are in `DIR/vtp/`.
//!
//! | part | geometry | cell data |
//! | --- | --- | --- |
//! | grains | one polygon per grain: the deformed contour cut flat along its contacts (SDEM), or the boundary nodes of its contour (meshfree) | `id`, `radius`, `mean_stress_c`, `von_mises`, `stress` (xx, yy, xy, tension positive), the six DoF `x`, `y`, `theta`, `eps1`, `eps2`, `alpha`, `level`, `contacts` |
//! | contacts | one line per grain–grain contact, between the two centres | `first`, `second`, `normal_force`, `tangential_force`, `length` |
//! | boundary | the four walls (or the periodic cell's sides) as lines | `wall` (0 left, 1 right, 2 bottom, 3 top), `velocity` |
//!
//! Every data array is little-endian binary, zlib-compressed in 32 KiB blocks and base64-encoded
//! inline (`format="binary"`, `compressor="vtkZLibDataCompressor"`, `header_type="UInt64"`):
//! the standard layout of VTK's own XML writers, read by ParaView and the `vtk` Python package.
//!
//! Points are single precision (as ParaView keeps them), cell data double. Units are the
//! scenario's. `normal_force` is compression positive (the magnitude of the
//! repulsive normal force); `tangential_force` is signed along `perp(normal)` of the pair's
//! first grain and zero without friction. `von_mises` is that of the plane-stress tensor
//! `sqrt(sxx² - sxx syy + syy² + 3 sxy²)`. `level` is the grain model level (0 rigid,
//! 1 volumetric, 2 full) where the frame knows it, -1 where not (a meshfree grain, or an
//! adaptive run read back from a log, which does not store the level of each grain).

use crate::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP, Wall};
use crate::output::frame::outline::{frame_cuts, grain_outline};
use crate::output::frame::{Frame, FrameContour, FrameGrain};
use flate2::Compression;
use flate2::write::ZlibEncoder;
use glam::DVec2;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Nodes of the contour polygon of an SDEM grain before its flat contact cuts (one every 3°).
pub const DEFAULT_OUTLINE_NODES: usize = 120;

/// Errors of the VTK export.
#[derive(Debug, thiserror::Error)]
pub enum VtkError {
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("frame at step {step}: {reason}")]
    BadFrame { step: u64, reason: String },
}

/// How to export.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VtkOptions {
    /// Nodes of an SDEM grain's contour polygon (see [`DEFAULT_OUTLINE_NODES`]).
    pub outline_nodes: usize,
}

impl Default for VtkOptions {
    fn default() -> Self {
        Self {
            outline_nodes: DEFAULT_OUTLINE_NODES,
        }
    }
}

/// The parts of a frame, each its own `.pvd` series.
const PARTS: [&str; 3] = ["grains", "contacts", "boundary"];

/// Writes frames as `.vtp` files and keeps the `.pvd` collections up to date (rewritten after
/// each frame, so that the files of an interrupted run still open).
pub struct VtkWriter {
    dir: PathBuf,
    options: VtkOptions,
    /// Per part: (time, file name relative to `dir`) of its frames.
    series: [Vec<(f64, String)>; 3],
    frames: usize,
}

/// What an export wrote.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct VtkSummary {
    pub frames: usize,
    /// The `.pvd` files written.
    pub collections: Vec<PathBuf>,
    /// Bytes of all files written.
    pub bytes: u64,
}

impl VtkWriter {
    /// Creates `dir` and `dir/vtp`.
    pub fn create(dir: impl Into<PathBuf>, options: VtkOptions) -> Result<Self, VtkError> {
        let dir = dir.into();
        let sub = dir.join("vtp");
        std::fs::create_dir_all(&sub).map_err(|error| VtkError::Io {
            path: sub.display().to_string(),
            error,
        })?;
        Ok(Self {
            dir,
            options,
            series: Default::default(),
            frames: 0,
        })
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Writes one frame: its grains, contacts (SDEM) and boundary, then the collections.
    pub fn write_frame(&mut self, frame: &Frame) -> Result<(), VtkError> {
        frame.check().map_err(|reason| VtkError::BadFrame {
            step: frame.step,
            reason,
        })?;
        let k = self.frames;
        let mut parts: Vec<(usize, PolyData)> = vec![(0, grains_part(frame, &self.options))];
        if frame.contours.is_none() {
            parts.push((1, contacts_part(frame)));
        }
        parts.push((2, boundary_part(frame)));
        for (part, poly) in parts {
            let name = format!("vtp/{}_{k:06}.vtp", PARTS[part]);
            let text = poly.to_xml(frame.time, frame.step);
            self.write_file(&name, text.as_bytes())?;
            self.series[part].push((frame.time, name));
        }
        self.frames += 1;
        self.write_collections()?;
        Ok(())
    }

    /// Ends the export; returns what it wrote.
    pub fn finish(self) -> Result<VtkSummary, VtkError> {
        let mut summary = VtkSummary {
            frames: self.frames,
            ..Default::default()
        };
        for (part, series) in PARTS.iter().zip(&self.series) {
            if series.is_empty() {
                continue;
            }
            summary
                .collections
                .push(self.dir.join(format!("{part}.pvd")));
            for (_, name) in series {
                summary.bytes += file_size(&self.dir.join(name));
            }
            summary.bytes += file_size(&self.dir.join(format!("{part}.pvd")));
        }
        Ok(summary)
    }

    fn write_collections(&self) -> Result<(), VtkError> {
        for (part, series) in PARTS.iter().zip(&self.series) {
            if series.is_empty() {
                continue;
            }
            let mut text = String::from(
                "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <Collection>\n",
            );
            for (time, name) in series {
                let _ = writeln!(
                    text,
                    "    <DataSet timestep=\"{time:e}\" group=\"\" part=\"0\" file=\"{name}\"/>"
                );
            }
            text.push_str("  </Collection>\n</VTKFile>\n");
            self.write_file(&format!("{part}.pvd"), text.as_bytes())?;
        }
        Ok(())
    }

    fn write_file(&self, name: &str, bytes: &[u8]) -> Result<(), VtkError> {
        let path = self.dir.join(name);
        std::fs::write(&path, bytes).map_err(|error| VtkError::Io {
            path: path.display().to_string(),
            error,
        })
    }
}

fn file_size(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
}

// ---------------------------------------------------------------------------------------------
// The parts of a frame
// ---------------------------------------------------------------------------------------------

/// Von Mises stress of a plane-stress tensor (xx, yy, xy).
fn von_mises(s: [f64; 3]) -> f64 {
    (s[0] * s[0] - s[0] * s[1] + s[1] * s[1] + 3.0 * s[2] * s[2])
        .max(0.0)
        .sqrt()
}

/// Contacts of each grain in the frame.
fn contact_counts(frame: &Frame) -> Vec<i32> {
    let mut counts = vec![0i32; frame.grain_count()];
    for c in &frame.contacts {
        counts[c.first as usize] += 1;
        counts[c.second as usize] += 1;
    }
    counts
}

fn grains_part(frame: &Frame, options: &VtkOptions) -> PolyData {
    match &frame.contours {
        Some(contours) => contour_grains(contours),
        None => ellipse_grains(frame, options),
    }
}

/// SDEM grains: each contour polygon cut flat along its contacts and the walls, as `render`
/// draws it.
fn ellipse_grains(frame: &Frame, options: &VtkOptions) -> PolyData {
    let cuts = frame_cuts(frame);
    let mut poly = PolyData::default();
    for (g, cut) in frame.grains.iter().zip(&cuts) {
        let outline = grain_outline(g, options.outline_nodes, cut);
        poly.add_cell(CellKind::Poly, &outline);
    }
    let column =
        |f: fn(&FrameGrain) -> f64| -> Values { Values::F64(frame.grains.iter().map(f).collect()) };
    let n = frame.grains.len();
    poly.cell_data = vec![
        DataArray::new("id", 1, Values::I32((0..n as i32).collect())),
        DataArray::new("radius", 1, column(|g| g.radius)),
        DataArray::new("mean_stress_c", 1, column(|g| g.mean_stress_c())),
        DataArray::new("von_mises", 1, column(|g| von_mises(g.stress))),
        DataArray::new(
            "stress",
            3,
            Values::F64(frame.grains.iter().flat_map(|g| g.stress).collect()),
        ),
        DataArray::new("x", 1, column(|g| g.center.x)),
        DataArray::new("y", 1, column(|g| g.center.y)),
        DataArray::new("theta", 1, column(|g| g.theta)),
        DataArray::new("eps1", 1, column(|g| g.eps1)),
        DataArray::new("eps2", 1, column(|g| g.eps2)),
        DataArray::new("alpha", 1, column(|g| g.alpha)),
        DataArray::new(
            "level",
            1,
            Values::I32(match &frame.levels {
                Some(l) if l.len() == n => l.iter().map(|&l| l as i32).collect(),
                _ => vec![-1; n],
            }),
        ),
        DataArray::new("contacts", 1, Values::I32(contact_counts(frame))),
    ];
    poly
}

/// Meshfree grains: the polygons of their boundary nodes.
fn contour_grains(contours: &[FrameContour]) -> PolyData {
    let mut poly = PolyData::default();
    for c in contours {
        poly.add_cell(CellKind::Poly, &c.points);
    }
    let n = contours.len();
    poly.cell_data = vec![
        DataArray::new(
            "id",
            1,
            Values::I32(contours.iter().map(|c| c.grain as i32).collect()),
        ),
        DataArray::new(
            "radius",
            1,
            Values::F64(contours.iter().map(|c| c.equivalent_radius()).collect()),
        ),
        DataArray::new(
            "mean_stress_c",
            1,
            Values::F64(contours.iter().map(|c| c.mean_stress_c).collect()),
        ),
        DataArray::new(
            "von_mises",
            1,
            Values::F64(contours.iter().map(|c| von_mises(c.stress)).collect()),
        ),
        DataArray::new(
            "stress",
            3,
            Values::F64(contours.iter().flat_map(|c| c.stress).collect()),
        ),
        DataArray::new("level", 1, Values::I32(vec![-1; n])),
    ];
    poly
}

/// The contact network: a line from the first grain's centre to the second's (in a periodic
/// cell, to the image of the second nearest the first).
fn contacts_part(frame: &Frame) -> PolyData {
    let mut poly = PolyData::default();
    for c in &frame.contacts {
        let a = frame.grains[c.first as usize].center;
        let mut b = frame.grains[c.second as usize].center;
        if let Some(cell) = &frame.cell {
            b = a + cell.minimum_image(b - a).0;
        }
        poly.add_cell(CellKind::Line, &[a, b]);
    }
    let column = |f: fn(&crate::output::frame::FrameContact) -> f64| -> Values {
        Values::F64(frame.contacts.iter().map(f).collect())
    };
    poly.cell_data = vec![
        DataArray::new(
            "first",
            1,
            Values::I32(frame.contacts.iter().map(|c| c.first as i32).collect()),
        ),
        DataArray::new(
            "second",
            1,
            Values::I32(frame.contacts.iter().map(|c| c.second as i32).collect()),
        ),
        DataArray::new("normal_force", 1, column(|c| -c.force)),
        DataArray::new("tangential_force", 1, column(|c| c.tangential_force)),
        DataArray::new("length", 1, column(|c| c.length)),
    ];
    poly
}

/// The box (or periodic cell) as four lines through the corners of its four walls; further
/// planes are not drawn.
fn boundary_part(frame: &Frame) -> PolyData {
    let mut poly = PolyData::default();
    let walls: &[Wall] = &frame.walls;
    if walls.len() >= 4 {
        let (x0, x1) = (walls[LEFT].point.x, walls[RIGHT].point.x);
        let (y0, y1) = (walls[BOTTOM].point.y, walls[TOP].point.y);
        // A sheared periodic cell: the sides along h2 = (tilt, height).
        let n = walls[LEFT].normal;
        let shift = if n.y != 0.0 {
            -n.y / n.x * (y1 - y0)
        } else {
            0.0
        };
        let (a, b) = (DVec2::new(x0, y0), DVec2::new(x1, y0));
        let (c, d) = (DVec2::new(x1 + shift, y1), DVec2::new(x0 + shift, y1));
        // In the order of the walls: left, right, bottom, top.
        for side in [[a, d], [b, c], [a, b], [d, c]] {
            poly.add_cell(CellKind::Line, &side);
        }
        poly.cell_data = vec![
            DataArray::new("wall", 1, Values::I32(vec![0, 1, 2, 3])),
            DataArray::new(
                "velocity",
                3,
                Values::F64(
                    [LEFT, RIGHT, BOTTOM, TOP]
                        .iter()
                        .flat_map(|&w| [walls[w].velocity.x, walls[w].velocity.y, 0.0])
                        .collect(),
                ),
            ),
        ];
    }
    poly
}

// ---------------------------------------------------------------------------------------------
// XML PolyData
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy, PartialEq)]
enum CellKind {
    Line,
    Poly,
}

/// Values of a data array, of a VTK type.
#[derive(Debug, Clone, PartialEq)]
enum Values {
    F32(Vec<f32>),
    F64(Vec<f64>),
    I32(Vec<i32>),
    I64(Vec<i64>),
}

impl Values {
    fn vtk_type(&self) -> &'static str {
        match self {
            Values::F32(_) => "Float32",
            Values::F64(_) => "Float64",
            Values::I32(_) => "Int32",
            Values::I64(_) => "Int64",
        }
    }

    fn len(&self) -> usize {
        match self {
            Values::F32(v) => v.len(),
            Values::F64(v) => v.len(),
            Values::I32(v) => v.len(),
            Values::I64(v) => v.len(),
        }
    }

    fn le_bytes(&self) -> Vec<u8> {
        match self {
            Values::F32(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Values::F64(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Values::I32(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            Values::I64(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
struct DataArray {
    name: &'static str,
    components: usize,
    values: Values,
}

impl DataArray {
    fn new(name: &'static str, components: usize, values: Values) -> Self {
        Self {
            name,
            components,
            values,
        }
    }
}

/// Points in the plane z = 0 and the lines and polygons through them.
#[derive(Debug, Clone, PartialEq, Default)]
struct PolyData {
    points: Vec<DVec2>,
    lines: Cells,
    polys: Cells,
    cell_data: Vec<DataArray>,
}

/// Cells as VTK stores them: the point ids of all cells, and where each cell ends.
#[derive(Debug, Clone, PartialEq, Default)]
struct Cells {
    connectivity: Vec<i64>,
    offsets: Vec<i64>,
}

impl PolyData {
    fn add_cell(&mut self, kind: CellKind, points: &[DVec2]) {
        let first = self.points.len() as i64;
        self.points.extend_from_slice(points);
        let cells = match kind {
            CellKind::Line => &mut self.lines,
            CellKind::Poly => &mut self.polys,
        };
        cells
            .connectivity
            .extend(first..first + points.len() as i64);
        cells.offsets.push(cells.connectivity.len() as i64);
    }

    /// The `.vtp` file, with the frame's time and step as field data.
    fn to_xml(&self, time: f64, step: u64) -> String {
        let mut x = String::with_capacity(1024 + self.points.len() * 40);
        x.push_str("<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\">\n<PolyData>\n<FieldData>\n");
        data_array(&mut x, "TimeValue", 1, &Values::F64(vec![time]), true);
        data_array(&mut x, "step", 1, &Values::I64(vec![step as i64]), true);
        x.push_str("</FieldData>\n");
        let _ = writeln!(
            x,
            "<Piece NumberOfPoints=\"{}\" NumberOfVerts=\"0\" NumberOfLines=\"{}\" NumberOfStrips=\"0\" NumberOfPolys=\"{}\">",
            self.points.len(),
            self.lines.offsets.len(),
            self.polys.offsets.len()
        );
        let scalars = if self.cell_data.iter().any(|a| a.name == "mean_stress_c") {
            " Scalars=\"mean_stress_c\""
        } else {
            ""
        };
        let _ = writeln!(x, "<CellData{scalars}>");
        for a in &self.cell_data {
            data_array(&mut x, a.name, a.components, &a.values, false);
        }
        x.push_str("</CellData>\n<Points>\n");
        // Single precision, as ParaView keeps points: 1e-7 of the box is far below a grain's
        // size, and it halves the files (the cell data stay double).
        let xyz: Vec<f32> = self
            .points
            .iter()
            .flat_map(|p| [p.x as f32, p.y as f32, 0.0])
            .collect();
        data_array(&mut x, "Points", 3, &Values::F32(xyz), false);
        x.push_str("</Points>\n");
        for (tag, cells) in [("Lines", &self.lines), ("Polys", &self.polys)] {
            let _ = writeln!(x, "<{tag}>");
            data_array(
                &mut x,
                "connectivity",
                1,
                &Values::I64(cells.connectivity.clone()),
                false,
            );
            data_array(
                &mut x,
                "offsets",
                1,
                &Values::I64(cells.offsets.clone()),
                false,
            );
            let _ = writeln!(x, "</{tag}>");
        }
        x.push_str("</Piece>\n</PolyData>\n</VTKFile>\n");
        x
    }
}

/// Block size of the zlib-compressed data (that of VTK's own writers).
const BLOCK: usize = 32768;

/// One `<DataArray>`: compressed binary, or ascii when empty (a compressed array needs at least
/// one block).
fn data_array(out: &mut String, name: &str, components: usize, values: &Values, field: bool) {
    let tuples = if field {
        format!(" NumberOfTuples=\"{}\"", values.len() / components.max(1))
    } else {
        String::new()
    };
    let head = format!(
        "<DataArray type=\"{}\" Name=\"{name}\" NumberOfComponents=\"{components}\"{tuples}",
        values.vtk_type()
    );
    if values.len() == 0 {
        let _ = writeln!(out, "{head} format=\"ascii\"></DataArray>");
        return;
    }
    let bytes = values.le_bytes();
    let blocks: Vec<Vec<u8>> = bytes.chunks(BLOCK).map(zlib).collect();
    let last = match bytes.len() % BLOCK {
        0 => BLOCK,
        r => r,
    };
    let mut header: Vec<u8> = Vec::with_capacity(8 * (3 + blocks.len()));
    for v in [blocks.len(), BLOCK, last]
        .into_iter()
        .chain(blocks.iter().map(|b| b.len()))
    {
        header.extend_from_slice(&(v as u64).to_le_bytes());
    }
    let _ = write!(out, "{head} format=\"binary\">");
    // The header and the data are base64-encoded separately, as VTK's writers do.
    base64(out, &header);
    base64(out, &blocks.concat());
    out.push_str("</DataArray>\n");
}

fn zlib(block: &[u8]) -> Vec<u8> {
    let mut e = ZlibEncoder::new(Vec::with_capacity(block.len() / 2), Compression::default());
    // Writing to a Vec cannot fail.
    let _ = e.write_all(block);
    e.finish().unwrap_or_default()
}

/// Standard base64 (RFC 4648) with padding.
fn base64(out: &mut String, bytes: &[u8]) {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (input, expected) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            let mut out = String::new();
            base64(&mut out, input.as_bytes());
            assert_eq!(out, expected, "{input}");
        }
    }

    #[test]
    fn von_mises_of_pure_shear_and_uniaxial_stress() {
        assert!((von_mises([2.0, 0.0, 0.0]) - 2.0).abs() < 1e-12);
        assert!((von_mises([0.0, 0.0, 1.0]) - 3f64.sqrt()).abs() < 1e-12);
        assert_eq!(von_mises([-1.0, -1.0, 0.0]), 1.0);
    }

    #[test]
    fn cells_end_where_their_points_end() {
        let mut p = PolyData::default();
        p.add_cell(CellKind::Poly, &[DVec2::ZERO, DVec2::X, DVec2::Y]);
        p.add_cell(CellKind::Line, &[DVec2::ZERO, DVec2::X]);
        p.add_cell(
            CellKind::Poly,
            &[DVec2::ZERO, DVec2::X, DVec2::ONE, DVec2::Y],
        );
        assert_eq!(p.points.len(), 9);
        assert_eq!(p.polys.offsets, [3, 7]);
        assert_eq!(p.polys.connectivity, [0, 1, 2, 5, 6, 7, 8]);
        assert_eq!(p.lines.offsets, [2]);
        assert_eq!(p.lines.connectivity, [3, 4]);
    }
}
