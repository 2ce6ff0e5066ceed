//! Continuing a trajectory log from a checkpoint (`sdem resume --mcap FILE`).
//!
//! A log cannot be appended to: a finished one ends with its summary section, and a killed
//! writer leaves a partial chunk and no summary. So the log is rewritten: every message of the
//! frames written up to the checkpoint is read back (from a finished or an unfinished file) and
//! copied, with its channel, sequence number and log time, into a new file beside it; the run
//! goes on writing into that file, which replaces the old log at the first checkpoint or when
//! the log is finished. The result holds exactly the messages of the uninterrupted run.
//!
//! A frame is identified by the `step` of its `/grains` message (`/contours` in the log of a
//! meshfree run): the frames of the checkpoint are those with `step <= checkpoint.step` (frames
//! are written in step order, at most one per step), and there must be exactly as many as the
//! checkpoint's `macro.csv` rows. Every message of those frames (they share the frame's log
//! time) is kept; everything after them is dropped.

use super::contours::{ContourLogInfo, TOPIC_CONTOURS};
use super::writer::WithPreamble;
use super::{
    TOPIC_CONTACTS, TOPIC_GRAINS, TOPIC_MACRO, TOPIC_SCENE, TOPIC_WALLS, TrajectoryWriter,
    WriteError,
};
use crate::integration::World;
use crate::output::mcap::McapSettings;
use crate::scenario::Scenario;
use mcap::records::{MessageHeader, Record};
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Where a continued log picks up: the checkpoint's step and the number of frames (rows of
/// `macro.csv`) written up to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ContinueFrom {
    pub step: u64,
    pub frames: u64,
}

/// What [`TrajectoryWriter::continue_log`] (or [`TrajectoryWriter::continue_contours`]) found
/// in the log it continues.
#[derive(Debug, Clone, PartialEq)]
pub struct Continued {
    /// Frames kept (those of the checkpoint).
    pub kept_frames: u64,
    /// Complete frames after the checkpoint's step, dropped (the run writes them again).
    pub dropped_frames: u64,
    /// Whether the old log was finished (had its footer).
    pub was_finished: bool,
    /// Why reading stopped before the end of the old log, for an unfinished or damaged one.
    pub stopped: Option<String>,
    /// The file written until it replaces the old log.
    pub temporary: PathBuf,
}

/// A channel as read back from a log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScannedChannel {
    pub topic: String,
    pub message_encoding: String,
    pub schema_name: String,
    pub schema_encoding: String,
    pub schema_data: Vec<u8>,
}

/// Everything complete that a linear read of a log (finished or not) found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LogScan {
    /// Channels by id.
    pub channels: BTreeMap<u16, ScannedChannel>,
    /// Attachments: name and content.
    pub attachments: Vec<(String, Vec<u8>)>,
    /// Metadata records by name.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// Log times of the messages of each channel, in file order.
    pub messages: BTreeMap<u16, Vec<u64>>,
    /// The frames: (log time, step) of each message of the frame channel, in file order: the
    /// first `/grains` (SDEM) or `/contours` (meshfree) channel of the log.
    pub frames: Vec<(u64, u64)>,
    /// Whether the footer was reached (a finished log).
    pub finished: bool,
    /// Why the read stopped before the end, if it did (unfinished file, damaged chunk, ...).
    pub stopped: Option<String>,
}

impl LogScan {
    fn channel_id(&self, topic: &str) -> Option<u16> {
        self.channels
            .iter()
            .find(|(_, c)| c.topic == topic)
            .map(|(&id, _)| id)
    }
}

