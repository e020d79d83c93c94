//! Reading recordings, damaged ones included.
//!
//! The reader walks the file's top-level records itself (an opcode, a length, a body)
//! so it always knows the byte position it is at, and hands each chunk to the `mcap`
//! crate to decompress and check against its CRC. A file cut off by `kill -9`, a
//! truncated download or a corrupt chunk stops the walk at the first damaged record:
//! everything before it reads, and [`Recording::damage`] names the position and the
//! reason. A file that is not MCAP, or whose esgm channels have a schema this version
//! does not know, is refused with a [`ReadError`] naming the file and the position.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use esgm_core::EntityStructure;
use esgm_core::codec;
use esgm_core::esgm::TrajectoryInfo;
use esgm_core::octets::Octets;
use esgm_core::time::Time;
use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::layout::{
    ARCHIVE_ENCODING, EVENTS_TOPIC, EventKind, PIXELS_ATTRIBUTE, RECORDING_METADATA, RecordHeader,
    RecordedEvent, TYPES_ENCODING, TrajectoryMeta, TypeSchema,
};
use crate::ros2_bag;
use crate::view::raw_image;

/// The 8 bytes every MCAP file starts and ends with.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// Opcodes of the top-level records the walker looks into.
const OP_FOOTER: u8 = 0x02;
const OP_CHUNK: u8 = 0x06;
const OP_DATA_END: u8 = 0x0F;

/// Opening or reading a recording failed; each names the file and, where there is
/// one, the byte position.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadError {
    /// The file cannot be opened or read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file does not start with the MCAP magic.
    #[error("{path} is not an MCAP file (no MCAP magic at byte 0)")]
    NotMcap {
        /// The file.
        path: PathBuf,
    },
    /// An esgm channel's schema has an encoding or content this version cannot read.
    #[error("{path}: byte {position}: unknown schema for `{topic}`: {reason}")]
    UnknownSchema {
        /// The file.
        path: PathBuf,
        /// Where the channel record is.
        position: u64,
        /// The channel's topic.
        topic: String,
        /// What is unknown.
        reason: String,
    },
    /// A recorded structure cannot be read back.
    #[error(
        "{path}: byte {position}: structure {sequence} of `{trajectory}` is malformed: {reason}"
    )]
    Malformed {
        /// The file.
        path: PathBuf,
        /// The chunk (or record) holding it.
        position: u64,
        /// Its trajectory.
        trajectory: String,
        /// Its sequence number.
        sequence: u64,
        /// What is wrong.
        reason: String,
    },
    /// The file could not be read on at a position it was readable at when opened
    /// (changed, truncated or unreadable since): what came before was read, nothing
    /// after.
    #[error("{path}: byte {position}: damaged: {reason}")]
    Damaged {
        /// The file.
        path: PathBuf,
        /// Where reading stopped.
        position: u64,
        /// What is wrong there.
        reason: String,
    },
}

/// Where and why a file stops being readable.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Damage {
    /// Byte position of the first damaged record.
    pub position: u64,
    /// What is wrong there.
    pub reason: String,
}

/// One recorded trajectory: its declaration, its types and what the file holds of it.
#[derive(Debug, Clone)]
pub struct RecordedTrajectory {
    /// The trajectory as declared in the recorded system.
    pub info: TrajectoryInfo,
    /// Its type and nested types.
    pub types: TypeSchema,
    /// Topic of its Foxglove view, if any.
    pub view_topic: Option<String>,
    /// Structures readable.
    pub count: u64,
    /// Bytes of its messages, lossless and view.
    pub bytes: u64,
    /// Earliest and latest valid time.
    pub valid_range: Option<(Time, Time)>,
    /// Earliest and latest add time.
    pub add_range: Option<(Time, Time)>,
    /// Structures that did not reach the recording, per cause (events channel, and
    /// gaps in the recorded sequence not explained by it).
    pub losses: BTreeMap<String, u64>,
    /// Policy violations seen while recording.
    pub violations: u64,
    /// Lossless channel id.
    channel: u16,
}

impl RecordedTrajectory {
    /// A trajectory found in the file, nothing of it read yet.
    fn new(
        info: TrajectoryInfo,
        types: TypeSchema,
        view_topic: Option<String>,
        channel: u16,
    ) -> Self {
        Self {
            info,
            types,
            view_topic,
            count: 0,
            bytes: 0,
            valid_range: None,
            add_range: None,
            losses: BTreeMap::new(),
            violations: 0,
            channel,
        }
    }

