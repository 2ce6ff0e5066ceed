//! Trajectory logs in MCAP (<https://mcap.dev>): a writer hooked into the run loop and a reader
//! for `sdem inspect`, `sdem render`, `sdem plot`, tests and tools.
//!
//! One log holds, at every output interval of a run (every row of `macro.csv`), one message on
//! each channel below, all with the same `log_time`:
//!
//! | topic | schema (encoding) | message encoding | content |
//! | --- | --- | --- | --- |
//! | `/grains` | `sdem_msgs/msg/Grains` (ros2msg) | cdr | the six DoF, radius and Love–Weber stress of every grain, f64 |
//! | `/contacts` | `sdem_msgs/msg/Contacts` (ros2msg) | cdr | active grain–grain contacts: pair, point, normal, force, length, f32 |
//! | `/walls` | `sdem_msgs/msg/Walls` (ros2msg) | cdr | wall point, normal, velocity, f64 |
//! | `/macro` | `sdem_msgs/msg/Macro` (ros2msg) | cdr | the row of `macro.csv` |
//! | `/scene` | `foxglove.SceneUpdate` (jsonschema) | json | grains as flat ellipses (scaled cylinders) coloured by mean stress, and the box |
//!
//! A meshfree run (`model: Meshfree(...)`) writes `/contours` in place of `/grains` and
//! `/contacts`, with the same `/walls`, `/macro` and `/scene` (its metadata `sdem.run` has
//! `solver=meshfree`; see [`contours`] for the details):
//!
//! | topic | schema (encoding) | message encoding | content |
//! | --- | --- | --- | --- |
//! | `/contours` | `sdem_msgs/msg/Contours` (ros2msg) | cdr | per grain: id, mean Cauchy stress (tension positive), `mean_stress_c` (compression positive), point count; then the boundary nodes of all grains (x, y columns, counter-clockwise), f64 |
//! | `/scene` | `foxglove.SceneUpdate` (jsonschema) | json | each contour as a triangle fan filled with the colour of its mean stress, outlined by a line loop, and the box |
//!
//! A frame is a message on `/grains` (SDEM) or `/contours` (meshfree); [`Frame::contours`] is
//! `Some` for the latter, with [`Frame::grains`] and [`Frame::contacts`] empty.
//!
//! The bulk channels are little-endian CDR (XCDR1, `CDR_LE`) described by ROS 2 `.msg` schemas:
//! a standard, self-describing layout that Foxglove decodes natively and any reader can parse
//! from the schema text (see `tools/check_mcap.py`). Arrays are columns indexed by grain id (the
//! line order of `grains.csv`) or by contact. `/scene` is written every `scene_every`-th frame
//! only (it is ~5x the size of `/grains` once compressed).
//!
//! The scenario is attached as `scenario.ron` (the parsed scenario with every default filled in,
//! loadable by `Scenario::parse`); metadata record `sdem.run` describes the run and
//! `sdem.summary` (written when the log is finished) its outcome.
//!
//! `log_time` is the simulated time in nanoseconds, `round(time * 1e9)`, bumped by 1 ns when
//! needed to stay strictly increasing; every message also carries the exact `step` and `time`.
//! Nothing in a log comes from the wall clock: the same run gives the same bytes.

use crate::boundary::walls::Wall;
use crate::geometry::GrainShape;
use crate::grain::{Grain, Material};
use crate::integration::World;
use crate::output::measures::Measures;
use crate::scenario::Scenario;
use glam::DVec2;
use mcap::records::{self, Record};
use mcap::{Compression, WriteOptions};
use rayon::prelude::*;
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write as _};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

pub mod contours;
mod resume;
pub use contours::{
    CONTOUR_SCENE_SCHEMA, CONTOURS_MSG, ContourLogInfo, FrameContour, SCHEMA_CONTOURS,
    TOPIC_CONTOURS,
};
pub use resume::{ContinueFrom, Continued, LogScan, scan_log};

/// Version of the channel layout below; stored in the `sdem.run` metadata.
/// 2: `/macro` gained `grains_rigid`, `grains_volumetric`, `grains_full` (adaptive level).
pub const FORMAT_VERSION: &str = "2";

pub const TOPIC_GRAINS: &str = "/grains";
pub const TOPIC_CONTACTS: &str = "/contacts";
pub const TOPIC_WALLS: &str = "/walls";
pub const TOPIC_MACRO: &str = "/macro";
pub const TOPIC_SCENE: &str = "/scene";

pub const SCHEMA_GRAINS: &str = "sdem_msgs/msg/Grains";
pub const SCHEMA_CONTACTS: &str = "sdem_msgs/msg/Contacts";
pub const SCHEMA_WALLS: &str = "sdem_msgs/msg/Walls";
pub const SCHEMA_MACRO: &str = "sdem_msgs/msg/Macro";
pub const SCHEMA_SCENE: &str = "foxglove.SceneUpdate";

/// ROS 2 message definition of `/grains`.
pub const GRAINS_MSG: &str = "\
# sdem_msgs/msg/Grains: every grain at one output interval (sdem trajectory log, format 1).
# Arrays are indexed by grain id, the line order of grains.csv. Units: those of the scenario.
uint64 step
float64 time
float64[] x             # centre
float64[] y
float64[] theta         # rigid rotation (rad)
float64[] eps1          # principal strains: semi-axes R (1 + eps1), R (1 + eps2); tension positive
float64[] eps2
float64[] alpha         # orientation of e1 relative to the grain: e1 is at angle theta + alpha
float64[] radius        # reference radius R
float64[] stress_xx     # Love-Weber stress of the contact forces over the current area,
float64[] stress_yy     # global frame, TENSION positive; mean stress (compression positive)
float64[] stress_xy     # is -(stress_xx + stress_yy) / 2
";

/// ROS 2 message definition of `/contacts`.
pub const CONTACTS_MSG: &str = "\
# sdem_msgs/msg/Contacts: active grain-grain contacts of the step that ended at this frame.
uint64 step
float64 time
uint32[] first          # grain ids of the pair; the normal points from first to second
uint32[] second
float32[] point_x       # contact point x_c = (P + P')/2, P and P' where the contours cross
float32[] point_y
float32[] normal_x      # unit normal, perpendicular to the chord PP'
float32[] normal_y
float32[] force         # total normal force (<= 0: repulsive); force on first = force * normal
float32[] length        # chord length L_c = |PP'|
";

/// ROS 2 message definition of `/walls`.
pub const WALLS_MSG: &str = "\
# sdem_msgs/msg/Walls: the rigid walls (infinite lines); for a box: left, right, bottom, top.
uint64 step
float64 time
float64[] point_x       # a point of the wall line
float64[] point_y
float64[] normal_x      # unit normal pointing into the domain
float64[] normal_y
float64[] velocity_x
float64[] velocity_y
";

/// ROS 2 message definition of `/macro`.
pub const MACRO_MSG: &str = "\
# sdem_msgs/msg/Macro: one row of macro.csv (stresses COMPRESSION positive, suffix _c).
uint64 step
float64 time
string phase
float64 phi
float64 sxx_c
float64 syy_c
float64 p_c
float64 q_c
float64 z
float64 z_nr
float64 kinetic_energy
float64 elastic_energy
float64 inertial_number
float64 strain_rate
float64 box_width
float64 box_height
uint64 contacts
uint64 capped_contacts
uint64 grains_rigid
uint64 grains_volumetric
uint64 grains_full
float64 z_nr3
";

/// The subset of Foxglove's `foxglove.SceneUpdate` JSON schema that a `/scene` uses, as a
/// literal: `$what` closes its description, `$defs` are the definitions of primitives it adds
/// (whole lines) and `$triangles` the schema of an entity's `triangles`.
macro_rules! scene_schema {
    ($what:literal, $defs:literal, $triangles:literal) => {
        concat!(
            r##"{
  "title": "foxglove.SceneUpdate",
  "description": "An update to the entities displayed in a 3D scene (subset written by sdem"##,
            $what,
            r##")",
  "type": "object",
  "$defs": {
    "time": {"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}},
    "vector3": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}},
    "quaternion": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}},
    "pose": {"type": "object", "properties": {"position": {"$ref": "#/$defs/vector3"}, "orientation": {"$ref": "#/$defs/quaternion"}}},
    "color": {"type": "object", "properties": {"r": {"type": "number"}, "g": {"type": "number"}, "b": {"type": "number"}, "a": {"type": "number"}}},
    "cylinder": {"title": "foxglove.CylinderPrimitive", "type": "object", "properties": {"pose": {"$ref": "#/$defs/pose"}, "size": {"$ref": "#/$defs/vector3"}, "bottom_scale": {"type": "number"}, "top_scale": {"type": "number"}, "color": {"$ref": "#/$defs/color"}}},
"##,
            $defs,
            r##"    "line": {"title": "foxglove.LinePrimitive", "type": "object", "properties": {"type": {"type": "integer"}, "pose": {"$ref": "#/$defs/pose"}, "thickness": {"type": "number"}, "scale_invariant": {"type": "boolean"}, "points": {"type": "array", "items": {"$ref": "#/$defs/vector3"}}, "color": {"$ref": "#/$defs/color"}, "colors": {"type": "array", "items": {"$ref": "#/$defs/color"}}, "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}}}}
  },
  "properties": {
    "deletions": {"type": "array", "items": {"type": "object"}},
    "entities": {"type": "array", "items": {"title": "foxglove.SceneEntity", "type": "object", "properties": {
      "timestamp": {"$ref": "#/$defs/time"},
      "frame_id": {"type": "string"},
      "id": {"type": "string"},
      "lifetime": {"$ref": "#/$defs/time"},
      "frame_locked": {"type": "boolean"},
      "metadata": {"type": "array", "items": {"type": "object", "properties": {"key": {"type": "string"}, "value": {"type": "string"}}}},
      "arrows": {"type": "array"}, "cubes": {"type": "array"}, "spheres": {"type": "array"},
      "cylinders": {"type": "array", "items": {"$ref": "#/$defs/cylinder"}},
      "lines": {"type": "array", "items": {"$ref": "#/$defs/line"}},
      "triangles": "##,
            $triangles,
            r##", "texts": {"type": "array"}, "models": {"type": "array"}
    }}}
  }
}
"##
        )
    };
}
use scene_schema;

