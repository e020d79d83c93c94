//! The file layout: what each MCAP schema, channel, message and metadata record of an
//! esgm recording holds. Writer and reader both go through this file, so the two can
//! never disagree about a byte.
//!
//! # Channels
//! Every recorded trajectory `T` has a **lossless channel**, topic `esgm/T`, message
//! encoding [`ARCHIVE_ENCODING`]. Its schema is named after the trajectory's type, with
//! encoding [`TYPES_ENCODING`]: the type and every type it nests, as JSON, so a
//! recording can be read with no system running. The channel's metadata holds the
//! trajectory's kind, source, inputs and policy ([`TrajectoryMeta`]).
//!
//! Beside it, a **view channel** with topic `T` carries what Foxglove decodes:
//! `foxglove.RawImage` (protobuf) for image types, JSON with a JSON Schema for the
//! rest. Images are stored once: an image structure's lossless message is the archive
//! of the structure with its pixels taken out ([`RecordHeader::pixels_in_view`]); the
//! reader puts the view message's pixels back and re-encodes, which gives the canonical
//! archive again, byte for byte.
//!
//! Policy violations and losses seen while recording go to the [`EVENTS_TOPIC`]
//! channel as JSON ([`RecordedEvent`]).
//!
//! # Times
//! A message's MCAP `log_time` is the structure's **valid time** (clamped at 0), so
//! Foxglove's timeline is the robot's time and an image and the blobs computed from it
//! line up. `publish_time` is the add time. All four times (valid and create in the
//! archive; add and recorded in the [`RecordHeader`]) are kept exactly, as signed
//! nanoseconds.

use std::collections::BTreeMap;

use esgm_core::EntityStructureType;
use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
use esgm_core::policy::FluentStreamPolicy;
use esgm_core::time::Time;

/// The MCAP profile of esgm recordings.
pub const PROFILE: &str = "esgm";
/// Version of this layout; a reader refuses a newer one by name.
pub const FORMAT_VERSION: u32 = 1;
/// Schema encoding of a lossless channel: the types as JSON ([`TypeSchema`]).
pub const TYPES_ENCODING: &str = "esgm-types+json";
/// Message encoding of a lossless channel: a [`RecordHeader`] then a codec archive.
pub const ARCHIVE_ENCODING: &str = "esgm-archive";
/// Topic prefix of lossless channels.
pub const LOSSLESS_PREFIX: &str = "esgm/";
/// Topic of the violations and losses channel.
pub const EVENTS_TOPIC: &str = "esgm-events";
/// The attribute whose octets an image's view carries instead of its archive.
pub const PIXELS_ATTRIBUTE: &str = "image_data";
/// Name of the metadata record written when a recording starts.
pub const RECORDING_METADATA: &str = "esgm.recording";

/// Channel metadata keys of a lossless channel.
pub mod keys {
    /// The trajectory's name.
    pub const TRAJECTORY: &str = "esgm.trajectory";
    /// `primitive`, `sampled`, `computed`, … ([`super::kind_name`]).
    pub const KIND: &str = "esgm.kind";
    /// The type's registered name.
    pub const TYPE: &str = "esgm.type";
    /// The sensor or unit feeding it (empty if none).
    pub const SOURCE: &str = "esgm.source";
    /// Its inputs, a JSON array of names.
    pub const INPUTS: &str = "esgm.inputs";
    /// Its policy as JSON.
    pub const POLICY: &str = "esgm.policy";
    /// The topic of its view channel (empty if none).
    pub const VIEW: &str = "esgm.view";
}

/// The lossless topic of a trajectory.
pub fn lossless_topic(trajectory: &str) -> String {
    format!("{LOSSLESS_PREFIX}{trajectory}")
}

/// The name a kind has in files (its lower-case name).
pub fn kind_name(kind: TrajectoryKind) -> String {
    kind.name().to_owned()
}

/// The kind a file names, if this version knows it.
pub fn parse_kind(name: &str) -> Option<TrajectoryKind> {
    [
        TrajectoryKind::Primitive,
        TrajectoryKind::Sampled,
        TrajectoryKind::Computed,
        TrajectoryKind::Sync,
        TrajectoryKind::Merge,
        TrajectoryKind::SampledGenerators,
        TrajectoryKind::SampledFunction,
    ]
    .into_iter()
    .find(|k| k.name() == name)
}

/// What a lossless channel's metadata says about its trajectory.
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryMeta {
    /// The trajectory as it was declared in the recorded system.
    pub info: TrajectoryInfo,
    /// The view channel's topic, if one was written.
    pub view_topic: Option<String>,
}