/// Reads a log from its start as far as it is complete: chunks are taken whole (their CRC
/// checked) or not at all, so a file cut anywhere, or damaged, gives what comes before the cut.
/// `on_message` sees every message in file order and returns false to stop early.
pub fn scan_log(
    path: &Path,
    mut on_message: impl FnMut(&MessageHeader, &[u8]) -> Result<bool, WriteError>,
) -> Result<LogScan, WriteError> {
    let name = path.display().to_string();
    let io = |error| WriteError::Io {
        path: name.clone(),
        error,
    };
    let mut file = File::open(path).map_err(io)?;
    let size = file.metadata().map_err(io)?.len();
    let mut magic = [0u8; 8];
    if size < 8 || file.read_exact(&mut magic).is_err() || magic != *mcap::MAGIC {
        return Err(WriteError::Continue {
            path: name,
            reason: "not an MCAP file (no MCAP magic at its start)".into(),
        });
    }
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_start_magic(true)
            .with_validate_chunk_crcs(true)
            .with_prevalidate_chunk_crcs(true)
            // Chunks decompress to far more than the file holds when it is small; a corrupt
            // length must not make the reader reserve absurd amounts of memory either.
            .with_record_length_limit(size.saturating_mul(64).clamp(1 << 26, 1 << 32) as usize),
    );
    let mut scan = LogScan::default();
    let mut schemas: BTreeMap<u16, (String, String, Vec<u8>)> = BTreeMap::new();
    let mut frame_channel: Option<(u16, &str)> = None;
    let mut read_bytes = 8u64;
    let mut messages_read = 0u64;
    while let Some(event) = reader.next_event() {
        let record = match event {
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let got = file.read(reader.insert(need)).map_err(io)?;
                reader.notify_read(got);
                read_bytes += got as u64;
                continue;
            }
            Ok(LinearReadEvent::Record { opcode, data }) => mcap::parse_record(opcode, data),
            Err(e) => Err(e),
        };
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                scan.stopped = Some(match e {
                    mcap::McapError::UnexpectedEof => format!(
                        "it ends inside a record after {size} bytes (an unfinished log: its \
                         writer was killed); {messages_read} messages before that are complete"
                    ),
                    e => format!(
                        "reading stopped near byte {read_bytes} of {size}: {e}; \
                         {messages_read} messages before that are complete"
                    ),
                });
                break;
            }
        };
        match record {
            Record::Schema { header, data } => {
                schemas.insert(header.id, (header.name, header.encoding, data.into_owned()));
            }
            Record::Channel(c) => {
                let (schema_name, schema_encoding, schema_data) =
                    schemas.get(&c.schema_id).cloned().unwrap_or_default();
                if frame_channel.is_none() {
                    frame_channel = [TOPIC_GRAINS, TOPIC_CONTOURS]
                        .into_iter()
                        .find(|&t| c.topic == t)
                        .map(|t| (c.id, t));
                }
                scan.channels.insert(
                    c.id,
                    ScannedChannel {
                        topic: c.topic,
                        message_encoding: c.message_encoding,
                        schema_name,
                        schema_encoding,
                        schema_data,
                    },
                );
            }
            Record::Attachment { header, data, .. } => {
                scan.attachments.push((header.name, data.into_owned()));
            }
            Record::Metadata(m) => {
                scan.metadata.insert(m.name, m.metadata);
            }
            Record::Message { header, data } => {
                messages_read += 1;
                if let Some((_, topic)) = frame_channel.filter(|&(id, _)| id == header.channel_id) {
                    // The step is the first field of `/grains` and of `/contours` (after the
                    // CDR header).
                    let Some(step) = data.get(4..12) else {
                        return Err(WriteError::Continue {
                            path: name,
                            reason: format!(
                                "a {topic} message at log time {} is too short",
                                header.log_time
                            ),
                        });
                    };
                    let step = u64::from_le_bytes(step.try_into().unwrap());
                    scan.frames.push((header.log_time, step));
                }
                scan.messages
                    .entry(header.channel_id)
                    .or_default()
                    .push(header.log_time);
                if !on_message(&header, &data)? {
                    break;
                }
            }
            Record::Footer(_) => scan.finished = true,
            _ => {}
        }
    }
    Ok(scan)
}