/// The subset of Foxglove's `foxglove.SceneUpdate` JSON schema that `/scene` uses (entities
/// made of cylinders and lines).
pub const SCENE_SCHEMA: &str = scene_schema!(": cylinders and lines", "", r#"{"type": "array"}"#);

/// Errors of the trajectory writer.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: MCAP writer: {error}")]
    Mcap {
        path: String,
        error: mcap::McapError,
    },
    /// An existing log cannot be continued from a checkpoint (see
    /// [`TrajectoryWriter::continue_log`]).
    #[error("{path}: cannot continue this trajectory log: {reason}")]
    Continue { path: String, reason: String },
}

impl From<WriteError> for std::io::Error {
    fn from(e: WriteError) -> Self {
        match e {
            WriteError::Io { error, .. } => error,
            // A full disk while writing the log: the I/O error itself (the caller names the file).
            WriteError::Mcap {
                error: mcap::McapError::Io(error),
                ..
            } => error,
            other => std::io::Error::other(other.to_string()),
        }
    }
}

/// Errors of the trajectory reader: every way a file can be missing, truncated or corrupt ends
/// here, with the file named.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error(
        "{path}: not a complete MCAP file ({reason}); a log whose run was killed has no summary section at its end"
    )]
    Incomplete { path: String, reason: String },
    #[error("{path}: corrupt MCAP file: {reason}")]
    Corrupt { path: String, reason: String },
    #[error("{path}: {reason}")]
    NotATrajectory { path: String, reason: String },
    #[error("{path}: frame {frame} out of range: the log holds {frames} frames")]
    NoSuchFrame {
        path: String,
        frame: i64,
        frames: usize,
    },
}

// ---------------------------------------------------------------------------------------------
// CDR (XCDR1, little endian) encoding
// ---------------------------------------------------------------------------------------------

/// Serializer of plain CDR (the encoding of ROS 2 messages), little endian.
struct CdrWriter<'a> {
    buf: &'a mut Vec<u8>,
}

impl<'a> CdrWriter<'a> {
    fn new(buf: &'a mut Vec<u8>) -> Self {
        buf.clear();
        // Encapsulation header: CDR_LE.
        buf.extend_from_slice(&[0, 1, 0, 0]);
        Self { buf }
    }

    /// Pads to a multiple of `n` counted from the end of the encapsulation header.
    fn align(&mut self, n: usize) {
        let pad = (n - (self.buf.len() - 4) % n) % n;
        self.buf.extend(std::iter::repeat_n(0u8, pad));
    }

    fn u64(&mut self, v: u64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// A sequence: its length, then (for a non-empty one) padding to the element size and the
    /// elements. Empty sequences get no padding, as in Fast-CDR and the Foxglove/Python readers.
    fn f64_seq(&mut self, n: usize, values: impl Iterator<Item = f64>) {
        self.u32(n as u32);
        if n > 0 {
            self.align(8);
        }
        self.buf.reserve(8 * n);
        let mut count = 0;
        for v in values {
            self.buf.extend_from_slice(&v.to_le_bytes());
            count += 1;
        }
        debug_assert_eq!(count, n);
    }

    fn f32_seq(&mut self, n: usize, values: impl Iterator<Item = f32>) {
        self.u32(n as u32);
        self.buf.reserve(4 * n);
        for v in values {
            self.buf.extend_from_slice(&v.to_le_bytes());
        }
    }

    fn u32_seq(&mut self, n: usize, values: impl Iterator<Item = u32>) {
        self.u32(n as u32);
        self.buf.reserve(4 * n);
        for v in values {
            self.buf.extend_from_slice(&v.to_le_bytes());
        }
    }
}

/// Deserializer of plain CDR, little endian, with every read bounds-checked.
struct CdrReader<'a> {
    data: &'a [u8],
    pos: usize,
}

type CdrResult<T> = Result<T, String>;

impl<'a> CdrReader<'a> {
    fn new(data: &'a [u8]) -> CdrResult<Self> {
        if data.len() < 4 {
            return Err("message shorter than its CDR header".into());
        }
        if data[1] != 1 {
            return Err(format!(
                "unsupported CDR encapsulation kind {} (expected 1, CDR_LE)",
                data[1]
            ));
        }
        Ok(Self { data, pos: 4 })
    }

    fn align(&mut self, n: usize) {
        self.pos += (n - (self.pos - 4) % n) % n;
    }

    /// Bytes left after the current position.
    fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    fn take(&mut self, n: usize) -> CdrResult<&'a [u8]> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or_else(|| {
                format!(
                    "message ends at byte {} of {}",
                    self.data.len(),
                    self.pos + n
                )
            })?;
        let bytes = &self.data[self.pos..end];
        self.pos = end;
        Ok(bytes)
    }

    fn u64(&mut self) -> CdrResult<u64> {
        self.align(8);
        Ok(u64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }

    fn f64(&mut self) -> CdrResult<f64> {
        self.align(8);
        Ok(f64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }

    fn u32(&mut self) -> CdrResult<u32> {
        self.align(4);
        Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }

    fn string(&mut self) -> CdrResult<String> {
        let n = self.u32()? as usize;
        let bytes = self.take(n)?;
        let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        String::from_utf8(text.to_vec()).map_err(|_| "string is not UTF-8".to_string())
    }

    /// Length of a sequence of `size`-byte elements, checked against the bytes left.
    fn seq_len(&mut self, size: usize) -> CdrResult<usize> {
        let n = self.u32()? as usize;
        if n > 0 {
            self.align(size);
        }
        if n.saturating_mul(size) > self.data.len().saturating_sub(self.pos) {
            return Err(format!(
                "sequence of {n} elements runs past the message end"
            ));
        }
        Ok(n)
    }

    fn f64_seq(&mut self) -> CdrResult<Vec<f64>> {
        let n = self.seq_len(8)?;
        let bytes = self.take(8 * n)?;
        Ok(bytes
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
            .collect())
    }

    fn f32_seq(&mut self) -> CdrResult<Vec<f32>> {
        let n = self.seq_len(4)?;
        let bytes = self.take(4 * n)?;
        Ok(bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect())
    }

    fn u32_seq(&mut self) -> CdrResult<Vec<u32>> {
        let n = self.seq_len(4)?;
        let bytes = self.take(4 * n)?;
        Ok(bytes
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes(b.try_into().unwrap()))
            .collect())
    }
}

// ---------------------------------------------------------------------------------------------
// What a frame holds
// ---------------------------------------------------------------------------------------------

/// One grain as logged: its six DoF, radius and Love–Weber stress (tension positive).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameGrain {
    pub center: DVec2,
    pub radius: f64,
    pub theta: f64,
    pub eps1: f64,
    pub eps2: f64,
    pub alpha: f64,
    /// (xx, yy, xy), global frame, tension positive.
    pub stress: [f64; 3],
}

impl FrameGrain {
    /// The grain at rest in this configuration (rates are not logged).
    pub fn grain(&self) -> Grain {
        Grain {
            radius: self.radius,
            center: self.center,
            theta: self.theta,
            eps1: self.eps1,
            eps2: self.eps2,
            alpha: self.alpha,
            ..Default::default()
        }
    }

    pub fn shape(&self) -> GrainShape {
        self.grain().shape()
    }

    /// Mean stress, compression positive: `-(sxx + syy) / 2`.
    pub fn mean_stress_c(&self) -> f64 {
        -0.5 * (self.stress[0] + self.stress[1])
    }
}

/// One active grain–grain contact as logged (single precision on disk).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameContact {
    pub first: u32,
    pub second: u32,
    pub point: DVec2,
    /// From `first` towards `second`.
    pub normal: DVec2,
    /// Total normal force, <= 0 when repulsive; the force on `first` is `force * normal`.
    pub force: f64,
    pub length: f64,
}

/// Everything logged at one output interval.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Frame {
    pub step: u64,
    pub time: f64,
    pub log_time: u64,
    /// The SDEM grains (empty in a meshfree log).
    pub grains: Vec<FrameGrain>,
    /// The meshfree grains as contours (`/contours`); `None` in an SDEM log.
    pub contours: Option<Vec<FrameContour>>,
    pub walls: Vec<Wall>,
    /// Grain–grain contacts (none in a meshfree log).
    pub contacts: Vec<FrameContact>,
    /// The `macro.csv` row of this frame (absent if the log has no `/macro` message for it).
    pub measures: Option<Measures>,
    /// The periodic cell of a run without walls, from its four sides in `walls`; None in a box.
    pub cell: Option<crate::boundary::periodic::PeriodicCell>,
}