impl TrajectoryMeta {
    /// The channel metadata map.
    pub fn to_map(&self) -> BTreeMap<String, String> {
        let i = &self.info;
        let mut m = BTreeMap::new();
        m.insert(keys::TRAJECTORY.into(), i.name.clone());
        m.insert(keys::KIND.into(), kind_name(i.kind));
        m.insert(keys::TYPE.into(), i.type_name.clone());
        m.insert(keys::SOURCE.into(), i.source.clone().unwrap_or_default());
        m.insert(keys::INPUTS.into(), json_string(&i.inputs));
        m.insert(keys::POLICY.into(), json_string(&i.policy));
        m.insert(keys::VIEW.into(), self.view_topic.clone().unwrap_or_default());
        m
    }

    /// Reads the metadata map back; the error names the key that is missing or wrong.
    pub fn from_map(m: &BTreeMap<String, String>) -> Result<Self, String> {
        let get = |k: &str| m.get(k).ok_or_else(|| format!("channel metadata lacks `{k}`"));
        let kind_text = get(keys::KIND)?;
        let kind = parse_kind(kind_text)
            .ok_or_else(|| format!("unknown trajectory kind `{kind_text}` in `{}`", keys::KIND))?;
        let inputs: Vec<String> = serde_json::from_str(get(keys::INPUTS)?)
            .map_err(|e| format!("`{}` is not a JSON list of names: {e}", keys::INPUTS))?;
        let policy: FluentStreamPolicy = serde_json::from_str(get(keys::POLICY)?)
            .map_err(|e| format!("`{}` is not a policy: {e}", keys::POLICY))?;
        let source = get(keys::SOURCE)?;
        let view = m.get(keys::VIEW).filter(|v| !v.is_empty()).cloned();
        Ok(Self {
            info: TrajectoryInfo {
                name: get(keys::TRAJECTORY)?.clone(),
                kind,
                type_name: get(keys::TYPE)?.clone(),
                source: (!source.is_empty()).then(|| source.clone()),
                inputs,
                policy,
            },
            view_topic: view,
        })
    }
}

/// JSON of a value whose serialisation cannot fail (plain data).
fn json_string<T: serde::Serialize>(value: &T) -> String {
    serde_json::to_string(value).unwrap_or_else(|e| format!("\"unserialisable: {e}\""))
}

/// A lossless channel's schema data: the trajectory's type and every type it nests.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TypeSchema {
    /// The trajectory's type.
    #[serde(rename = "type")]
    pub root: EntityStructureType,
    /// Element types of nested frames, transitively, by registered name.
    pub nested: BTreeMap<String, EntityStructureType>,
}

impl TypeSchema {
    /// The schema of `root`, collecting nested types through `lookup`.
    pub fn collect(
        root: EntityStructureType,
        lookup: &dyn Fn(&str) -> Option<EntityStructureType>,
    ) -> Self {
        let mut nested = BTreeMap::new();
        let mut todo: Vec<String> =
            root.attributes.iter().filter_map(|a| a.element_type.clone()).collect();
        while let Some(name) = todo.pop() {
            if nested.contains_key(&name) {
                continue;
            }
            if let Some(t) = lookup(&name) {
                todo.extend(t.attributes.iter().filter_map(|a| a.element_type.clone()));
                nested.insert(name, t);
            }
        }
        Self { root, nested }
    }

    /// The schema as stored.
    pub fn to_bytes(&self) -> Vec<u8> {
        json_string(self).into_bytes()
    }

    /// The schema from stored bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, String> {
        serde_json::from_slice(bytes).map_err(|e| format!("not an esgm type schema: {e}"))
    }

    /// The type registered under `name`: the root (under its trajectory's type name)
    /// or a nested one.
    pub fn lookup(&self, registered_as: &str, name: &str) -> Option<EntityStructureType> {
        if name == registered_as {
            return Some(self.root.clone());
        }
        self.nested.get(name).cloned()
    }
}