impl TrajectoryWriter {
    /// Continues the SDEM log at `settings.path` from a checkpoint: reads back every message of
    /// the `from.frames` frames written up to step `from.step` (the old log may be unfinished),
    /// writes them into `<path>.resume.tmp` after the same header, channels, scenario and
    /// `sdem.run` metadata, and returns a writer that goes on from there. The temporary file
    /// replaces the old log at the first [`TrajectoryWriter::sync`] or at
    /// [`TrajectoryWriter::finish`]; until then the old log is left as it was.
    ///
    /// Fails, naming the file, when a frame the checkpoint counts cannot be read back (the log
    /// was cut before the checkpoint's frames or is damaged), when the log holds more frames up
    /// to the checkpoint's step than the checkpoint counts, or when its channels, scenario or
    /// `sdem.run` metadata are not those of this run. The scene interval is the old log's.
    pub fn continue_log(
        settings: &McapSettings,
        scenario: &Scenario,
        world: &World,
        from: ContinueFrom,
    ) -> Result<(Self, Continued), WriteError> {
        Self::continue_with(
            settings,
            from,
            &[TOPIC_GRAINS, TOPIC_CONTACTS],
            |settings| Self::create_with_preamble(settings, scenario, world),
        )
    }

    /// [`TrajectoryWriter::continue_log`] for the log of a meshfree run, as
    /// [`TrajectoryWriter::create_contours`] creates it: its frames are identified by the step
    /// of their `/contours` message, which takes the place of `/grains` and `/contacts`.
    pub fn continue_contours(
        settings: &McapSettings,
        scenario: &Scenario,
        info: &ContourLogInfo,
        from: ContinueFrom,
    ) -> Result<(Self, Continued), WriteError> {
        Self::continue_with(settings, from, &[TOPIC_CONTOURS], |settings| {
            Self::create_contours_with_preamble(settings, scenario, info)
        })
    }