impl Frame {
    /// Number of grains: ellipses, or contours in a meshfree frame.
    pub fn grain_count(&self) -> usize {
        match &self.contours {
            Some(c) => c.len(),
            None => self.grains.len(),
        }
    }

    /// The frame's grains with their contact pairs checked against the grain count.
    pub fn check(&self) -> Result<(), String> {
        let n = self.grain_count() as u32;
        if let Some(c) = self.contacts.iter().find(|c| c.first >= n || c.second >= n) {
            return Err(format!(
                "contact ({}, {}) names a grain beyond the {n} of the frame",
                c.first, c.second
            ));
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Encoders and decoders of the channels
// ---------------------------------------------------------------------------------------------

fn encode_grains(buf: &mut Vec<u8>, world: &World) {
    let g = &world.grains;
    let s = &world.grain_stress;
    let n = g.len();
    let mut w = CdrWriter::new(buf);
    w.u64(world.step);
    w.f64(world.time);
    w.f64_seq(n, g.iter().map(|g| g.center.x));
    w.f64_seq(n, g.iter().map(|g| g.center.y));
    w.f64_seq(n, g.iter().map(|g| g.theta));
    w.f64_seq(n, g.iter().map(|g| g.eps1));
    w.f64_seq(n, g.iter().map(|g| g.eps2));
    w.f64_seq(n, g.iter().map(|g| g.alpha));
    w.f64_seq(n, g.iter().map(|g| g.radius));
    w.f64_seq(n, s.iter().map(|s| s.external[0]));
    w.f64_seq(n, s.iter().map(|s| s.external[1]));
    w.f64_seq(n, s.iter().map(|s| s.external[2]));
}

fn decode_grains(data: &[u8]) -> CdrResult<(u64, f64, Vec<FrameGrain>)> {
    let mut r = CdrReader::new(data)?;
    let step = r.u64()?;
    let time = r.f64()?;
    let columns: Vec<Vec<f64>> = (0..10).map(|_| r.f64_seq()).collect::<CdrResult<_>>()?;
    let n = columns[0].len();
    if columns.iter().any(|c| c.len() != n) {
        return Err("grain columns of different lengths".into());
    }
    let grains = (0..n)
        .map(|k| FrameGrain {
            center: DVec2::new(columns[0][k], columns[1][k]),
            theta: columns[2][k],
            eps1: columns[3][k],
            eps2: columns[4][k],
            alpha: columns[5][k],
            radius: columns[6][k],
            stress: [columns[7][k], columns[8][k], columns[9][k]],
        })
        .collect();
    Ok((step, time, grains))
}

/// The active contacts of the world's last step, in pair order.
pub fn active_contacts(world: &World) -> Vec<FrameContact> {
    world
        .neighbors
        .pairs
        .iter()
        .zip(&world.pair_contacts)
        .filter(|(_, c)| c.active)
        .map(|(&[i, j], c)| FrameContact {
            first: i,
            second: j,
            point: c.point,
            normal: c.normal,
            force: c.force,
            length: c.length,
        })
        .collect()
}

fn encode_contacts(buf: &mut Vec<u8>, world: &World, contacts: &[FrameContact]) {
    let n = contacts.len();
    let mut w = CdrWriter::new(buf);
    w.u64(world.step);
    w.f64(world.time);
    w.u32_seq(n, contacts.iter().map(|c| c.first));
    w.u32_seq(n, contacts.iter().map(|c| c.second));
    w.f32_seq(n, contacts.iter().map(|c| c.point.x as f32));
    w.f32_seq(n, contacts.iter().map(|c| c.point.y as f32));
    w.f32_seq(n, contacts.iter().map(|c| c.normal.x as f32));
    w.f32_seq(n, contacts.iter().map(|c| c.normal.y as f32));
    w.f32_seq(n, contacts.iter().map(|c| c.force as f32));
    w.f32_seq(n, contacts.iter().map(|c| c.length as f32));
}

fn decode_contacts(data: &[u8]) -> CdrResult<Vec<FrameContact>> {
    let mut r = CdrReader::new(data)?;
    let _step = r.u64()?;
    let _time = r.f64()?;
    let first = r.u32_seq()?;
    let second = r.u32_seq()?;
    let columns: Vec<Vec<f32>> = (0..6).map(|_| r.f32_seq()).collect::<CdrResult<_>>()?;
    let n = first.len();
    if second.len() != n || columns.iter().any(|c| c.len() != n) {
        return Err("contact columns of different lengths".into());
    }
    Ok((0..n)
        .map(|k| FrameContact {
            first: first[k],
            second: second[k],
            point: DVec2::new(columns[0][k] as f64, columns[1][k] as f64),
            normal: DVec2::new(columns[2][k] as f64, columns[3][k] as f64),
            force: columns[4][k] as f64,
            length: columns[5][k] as f64,
        })
        .collect())
}

fn encode_walls(buf: &mut Vec<u8>, step: u64, time: f64, walls: &[Wall]) {
    let n = walls.len();
    let mut w = CdrWriter::new(buf);
    w.u64(step);
    w.f64(time);
    w.f64_seq(n, walls.iter().map(|w| w.point.x));
    w.f64_seq(n, walls.iter().map(|w| w.point.y));
    w.f64_seq(n, walls.iter().map(|w| w.normal.x));
    w.f64_seq(n, walls.iter().map(|w| w.normal.y));
    w.f64_seq(n, walls.iter().map(|w| w.velocity.x));
    w.f64_seq(n, walls.iter().map(|w| w.velocity.y));
}

fn decode_walls(data: &[u8]) -> CdrResult<Vec<Wall>> {
    let mut r = CdrReader::new(data)?;
    let _step = r.u64()?;
    let _time = r.f64()?;
    let c: Vec<Vec<f64>> = (0..6).map(|_| r.f64_seq()).collect::<CdrResult<_>>()?;
    let n = c[0].len();
    if c.iter().any(|col| col.len() != n) {
        return Err("wall columns of different lengths".into());
    }
    Ok((0..n)
        .map(|k| Wall {
            point: DVec2::new(c[0][k], c[1][k]),
            normal: DVec2::new(c[2][k], c[3][k]),
            velocity: DVec2::new(c[4][k], c[5][k]),
        })
        .collect())
}

fn encode_macro(buf: &mut Vec<u8>, m: &Measures) {
    let mut w = CdrWriter::new(buf);
    w.u64(m.step);
    w.f64(m.time);
    w.string(&m.phase);
    for v in [
        m.phi,
        m.sxx_c,
        m.syy_c,
        m.p_c,
        m.q_c,
        m.z,
        m.z_nr,
        m.kinetic_energy,
        m.elastic_energy,
        m.inertial_number,
        m.strain_rate,
        m.box_width,
        m.box_height,
    ] {
        w.f64(v);
    }
    w.u64(m.contacts);
    w.u64(m.capped_contacts);
    for n in m.levels {
        w.u64(n);
    }
    w.f64(m.z_nr3);
}

fn decode_macro(data: &[u8]) -> CdrResult<Measures> {
    let mut r = CdrReader::new(data)?;
    Ok(Measures {
        step: r.u64()?,
        time: r.f64()?,
        phase: r.string()?,
        phi: r.f64()?,
        sxx_c: r.f64()?,
        syy_c: r.f64()?,
        p_c: r.f64()?,
        q_c: r.f64()?,
        z: r.f64()?,
        z_nr: r.f64()?,
        kinetic_energy: r.f64()?,
        elastic_energy: r.f64()?,
        inertial_number: r.f64()?,
        strain_rate: r.f64()?,
        box_width: r.f64()?,
        box_height: r.f64()?,
        contacts: r.u64()?,
        capped_contacts: r.u64()?,
        levels: [r.u64()?, r.u64()?, r.u64()?],
        // Logs written before the column end here.
        z_nr3: if r.remaining() > 0 {
            r.f64()?
        } else {
            f64::NAN
        },
    })
}

/// Colour scale of the grains' mean stress in `/scene` and in rendered pictures: `[0, max]`
/// with `max` the 99th percentile of the frame's positive mean stresses (a few very loaded
/// grains would otherwise flatten the picture).
pub fn stress_colour_max(mean_stresses_c: &[f64]) -> f64 {
    let mut positive: Vec<f64> = mean_stresses_c
        .iter()
        .copied()
        .filter(|s| s.is_finite() && *s > 0.0)
        .collect();
    if positive.is_empty() {
        return 0.0;
    }
    let k = ((positive.len() as f64 * 0.99) as usize).min(positive.len() - 1);
    let (_, v, _) = positive.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    *v
}

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
fn length_decimals(min_radius: f64) -> usize {
    if min_radius.is_finite() && min_radius > 0.0 {
        (-(min_radius * 1e-3).log10()).ceil().clamp(0.0, 15.0) as usize
    } else {
        6
    }
}

/// The `/scene` message: one entity of cylinders (the grains: ellipses seen from +z, coloured
/// by mean stress) and one of lines (the box).
fn encode_scene(out: &mut String, world: &World, log_time: u64) {
    out.clear();
    let grains = &world.grains;
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
fn encode_box(out: &mut String, walls: &[Wall], log_time: u64, mean_radius: f64, decimals: usize) {
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
const IDENTITY_POSE: &str = "\"pose\":{\"position\":{\"x\":0,\"y\":0,\"z\":0},\"orientation\":{\"x\":0,\"y\":0,\"z\":0,\"w\":1}}";

/// Starts a `/scene` message: up to the metadata of its `grains` entity (colour scale from 0
/// to `top`, step), which the caller may extend before it closes them.
fn scene_grains_start(out: &mut String, log_time: u64, top: f64, step: u64) {
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
fn stress_colour(mean_stress_c: f64, top: f64) -> [u8; 3] {
    let t = if top > 0.0 {
        (mean_stress_c / top).clamp(0.0, 1.0)
    } else {
        0.0
    };
    crate::output::render::viridis(t)
}

/// A point of a `/scene` primitive, in the plane z = 0, with `decimals` decimals.
fn json_point(out: &mut String, p: DVec2, decimals: usize) {
    let _ = write!(
        out,
        "{{\"x\":{:.d$},\"y\":{:.d$},\"z\":0}}",
        num(p.x),
        num(p.y),
        d = decimals
    );
}

/// A dark grey line loop through `points`, `thickness` thick, as a `/scene` line primitive.
fn json_line_loop(out: &mut String, points: &[DVec2], thickness: f64, decimals: usize) {
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

// ---------------------------------------------------------------------------------------------
// Writer
// ---------------------------------------------------------------------------------------------

/// Settings of a trajectory log.
#[derive(Debug, Clone, PartialEq)]
pub struct McapSettings {
    pub path: PathBuf,
    /// Write `/scene` every this many frames (0: never). `None`: every frame up to 10^4
    /// grains, every `ceil(N / 10^4)`-th frame above.
    pub scene_every: Option<u64>,
}

impl McapSettings {
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            scene_every: None,
        }
    }

    /// The scene interval used for `grains` grains.
    pub fn scene_interval(&self, grains: usize) -> u64 {
        self.scene_every
            .unwrap_or_else(|| (grains as u64).div_ceil(10_000).max(1))
    }
}

/// Writes a run's trajectory log, one frame per call of [`TrajectoryWriter::write_frame`].
pub struct TrajectoryWriter {
    path: String,
    inner: mcap::Writer<BufWriter<File>>,
    /// The same open file, to fsync it.
    file: File,
    /// A continued log is written to a temporary file that replaces this one at the first
    /// [`TrajectoryWriter::sync`] or at [`TrajectoryWriter::finish`].
    replaces: Option<PathBuf>,
    /// The channels of the grains: SDEM ellipses or meshfree contours.
    bodies: Bodies,
    walls: u16,
    macro_row: u16,
    scene: u16,
    scene_every: u64,
    sequence: u32,
    last_log_time: Option<u64>,
    frames: u64,
    buf: Vec<u8>,
    text: String,
}

/// A new log's writer with the `sdem.run` metadata and the scenario attachment it wrote (see
/// [`TrajectoryWriter::create_log`]).
type WithPreamble = (TrajectoryWriter, BTreeMap<String, String>, String);

/// A row of [`TrajectoryWriter::channel_table`].
type ChannelRow = (
    u16,
    &'static str,
    &'static str,
    &'static str,
    &'static str,
    &'static str,
);

/// How a log describes its grains.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Bodies {
    /// SDEM: `/grains` (ellipses) and `/contacts`.
    Ellipses { grains: u16, contacts: u16 },
    /// Meshfree: `/contours` (boundary-node polygons).
    Contours { contours: u16 },
}

/// What the `sdem.run` metadata of a log says of its run beyond the scenario.
struct RunInfo<'a> {
    grains: usize,
    material: &'a Material,
    /// The grain model, as the `model` entry writes it.
    model: String,
    dt: f64,
    /// The `stress_sign` entry: the sign conventions of the channels.
    stress_sign: &'static str,
    /// The entries of one solver.
    extra: Vec<(&'static str, String)>,
}

/// `round(time * 1e9)` as u64 (saturating; 0 for negative or non-finite times).
pub fn time_to_ns(time: f64) -> u64 {
    let ns = (time * 1e9).round();
    if ns.is_finite() && ns > 0.0 {
        if ns >= u64::MAX as f64 {
            u64::MAX
        } else {
            ns as u64
        }
    } else {
        0
    }
}

impl TrajectoryWriter {
    /// Creates the log, writing its header, schemas, channels, the scenario attachment and the
    /// `sdem.run` metadata.
    pub fn create(
        settings: &McapSettings,
        scenario: &Scenario,
        world: &World,
    ) -> Result<Self, WriteError> {
        Ok(Self::create_with_preamble(settings, scenario, world)?.0)
    }

    /// [`TrajectoryWriter::create`], also returning the `sdem.run` metadata and the scenario
    /// attachment it wrote.
    fn create_with_preamble(
        settings: &McapSettings,
        scenario: &Scenario,
        world: &World,
    ) -> Result<WithPreamble, WriteError> {
        let p = &world.params;
        let info = RunInfo {
            grains: world.grains.len(),
            material: &p.material,
            model: match &p.adaptive {
                Some(a) => format!("Adaptive({:?})", a.settings),
                None => format!("{:?}", p.level),
            },
            dt: p.dt,
            stress_sign: "/grains: tension positive; /macro: compression positive",
            extra: vec![
                ("resolution_deg", format!("{}", p.resolution_deg)),
                ("contour_nodes", world.table.nodes.to_string()),
            ],
        };
        Self::create_log(settings, scenario, SCENE_SCHEMA, info, |inner, path| {
            let grains = add_channel(
                inner,
                path,
                TOPIC_GRAINS,
                SCHEMA_GRAINS,
                "ros2msg",
                GRAINS_MSG,
                "cdr",
            )?;
            let contacts = add_channel(
                inner,
                path,
                TOPIC_CONTACTS,
                SCHEMA_CONTACTS,
                "ros2msg",
                CONTACTS_MSG,
                "cdr",
            )?;
            Ok(Bodies::Ellipses { grains, contacts })
        })
    }

    /// Creates a log: header, the channels of the bodies (added by `add_bodies`), then
    /// `/walls`, `/macro` and `/scene` (of schema `scene_schema`), the scenario attachment and
    /// the `sdem.run` metadata. Also returns the metadata and the scenario attachment.
    fn create_log(
        settings: &McapSettings,
        scenario: &Scenario,
        scene_schema: &str,
        info: RunInfo<'_>,
        add_bodies: impl FnOnce(&mut McapWriter, &str) -> Result<Bodies, WriteError>,
    ) -> Result<WithPreamble, WriteError> {
        let (path, mut inner, handle) = Self::open_file(settings)?;
        let bodies = add_bodies(&mut inner, &path)?;
        let walls = add_channel(
            &mut inner,
            &path,
            TOPIC_WALLS,
            SCHEMA_WALLS,
            "ros2msg",
            WALLS_MSG,
            "cdr",
        )?;
        let macro_row = add_channel(
            &mut inner,
            &path,
            TOPIC_MACRO,
            SCHEMA_MACRO,
            "ros2msg",
            MACRO_MSG,
            "cdr",
        )?;
        let scene = add_channel(
            &mut inner,
            &path,
            TOPIC_SCENE,
            SCHEMA_SCENE,
            "jsonschema",
            scene_schema,
            "json",
        )?;
        let scenario_text = attach_scenario(&mut inner, &path, scenario)?;
        let scene_every = settings.scene_interval(info.grains);
        let m = info.material;
        let run: BTreeMap<String, String> = [
            ("format_version", FORMAT_VERSION.to_string()),
            ("sdem_version", env!("CARGO_PKG_VERSION").to_string()),
            ("scenario", scenario.name.clone()),
            ("grains", info.grains.to_string()),
            ("seed", scenario.seed.to_string()),
            ("young", format!("{:e}", m.young)),
            ("poisson", format!("{}", m.poisson)),
            ("density", format!("{:e}", m.density)),
            ("model", info.model),
            ("dt", format!("{:e}", info.dt)),
            ("output_every", scenario.output.every.to_string()),
            (
                "jamming_pressure",
                format!("{:e}", scenario.output.jamming_pressure * m.young),
            ),
            ("scene_every", scene_every.to_string()),
            (
                "log_time",
                "round(simulated time * 1e9) ns, strictly increasing".to_string(),
            ),
            ("stress_sign", info.stress_sign.to_string()),
        ]
        .into_iter()
        .chain(
            // A periodic cell's `/walls` are the cell's four sides (SPEC §14), met by no grain.
            (!scenario.boundary.is_walls()).then(|| ("boundary", "periodic".to_string())),
        )
        .chain(info.extra)
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        inner
            .write_metadata(&records::Metadata {
                name: "sdem.run".into(),
                metadata: run.clone(),
            })
            .map_err(|error| WriteError::Mcap {
                path: path.clone(),
                error,
            })?;
        let writer = Self {
            path,
            inner,
            file: handle,
            replaces: None,
            bodies,
            walls,
            macro_row,
            scene,
            scene_every,
            sequence: 0,
            last_log_time: None,
            frames: 0,
            buf: Vec::new(),
            text: String::new(),
        };
        Ok((writer, run, scenario_text))
    }

    /// (id, topic, schema name, schema encoding, schema, message encoding) of the channels.
    fn channel_table(&self) -> Vec<ChannelRow> {
        let mut table = match self.bodies {
            Bodies::Ellipses { grains, contacts } => vec![
                (
                    grains,
                    TOPIC_GRAINS,
                    SCHEMA_GRAINS,
                    "ros2msg",
                    GRAINS_MSG,
                    "cdr",
                ),
                (
                    contacts,
                    TOPIC_CONTACTS,
                    SCHEMA_CONTACTS,
                    "ros2msg",
                    CONTACTS_MSG,
                    "cdr",
                ),
            ],
            Bodies::Contours { contours: id } => vec![(
                id,
                contours::TOPIC_CONTOURS,
                contours::SCHEMA_CONTOURS,
                "ros2msg",
                contours::CONTOURS_MSG,
                "cdr",
            )],
        };
        table.push((
            self.walls,
            TOPIC_WALLS,
            SCHEMA_WALLS,
            "ros2msg",
            WALLS_MSG,
            "cdr",
        ));
        table.push((
            self.macro_row,
            TOPIC_MACRO,
            SCHEMA_MACRO,
            "ros2msg",
            MACRO_MSG,
            "cdr",
        ));
        let scene_schema = match self.bodies {
            Bodies::Ellipses { .. } => SCENE_SCHEMA,
            Bodies::Contours { .. } => contours::CONTOUR_SCENE_SCHEMA,
        };
        table.push((
            self.scene,
            TOPIC_SCENE,
            SCHEMA_SCENE,
            "jsonschema",
            scene_schema,
            "json",
        ));
        table
    }

    fn mcap_error(&self, error: mcap::McapError) -> WriteError {
        WriteError::Mcap {
            path: self.path.clone(),
            error,
        }
    }

    fn put(&mut self, channel: u16, log_time: u64, data: &[u8]) -> Result<(), WriteError> {
        let header = records::MessageHeader {
            channel_id: channel,
            sequence: self.sequence,
            log_time,
            publish_time: log_time,
        };
        self.sequence = self.sequence.wrapping_add(1);
        self.inner
            .write_to_known_channel(&header, data)
            .map_err(|e| self.mcap_error(e))
    }

    /// The log time of a frame at simulated time `time`: `round(time * 1e9)` ns, bumped to
    /// stay strictly increasing.
    fn next_log_time(&mut self, time: f64) -> u64 {
        let mut log_time = time_to_ns(time);
        if let Some(last) = self.last_log_time
            && log_time <= last
        {
            log_time = last + 1;
        }
        self.last_log_time = Some(log_time);
        log_time
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Logs the world's current state with its `macro.csv` row.
    pub fn write_frame(&mut self, world: &World, row: &Measures) -> Result<(), WriteError> {
        let Bodies::Ellipses {
            grains,
            contacts: contacts_channel,
        } = self.bodies
        else {
            return Err(self.io_error(std::io::Error::other(
                "an SDEM frame cannot go into a log of meshfree contours",
            )));
        };
        let log_time = self.next_log_time(world.time);
        let mut buf = std::mem::take(&mut self.buf);
        encode_grains(&mut buf, world);
        self.put(grains, log_time, &buf)?;
        let contacts = active_contacts(world);
        encode_contacts(&mut buf, world, &contacts);
        self.put(contacts_channel, log_time, &buf)?;
        self.finish_frame(
            buf,
            log_time,
            (world.step, world.time),
            &world.walls,
            row,
            |text| encode_scene(text, world, log_time),
        )
    }

    /// Ends the frame at `log_time` whose bodies are written: `/walls`, `/macro` and, on its
    /// interval, `/scene` (encoded by `scene`); `buf` is the message buffer, taken from
    /// `self.buf`, given back.
    fn finish_frame(
        &mut self,
        mut buf: Vec<u8>,
        log_time: u64,
        (step, time): (u64, f64),
        walls: &[Wall],
        row: &Measures,
        scene: impl FnOnce(&mut String),
    ) -> Result<(), WriteError> {
        encode_walls(&mut buf, step, time, walls);
        self.put(self.walls, log_time, &buf)?;
        encode_macro(&mut buf, row);
        self.put(self.macro_row, log_time, &buf)?;
        self.buf = buf;
        if self.scene_every > 0 && self.frames % self.scene_every == 0 {
            let mut text = std::mem::take(&mut self.text);
            scene(&mut text);
            self.put(self.scene, log_time, text.as_bytes())?;
            self.text = text;
        }
        self.frames += 1;
        Ok(())
    }

    fn io_error(&self, error: std::io::Error) -> WriteError {
        WriteError::Io {
            path: self.path.clone(),
            error,
        }
    }

    /// Makes everything logged so far durable: finishes the current chunk, flushes and fsyncs
    /// the file. The run calls it before each checkpoint, so that a checkpoint never counts a
    /// frame that a killed process left in memory. A continued log (see
    /// [`TrajectoryWriter::continue_log`]) then replaces the log it continues.
    pub fn sync(&mut self) -> Result<(), WriteError> {
        self.inner.flush().map_err(|e| self.mcap_error(e))?;
        self.file.sync_data().map_err(|e| self.io_error(e))?;
        self.replace_original()
    }

    /// Renames the temporary file of a continued log over the log it continues (once).
    fn replace_original(&mut self) -> Result<(), WriteError> {
        if let Some(to) = self.replaces.take() {
            rename_durably(&self.path, &to)?;
            self.path = to.display().to_string();
        }
        Ok(())
    }

    /// Writes the `sdem.summary` metadata and the summary section, and closes the file (a
    /// continued log then replaces the log it continues).
    pub fn finish(mut self, summary: BTreeMap<String, String>) -> Result<(), WriteError> {
        let mut summary = summary;
        summary.insert("frames".into(), self.frames.to_string());
        self.inner
            .write_metadata(&records::Metadata {
                name: "sdem.summary".into(),
                metadata: summary,
            })
            .map_err(|e| self.mcap_error(e))?;
        self.inner.finish().map_err(|e| self.mcap_error(e))?;
        if let Some(to) = self.replaces.take() {
            let io = |error| WriteError::Io {
                path: self.path.clone(),
                error,
            };
            let mut out = self.inner.into_inner();
            out.flush().map_err(io)?;
            self.file.sync_data().map_err(io)?;
            rename_durably(&self.path, &to)?;
        }
        Ok(())
    }
}

type McapWriter = mcap::Writer<BufWriter<File>>;

impl TrajectoryWriter {
    /// Creates the file of a new log (and its folder) and writes the MCAP header: (path for
    /// messages, writer, a handle on the same file to fsync it).
    fn open_file(settings: &McapSettings) -> Result<(String, McapWriter, File), WriteError> {
        let path = settings.path.display().to_string();
        if let Some(dir) = settings.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|error| WriteError::Io {
                path: path.clone(),
                error,
            })?;
        }
        let file = File::create(&settings.path).map_err(|error| WriteError::Io {
            path: path.clone(),
            error,
        })?;
        let handle = file.try_clone().map_err(|error| WriteError::Io {
            path: path.clone(),
            error,
        })?;
        let inner = WriteOptions::new()
            .compression(Some(Compression::Zstd))
            // No thread per core beside rayon's workers.
            .compression_threads(0)
            .profile("")
            .library(format!("sdem {}", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::with_capacity(1 << 20, file))
            .map_err(|error| WriteError::Mcap {
                path: path.clone(),
                error,
            })?;
        Ok((path, inner, handle))
    }
}

/// Adds a schema and its channel to a new log; returns the channel id.
fn add_channel(
    inner: &mut McapWriter,
    path: &str,
    topic: &str,
    schema: &str,
    schema_encoding: &str,
    data: &str,
    encoding: &str,
) -> Result<u16, WriteError> {
    let mcap_err = |error| WriteError::Mcap {
        path: path.to_string(),
        error,
    };
    let id = inner
        .add_schema(schema, schema_encoding, data.as_bytes())
        .map_err(mcap_err)?;
    inner
        .add_channel(id, topic, encoding, &BTreeMap::new())
        .map_err(mcap_err)
}

/// Attaches the scenario (RON, every default filled in) as `scenario.ron`; returns its text.
fn attach_scenario(
    inner: &mut McapWriter,
    path: &str,
    scenario: &Scenario,
) -> Result<String, WriteError> {
    let scenario_text = ron::ser::to_string_pretty(
        scenario,
        ron::ser::PrettyConfig::default().struct_names(true),
    )
    .unwrap_or_default();
    inner
        .attach(&mcap::Attachment {
            log_time: 0,
            create_time: 0,
            name: "scenario.ron".into(),
            media_type: "text/x-ron".into(),
            data: std::borrow::Cow::Borrowed(scenario_text.as_bytes()),
        })
        .map_err(|error| WriteError::Mcap {
            path: path.to_string(),
            error,
        })?;
    Ok(scenario_text)
}

/// Renames `from` to `to` and fsyncs the folder (where the platform allows opening one).
fn rename_durably(from: &str, to: &Path) -> Result<(), WriteError> {
    std::fs::rename(from, to).map_err(|error| WriteError::Io {
        path: format!("{from} -> {}", to.display()),
        error,
    })?;
    if let Some(dir) = to.parent().filter(|d| !d.as_os_str().is_empty())
        && let Ok(d) = File::open(dir)
    {
        d.sync_all().ok();
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Reader
// ---------------------------------------------------------------------------------------------

/// A channel of a log and its message count.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelInfo {
    pub id: u16,
    pub topic: String,
    pub schema_name: String,
    pub schema_encoding: String,
    pub message_encoding: String,
    pub messages: u64,
}

/// An attachment of a log.
#[derive(Debug, Clone, PartialEq)]
pub struct AttachmentInfo {
    pub name: String,
    pub media_type: String,
    pub size: u64,
    offset: u64,
    length: u64,
}

/// Where one message lies: its log time and the chunk that holds it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct MessageRef {
    log_time: u64,
    chunk: usize,
}

/// A trajectory log opened for reading. Only the summary and the message indexes are read at
/// open; a frame decompresses only the chunks that hold it.
pub struct Trajectory {
    path: PathBuf,
    file: Mutex<File>,
    file_size: u64,
    header: records::Header,
    summary: mcap::Summary,
    channels: Vec<ChannelInfo>,
    /// Per channel id, its messages in log-time order.
    messages: HashMap<u16, Vec<MessageRef>>,
    attachments: Vec<AttachmentInfo>,
    metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// The channel with one message per frame: `/grains` (SDEM) or `/contours` (meshfree).
    frame_topic: &'static str,
}

/// A step count and its simulated time.
pub type StepTime = (u64, f64);

/// Sizes of a log.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SizeInfo {
    pub file_bytes: u64,
    pub chunks: usize,
    pub compressed_bytes: u64,
    pub uncompressed_bytes: u64,
}

impl Trajectory {
    /// Opens a log: reads its summary section, attachments index, metadata and message indexes.
    /// A truncated or corrupt file gives a [`ReadError`] naming it, never a panic.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, ReadError> {
        let path = path.as_ref().to_path_buf();
        let name = path.display().to_string();
        let io = |error| ReadError::Io {
            path: name.clone(),
            error,
        };
        let mut file = File::open(&path).map_err(io)?;
        let file_size = file.metadata().map_err(io)?.len();
        let corrupt = |reason: String| ReadError::Corrupt {
            path: name.clone(),
            reason,
        };

        // Magic at both ends, then the summary through the sans-io reader.
        let mut start = [0u8; 8];
        if file_size < 8 || file.read_exact(&mut start).is_err() || start != *mcap::MAGIC {
            return Err(ReadError::NotATrajectory {
                path: name,
                reason: "not an MCAP file (no MCAP magic at its start)".into(),
            });
        }
        let mut end = [0u8; 8];
        file.seek(SeekFrom::End(-8)).map_err(io)?;
        file.read_exact(&mut end).map_err(io)?;
        if end != *mcap::MAGIC {
            return Err(ReadError::Incomplete {
                path: name,
                reason: "no MCAP magic at its end".into(),
            });
        }
        let summary = read_summary(&mut file, file_size).map_err(|e| ReadError::Incomplete {
            path: name.clone(),
            reason: format!("its summary section cannot be read: {e}"),
        })?;
        let Some(summary) = summary else {
            return Err(ReadError::Incomplete {
                path: name,
                reason: "it has no summary section".into(),
            });
        };

        // Header record, right after the start magic.
        let header = {
            let mut head = vec![0u8; 9];
            file.seek(SeekFrom::Start(8)).map_err(io)?;
            file.read_exact(&mut head).map_err(io)?;
            let len = u64::from_le_bytes(head[1..9].try_into().unwrap());
            if head[0] != records::op::HEADER || len > file_size.saturating_sub(17) {
                return Err(corrupt("bad header record".into()));
            }
            let mut body = vec![0u8; len as usize];
            file.read_exact(&mut body).map_err(io)?;
            match mcap::parse_record(records::op::HEADER, &body) {
                Ok(Record::Header(h)) => h,
                _ => return Err(corrupt("bad header record".into())),
            }
        };

        let mut traj = Self {
            path,
            file: Mutex::new(file),
            file_size,
            header,
            summary,
            channels: Vec::new(),
            messages: HashMap::new(),
            attachments: Vec::new(),
            metadata: BTreeMap::new(),
            frame_topic: TOPIC_GRAINS,
        };
        traj.check_chunk_indexes()?;
        traj.index_messages()?;
        traj.read_attachment_and_metadata_indexes()?;
        let counts = traj
            .summary
            .stats
            .as_ref()
            .map(|s| &s.channel_message_counts);
        let mut channels: Vec<ChannelInfo> = traj
            .summary
            .channels
            .values()
            .map(|c| ChannelInfo {
                id: c.id,
                topic: c.topic.clone(),
                schema_name: c
                    .schema
                    .as_ref()
                    .map(|s| s.name.clone())
                    .unwrap_or_default(),
                schema_encoding: c
                    .schema
                    .as_ref()
                    .map(|s| s.encoding.clone())
                    .unwrap_or_default(),
                message_encoding: c.message_encoding.clone(),
                messages: counts
                    .and_then(|m| m.get(&c.id).copied())
                    .unwrap_or_else(|| traj.messages.get(&c.id).map_or(0, |v| v.len() as u64)),
            })
            .collect();
        channels.sort_by_key(|c| c.id);
        traj.channels = channels;
        // SDEM logs have `/grains`, meshfree logs `/contours` in its place.
        if traj.channel(TOPIC_GRAINS).is_none() && traj.channel(contours::TOPIC_CONTOURS).is_some()
        {
            traj.frame_topic = contours::TOPIC_CONTOURS;
        }
        let not_ours = |reason: String| ReadError::NotATrajectory {
            path: traj.name(),
            reason,
        };
        for topic in [traj.frame_topic, TOPIC_WALLS] {
            if traj.channel(topic).is_none() {
                return Err(not_ours(format!(
                    "an MCAP file but not an sdem trajectory: no {topic} channel"
                )));
            }
        }
        let expected = match traj.frame_topic {
            TOPIC_GRAINS => SCHEMA_GRAINS,
            _ => contours::SCHEMA_CONTOURS,
        };
        if let Some(c) = traj.channel(traj.frame_topic)
            && c.schema_name != expected
        {
            return Err(not_ours(format!(
                "{} has schema {}, expected {expected}",
                traj.frame_topic, c.schema_name
            )));
        }
        Ok(traj)
    }

    fn name(&self) -> String {
        self.path.display().to_string()
    }

    fn corrupt(&self, reason: impl Into<String>) -> ReadError {
        ReadError::Corrupt {
            path: self.name(),
            reason: reason.into(),
        }
    }

    /// Reads `len` bytes at `offset`, checked against the file size.
    fn read_range(&self, offset: u64, len: u64) -> Result<Vec<u8>, ReadError> {
        let end = offset.checked_add(len).filter(|&e| e <= self.file_size);
        if end.is_none() {
            return Err(self.corrupt(format!(
                "an index points at bytes {offset}..{} beyond the file's {} bytes",
                offset.saturating_add(len),
                self.file_size
            )));
        }
        let mut buf = vec![0u8; len as usize];
        let mut file = self.file.lock().unwrap_or_else(|e| e.into_inner());
        file.seek(SeekFrom::Start(offset))
            .and_then(|_| file.read_exact(&mut buf))
            .map_err(|error| ReadError::Io {
                path: self.name(),
                error,
            })?;
        Ok(buf)
    }

    fn check_chunk_indexes(&self) -> Result<(), ReadError> {
        for (k, c) in self.summary.chunk_indexes.iter().enumerate() {
            let end = c
                .chunk_start_offset
                .checked_add(c.chunk_length)
                .and_then(|e| e.checked_add(c.message_index_length));
            let ok = c.chunk_length > 9
                && end.is_some_and(|e| e <= self.file_size)
                && c.message_start_time <= c.message_end_time;
            if !ok {
                return Err(self.corrupt(format!("chunk index {k} is inconsistent")));
            }
        }
        Ok(())
    }

    /// Builds the per-channel message lists from the message indexes after each chunk, or by
    /// reading the chunks if a file has no message indexes.
    fn index_messages(&mut self) -> Result<(), ReadError> {
        let mut messages: HashMap<u16, Vec<MessageRef>> = HashMap::new();
        for k in 0..self.summary.chunk_indexes.len() {
            let c = &self.summary.chunk_indexes[k];
            if c.message_index_offsets.is_empty() || c.message_index_length == 0 {
                for (channel, log_time) in
                    self.chunk_messages(k, |_, _| true, |ch, t, _| (ch, t))?
                {
                    messages
                        .entry(channel)
                        .or_default()
                        .push(MessageRef { log_time, chunk: k });
                }
                continue;
            }
            let start = c.chunk_start_offset + c.chunk_length;
            let bytes = self.read_range(start, c.message_index_length)?;
            for record in mcap::read::LinearReader::sans_magic(&bytes) {
                match record {
                    Ok(Record::MessageIndex(index)) => {
                        let list = messages.entry(index.channel_id).or_default();
                        list.extend(index.records.iter().map(|e| MessageRef {
                            log_time: e.log_time,
                            chunk: k,
                        }));
                    }
                    Ok(_) => {}
                    Err(e) => return Err(self.corrupt(format!("message index of chunk {k}: {e}"))),
                }
            }
        }
        for list in messages.values_mut() {
            list.sort_by_key(|m| (m.log_time, m.chunk));
        }
        self.messages = messages;
        Ok(())
    }

    fn read_attachment_and_metadata_indexes(&mut self) -> Result<(), ReadError> {
        let attachments = self
            .summary
            .attachment_indexes
            .iter()
            .map(|a| AttachmentInfo {
                name: a.name.clone(),
                media_type: a.media_type.clone(),
                size: a.data_size,
                offset: a.offset,
                length: a.length,
            })
            .collect();
        self.attachments = attachments;
        let indexes = self.summary.metadata_indexes.clone();
        for index in &indexes {
            let bytes = self.read_range(index.offset, index.length)?;
            match mcap::read::LinearReader::sans_magic(&bytes).next() {
                Some(Ok(Record::Metadata(m))) => {
                    self.metadata.insert(m.name, m.metadata);
                }
                Some(Err(e)) => {
                    return Err(self.corrupt(format!("metadata {}: {e}", index.name)));
                }
                _ => return Err(self.corrupt(format!("metadata {}: bad index", index.name))),
            }
        }
        Ok(())
    }

    /// Decompresses chunk `k` and maps `f` over its messages that `keep` selects (by channel
    /// id and log time).
    fn chunk_messages<T>(
        &self,
        k: usize,
        keep: impl Fn(u16, u64) -> bool,
        mut f: impl FnMut(u16, u64, &[u8]) -> T,
    ) -> Result<Vec<T>, ReadError> {
        let index = &self.summary.chunk_indexes[k];
        let bytes = self.read_range(index.chunk_start_offset, index.chunk_length)?;
        let declared = u64::from_le_bytes(bytes[1..9].try_into().unwrap());
        if bytes[0] != records::op::CHUNK || declared != index.chunk_length - 9 {
            return Err(self.corrupt(format!("chunk {k} is not where its index says")));
        }
        // A corrupt size must not make the decompressor reserve absurd amounts of memory: the
        // reader below refuses any record or chunk content larger than `limit`, and checks the
        // chunk's CRC before it parses a single record out of it.
        let limit = index.uncompressed_size;
        if limit > (1 << 30) || limit > 4096 * index.chunk_length.max(1 << 20) {
            return Err(self.corrupt(format!("chunk {k}: implausible uncompressed size {limit}")));
        }
        use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
        let mut reader = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_skip_start_magic(true)
                .with_skip_end_magic(true)
                .with_validate_chunk_crcs(true)
                .with_prevalidate_chunk_crcs(true)
                .with_record_length_limit((limit as usize).max(bytes.len())),
        );
        let mut remaining: &[u8] = &bytes;
        let mut out = Vec::new();
        while let Some(event) = reader.next_event() {
            match event {
                Ok(LinearReadEvent::ReadRequest(need)) => {
                    let len = need.min(remaining.len());
                    reader.insert(len).copy_from_slice(&remaining[..len]);
                    reader.notify_read(len);
                    remaining = &remaining[len..];
                }
                Ok(LinearReadEvent::Record { data, opcode }) => {
                    match mcap::parse_record(opcode, data) {
                        Ok(Record::Message { header, data }) => {
                            if keep(header.channel_id, header.log_time) {
                                out.push(f(header.channel_id, header.log_time, &data));
                            }
                        }
                        Ok(_) => {}
                        Err(e) => return Err(self.corrupt(format!("chunk {k}: {e}"))),
                    }
                }
                Err(e) => return Err(self.corrupt(format!("chunk {k}: {e}"))),
            }
        }
        Ok(out)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }

    pub fn channel(&self, topic: &str) -> Option<&ChannelInfo> {
        self.channels.iter().find(|c| c.topic == topic)
    }

    /// The library string of the MCAP header (`sdem <version>` for our logs).
    pub fn library(&self) -> &str {
        &self.header.library
    }

    pub fn attachments(&self) -> &[AttachmentInfo] {
        &self.attachments
    }

    /// Metadata records by name (`sdem.run`, `sdem.summary`).
    pub fn metadata(&self) -> &BTreeMap<String, BTreeMap<String, String>> {
        &self.metadata
    }

    /// A value of the `sdem.run` metadata record.
    pub fn run_info(&self, key: &str) -> Option<&str> {
        self.metadata
            .get("sdem.run")
            .and_then(|m| m.get(key))
            .map(|s| s.as_str())
    }

    /// A value of the `sdem.summary` metadata record.
    pub fn summary_info(&self, key: &str) -> Option<&str> {
        self.metadata
            .get("sdem.summary")
            .and_then(|m| m.get(key))
            .map(|s| s.as_str())
    }

    pub fn sizes(&self) -> SizeInfo {
        SizeInfo {
            file_bytes: self.file_size,
            chunks: self.summary.chunk_indexes.len(),
            // Saturating: the sizes are the file's word (a damaged index can say anything).
            compressed_bytes: self
                .summary
                .chunk_indexes
                .iter()
                .fold(0u64, |a, c| a.saturating_add(c.compressed_size)),
            uncompressed_bytes: self
                .summary
                .chunk_indexes
                .iter()
                .fold(0u64, |a, c| a.saturating_add(c.uncompressed_size)),
        }
    }

    /// Compression of the chunks (e.g. `zstd`), comma-separated if mixed.
    pub fn compression(&self) -> String {
        let mut names: Vec<&str> = self
            .summary
            .chunk_indexes
            .iter()
            .map(|c| {
                if c.compression.is_empty() {
                    "none"
                } else {
                    c.compression.as_str()
                }
            })
            .collect();
        names.sort_unstable();
        names.dedup();
        names.join(",")
    }

    fn refs(&self, topic: &str) -> &[MessageRef] {
        self.channel(topic)
            .and_then(|c| self.messages.get(&c.id))
            .map_or(&[], |v| v.as_slice())
    }

    /// The solver that wrote the log: `meshfree` (grains as contours on `/contours`) or
    /// `sdem` (ellipses on `/grains`).
    pub fn solver(&self) -> &str {
        if self.frame_topic == contours::TOPIC_CONTOURS {
            "meshfree"
        } else {
            "sdem"
        }
    }

    /// The channel with one message per frame: `/grains`, or `/contours` in a meshfree log.
    pub fn frame_topic(&self) -> &'static str {
        self.frame_topic
    }