/// The fixed part of every lossless message, before the archive.
///
/// Little-endian: magic `ESGM`, version `u16`, flags `u16`, add time `i64`, recorded
/// time `i64`, sequence `u64`, view channel `u16`, lineage length `u32`, 2 bytes of
/// zeros: 40 bytes. With the lineage flag, the structure's lineage
/// ([`esgm_core::codec::decode_lineage`]'s bytes, that many) comes before the archive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordHeader {
    /// When the structure entered its trajectory (Definition 3.3.9).
    pub add_time: Time,
    /// When the recorder received it.
    pub recorded_time: Time,
    /// Position in its trajectory's recorded stream, from 0. A gap means the recorder
    /// missed structures (counted in the events channel with the cause).
    pub sequence: u64,
    /// The archive's `image_data` octets are empty here and the pixels are the
    /// data of the view message with the same MCAP sequence on `view_channel`.
    pub pixels_in_view: bool,
    /// The view channel holding the pixels (0 when `pixels_in_view` is false).
    pub view_channel: u16,
    /// Bytes of the structure's lineage between the header and the archive (0: none,
    /// a pushed or sampled structure's).
    pub lineage_len: u32,
}

/// A lossless message split: its header, its lineage bytes (if any) and its archive.
pub type Split<'a> = (RecordHeader, Option<&'a [u8]>, &'a [u8]);

/// Length of an encoded [`RecordHeader`].
pub const HEADER_LEN: usize = 40;
const MAGIC: &[u8; 4] = b"ESGM";
const HEADER_VERSION: u16 = 1;
const FLAG_PIXELS_IN_VIEW: u16 = 1;
const FLAG_LINEAGE: u16 = 2;

impl RecordHeader {
    /// Appends the header to `out`.
    pub fn encode(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&HEADER_VERSION.to_le_bytes());
        let mut flags = if self.pixels_in_view { FLAG_PIXELS_IN_VIEW } else { 0 };
        if self.lineage_len > 0 {
            flags |= FLAG_LINEAGE;
        }
        out.extend_from_slice(&flags.to_le_bytes());
        out.extend_from_slice(&self.add_time.to_le_bytes());
        out.extend_from_slice(&self.recorded_time.to_le_bytes());
        out.extend_from_slice(&self.sequence.to_le_bytes());
        out.extend_from_slice(&self.view_channel.to_le_bytes());
        out.extend_from_slice(&self.lineage_len.to_le_bytes());
        out.extend_from_slice(&[0; 2]);
    }

    /// Splits a lossless message into its header, its lineage bytes (if any) and its
    /// archive; the error says what is wrong.
    pub fn decode_with_lineage(data: &[u8]) -> Result<Split<'_>, String> {
        let (header, rest) = Self::decode_header(data)?;
        if header.lineage_len == 0 {
            return Ok((header, None, rest));
        }
        let len = header.lineage_len as usize;
        if rest.len() < len {
            return Err(format!(
                "a lineage of {len} bytes in {} bytes after the header",
                rest.len()
            ));
        }
        let (lineage, archive) = rest.split_at(len);
        Ok((header, Some(lineage), archive))
    }

    /// Splits a lossless message into its header and archive (past any lineage); the
    /// error says what is wrong with the header.
    pub fn decode(data: &[u8]) -> Result<(Self, &[u8]), String> {
        Self::decode_with_lineage(data).map(|(header, _, archive)| (header, archive))
    }

    fn decode_header(data: &[u8]) -> Result<(Self, &[u8]), String> {
        if data.len() < HEADER_LEN {
            return Err(format!(
                "message of {} bytes is shorter than the {HEADER_LEN}-byte header",
                data.len()
            ));
        }
        let (h, archive) = data.split_at(HEADER_LEN);
        if &h[0..4] != MAGIC {
            return Err("message does not start with the `ESGM` header magic".into());
        }
        let u16_at = |i: usize| u16::from_le_bytes([h[i], h[i + 1]]);
        let u64_at = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&h[i..i + 8]);
            u64::from_le_bytes(b)
        };
        let version = u16_at(4);
        if version != HEADER_VERSION {
            return Err(format!("header version {version}, this reader knows {HEADER_VERSION}"));
        }
        let flags = u16_at(6);
        if flags & !(FLAG_PIXELS_IN_VIEW | FLAG_LINEAGE) != 0 {
            return Err(format!("unknown header flags {flags:#06x}"));
        }
        let header = Self {
            add_time: u64_at(8) as i64,
            recorded_time: u64_at(16) as i64,
            sequence: u64_at(24),
            pixels_in_view: flags & FLAG_PIXELS_IN_VIEW != 0,
            view_channel: u16_at(32),
            lineage_len: if flags & FLAG_LINEAGE != 0 {
                u32::from_le_bytes([h[34], h[35], h[36], h[37]])
            } else {
                0
            },
        };
        if flags & FLAG_LINEAGE != 0 && header.lineage_len == 0 {
            return Err("the lineage flag is set and its length is 0".into());
        }
        Ok((header, archive))
    }
}