    /// Continues a log whose grains are on the channels `bodies` (the first one identifies the
    /// frames by its step): `create` writes the preamble of this run into the temporary file it
    /// is given the settings of, and the old log's must be the same.
    fn continue_with(
        settings: &McapSettings,
        from: ContinueFrom,
        bodies: &[&'static str],
        create: impl FnOnce(&McapSettings) -> Result<WithPreamble, WriteError>,
    ) -> Result<(Self, Continued), WriteError> {
        let path = &settings.path;
        let name = path.display().to_string();
        let fail = |reason: String| WriteError::Continue {
            path: name.clone(),
            reason,
        };
        let scan = scan_log(path, |_, _| Ok(true))?;
        let stopped = || {
            scan.stopped
                .as_ref()
                .map_or(String::new(), |s| format!(" ({s})"))
        };
        let Some(run) = scan.metadata.get("sdem.run") else {
            return Err(fail(format!(
                "no sdem.run metadata record can be read: not an sdem trajectory log, or a \
                 damaged one{}",
                stopped()
            )));
        };
        if scan.channel_id(bodies[0]).is_none() {
            return Err(fail(format!(
                "no {} channel can be read{}",
                bodies[0],
                stopped()
            )));
        }

        // The checkpoint's frames.
        let kept = scan
            .frames
            .iter()
            .take_while(|(_, step)| *step <= from.step)
            .count() as u64;
        if kept != from.frames {
            let last = match kept {
                0 => "none".to_string(),
                k => format!("the last at step {}", scan.frames[k as usize - 1].1),
            };
            let why = if kept < from.frames {
                format!(
                    "continuing it would leave a hole{}; write the continued part to another \
                     file instead",
                    stopped()
                )
            } else {
                "it is not the log of this run".to_string()
            };
            return Err(fail(format!(
                "the checkpoint (step {}) counts {} frames written up to its step, the log holds \
                 {kept} that can be read back ({last}): {why}",
                from.step, from.frames
            )));
        }
        let cutoff = kept.checked_sub(1).map(|k| scan.frames[k as usize].0);
        let upto = |topic: &str| -> u64 {
            scan.channel_id(topic)
                .and_then(|id| scan.messages.get(&id))
                .map_or(0, |times| {
                    times
                        .iter()
                        .filter(|&&t| cutoff.is_some_and(|c| t <= c))
                        .count() as u64
                })
        };

        // The new file starts as the old one did; its preamble must be the old one's.
        let scene_every = run.get("scene_every").and_then(|v| v.parse::<u64>().ok());
        let mut temporary = path.clone().into_os_string();
        temporary.push(".resume.tmp");
        let temporary = PathBuf::from(temporary);
        let tmp_settings = McapSettings {
            path: temporary.clone(),
            scene_every: scene_every.or(settings.scene_every),
        };
        let (mut writer, new_run, scenario_text) = create(&tmp_settings)?;
        let mismatch = |what: String| {
            std::fs::remove_file(&temporary).ok();
            fail(format!(
                "{what}: it is not the log of this run (or was written by another sdem); write \
                 the continued part to another file instead"
            ))
        };
        if *run != new_run {
            let keys: Vec<String> = run
                .keys()
                .chain(new_run.keys())
                .collect::<BTreeSet<_>>()
                .into_iter()
                .filter(|k| run.get(*k) != new_run.get(*k))
                .map(|k| {
                    format!(
                        "{k}: {:?} in the log, {:?} in this run",
                        run.get(k).map_or("-", |v| v.as_str()),
                        new_run.get(k).map_or("-", |v| v.as_str())
                    )
                })
                .collect();
            return Err(mismatch(format!(
                "its sdem.run metadata differs ({})",
                keys.join("; ")
            )));
        }
        match scan.attachments.iter().find(|(n, _)| n == "scenario.ron") {
            Some((_, data)) if *data == scenario_text.as_bytes() => {}
            Some(_) => {
                return Err(mismatch(
                    "its scenario.ron differs from the checkpoint's scenario".into(),
                ));
            }
            None => return Err(mismatch("it has no scenario.ron attachment".into())),
        }
        let expected = writer.channel_table();
        for (id, c) in &scan.channels {
            let same = expected
                .iter()
                .any(|(eid, topic, schema, enc, data, msg_enc)| {
                    eid == id
                        && c.topic == *topic
                        && c.schema_name == *schema
                        && c.schema_encoding == *enc
                        && c.schema_data == data.as_bytes()
                        && c.message_encoding == *msg_enc
                });
            if !same {
                return Err(mismatch(format!(
                    "its channel {id} ({}, schema {}) is not this sdem's",
                    c.topic, c.schema_name
                )));
            }
        }

        // Every message of each kept frame must be there (a frame can straddle two chunks).
        let scenes = match writer.scene_every {
            0 => 0,
            k => kept.div_ceil(k),
        };
        let expected: Vec<(&str, u64)> = bodies
            .iter()
            .map(|&topic| (topic, kept))
            .chain([
                (TOPIC_WALLS, kept),
                (TOPIC_MACRO, kept),
                (TOPIC_SCENE, scenes),
            ])
            .collect();
        for &(topic, want) in &expected {
            let have = upto(topic);
            if have != want {
                std::fs::remove_file(&temporary).ok();
                return Err(fail(format!(
                    "{topic} has {have} messages in the checkpoint's {kept} frames, expected \
                     {want}: a frame is incomplete{}",
                    stopped()
                )));
            }
        }

        // Copy the kept messages as they were.
        let mut copied = 0u64;
        let mut next_sequence = 0u32;
        if let Some(cutoff) = cutoff {
            scan_log(path, |header, data| {
                if header.log_time > cutoff {
                    return Ok(false);
                }
                writer
                    .inner
                    .write_to_known_channel(header, data)
                    .map_err(|e| writer.mcap_error(e))?;
                next_sequence = header.sequence.wrapping_add(1);
                copied += 1;
                Ok(true)
            })?;
        }
        let want: u64 = expected.iter().map(|&(_, n)| n).sum();
        if copied != want {
            std::fs::remove_file(&temporary).ok();
            return Err(fail(format!(
                "{copied} messages could be copied on a second read, {want} on the first: the \
                 file changed while it was read"
            )));
        }
        writer.sequence = next_sequence;
        writer.last_log_time = cutoff;
        writer.frames = kept;
        writer.replaces = Some(path.clone());
        let dropped = scan.frames.len() as u64 - kept;
        Ok((
            writer,
            Continued {
                kept_frames: kept,
                dropped_frames: dropped,
                was_finished: scan.finished,
                stopped: scan.stopped.clone(),
                temporary,
            },
        ))
    }
}