    /// Number of frames (messages on `/grains`, or `/contours` in a meshfree log).
    pub fn frame_count(&self) -> usize {
        self.refs(self.frame_topic).len()
    }

    /// Log times (ns) of the frames.
    pub fn frame_log_times(&self) -> Vec<u64> {
        self.refs(self.frame_topic)
            .iter()
            .map(|m| m.log_time)
            .collect()
    }

    /// Resolves a frame number: `k >= 0` from the start, `k < 0` from the end (-1: the last).
    pub fn resolve_frame(&self, k: i64) -> Result<usize, ReadError> {
        let n = self.frame_count();
        let index = if k < 0 { n as i64 + k } else { k };
        if index < 0 || index >= n as i64 {
            return Err(ReadError::NoSuchFrame {
                path: self.name(),
                frame: k,
                frames: n,
            });
        }
        Ok(index as usize)
    }

    /// The raw payloads of the messages on `topic` at `log_time`.
    fn payloads_at(&self, topic: &str, log_time: u64) -> Result<Vec<Vec<u8>>, ReadError> {
        let Some(channel) = self.channel(topic).map(|c| c.id) else {
            return Ok(Vec::new());
        };
        let mut chunks: Vec<usize> = self
            .refs(topic)
            .iter()
            .filter(|m| m.log_time == log_time)
            .map(|m| m.chunk)
            .collect();
        chunks.dedup();
        let mut out = Vec::new();
        for k in chunks {
            out.extend(self.chunk_messages(
                k,
                |c, t| c == channel && t == log_time,
                |_, _, data| data.to_vec(),
            )?);
        }
        Ok(out)
    }

