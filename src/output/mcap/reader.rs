//! The reader of trajectory logs, for `sdem inspect`, `render`, `plot`, `export`, tests and
//! tools: only the summary and the message indexes are read at open.

use super::ReadError;
use super::cdr::CdrReader;
use super::contours;
use super::schemas::*;
use crate::output::frame::Frame;
use crate::output::measures::Measures;
use crate::scenario::Scenario;
use mcap::records::{self, Record};
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

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
pub(super) struct MessageRef {
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
            // A log does not store each grain's model level.
            levels: None,
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