    /// All losses, whatever the cause.
    pub fn lost(&self) -> u64 {
        // Counts come from the file, which may be crafted: they saturate, never wrap.
        self.losses.values().fold(0, |a, &n| a.saturating_add(n))
    }
}

/// A recording, opened: what it holds and how much of it is readable.
#[derive(Debug, Clone)]
pub struct Recording {
    /// The file.
    pub path: PathBuf,
    /// Its trajectories, in the order they were declared.
    pub trajectories: Vec<RecordedTrajectory>,
    /// Violations and losses recorded, in file order.
    pub events: Vec<RecordedEvent>,
    /// The recording's metadata (domain, host, format version…).
    pub metadata: BTreeMap<String, String>,
    /// Channels that are not esgm's (another tool's topics), by topic.
    pub foreign_topics: Vec<String>,
    /// True when the file ends with its summary, footer and magic.
    pub complete: bool,
    /// The first damaged record, if any; everything before it is readable.
    pub damage: Option<Damage>,
    /// The file's length.
    pub file_len: u64,
    /// Bytes readable (the position of the damage, or the whole file).
    pub readable_len: u64,
    /// The longest a structure took from its add to the recorder (recorded − add
    /// time), ns: structures that came as a trajectory's history when the recorder
    /// joined are as late as that history is long. Reading in add order needs a
    /// look-ahead this long ([`crate::replay::AddOrder`]).
    pub max_lateness: Time,
}

/// A structure read back, with the times the recorder kept.
#[derive(Debug, Clone)]
pub struct RecordedSample {
    /// Index of its trajectory in [`Recording::trajectories`].
    pub trajectory: usize,
    /// The structure, exactly as it was added.
    pub structure: EntityStructure,
    /// Add time, recorded time and sequence.
    pub header: RecordHeader,
    /// The input structures it was made from, as recorded (a produced structure's).
    pub lineage: Option<esgm_core::Lineage>,
}

impl Recording {
    /// Opens `path` and reads it through once, to learn its trajectories and find
    /// any damage.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, ReadError> {
        // A bag's directory (`esgm record --ros2`, rosbag2's) reads as its file.
        let path = crate::rosbag2::resolve(path.as_ref())
            .map_err(|source| ReadError::Io { path: path.as_ref().to_path_buf(), source })?;
        let mut walker = Walker::open(&path)?;
        let mut rec = Recording {
            path: path.clone(),
            trajectories: Vec::new(),
            events: Vec::new(),
            metadata: BTreeMap::new(),
            foreign_topics: Vec::new(),
            complete: false,
            damage: None,
            file_len: walker.file_len,
            readable_len: walker.file_len,
            max_lateness: 0,
        };
        let mut decoder = Decoder::default();
        let mut next_sequence: HashMap<usize, u64> = HashMap::new();
        loop {
            let item = match walker.next_item() {
                Ok(Some(item)) => item,
                Ok(None) => break,
                Err(damage) => {
                    rec.readable_len = damage.position;
                    rec.damage = Some(damage);
                    break;
                }
            };
            match item {
                Item::Footer => rec.complete = true,
                Item::Record(position, record) => {
                    match decoder.take(&path, position, record, &mut rec) {
                        Ok(Some(sample)) => {
                            let t = &mut rec.trajectories[sample.trajectory];
                            let expected = next_sequence.entry(sample.trajectory).or_insert(0);
                            // Sequence numbers come from the file: nothing here may wrap.
                            if sample.header.sequence > *expected {
                                let gap = t.losses.entry("sequence_gap".into()).or_default();
                                *gap = gap.saturating_add(sample.header.sequence - *expected);
                            }
                            *expected = sample.header.sequence.saturating_add(1);
                            t.count = t.count.saturating_add(1);
                            rec.max_lateness = rec.max_lateness.max(
                                sample.header.recorded_time.saturating_sub(sample.header.add_time),
                            );
                            let v = sample.structure.valid_time;
                            let a = sample.header.add_time;
                            t.valid_range = Some(
                                t.valid_range.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))),
                            );
                            t.add_range =
                                Some(t.add_range.map_or((a, a), |(lo, hi)| (lo.min(a), hi.max(a))));
                        }
                        Ok(None) => {}
                        Err(e @ ReadError::UnknownSchema { .. }) => return Err(e),
                        Err(e) => {
                            rec.readable_len = position;
                            rec.damage = Some(Damage { position, reason: e.to_string() });
                            break;
                        }
                    }
                }
            }
        }
        // Gaps the recorder itself explained are not counted twice.
        for t in &mut rec.trajectories {
            let explained: u64 = rec
                .events
                .iter()
                .filter(|e| {
                    e.kind == EventKind::Loss
                        && e.trajectory == t.info.name
                        && e.cause == "recorder_overflow"
                })
                .map(|e| e.count)
                .fold(0, u64::saturating_add);
            if let Some(gap) = t.losses.get_mut("sequence_gap") {
                *gap = gap.saturating_sub(explained);
                if *gap == 0 {
                    t.losses.remove("sequence_gap");
                }
            }
            for e in rec.events.iter().filter(|e| e.trajectory == t.info.name) {
                match e.kind {
                    EventKind::Violation => t.violations = t.violations.saturating_add(e.count),
                    EventKind::Loss => {
                        let n = t.losses.entry(e.cause.clone()).or_default();
                        *n = n.saturating_add(e.count);
                    }
                }
            }
        }
        Ok(rec)
    }

    /// The trajectory named `name`.
    pub fn trajectory(&self, name: &str) -> Option<&RecordedTrajectory> {
        self.trajectories.iter().find(|t| t.info.name == name)
    }

    /// Every readable structure, in file order (the order the recorder received them:
    /// add order within a trajectory). Stops quietly at the damage [`open`] found.
    ///
    /// [`open`]: Recording::open
    pub fn samples(&self) -> Result<Samples, ReadError> {
        let walker = Walker::open(&self.path)?;
        let mut shadow = Recording { trajectories: Vec::new(), events: Vec::new(), ..self.clone() };
        shadow.trajectories.clear();
        Ok(Samples {
            walker,
            decoder: Decoder::default(),
            path: self.path.clone(),
            shadow,
            stop_at: self.readable_len,
            done: false,
        })
    }

    /// Recording start and end in valid time, over every trajectory.
    pub fn valid_range(&self) -> Option<(Time, Time)> {
        self.trajectories
            .iter()
            .filter_map(|t| t.valid_range)
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
    }
}

