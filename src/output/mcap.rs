//! Trajectory logs in MCAP (<https://mcap.dev>): a writer hooked into the run loop and a reader
//! for `sdem inspect`, `sdem render`, `sdem plot`, tests and tools.
//!
//! One log holds, at every output interval of a run (every row of `macro.csv`), one message on
//! each channel below, all with the same `log_time`:
//!
//! | topic | schema (encoding) | message encoding | content |
//! | --- | --- | --- | --- |
//! | `/grains` | `sdem_msgs/msg/Grains` (ros2msg) | cdr | the six DoF, radius and Love–Weber stress of every grain, f64 |
//! | `/contacts` | `sdem_msgs/msg/Contacts` (ros2msg) | cdr | active grain–grain contacts: pair, point, normal, force, length, f32; a frictional run's log also the tangential force |
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
//!
//! The code by role: `schemas` (topics, `.msg` texts, the CDR encoders and decoders),
//! `cdr` (the encoding), `scene` (the Foxglove `/scene` JSON), `writer` ([`TrajectoryWriter`]),
//! `reader` ([`Trajectory`]), `resume` (continuing a log after a checkpoint) and [`contours`]
//! (the meshfree channel). What a frame holds is [`crate::output::frame`], shared with `render`,
//! `plot` and the VTK export.

mod cdr;
pub mod contours;
mod reader;
mod resume;
mod scene;
mod schemas;
mod writer;

pub use contours::{
    CONTOUR_SCENE_SCHEMA, CONTOURS_MSG, ContourLogInfo, SCHEMA_CONTOURS, TOPIC_CONTOURS,
};
pub use reader::{AttachmentInfo, ChannelInfo, SizeInfo, StepTime, Trajectory};
pub use resume::{ContinueFrom, Continued, LogScan, scan_log};
pub use schemas::{
    CONTACTS_FRICTION_MSG, CONTACTS_MSG, FORMAT_VERSION, GRAINS_MSG, MACRO_MSG, SCENE_SCHEMA,
    SCHEMA_CONTACTS, SCHEMA_GRAINS, SCHEMA_MACRO, SCHEMA_SCENE, SCHEMA_WALLS, TOPIC_CONTACTS,
    TOPIC_GRAINS, TOPIC_MACRO, TOPIC_SCENE, TOPIC_WALLS, WALLS_MSG,
};
pub use writer::{McapSettings, TrajectoryWriter, time_to_ns};
// The frame model lives in `output::frame`; these paths stay for the code written against them.
pub use crate::output::colour::stress_colour_max;
pub use crate::output::frame::{Frame, FrameContact, FrameContour, FrameGrain, active_contacts};

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