    fn single_payload(&self, topic: &str, log_time: u64) -> Result<Option<Vec<u8>>, ReadError> {
        Ok(self.payloads_at(topic, log_time)?.into_iter().next())
    }

    /// Frame `k` (0-based; negative counts from the end): grains (or contours), walls,
    /// contacts, macro row.
    pub fn frame(&self, k: i64) -> Result<Frame, ReadError> {
        let index = self.resolve_frame(k)?;
        let topic = self.frame_topic;
        let log_time = self.refs(topic)[index].log_time;
        let bad = |topic: &str, e: String| self.corrupt(format!("{topic} at frame {index}: {e}"));
        let bodies = self
            .single_payload(topic, log_time)?
            .ok_or_else(|| bad(topic, "message missing from its chunk".into()))?;
        let (step, time, grains, contours) = if topic == TOPIC_GRAINS {
            let (step, time, grains) = decode_grains(&bodies).map_err(|e| bad(topic, e))?;
            (step, time, grains, None)
        } else {
            let (step, time, contours) =
                contours::decode_contours(&bodies).map_err(|e| bad(topic, e))?;
            (step, time, Vec::new(), Some(contours))
        };
        let walls = match self.single_payload(TOPIC_WALLS, log_time)? {
            Some(d) => decode_walls(&d).map_err(|e| bad(TOPIC_WALLS, e))?,
            None => Vec::new(),
        };
        let contacts = match self.single_payload(TOPIC_CONTACTS, log_time)? {
            Some(d) => decode_contacts(&d).map_err(|e| bad(TOPIC_CONTACTS, e))?,
            None => Vec::new(),
        };
        let measures = match self.single_payload(TOPIC_MACRO, log_time)? {
            Some(d) => Some(decode_macro(&d).map_err(|e| bad(TOPIC_MACRO, e))?),
            None => None,
        };
        let cell = if self.run_info("boundary") == Some("periodic") {
            Some(
                crate::boundary::periodic::PeriodicBoundary::cell_of_sides(&walls)
                    .map_err(|e| bad(TOPIC_WALLS, e))?,
            )
        } else {
            None
        };
        let frame = Frame {
            step,
            time,
            log_time,
            grains,
            contours,
            walls,
            contacts,
            measures,
            cell,
        };
        frame.check().map_err(|e| bad(TOPIC_CONTACTS, e))?;
        Ok(frame)
    }