/// The structures of a recording, streamed from the file ([`Recording::samples`]).
#[derive(Debug)]
pub struct Samples {
    walker: Walker,
    decoder: Decoder,
    path: PathBuf,
    /// The trajectories as this pass declares them (same indexes as the opened ones).
    shadow: Recording,
    stop_at: u64,
    done: bool,
}

impl Iterator for Samples {
    type Item = Result<RecordedSample, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            match self.walker.next_item() {
                Ok(Some(Item::Record(position, record))) => {
                    if position >= self.stop_at {
                        self.done = true;
                        break;
                    }
                    match self.decoder.take(&self.path, position, record, &mut self.shadow) {
                        Ok(Some(sample)) => return Some(Ok(sample)),
                        Ok(None) => {}
                        Err(e) => {
                            self.done = true;
                            return Some(Err(e));
                        }
                    }
                }
                Ok(Some(Item::Footer)) => {}
                Ok(None) => self.done = true,
                // Damage found when the file was opened ends the readable part
                // (`stop_at`, and `Recording::damage` says where); damage within it
                // appeared since, and is said, not taken for the end.
                Err(damage) if damage.position >= self.stop_at => self.done = true,
                Err(damage) => {
                    self.done = true;
                    return Some(Err(ReadError::Damaged {
                        path: self.path.clone(),
                        position: damage.position,
                        reason: damage.reason,
                    }));
                }
            }
        }
        None
    }
}

/// Turns records into trajectories, events and samples.
#[derive(Debug, Default)]
struct Decoder {
    schemas: HashMap<u16, (String, String, Vec<u8>)>,
    /// Lossless channel id → trajectory index.
    lossless: HashMap<u16, usize>,
    /// View channel id → the last view message (sequence, data).
    views: HashMap<u16, Option<(u32, Vec<u8>)>>,
    /// A ROS 2 bag's channel of a standard message → its trajectory's index, what it
    /// holds, and the sequence its next message gets ([`crate::ros2_bag`]).
    bags: HashMap<u16, (usize, ros2_bag::BagChannel, u64)>,
    /// View channels in the ROS 2 profile (`esgm record --ros2`): an image's pixels
    /// there are a `sensor_msgs/msg/Image`'s data, not a raw image view's.
    cdr_views: std::collections::HashSet<u16>,
    events_channel: Option<u16>,
}