/// A policy violation or a loss, as the events channel records it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RecordedEvent {
    /// The trajectory it concerns.
    pub trajectory: String,
    /// `violation` or `loss`.
    pub kind: EventKind,
    /// The broken constraint, or the cause of the loss (`lost` in transport,
    /// `recorder_overflow` when the recorder fell behind, …).
    pub cause: String,
    /// Structures concerned (1 for a violation; the increase for a loss).
    pub count: u64,
    /// The structure's valid time (violations), ns.
    pub valid_time: Option<Time>,
    /// When it was seen, ns.
    pub time: Time,
    /// What exactly was wrong, for people.
    pub detail: String,
}

/// The two kinds of [`RecordedEvent`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// A structure the trajectory's policy dropped.
    Violation,
    /// Structures that did not reach the recording.
    Loss,
}

/// The JSON Schema of [`RecordedEvent`], so Foxglove can show the events as a table.
pub fn events_json_schema() -> Vec<u8> {
    let schema = serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "esgm.Event",
        "type": "object",
        "properties": {
            "trajectory": {"type": "string"},
            "kind": {"type": "string", "enum": ["violation", "loss"]},
            "cause": {"type": "string"},
            "count": {"type": "integer"},
            "valid_time": {"type": ["integer", "null"]},
            "time": {"type": "integer"},
            "detail": {"type": "string"}
        },
        "required": ["trajectory", "kind", "cause", "count", "time", "detail"]
    });
    schema.to_string().into_bytes()
}

/// MCAP times are unsigned: negative times are written as 0 (the exact time is in the
/// archive and the header).
pub fn mcap_time(t: Time) -> u64 {
    u64::try_from(t).unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_round_trips_and_rejects_damage() {
        let h = RecordHeader {
            add_time: -5,
            recorded_time: 1_700_000_000_000_000_000,
            sequence: 42,
            pixels_in_view: true,
            view_channel: 7,
            lineage_len: 0,
        };
        let mut out = Vec::new();
        h.encode(&mut out);
        assert_eq!(out.len(), HEADER_LEN);
        out.extend_from_slice(b"archive");
        let (back, rest) = RecordHeader::decode(&out).expect("decodes");
        assert_eq!(back, h);
        assert_eq!(rest, b"archive");
        assert!(RecordHeader::decode(&out[..10]).unwrap_err().contains("shorter"));
        let mut bad = out.clone();
        bad[0] = b'X';
        assert!(RecordHeader::decode(&bad).unwrap_err().contains("magic"));
        let mut flags = out;
        flags[6] = 0x80;
        assert!(RecordHeader::decode(&flags).unwrap_err().contains("flags"));
    }

    #[test]
    fn a_lineage_sits_between_header_and_archive() {
        let h = RecordHeader {
            add_time: 1,
            recorded_time: 2,
            sequence: 3,
            pixels_in_view: false,
            view_channel: 0,
            lineage_len: 4,
        };
        let mut out = Vec::new();
        h.encode(&mut out);
        out.extend_from_slice(b"LINEarchive");
        let (back, lineage, archive) = RecordHeader::decode_with_lineage(&out).expect("decodes");
        assert_eq!((back, lineage, archive), (h, Some(&b"LINE"[..]), &b"archive"[..]));
        assert_eq!(RecordHeader::decode(&out).unwrap().1, b"archive");
        let short = &out[..HEADER_LEN + 2];
        assert!(RecordHeader::decode(short).unwrap_err().contains("a lineage of 4 bytes"));
        let mut zero = out.clone();
        zero[34..38].copy_from_slice(&0u32.to_le_bytes());
        assert!(RecordHeader::decode(&zero).unwrap_err().contains("length is 0"));
    }

    #[test]
    fn trajectory_meta_round_trips() {
        let meta = TrajectoryMeta {
            info: TrajectoryInfo {
                name: "blobs".into(),
                kind: TrajectoryKind::Computed,
                type_name: "BlobSeq".into(),
                source: Some("BlobDetection".into()),
                inputs: vec!["images".into()],
                policy: FluentStreamPolicy::default(),
            },
            view_topic: Some("blobs".into()),
        };
        assert_eq!(TrajectoryMeta::from_map(&meta.to_map()), Ok(meta.clone()));
        let mut m = meta.to_map();
        m.insert(keys::KIND.into(), "teleported".into());
        assert!(TrajectoryMeta::from_map(&m).unwrap_err().contains("teleported"));
    }
}