    /// Every `/macro` row, in log order (the content of `macro.csv`).
    pub fn macro_rows(&self) -> Result<Vec<Measures>, ReadError> {
        let Some(channel) = self.channel(TOPIC_MACRO).map(|c| c.id) else {
            return Ok(Vec::new());
        };
        let mut chunks: Vec<usize> = self.refs(TOPIC_MACRO).iter().map(|m| m.chunk).collect();
        chunks.sort_unstable();
        chunks.dedup();
        let mut rows: Vec<(u64, Measures)> = Vec::new();
        for k in chunks {
            for (t, data) in
                self.chunk_messages(k, |c, _| c == channel, |_, t, d| (t, d.to_vec()))?
            {
                let m = decode_macro(&data)
                    .map_err(|e| self.corrupt(format!("{TOPIC_MACRO} in chunk {k}: {e}")))?;
                rows.push((t, m));
            }
        }
        rows.sort_by_key(|(t, m)| (*t, m.step));
        Ok(rows.into_iter().map(|(_, m)| m).collect())
    }

    /// The scenario attached to the log (RON text), if any.
    pub fn scenario_text(&self) -> Result<Option<String>, ReadError> {
        let Some(a) = self.attachments.iter().find(|a| a.name == "scenario.ron") else {
            return Ok(None);
        };
        let bytes = self.read_range(a.offset, a.length)?;
        match mcap::read::LinearReader::sans_magic(&bytes).next() {
            Some(Ok(Record::Attachment { data, .. })) => Ok(Some(
                String::from_utf8(data.into_owned())
                    .map_err(|_| self.corrupt("scenario.ron is not UTF-8"))?,
            )),
            Some(Err(e)) => Err(self.corrupt(format!("attachment scenario.ron: {e}"))),
            _ => Err(self.corrupt("attachment scenario.ron: bad index")),
        }
    }

