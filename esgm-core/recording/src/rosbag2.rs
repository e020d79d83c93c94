//! rosbag2 directories: what `esgm record --ros2` writes ([`RecordOptions::bag`]) and
//! what every reader of recordings takes besides a bare `.mcap` ([`resolve`]).
//!
//! A bag is a directory `NAME/` holding `NAME_0.mcap` (then `NAME_1.mcap`… when it
//! splits) and `metadata.yaml`, as rosbag2's MCAP storage writes them: every channel in
//! the ROS 2 profile (`ros2msg` schema, `cdr` messages), topics `/<trajectory>`, and
//! the metadata's version 5 (ROS 2 Humble's; later distributions read it), rewritten
//! each time a file is closed, so a bag cut short still opens up to its last complete
//! file. A lossless esgm recording may sit beside the bag's files (`lossless/`), which
//! rosbag2 does not list and ignores; esgm's readers prefer it.
//!
//! [`RecordOptions::bag`]: crate::writer::RecordOptions::bag

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::writer::WriteSummary;

/// The MCAP profile of a bag's files.
pub const PROFILE: &str = "ros2";
/// The bag's metadata file.
pub const METADATA: &str = "metadata.yaml";
/// Where a lossless recording beside a bag goes (`esgm record --ros2 --lossless`).
pub const LOSSLESS_DIR: &str = "lossless";
/// The metadata's version (rosbag2 in ROS 2 Humble).
const VERSION: u32 = 5;

/// Creates the bag's directory: a new one, or an empty one (rosbag2 refuses to write
/// into a directory that holds anything, and so does this).
pub fn create_dir(dir: &Path) -> std::io::Result<()> {
    if dir.exists() && std::fs::read_dir(dir)?.next().is_some() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            "a bag is a new directory, and this one is not empty",
        ));
    }
    std::fs::create_dir_all(dir)
}

fn bag_name(dir: &Path) -> String {
    dir.file_name().map_or_else(|| "bag".to_owned(), |n| n.to_string_lossy().into_owned())
}

/// The `index`-th file of the bag in `dir`: `NAME_0.mcap`, `NAME_1.mcap`…
pub fn file_path(dir: &Path, index: usize) -> PathBuf {
    dir.join(format!("{}_{index}.mcap", bag_name(dir)))
}

fn quoted(s: &str) -> String {
    let mut q = String::with_capacity(s.len() + 2);
    q.push('"');
    for c in s.chars() {
        match c {
            '"' => q.push_str("\\\""),
            '\\' => q.push_str("\\\\"),
            c if c.is_control() => {
                let _ = write!(q, "\\u{:04x}", c as u32);
            }
            c => q.push(c),
        }
    }
    q.push('"');
    q
}

/// rosbag2's value for the start of a bag without messages.
const NO_START: i64 = i64::MAX;

/// The bag's `metadata.yaml` for what `summary` says was written.
pub fn metadata(summary: &WriteSummary) -> String {
    let range = summary
        .file_messages
        .iter()
        .filter_map(|f| f.log_range)
        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)));
    let (start, duration) = range.map_or((NO_START, 0), |(lo, hi)| (lo, hi.saturating_sub(lo)));
    let total: u64 = summary.file_messages.iter().map(|f| f.messages).sum();
    let mut y = String::new();
    let _ = writeln!(y, "rosbag2_bagfile_information:");
    let _ = writeln!(y, "  version: {VERSION}");
    let _ = writeln!(y, "  storage_identifier: mcap");
    let _ = writeln!(y, "  duration:\n    nanoseconds: {duration}");
    let _ = writeln!(y, "  starting_time:\n    nanoseconds_since_epoch: {start}");
    let _ = writeln!(y, "  message_count: {total}");
    if summary.bag_topics.is_empty() {
        let _ = writeln!(y, "  topics_with_message_count: []");
    } else {
        let _ = writeln!(y, "  topics_with_message_count:");
        for topic in summary.bag_topics.values() {
            let _ = writeln!(y, "    - topic_metadata:");
            let _ = writeln!(y, "        name: {}", quoted(&topic.topic));
            let _ = writeln!(y, "        type: {}", quoted(&topic.message_type));
            let _ = writeln!(y, "        serialization_format: cdr");
            let _ = writeln!(y, "        offered_qos_profiles: \"\"");
            let _ = writeln!(y, "      message_count: {}", topic.messages);
        }
    }
    // Chunks are compressed inside the MCAP files, which rosbag2 does not count as
    // compression of the bag.
    let _ = writeln!(y, "  compression_format: \"\"");
    let _ = writeln!(y, "  compression_mode: \"\"");
    let name =
        |p: &PathBuf| p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let _ = writeln!(y, "  relative_file_paths:");
    for f in &summary.files {
        let _ = writeln!(y, "    - {}", quoted(&name(f)));
    }
    let _ = writeln!(y, "  files:");
    for (f, m) in summary.files.iter().zip(&summary.file_messages) {
        let (start, duration) =
            m.log_range.map_or((NO_START, 0), |(lo, hi)| (lo, hi.saturating_sub(lo)));
        let _ = writeln!(y, "    - path: {}", quoted(&name(f)));
        let _ = writeln!(y, "      starting_time:\n        nanoseconds_since_epoch: {start}");
        let _ = writeln!(y, "      duration:\n        nanoseconds: {duration}");
        let _ = writeln!(y, "      message_count: {}", m.messages);
    }
    y
}

