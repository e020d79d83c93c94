//! Writing recordings: trajectories into chunked, compressed MCAP files.
//!
//! A [`RecordingWriter`] owns the file (or the files, when it splits by size or
//! duration). Every file it writes is complete on its own: its schemas, channels and
//! recording metadata are written again at the start of each, so any one of them opens
//! alone. Chunks are finished at least every [`RecordOptions::flush_interval`]: when
//! the process is killed, at most that much is lost and every chunk before it reads.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use esgm_core::codec::{self, CodecError};
use esgm_core::esgm::TrajectoryInfo;
use esgm_core::octets::Octets;
use esgm_core::time::Time;
use esgm_core::{EntityStructure, EntityStructureType};
use mcap::records::MessageHeader;

use crate::layout::{
    self, ARCHIVE_ENCODING, EVENTS_TOPIC, PROFILE, RECORDING_METADATA, RecordHeader, RecordedEvent,
    TYPES_ENCODING, TrajectoryMeta, TypeSchema,
};
use crate::view::{self, ViewSchema};

/// How chunks are compressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    /// zstd: the best ratio, the default (as `ros2 bag` and Foxglove write).
    #[default]
    Zstd,
    /// lz4: faster, larger.
    Lz4,
    /// No compression: the fastest, for images that do not compress anyway.
    None,
}

impl std::str::FromStr for Compression {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "zstd" => Ok(Self::Zstd),
            "lz4" => Ok(Self::Lz4),
            "none" | "off" => Ok(Self::None),
            other => Err(format!("unknown compression `{other}` (zstd, lz4 or none)")),
        }
    }
}

/// How a recording is written. `Default` is zstd, 4 MiB chunks, a flush at least every
/// second, one file, views on.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// Chunk compression.
    pub compression: Compression,
    /// A chunk is finished when it holds this many bytes.
    pub chunk_size: u64,
    /// A chunk is finished at least this often, so a killed recorder loses at most
    /// this much.
    pub flush_interval: Duration,
    /// Start a new file when the current one holds this many bytes.
    pub split_bytes: Option<u64>,
    /// Start a new file when the current one covers this much wall time.
    pub split_duration: Option<Duration>,
    /// Write the Foxglove JSON views of structured trajectories beside their lossless
    /// channels (they cost a second, JSON copy of each structure). Image trajectories
    /// always have their `foxglove.RawImage` view: it is where their pixels are stored.
    pub views: bool,
    /// Write every view in the ROS 2 MCAP profile instead (`ros2msg` schemas, `cdr`
    /// messages, as rosbag2 writes them), so ROS 2 tools read the views as a bag: the
    /// library types as their standard messages (`sensor_msgs/msg/Image`…), every other
    /// type as its generated `esgm_msgs` message. An image's pixels are then stored
    /// twice, in its view and in the lossless channel.
    pub ros2: bool,
    /// Write a rosbag2 directory instead of a file ([`crate::rosbag2`]): the path is
    /// the bag's directory, its files `<dir>_0.mcap`, `<dir>_1.mcap`… hold only the ROS 2
    /// profile's channels (as [`RecordOptions::ros2`] writes them, on topics
    /// `/<trajectory>`), and `metadata.yaml` says what is in them, as rosbag2 writes it.
    /// No lossless channel, no events channel: a bag is what ROS 2 tools read; record
    /// a second, lossless recording beside it to keep esgm's own (`esgm record --ros2
    /// --lossless`). A trajectory whose type has no ROS 2 message is left out (said).
    pub bag: bool,
    /// Free-form metadata of the recording (domain, host, command line…).
    pub metadata: BTreeMap<String, String>,
}

impl Default for RecordOptions {
    fn default() -> Self {
        Self {
            compression: Compression::default(),
            chunk_size: 4 << 20,
            flush_interval: Duration::from_secs(1),
            split_bytes: None,
            split_duration: None,
            views: true,
            ros2: false,
            bag: false,
            metadata: BTreeMap::new(),
        }
    }
}