    /// The scenario attached to the log, parsed.
    pub fn scenario(&self) -> Result<Option<Scenario>, ReadError> {
        let Some(text) = self.scenario_text()? else {
            return Ok(None);
        };
        Scenario::parse(&text, "scenario.ron")
            .map(Some)
            .map_err(|e| self.corrupt(format!("attached scenario.ron: {e}")))
    }

    /// (first, last) step and time of the frames, from their `/macro` rows or frames.
    pub fn span(&self) -> Result<Option<(StepTime, StepTime)>, ReadError> {
        if self.frame_count() == 0 {
            return Ok(None);
        }
        let first = self.frame_header(0)?;
        let last = self.frame_header(-1)?;
        Ok(Some((first, last)))
    }

    /// (step, time) of frame k, decoding only the start of its `/grains` (or `/contours`)
    /// message.
    pub fn frame_header(&self, k: i64) -> Result<(u64, f64), ReadError> {
        let index = self.resolve_frame(k)?;
        let topic = self.frame_topic;
        let log_time = self.refs(topic)[index].log_time;
        let data = self
            .single_payload(topic, log_time)?
            .ok_or_else(|| self.corrupt(format!("{topic} at frame {index} missing")))?;
        let mut r = CdrReader::new(&data).map_err(|e| self.corrupt(e))?;
        let step = r.u64().map_err(|e| self.corrupt(e))?;
        let time = r.f64().map_err(|e| self.corrupt(e))?;
        Ok((step, time))
    }