/// Writes the bag's `metadata.yaml` into `dir` (atomically: a reader never sees half).
pub fn write_metadata(dir: &Path, summary: &WriteSummary) -> std::io::Result<()> {
    let tmp = dir.join(format!(".{METADATA}.tmp"));
    std::fs::write(&tmp, metadata(summary))?;
    std::fs::rename(&tmp, dir.join(METADATA))
}

/// The file a reader of recordings opens for `path`: `path` itself if it is a file;
/// for a bag's directory, the lossless recording beside it if there is one, else the
/// bag's own file. A directory of several files (a split recording) is refused, naming
/// them: open one of them.
pub fn resolve(path: &Path) -> std::io::Result<PathBuf> {
    if !path.is_dir() {
        return Ok(path.to_path_buf());
    }
    let mcaps = |dir: &Path| -> std::io::Result<Vec<PathBuf>> {
        let mut v: Vec<PathBuf> = std::fs::read_dir(dir)?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e == "mcap") && p.is_file())
            .collect();
        v.sort();
        Ok(v)
    };
    let lossless = path.join(LOSSLESS_DIR);
    let files = if lossless.is_dir() && !mcaps(&lossless)?.is_empty() {
        mcaps(&lossless)?
    } else {
        mcaps(path)?
    };
    match files.as_slice() {
        [one] => Ok(one.clone()),
        [] => Err(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!("{} holds no .mcap file (neither a bag nor a recording)", path.display()),
        )),
        many => Err(std::io::Error::other(format!(
            "{} holds {} recording files ({}); open one of them",
            path.display(),
            many.len(),
            many.iter()
                .map(|p| p
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default())
                .collect::<Vec<_>>()
                .join(", ")
        ))),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::writer::{BagTopic, FileMessages};

    #[test]
    fn metadata_lists_topics_files_and_times_as_rosbag2_does() {
        let mut s = WriteSummary::default();
        s.files.push(PathBuf::from("/x/run/run_0.mcap"));
        s.file_messages.push(FileMessages { messages: 3, log_range: Some((10, 40)) });
        s.bag_topics.insert(
            "camera".into(),
            BagTopic {
                topic: "/camera".into(),
                message_type: "sensor_msgs/msg/Image".into(),
                messages: 3,
            },
        );
        let y = metadata(&s);
        for line in [
            "  version: 5\n",
            "  storage_identifier: mcap\n",
            "  duration:\n    nanoseconds: 30\n",
            "  starting_time:\n    nanoseconds_since_epoch: 10\n",
            "  message_count: 3\n",
            "        name: \"/camera\"\n        type: \"sensor_msgs/msg/Image\"\n",
            "  relative_file_paths:\n    - \"run_0.mcap\"\n",
        ] {
            assert!(y.contains(line), "no {line:?} in\n{y}");
        }
        let empty = metadata(&WriteSummary::default());
        assert!(empty.contains("topics_with_message_count: []"), "{empty}");
        assert!(empty.contains(&format!("nanoseconds_since_epoch: {NO_START}")), "{empty}");
    }

    #[test]
    fn a_directory_resolves_to_its_lossless_recording_else_its_one_file() {
        let dir = tempfile::tempdir().unwrap();
        let bag = dir.path().join("run");
        create_dir(&bag).unwrap();
        assert!(resolve(&bag).is_err(), "no file yet");
        std::fs::write(file_path(&bag, 0), b"").unwrap();
        assert_eq!(resolve(&bag).unwrap(), bag.join("run_0.mcap"));
        std::fs::write(file_path(&bag, 1), b"").unwrap();
        let e = resolve(&bag).unwrap_err().to_string();
        assert!(e.contains("run_0.mcap, run_1.mcap"), "{e}");
        std::fs::create_dir(bag.join(LOSSLESS_DIR)).unwrap();
        std::fs::write(bag.join(LOSSLESS_DIR).join("run.mcap"), b"").unwrap();
        assert_eq!(resolve(&bag).unwrap(), bag.join("lossless/run.mcap"));
        assert!(create_dir(&bag).is_err(), "not empty");
        let file = bag.join("run_0.mcap");
        assert_eq!(resolve(&file).unwrap(), file);
    }
}