impl Decoder {
    fn take(
        &mut self,
        path: &Path,
        position: u64,
        record: Record<'static>,
        rec: &mut Recording,
    ) -> Result<Option<RecordedSample>, ReadError> {
        match record {
            Record::Schema { header, data } => {
                self.schemas.insert(header.id, (header.name, header.encoding, data.into_owned()));
            }
            Record::Channel(c) => {
                if c.message_encoding == ARCHIVE_ENCODING {
                    let unknown = |reason: String| ReadError::UnknownSchema {
                        path: path.to_path_buf(),
                        position,
                        topic: c.topic.clone(),
                        reason,
                    };
                    let (_, encoding, data) = self.schemas.get(&c.schema_id).ok_or_else(|| {
                        unknown(format!("schema {} is not in the file", c.schema_id))
                    })?;
                    if encoding != TYPES_ENCODING {
                        return Err(unknown(format!(
                            "schema encoding `{encoding}`, expected `{TYPES_ENCODING}`"
                        )));
                    }
                    let types = TypeSchema::from_bytes(data).map_err(unknown)?;
                    let meta = TrajectoryMeta::from_map(&c.metadata).map_err(unknown)?;
                    let index =
                        match rec.trajectories.iter().position(|t| t.info.name == meta.info.name) {
                            Some(i) => i,
                            None => {
                                rec.trajectories.push(RecordedTrajectory::new(
                                    meta.info,
                                    types,
                                    meta.view_topic,
                                    c.id,
                                ));
                                rec.trajectories.len() - 1
                            }
                        };
                    rec.trajectories[index].channel = c.id;
                    self.lossless.insert(c.id, index);
                } else if c.topic == EVENTS_TOPIC {
                    self.events_channel = Some(c.id);
                } else if c.metadata.contains_key(crate::layout::keys::TRAJECTORY) {
                    self.views.insert(c.id, None);
                    if c.message_encoding == ros2_bag::CDR {
                        self.cdr_views.insert(c.id);
                    }
                } else if self.bags.contains_key(&c.id) {
                    // The summary repeats the channels: this one is read already.
                } else if let Some(bag) =
                    self.bag_channel(&c.topic, &c.message_encoding, c.schema_id)
                    && !rec.trajectories.iter().any(|t| t.info.name == bag.info.name)
                {
                    rec.trajectories.push(RecordedTrajectory::new(
                        bag.info.clone(),
                        bag.types.clone(),
                        None,
                        c.id,
                    ));
                    self.bags.insert(c.id, (rec.trajectories.len() - 1, bag, 0));
                } else if !rec.foreign_topics.contains(&c.topic) {
                    rec.foreign_topics.push(c.topic);
                }
            }
            Record::Metadata(m) if m.name == RECORDING_METADATA => rec.metadata.extend(m.metadata),
            Record::Message { header, data } => {
                if let Some(slot) = self.views.get_mut(&header.channel_id) {
                    *slot = Some((header.sequence, data.into_owned()));
                    return Ok(None);
                }
                if Some(header.channel_id) == self.events_channel {
                    let event: RecordedEvent =
                        serde_json::from_slice(&data).map_err(|e| ReadError::Malformed {
                            path: path.to_path_buf(),
                            position,
                            trajectory: EVENTS_TOPIC.into(),
                            sequence: u64::from(header.sequence),
                            reason: e.to_string(),
                        })?;
                    rec.events.push(event);
                    return Ok(None);
                }
                if let Some((index, bag, next)) = self.bags.get_mut(&header.channel_id) {
                    let t = &mut rec.trajectories[*index];
                    let log_time = Time::try_from(header.log_time).unwrap_or(Time::MAX);
                    return Ok(match ros2_bag::bag_structure(bag, &data, log_time) {
                        Ok(structure) => {
                            t.bytes = t.bytes.saturating_add(data.len() as u64);
                            let sequence = *next;
                            *next = next.saturating_add(1);
                            let header = RecordHeader {
                                add_time: log_time,
                                recorded_time: log_time,
                                sequence,
                                pixels_in_view: false,
                                view_channel: 0,
                                lineage_len: 0,
                            };
                            let lineage = None;
                            Some(RecordedSample { trajectory: *index, structure, header, lineage })
                        }
                        Err(e) => {
                            // A bag is another tool's file: a message esgm cannot read
                            // is counted with its cause, and the rest still reads.
                            ros2_bag::count_loss(&mut t.losses, ros2_bag::loss_cause(&e));
                            tracing::debug!(trajectory = %t.info.name, error = %e,
                                "a ROS 2 bag message not read");
                            None
                        }
                    });
                }
                let Some(&index) = self.lossless.get(&header.channel_id) else { return Ok(None) };
                let t = &mut rec.trajectories[index];
                let malformed = |sequence: u64, reason: String| ReadError::Malformed {
                    path: path.to_path_buf(),
                    position,
                    trajectory: t.info.name.clone(),
                    sequence,
                    reason,
                };
                let (h, lineage, archive) = RecordHeader::decode_with_lineage(&data)
                    .map_err(|r| malformed(u64::from(header.sequence), r))?;
                let lineage = lineage
                    .map(codec::decode_lineage)
                    .transpose()
                    .map_err(|e| malformed(h.sequence, e.to_string()))?;
                let mut structure = codec::decode_bytes(archive)
                    .map_err(|e| malformed(h.sequence, e.to_string()))?;
                let mut view_len = 0;
                if h.pixels_in_view {
                    let view = self
                        .views
                        .get_mut(&h.view_channel)
                        .and_then(Option::take)
                        .filter(|(seq, _)| *seq == header.sequence)
                        .ok_or_else(|| {
                            malformed(h.sequence, "its image view message is missing".into())
                        })?;
                    view_len = view.1.len() as u64;
                    let pixels = if self.cdr_views.contains(&h.view_channel) {
                        ros2_bag::image_pixels(&view.1)
                            .map_err(|e| malformed(h.sequence, format!("ROS 2 image view: {e}")))?
                    } else {
                        raw_image::decode_raw_image(&view.1)
                            .map_err(|e| malformed(h.sequence, format!("image view: {e}")))?
                            .data
                            .to_vec()
                    };
                    structure.set(PIXELS_ATTRIBUTE, Octets::new(pixels));
                }
                t.bytes = t.bytes.saturating_add(data.len() as u64).saturating_add(view_len);
                return Ok(Some(RecordedSample {
                    trajectory: index,
                    structure,
                    header: h,
                    lineage,
                }));
            }
            _ => {}
        }
        Ok(None)
    }
}