    /// The frame whose step is the first at or after `step` (the last frame if none).
    pub fn frame_at_step(&self, step: u64) -> Result<usize, ReadError> {
        let n = self.frame_count();
        if n == 0 {
            return Err(ReadError::NoSuchFrame {
                path: self.name(),
                frame: 0,
                frames: 0,
            });
        }
        // Frames are in step order: binary search on their headers.
        let (mut lo, mut hi) = (0usize, n - 1);
        if self.frame_header(hi as i64)?.0 < step {
            return Ok(hi);
        }
        while lo < hi {
            let mid = (lo + hi) / 2;
            if self.frame_header(mid as i64)?.0 >= step {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        Ok(lo)
    }
}

/// Drives the mcap crate's sans-io summary reader over a file.
fn read_summary(file: &mut File, file_size: u64) -> mcap::McapResult<Option<mcap::Summary>> {
    use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
    let mut reader = SummaryReader::new_with_options(
        SummaryReaderOptions::default()
            .with_file_size(file_size)
            .with_record_length_limit(file_size.min(1 << 32) as usize),
    );
    while let Some(event) = reader.next_event() {
        match event? {
            SummaryReadEvent::ReadRequest(n) => {
                let read = file.read(reader.insert(n))?;
                reader.notify_read(read);
            }
            SummaryReadEvent::SeekRequest(to) => {
                let pos = file.seek(to)?;
                reader.notify_seeked(pos);
            }
        }
    }
    Ok(reader.finish())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cdr_layout_matches_the_ros2_rules() {
        // Expectation (XCDR1): u64 at 0, f64 at 8, sequence length at 16, 4 bytes of padding,
        // the first element at 24; an empty sequence gets no padding.
        let mut buf = Vec::new();
        let mut w = CdrWriter::new(&mut buf);
        w.u64(7);
        w.f64(0.5);
        w.f64_seq(1, [2.0].into_iter());
        w.f64_seq(0, std::iter::empty());
        w.f64_seq(1, [3.0].into_iter());
        assert_eq!(&buf[..4], &[0, 1, 0, 0]);
        assert_eq!(
            u32::from_le_bytes(buf[4 + 16..4 + 20].try_into().unwrap()),
            1
        );
        assert_eq!(
            f64::from_le_bytes(buf[4 + 24..4 + 32].try_into().unwrap()),
            2.0
        );
        // Empty sequence: its length at 32, then the next length at 36, its element at 40.
        assert_eq!(
            u32::from_le_bytes(buf[4 + 32..4 + 36].try_into().unwrap()),
            0
        );
        assert_eq!(
            u32::from_le_bytes(buf[4 + 36..4 + 40].try_into().unwrap()),
            1
        );
        assert_eq!(
            f64::from_le_bytes(buf[4 + 40..4 + 48].try_into().unwrap()),
            3.0
        );
        let mut r = CdrReader::new(&buf).unwrap();
        assert_eq!(r.u64().unwrap(), 7);
        assert_eq!(r.f64().unwrap(), 0.5);
        assert_eq!(r.f64_seq().unwrap(), vec![2.0]);
        assert!(r.f64_seq().unwrap().is_empty());
        assert_eq!(r.f64_seq().unwrap(), vec![3.0]);
        assert!(r.f64_seq().is_err());
    }

    #[test]
    fn macro_row_round_trips_with_infinities() {
        let m = Measures {
            step: 12,
            time: 0.25,
            phase: "isotropic".into(),
            phi: 0.8,
            inertial_number: f64::INFINITY,
            contacts: 5,
            ..Default::default()
        };
        let mut buf = Vec::new();
        encode_macro(&mut buf, &m);
        assert_eq!(decode_macro(&buf).unwrap(), m);
        // A message of a log written before z_nr3 ends just before it: read, z_nr3 unknown.
        let old_end = buf.len() - 8;
        let old = decode_macro(&buf[..old_end]).unwrap();
        assert!(old.z_nr3.is_nan());
        assert_eq!(
            Measures {
                z_nr3: m.z_nr3,
                ..old
            },
            m
        );
        // Truncated anywhere else: an error, not a panic.
        for cut in (0..buf.len()).filter(|&cut| cut != old_end) {
            assert!(decode_macro(&buf[..cut]).is_err());
        }
    }

    #[test]
    fn colour_scale_ignores_rattlers_and_outliers() {
        let mut s: Vec<f64> = (1..=1000).map(|k| k as f64).collect();
        s.push(0.0);
        s.push(1e9);
        let top = stress_colour_max(&s);
        assert!((985.0..=1000.0).contains(&top), "{top}");
        assert_eq!(stress_colour_max(&[0.0, -1.0]), 0.0);
    }
}
