//! The writer of a run's trajectory log, hooked into the run loop.

use super::WriteError;
use super::contours;
use super::scene::encode_scene;
use super::schemas::*;
use crate::boundary::walls::Wall;
use crate::grain::Material;
use crate::integration::World;
use crate::output::frame::active_contacts;
use crate::output::measures::Measures;
use crate::scenario::Scenario;
use mcap::records;
use mcap::{Compression, WriteOptions};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};

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
    pub(super) inner: mcap::Writer<BufWriter<File>>,
    /// The same open file, to fsync it.
    file: File,
    /// A continued log is written to a temporary file that replaces this one at the first
    /// [`TrajectoryWriter::sync`] or at [`TrajectoryWriter::finish`].
    pub(super) replaces: Option<PathBuf>,
    /// The channels of the grains: SDEM ellipses or meshfree contours.
    pub(super) bodies: Bodies,
    walls: u16,
    macro_row: u16,
    scene: u16,
    pub(super) scene_every: u64,
    pub(super) sequence: u32,
    pub(super) last_log_time: Option<u64>,
    pub(super) frames: u64,
    pub(super) buf: Vec<u8>,
    text: String,
}

/// A new log's writer with the `sdem.run` metadata and the scenario attachment it wrote (see
/// [`TrajectoryWriter::create_log`]).
pub(super) type WithPreamble = (TrajectoryWriter, BTreeMap<String, String>, String);

/// A row of [`TrajectoryWriter::channel_table`].
pub(super) type ChannelRow = (
    u16,
    &'static str,
    &'static str,
    &'static str,
    &'static str,
    &'static str,
);

/// How a log describes its grains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Bodies {
    /// SDEM: `/grains` (ellipses) and `/contacts`.
    /// `tangential`: `/contacts` has the `tangential_force` column (a frictional run).
    Ellipses {
        grains: u16,
        contacts: u16,
        tangential: bool,
    },
    /// Meshfree: `/contours` (boundary-node polygons).
    Contours { contours: u16 },
}

/// What the `sdem.run` metadata of a log says of its run beyond the scenario.
pub(super) struct RunInfo<'a> {
    pub(super) grains: usize,
    pub(super) material: &'a Material,
    /// The grain model, as the `model` entry writes it.
    pub(super) model: String,
    pub(super) dt: f64,
    /// The `stress_sign` entry: the sign conventions of the channels.
    pub(super) stress_sign: &'static str,
    /// The entries of one solver.
    pub(super) extra: Vec<(&'static str, String)>,
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
    pub(super) fn create_with_preamble(
        settings: &McapSettings,
        scenario: &Scenario,
        world: &World,
    ) -> Result<WithPreamble, WriteError> {
        let p = &world.params;
        // Only a frictional run's `/contacts` has the tangential force: a frictionless run's
        // log stays as it was before friction existed, byte for byte.
        let tangential = scenario.friction().is_some();
        let info = RunInfo {
            grains: world.grains().len(),
            material: &p.material,
            model: match &p.adaptive {
                Some(a) => format!("Adaptive({:?})", a.settings),
                None => format!("{:?}", p.level),
            },
            dt: p.dt,
            stress_sign: "/grains: tension positive; /macro: compression positive",
            extra: vec![
                ("resolution_deg", format!("{}", p.resolution_deg)),
                ("contour_nodes", world.contours.nodes().to_string()),
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
                contacts_msg(tangential),
                "cdr",
            )?;
            Ok(Bodies::Ellipses {
                grains,
                contacts,
                tangential,
            })
        })
    }

    /// Creates a log: header, the channels of the bodies (added by `add_bodies`), then
    /// `/walls`, `/macro` and `/scene` (of schema `scene_schema`), the scenario attachment and
    /// the `sdem.run` metadata. Also returns the metadata and the scenario attachment.
    pub(super) fn create_log(
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
    pub(super) fn channel_table(&self) -> Vec<ChannelRow> {
        let mut table = match self.bodies {
            Bodies::Ellipses {
                grains,
                contacts,
                tangential,
            } => vec![
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
                    contacts_msg(tangential),
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

    pub(super) fn mcap_error(&self, error: mcap::McapError) -> WriteError {
        WriteError::Mcap {
            path: self.path.clone(),
            error,
        }
    }

    pub(super) fn put(
        &mut self,
        channel: u16,
        log_time: u64,
        data: &[u8],
    ) -> Result<(), WriteError> {
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
    pub(super) fn next_log_time(&mut self, time: f64) -> u64 {
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
            tangential,
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
        encode_contacts(&mut buf, world, &contacts, tangential);
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
    pub(super) fn finish_frame(
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
        if self.scene_every > 0 && self.frames.is_multiple_of(self.scene_every) {
            let mut text = std::mem::take(&mut self.text);
            scene(&mut text);
            self.put(self.scene, log_time, text.as_bytes())?;
            self.text = text;
        }
        self.frames += 1;
        Ok(())
    }

    pub(super) fn io_error(&self, error: std::io::Error) -> WriteError {
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

pub(super) type McapWriter = mcap::Writer<BufWriter<File>>;

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
pub(super) fn add_channel(
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