impl RecordOptions {
    /// Sets the compression.
    #[must_use]
    pub fn compression(mut self, c: Compression) -> Self {
        self.compression = c;
        self
    }
    /// Sets the chunk size in bytes.
    #[must_use]
    pub fn chunk_size(mut self, bytes: u64) -> Self {
        self.chunk_size = bytes.max(1);
        self
    }
    /// Sets the longest time between flushes.
    #[must_use]
    pub fn flush_interval(mut self, d: Duration) -> Self {
        self.flush_interval = d;
        self
    }
    /// Splits files at this size.
    #[must_use]
    pub fn split_bytes(mut self, bytes: Option<u64>) -> Self {
        self.split_bytes = bytes;
        self
    }
    /// Splits files at this duration.
    #[must_use]
    pub fn split_duration(mut self, d: Option<Duration>) -> Self {
        self.split_duration = d;
        self
    }
    /// Writes the views in the ROS 2 MCAP profile ([`RecordOptions::ros2`]).
    #[must_use]
    pub fn ros2(mut self, on: bool) -> Self {
        self.ros2 = on;
        self
    }

    /// Writes a rosbag2 directory ([`RecordOptions::bag`]); implies
    /// [`RecordOptions::ros2`].
    #[must_use]
    pub fn bag(mut self, on: bool) -> Self {
        self.bag = on;
        self.ros2 |= on;
        self
    }

    /// Turns the Foxglove views on or off.
    #[must_use]
    pub fn views(mut self, on: bool) -> Self {
        self.views = on;
        self
    }
    /// Adds a metadata entry.
    #[must_use]
    pub fn meta(mut self, key: impl Into<String>, value: impl Into<String>) -> Self {
        self.metadata.insert(key.into(), value.into());
        self
    }
}

/// Writing a recording failed; each names the file or the trajectory.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordError {
    /// The file cannot be created or written.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The MCAP writer refused.
    #[error("cannot write {path}: {source}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// Why.
        source: mcap::McapError,
    },
    /// A structure cannot be archived.
    #[error("cannot archive a structure of `{trajectory}`: {source}")]
    Encode {
        /// The trajectory.
        trajectory: String,
        /// Why.
        source: CodecError,
    },
    /// The same trajectory was added twice.
    #[error("trajectory `{0}` is already being recorded")]
    DuplicateTrajectory(String),
}

/// A trajectory being written, as [`RecordingWriter::add_trajectory`] returned it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TrajectoryId(usize);

/// What a finished recording holds.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct WriteSummary {
    /// The files written, in order.
    pub files: Vec<PathBuf>,
    /// Structures written, per trajectory.
    pub structures: BTreeMap<String, u64>,
    /// Bytes of lossless messages (headers and archives), per trajectory.
    pub lossless_bytes: BTreeMap<String, u64>,
    /// Bytes of view messages, per trajectory: what the Foxglove views cost. For image
    /// trajectories this is the pixels, which the lossless messages do not repeat.
    pub view_bytes: BTreeMap<String, u64>,
    /// Events (violations and losses) written.
    pub events: u64,
    /// Per file, in order: the messages it holds and their first and last log time
    /// (valid time, ns), what a bag's `metadata.yaml` says of each file.
    pub file_messages: Vec<FileMessages>,
    /// A bag's topics ([`RecordOptions::bag`]), by trajectory: topic, message type,
    /// messages written.
    pub bag_topics: BTreeMap<String, BagTopic>,
    /// Trajectories left out of a bag: their type has no ROS 2 message.
    pub left_out: Vec<String>,
}

/// What one file of a recording holds.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FileMessages {
    /// Messages written into it.
    pub messages: u64,
    /// The first and last log time (ns), if any message.
    pub log_range: Option<(Time, Time)>,
}

/// One topic of a bag.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct BagTopic {
    /// The ROS 2 topic, `/<trajectory>`.
    pub topic: String,
    /// Its message type, e.g. `sensor_msgs/msg/Image`.
    pub message_type: String,
    /// Messages written.
    pub messages: u64,
}

/// How a trajectory is shown in Foxglove.
#[derive(Debug, Clone)]
enum ViewKind {
    /// `foxglove.RawImage`; the lossless message leaves the pixels out.
    Image,
    /// JSON with a JSON Schema.
    Json,
    /// A ROS 2 message in CDR ([`RecordOptions::ros2`]).
    Ros2(Ros2View),
}