impl Decoder {
    /// The trajectory a ROS 2 bag's channel holds, if it is one esgm reads.
    fn bag_channel(
        &self,
        topic: &str,
        message_encoding: &str,
        schema_id: u16,
    ) -> Option<ros2_bag::BagChannel> {
        let (name, encoding, _) = self.schemas.get(&schema_id)?;
        ros2_bag::bag_channel(topic, message_encoding, name, encoding)
    }
}

/// What the walker yields.
#[derive(Debug)]
enum Item {
    /// A record, at the byte position of its top-level record (its chunk's).
    Record(u64, Record<'static>),
    /// The footer: the file is complete.
    Footer,
}

/// Walks a file's top-level records, and the records inside each chunk.
#[derive(Debug)]
struct Walker {
    file: BufReader<File>,
    position: u64,
    file_len: u64,
    pending: std::collections::VecDeque<Record<'static>>,
    pending_position: u64,
    finished: bool,
}

impl Walker {
    fn open(path: &Path) -> Result<Self, ReadError> {
        let io = |source| ReadError::Io { path: path.to_path_buf(), source };
        let file = File::open(path).map_err(io)?;
        let file_len = file.metadata().map_err(io)?.len();
        let mut file = BufReader::with_capacity(1 << 20, file);
        let mut magic = [0u8; 8];
        if file_len < 8 || file.read_exact(&mut magic).is_err() || &magic != MAGIC {
            return Err(ReadError::NotMcap { path: path.to_path_buf() });
        }
        Ok(Self {
            file,
            position: 8,
            file_len,
            pending: Default::default(),
            pending_position: 0,
            finished: false,
        })
    }