/// Which ROS 2 message a trajectory's view is.
#[derive(Debug, Clone)]
enum Ros2View {
    /// A standard message of a library type.
    Standard(esgm_ros2msg::mapping::RosType),
    /// The type's generated `esgm_msgs` message.
    Generated(std::sync::Arc<esgm_ros2msg::generated::Schema>),
}

/// A trajectory's declaration, kept to write it again into each new file.
#[derive(Debug)]
struct Recorded {
    meta: TrajectoryMeta,
    schema: TypeSchema,
    view: Option<(ViewKind, ViewSchema)>,
    /// Channel ids in the current file.
    lossless_channel: u16,
    view_channel: u16,
    sequence: u64,
    /// False for a trajectory a bag leaves out (no ROS 2 message for its type).
    in_bag: bool,
}

/// The MCAP writer of the current file.
type McapFile = mcap::Writer<BufWriter<File>>;

/// The file's write buffer: small records (headers, small structures) gather here
/// into few system calls, while a record at least this large (an image: 921,600 bytes
/// for 640×480 RGB) bypasses it and goes to the file in one `write`, without a copy
/// into the buffer first. A buffer larger than an image would copy every frame once
/// more (measured: that copy was half of the recorder's user-space time per frame).
const WRITE_BUFFER: usize = 64 << 10;

/// Writes one recording: see the [module docs](self).
pub struct RecordingWriter {
    path: PathBuf,
    options: RecordOptions,
    file: Option<McapFile>,
    file_path: PathBuf,
    file_opened: Instant,
    file_bytes: u64,
    last_flush: Instant,
    events_channel: u16,
    trajectories: Vec<Recorded>,
    summary: WriteSummary,
    scratch: Vec<u8>,
    view_scratch: Vec<u8>,
}

impl std::fmt::Debug for RecordingWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordingWriter")
            .field("file", &self.file_path)
            .field("trajectories", &self.trajectories.len())
            .finish_non_exhaustive()
    }
}

impl RecordingWriter {
    /// Creates the recording at `path` (replacing a file there).
    pub fn create(path: impl Into<PathBuf>, options: RecordOptions) -> Result<Self, RecordError> {
        let path = path.into();
        let mut w = Self {
            file_path: path.clone(),
            path,
            options,
            file: None,
            file_opened: Instant::now(),
            file_bytes: 0,
            last_flush: Instant::now(),
            events_channel: 0,
            trajectories: Vec::new(),
            summary: WriteSummary::default(),
            scratch: Vec::new(),
            view_scratch: Vec::new(),
        };
        w.open_file()?;
        Ok(w)
    }

    /// The file being written now.
    pub fn current_file(&self) -> &Path {
        &self.file_path
    }

    /// Declares a trajectory: its type (with nested types) and its declaration go into
    /// the file before any of its structures.
    pub fn add_trajectory(
        &mut self,
        info: TrajectoryInfo,
        types: TypeSchema,
    ) -> Result<TrajectoryId, RecordError> {
        if self.trajectories.iter().any(|t| t.meta.info.name == info.name) {
            return Err(RecordError::DuplicateTrajectory(info.name));
        }
        let view = if self.options.ros2 {
            Some(ros2_view_of(&info.type_name, &types))
        } else if self.options.views || view::raw_image::image_view(&types.root).is_some() {
            Some(view_of(&types))
        } else {
            None
        };
        let in_bag = matches!(view, Some((ViewKind::Ros2(_), _)));
        let view_topic = view
            .as_ref()
            .map(|_| if self.options.bag { format!("/{}", info.name) } else { info.name.clone() });
        if self.options.bag {
            if in_bag {
                if let (Some(topic), Some((_, schema))) = (&view_topic, &view) {
                    self.summary.bag_topics.insert(
                        info.name.clone(),
                        BagTopic {
                            topic: topic.clone(),
                            message_type: schema.name.clone(),
                            messages: 0,
                        },
                    );
                }
            } else {
                tracing::warn!(trajectory = %info.name, "left out of the bag: its type `{}` has no ROS 2 message", info.type_name);
                self.summary.left_out.push(info.name.clone());
            }
        }
        let mut recorded = Recorded {
            meta: TrajectoryMeta { info, view_topic },
            schema: types,
            view,
            lossless_channel: 0,
            view_channel: 0,
            sequence: 0,
            in_bag,
        };
        let file = self.file.as_mut().ok_or_else(|| closed(&self.file_path))?;
        declare(file, &self.file_path, &mut recorded, self.options.bag)?;
        self.trajectories.push(recorded);
        Ok(TrajectoryId(self.trajectories.len() - 1))
    }

    /// Writes one structure of a trajectory, with the time it was added and the time
    /// the recorder received it.
    pub fn write(
        &mut self,
        id: TrajectoryId,
        es: &EntityStructure,
        add_time: Time,
        recorded_time: Time,
    ) -> Result<(), RecordError> {
        self.write_traced(id, es, add_time, recorded_time, None)
    }

    /// [`Self::write`] of a sample as a trajectory delivered it: its lineage is
    /// recorded with it ([`crate::RecordedSample::lineage`]).
    pub fn write_sample(
        &mut self,
        id: TrajectoryId,
        sample: &esgm_core::Sample,
        recorded_time: Time,
    ) -> Result<(), RecordError> {
        let lineage = sample.lineage.as_deref();
        // The views (image, JSON, ROS 2) are made of owned values: an archived structure
        // is converted for them (its pixels stay where they are).
        let es = sample.structure.to_arc();
        self.write_traced(id, &es, sample.add_time, recorded_time, lineage)
    }

    fn write_traced(
        &mut self,
        id: TrajectoryId,
        es: &EntityStructure,
        add_time: Time,
        recorded_time: Time,
        lineage: Option<&esgm_core::Lineage>,
    ) -> Result<(), RecordError> {
        self.rotate_if_due()?;
        let bag = self.options.bag;
        let t = &mut self.trajectories[id.0];
        if bag && !t.in_bag {
            return Ok(());
        }
        let name = &t.meta.info.name;
        let sequence = t.sequence;
        t.sequence += 1;
        let mcap_sequence = sequence as u32;
        let valid = layout::mcap_time(es.valid_time);
        let published = layout::mcap_time(add_time);
        let file = self.file.as_mut().ok_or_else(|| closed(&self.file_path))?;
        let path = &self.file_path;

        let mut pixels_in_view = false;
        if let Some((kind, _)) = &t.view {
            self.view_scratch.clear();
            let viewable = match kind {
                ViewKind::Image => {
                    match view::raw_image::encode_raw_image(es, name, &mut self.view_scratch) {
                        Ok(_) => {
                            pixels_in_view = true;
                            true
                        }
                        Err(e) => {
                            // Not a showable image (a format Foxglove lacks, a wrong pixel
                            // count): kept whole in the lossless channel, not shown.
                            tracing::warn!(
                                "`{name}` at valid time {}: no image view: {e}",
                                es.valid_time
                            );
                            false
                        }
                    }
                }
                ViewKind::Json => match view::json::encode_json(es, &mut self.view_scratch) {
                    Ok(()) => true,
                    Err(e) => {
                        tracing::warn!(
                            "`{name}` at valid time {}: no JSON view: {e}",
                            es.valid_time
                        );
                        false
                    }
                },
                ViewKind::Ros2(v) => match encode_ros2(v, es, &mut self.view_scratch) {
                    Ok(()) => {
                        // An image's pixels are the message's `data`: stored once.
                        pixels_in_view =
                            matches!(v, Ros2View::Standard(esgm_ros2msg::mapping::RosType::Image));
                        true
                    }
                    Err(e) => {
                        // Kept whole in the lossless channel, not shown.
                        tracing::warn!(
                            "`{name}` at valid time {}: no ROS 2 view: {e}",
                            es.valid_time
                        );
                        false
                    }
                },
            };
            if viewable {
                let header = MessageHeader {
                    channel_id: t.view_channel,
                    sequence: mcap_sequence,
                    log_time: valid,
                    publish_time: published,
                };
                file.write_to_known_channel(&header, &self.view_scratch)
                    .map_err(|source| RecordError::Mcap { path: path.clone(), source })?;
                let n = self.view_scratch.len() as u64;
                add_to(&mut self.summary.view_bytes, name, n);
                self.file_bytes += n;
                if let Some(f) = self.summary.file_messages.last_mut() {
                    f.messages += 1;
                    let v = es.valid_time;
                    f.log_range =
                        Some(f.log_range.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))));
                }
                if let Some(topic) = self.summary.bag_topics.get_mut(name.as_str()) {
                    topic.messages += 1;
                }
            }
        }
        if bag {
            // A bag holds the ROS 2 messages only.
            add_to(&mut self.summary.structures, name, 1);
            return self.flush_if_due();
        }

        let archive = if pixels_in_view {
            let mut stripped = es.clone();
            stripped.set(layout::PIXELS_ATTRIBUTE, Octets::new(Vec::new()));
            codec::encode(&stripped)
        } else {
            codec::encode(es)
        }
        .map_err(|source| RecordError::Encode { trajectory: name.clone(), source })?;
        let lineage = lineage
            .map(codec::encode_lineage)
            .transpose()
            .map_err(|source| RecordError::Encode { trajectory: name.clone(), source })?
            .unwrap_or_default();
        self.scratch.clear();
        RecordHeader {
            add_time,
            recorded_time,
            sequence,
            pixels_in_view,
            view_channel: if pixels_in_view { t.view_channel } else { 0 },
            lineage_len: u32::try_from(lineage.len()).unwrap_or(u32::MAX),
        }
        .encode(&mut self.scratch);
        self.scratch.extend_from_slice(&lineage);
        self.scratch.extend_from_slice(&archive);
        let header = MessageHeader {
            channel_id: t.lossless_channel,
            sequence: mcap_sequence,
            log_time: valid,
            publish_time: published,
        };
        file.write_to_known_channel(&header, &self.scratch)
            .map_err(|source| RecordError::Mcap { path: path.clone(), source })?;
        let n = self.scratch.len() as u64;
        add_to(&mut self.summary.lossless_bytes, name, n);
        add_to(&mut self.summary.structures, name, 1);
        self.file_bytes += n;
        self.flush_if_due()
    }

    /// Writes a violation or a loss into the events channel.
    pub fn write_event(&mut self, event: &RecordedEvent) -> Result<(), RecordError> {
        if self.options.bag {
            // A bag has no esgm channel; the lossless recording beside it keeps events.
            return Ok(());
        }
        let data = serde_json::to_vec(event).map_err(|e| RecordError::Io {
            path: self.file_path.clone(),
            source: std::io::Error::other(e),
        })?;
        let file = self.file.as_mut().ok_or_else(|| closed(&self.file_path))?;
        let time = layout::mcap_time(event.valid_time.unwrap_or(event.time));
        let header = MessageHeader {
            channel_id: self.events_channel,
            sequence: self.summary.events as u32,
            log_time: time,
            publish_time: layout::mcap_time(event.time),
        };
        file.write_to_known_channel(&header, &data)
            .map_err(|source| RecordError::Mcap { path: self.file_path.clone(), source })?;
        self.summary.events += 1;
        self.flush_if_due()
    }

    /// Finishes the chunk and hands it to the operating system if the flush interval
    /// has passed; call it when idle too, so a quiet trajectory's last structures are
    /// not held back.
    pub fn flush_if_due(&mut self) -> Result<(), RecordError> {
        if self.last_flush.elapsed() >= self.options.flush_interval {
            self.flush()?;
        }
        Ok(())
    }

    /// Finishes the current chunk and hands it to the operating system now.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        self.last_flush = Instant::now();
        let file = self.file.as_mut().ok_or_else(|| closed(&self.file_path))?;
        file.flush().map_err(|source| RecordError::Mcap { path: self.file_path.clone(), source })
    }

    /// Writes the summary section and closes the file.
    pub fn finish(mut self) -> Result<WriteSummary, RecordError> {
        self.close_file()?;
        Ok(std::mem::take(&mut self.summary))
    }

    /// Starts the next file when the current one is big or old enough.
    fn rotate_if_due(&mut self) -> Result<(), RecordError> {
        let by_size = self.options.split_bytes.is_some_and(|b| self.file_bytes >= b);
        let by_time = self.options.split_duration.is_some_and(|d| self.file_opened.elapsed() >= d);
        if (by_size || by_time) && self.file_bytes > 0 {
            self.close_file()?;
            self.open_file()?;
            let file = self.file.as_mut().ok_or_else(|| closed(&self.file_path))?;
            for t in &mut self.trajectories {
                declare(file, &self.file_path, t, self.options.bag)?;
            }
        }
        Ok(())
    }

    fn close_file(&mut self) -> Result<(), RecordError> {
        if let Some(mut file) = self.file.take() {
            file.finish()
                .map_err(|source| RecordError::Mcap { path: self.file_path.clone(), source })?;
            let inner = file.into_inner();
            inner.into_inner().map_err(|e| RecordError::Io {
                path: self.file_path.clone(),
                source: e.into_error(),
            })?;
            if self.options.bag {
                // Each closed file is in it: a bag cut short by a crash still opens up
                // to its last complete file.
                crate::rosbag2::write_metadata(&self.path, &self.summary).map_err(|source| {
                    RecordError::Io { path: self.path.join(crate::rosbag2::METADATA), source }
                })?;
            }
        }
        Ok(())
    }

    fn open_file(&mut self) -> Result<(), RecordError> {
        let index = self.summary.files.len();
        self.file_path = if self.options.bag {
            if index == 0 {
                crate::rosbag2::create_dir(&self.path)
                    .map_err(|source| RecordError::Io { path: self.path.clone(), source })?;
            }
            crate::rosbag2::file_path(&self.path, index)
        } else {
            split_path(&self.path, index)
        };
        let path = self.file_path.clone();
        let f =
            File::create(&path).map_err(|source| RecordError::Io { path: path.clone(), source })?;
        let compression = match self.options.compression {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        };
        let mcap_err = |source| RecordError::Mcap { path: path.clone(), source };
        let mut file = mcap::WriteOptions::new()
            .profile(if self.options.bag { crate::rosbag2::PROFILE } else { PROFILE })
            .library(format!("esgm {}", env!("CARGO_PKG_VERSION")))
            .compression(compression)
            .chunk_size(Some(self.options.chunk_size))
            .create(BufWriter::with_capacity(WRITE_BUFFER, f))
            .map_err(mcap_err)?;
        let mut meta = self.options.metadata.clone();
        meta.insert("format_version".into(), layout::FORMAT_VERSION.to_string());
        meta.insert("file_index".into(), index.to_string());
        meta.insert(
            "flush_interval_ms".into(),
            self.options.flush_interval.as_millis().to_string(),
        );
        file.write_metadata(&mcap::records::Metadata {
            name: RECORDING_METADATA.into(),
            metadata: meta,
        })
        .map_err(mcap_err)?;
        if !self.options.bag {
            let events_schema = file
                .add_schema("esgm.Event", "jsonschema", &layout::events_json_schema())
                .map_err(mcap_err)?;
            self.events_channel = file
                .add_channel(events_schema, EVENTS_TOPIC, "json", &BTreeMap::new())
                .map_err(mcap_err)?;
        }
        self.file = Some(file);
        self.summary.files.push(path);
        self.summary.file_messages.push(FileMessages::default());
        self.file_opened = Instant::now();
        self.file_bytes = 0;
        Ok(())
    }
}