    /// The next record, `Ok(None)` at the end of the data, or the damage.
    fn next_item(&mut self) -> Result<Option<Item>, Damage> {
        if let Some(r) = self.pending.pop_front() {
            return Ok(Some(Item::Record(self.pending_position, r)));
        }
        loop {
            if self.finished {
                return Ok(None);
            }
            let at = self.position;
            let damage = |reason: String| Damage { position: at, reason };
            let remaining = self.file_len - at;
            if remaining == 0 {
                self.finished = true;
                return Err(damage(
                    "the file ends without its summary and footer (the recorder did not finish)"
                        .into(),
                ));
            }
            if remaining < 9 {
                self.finished = true;
                return Err(damage(format!("truncated: {remaining} bytes where a record starts")));
            }
            let mut head = [0u8; 9];
            self.file.read_exact(&mut head).map_err(|e| damage(e.to_string()))?;
            let opcode = head[0];
            let mut len_bytes = [0u8; 8];
            len_bytes.copy_from_slice(&head[1..]);
            let len = u64::from_le_bytes(len_bytes);
            if opcode == OP_CHUNK && len == u64::MAX {
                // The writer writes a chunk's length when it finishes the chunk.
                self.finished = true;
                return Err(damage(
                    "an unfinished chunk: the recorder stopped while writing it, and the file ends without its summary"
                        .into(),
                ));
            }
            if len > remaining - 9 {
                self.finished = true;
                return Err(damage(format!(
                    "truncated: a record of {len} bytes (opcode {opcode:#04x}) but only {} bytes left",
                    remaining - 9
                )));
            }
            let mut body = vec![0u8; len as usize];
            self.file.read_exact(&mut body).map_err(|e| damage(e.to_string()))?;
            self.position = at + 9 + len;
            match opcode {
                OP_FOOTER => {
                    self.finished = true;
                    return Ok(Some(Item::Footer));
                }
                OP_CHUNK => {
                    let records = chunk_records(opcode, &head, &body).map_err(|e| {
                        self.finished = true;
                        damage(format!("corrupt chunk: {e}"))
                    })?;
                    self.pending = records.into();
                    self.pending_position = at;
                    if let Some(r) = self.pending.pop_front() {
                        return Ok(Some(Item::Record(at, r)));
                    }
                }
                OP_DATA_END => {}
                _ => {
                    let record = mcap::parse_record(opcode, &body).map_err(|e| {
                        self.finished = true;
                        damage(format!("corrupt record (opcode {opcode:#04x}): {e}"))
                    })?;
                    return Ok(Some(Item::Record(at, record.into_owned())));
                }
            }
        }
    }
}

/// The most bytes a chunk's records may take uncompressed. The `mcap` reader makes
/// room for them before it decompresses, so the size a damaged or crafted file claims
/// is checked first ([`check_chunk_size`]); a claim past this is damage, not an
/// allocation that aborts the process. The writer's chunks are 4 MiB, or one
/// structure when it is larger.
const MAX_CHUNK_RECORDS: u64 = 1 << 30;
/// The most zstd expands: a run-length block of 128 KiB takes 4 bytes.
const ZSTD_MAX_RATIO: u64 = 1 << 15;
/// The most lz4 expands: a length byte stands for at most 255 bytes.
const LZ4_MAX_RATIO: u64 = 256;
/// Expansion allowed on top of the ratio (a frame's header and one block).
const EXPANSION_SLACK: u64 = 1 << 17;

/// A chunk's uncompressed size, refused when it cannot be its records': past
/// [`MAX_CHUNK_RECORDS`], other than their length when they are not compressed, or
/// more than its compression can make of them. `None` for a body too short to say (or
/// an unknown compression), which the `mcap` reader refuses.
fn check_chunk_size(body: &[u8]) -> Result<Option<u64>, String> {
    let u64_at = |at: usize| {
        // An 8-byte slice always makes a `[u8; 8]`.
        let bytes: [u8; 8] = body.get(at..at.checked_add(8)?)?.try_into().ok()?;
        Some(u64::from_le_bytes(bytes))
    };
    // message start time, end time, then the uncompressed size, CRC, compression name
    // (u32 length + bytes) and the records' length.
    let Some(uncompressed) = u64_at(16) else { return Ok(None) };
    let Some(name_len) = body.get(28..32).and_then(|b| <[u8; 4]>::try_from(b).ok()) else {
        return Ok(None);
    };
    let name_end = 32usize.saturating_add(u32::from_le_bytes(name_len) as usize);
    let (Some(name), Some(records)) = (body.get(32..name_end), u64_at(name_end)) else {
        return Ok(None);
    };
    let most = match name {
        b"" => records,
        b"zstd" => records.saturating_mul(ZSTD_MAX_RATIO).saturating_add(EXPANSION_SLACK),
        b"lz4" => records.saturating_mul(LZ4_MAX_RATIO).saturating_add(EXPANSION_SLACK),
        _ => return Ok(None),
    };
    if uncompressed > MAX_CHUNK_RECORDS {
        return Err(format!(
            "its records are {uncompressed} bytes uncompressed, more than this reader's \
             limit of {MAX_CHUNK_RECORDS}"
        ));
    }
    if name.is_empty() && uncompressed != records {
        return Err(format!("{records} bytes of uncompressed records said to be {uncompressed}"));
    }
    if uncompressed > most {
        return Err(format!(
            "{records} compressed bytes cannot be {uncompressed} bytes uncompressed"
        ));
    }
    Ok(Some(uncompressed))
}

/// The records inside one chunk, decompressed and checked against the chunk's CRC.
fn chunk_records(opcode: u8, head: &[u8; 9], body: &[u8]) -> Result<Vec<Record<'static>>, String> {
    // No record inside is longer than the chunk's records uncompressed (the reader
    // makes room for a record's claimed length before decompressing it), nor any part
    // of the chunk longer than the chunk.
    let limit = check_chunk_size(body)?.unwrap_or(0).max(body.len() as u64);
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_record_length_limit(usize::try_from(limit).unwrap_or(usize::MAX))
            .with_skip_start_magic(true)
            .with_skip_end_magic(true)
            .with_validate_chunk_crcs(true)
            .with_prevalidate_chunk_crcs(true),
    );
    debug_assert_eq!(opcode, OP_CHUNK);
    let mut input: Vec<u8> = Vec::with_capacity(9 + body.len());
    input.extend_from_slice(head);
    input.extend_from_slice(body);
    let mut input = &input[..];
    let mut out = Vec::new();
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| e.to_string())? {
            LinearReadEvent::ReadRequest(n) => {
                let k = n.min(input.len());
                reader.insert(k).copy_from_slice(&input[..k]);
                reader.notify_read(k);
                input = &input[k..];
            }
            LinearReadEvent::Record { data, opcode } => {
                if opcode == OP_CHUNK {
                    continue;
                }
                let record = mcap::parse_record(opcode, data).map_err(|e| e.to_string())?;
                out.push(record.into_owned());
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chunk body: times, uncompressed size, CRC, compression and records' length.
    fn chunk(uncompressed: u64, compression: &str, records: u64) -> Vec<u8> {
        let mut body = vec![0u8; 16];
        body.extend(uncompressed.to_le_bytes());
        body.extend(0u32.to_le_bytes());
        body.extend((compression.len() as u32).to_le_bytes());
        body.extend(compression.as_bytes());
        body.extend(records.to_le_bytes());
        body
    }

    /// A crafted size made the `mcap` reader allocate it (3 PB in the fuzzer's case)
    /// and abort the process: `esgm info` on a hostile file died.
    #[test]
    fn a_chunk_claiming_more_than_its_records_can_be_is_damage() {
        assert!(check_chunk_size(&chunk(3_383_301_196_742_801, "zstd", 1000)).is_err());
        assert!(check_chunk_size(&chunk(MAX_CHUNK_RECORDS + 1, "zstd", 1 << 20)).is_err());
        assert!(check_chunk_size(&chunk(101, "", 100)).is_err());
        assert!(check_chunk_size(&chunk(100 * 257 + EXPANSION_SLACK, "lz4", 100)).is_err());
        assert!(check_chunk_size(&chunk(100, "", 100)).is_ok());
        assert!(check_chunk_size(&chunk(4 << 20, "zstd", 200)).is_ok());
        assert!(check_chunk_size(&chunk(4 << 20, "lz4", 1 << 15)).is_ok());
        // Too short to say: left to the mcap reader.
        assert!(check_chunk_size(&chunk(u64::MAX, "zstd", 1)[..20]).is_ok());
    }

    /// A record inside a chunk claiming a length past the chunk's made the `mcap`
    /// reader allocate it before decompressing (the fuzzer saw 2.4 EB): an abort.
    #[test]
    fn a_record_longer_than_its_chunk_is_damage() {
        let mut record = vec![0x05u8];
        record.extend((u64::MAX / 2).to_le_bytes());
        let mut body = chunk(record.len() as u64, "", record.len() as u64);
        body.extend(&record);
        let mut head = [OP_CHUNK; 9];
        head[1..].copy_from_slice(&(body.len() as u64).to_le_bytes());
        assert!(chunk_records(OP_CHUNK, &head, &body).is_err());
    }
}