impl Drop for RecordingWriter {
    /// A writer dropped without [`finish`](RecordingWriter::finish) (an error, a panic)
    /// still writes its summary, so the file is complete.
    fn drop(&mut self) {
        if let Err(e) = self.close_file() {
            tracing::error!("recording {} left incomplete: {e}", self.file_path.display());
        }
    }
}

/// Schema and channels of one trajectory in the current file.
fn declare(
    file: &mut McapFile,
    path: &Path,
    t: &mut Recorded,
    bag: bool,
) -> Result<(), RecordError> {
    let mcap_err = |source| RecordError::Mcap { path: path.to_path_buf(), source };
    if bag && !t.in_bag {
        return Ok(());
    }
    if let (Some((_, v)), Some(topic)) = (&t.view, &t.meta.view_topic) {
        let view_schema = file.add_schema(&v.name, v.encoding, &v.data).map_err(mcap_err)?;
        // A bag's channel is rosbag2's: no esgm key, so readers take it as a bag's
        // topic (there is no lossless channel it would be the view of).
        let meta = if bag {
            BTreeMap::from([("offered_qos_profiles".to_owned(), String::new())])
        } else {
            BTreeMap::from([(layout::keys::TRAJECTORY.to_owned(), t.meta.info.name.clone())])
        };
        t.view_channel =
            file.add_channel(view_schema, topic, v.message_encoding, &meta).map_err(mcap_err)?;
    }
    if bag {
        return Ok(());
    }
    let schema = file
        .add_schema(&t.meta.info.type_name, TYPES_ENCODING, &t.schema.to_bytes())
        .map_err(mcap_err)?;
    t.lossless_channel = file
        .add_channel(
            schema,
            &layout::lossless_topic(&t.meta.info.name),
            ARCHIVE_ENCODING,
            &t.meta.to_map(),
        )
        .map_err(mcap_err)?;
    Ok(())
}

/// The view of a type: an image if it has an image's attributes, else JSON.
fn view_of(types: &TypeSchema) -> (ViewKind, ViewSchema) {
    if view::raw_image::image_view(&types.root).is_some() {
        (ViewKind::Image, view::raw_image::raw_image_schema())
    } else {
        let lookup =
            |name: &str| -> Option<EntityStructureType> { types.nested.get(name).cloned() };
        (ViewKind::Json, view::json::json_schema(&types.root, &lookup))
    }
}

/// The ROS 2 view of a type: its standard message, else its generated one; a type no
/// message can hold (an `Agg` attribute…) keeps the JSON view, said once.
fn ros2_view_of(type_name: &str, types: &TypeSchema) -> (ViewKind, ViewSchema) {
    use esgm_ros2msg::{definitions, generated, mapping::RosType};
    let view = |kind, name: String, text: String| {
        let schema = ViewSchema {
            name,
            encoding: "ros2msg",
            message_encoding: "cdr",
            data: text.into_bytes(),
        };
        (ViewKind::Ros2(kind), schema)
    };
    if let Ok(t) = RosType::for_esgm_type(type_name) {
        return view(Ros2View::Standard(t), t.name().to_owned(), definitions::standard_schema(t));
    }
    let lookup = |n: &str| {
        if n == type_name { Some(types.root.clone()) } else { types.nested.get(n).cloned() }
    };
    match generated::Schema::new(type_name, lookup) {
        Ok(schema) => {
            let text = definitions::generated_schema(&schema);
            let name = format!("{}/msg/{type_name}", generated::PACKAGE);
            view(Ros2View::Generated(std::sync::Arc::new(schema)), name, text)
        }
        Err(e) => {
            tracing::warn!("type `{type_name}` has no ROS 2 message ({e}); its view is JSON");
            view_of(types)
        }
    }
}

/// `es` as its ROS 2 view's CDR bytes, into `out`.
fn encode_ros2(
    v: &Ros2View,
    es: &EntityStructure,
    out: &mut Vec<u8>,
) -> Result<(), Box<dyn std::error::Error>> {
    use esgm_ros2msg::{cdr, generated::GeneratedRef, mapping, mapping::RosType};
    match v {
        Ros2View::Standard(RosType::Image) => cdr::encode_into(&mapping::image_out(es)?, out)?,
        Ros2View::Standard(RosType::Pose2D) => cdr::encode_into(&mapping::pose_out(es)?, out)?,
        Ros2View::Standard(RosType::Vector3) => {
            cdr::encode_into(&mapping::velocity_out(es)?, out)?;
        }
        Ros2View::Generated(schema) => {
            cdr::encode_into(&GeneratedRef { structure: es, schema }, out)?;
        }
    }
    Ok(())
}

/// The `index`-th file of a recording at `path`: the path itself, then `stem_001.mcap`…
pub fn split_path(path: &Path, index: usize) -> PathBuf {
    if index == 0 {
        return path.to_path_buf();
    }
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let ext =
        path.extension().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "mcap".into());
    path.with_file_name(format!("{stem}_{index:03}.{ext}"))
}

/// Adds `n` to `name`'s count, allocating its key only the first time (this runs for
/// every structure written).
fn add_to(counts: &mut BTreeMap<String, u64>, name: &str, n: u64) {
    match counts.get_mut(name) {
        Some(c) => *c += n,
        None => {
            counts.insert(name.to_owned(), n);
        }
    }
}

fn closed(path: &Path) -> RecordError {
    RecordError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other("the recording is closed"),
    }
}
