//! `Message4kb`, the one message of the reference system, byte for byte as upstream's
//! `reference_interfaces/msg/Message4kb`: an 8-byte count of stats in use, 63 per-hop
//! `TransmissionStats` (timestamp, sequence number, dropped samples, a 48-byte node
//! name), then 56 bytes of data (the first 8 the last node's crunch result). Every
//! system carries these 4,096 bytes, so all move the same payload; the per-hop trace in
//! it is how the hot path's latency and the drops are read at the end.
//!
//! The rules for filling the trace are upstream's (`sample_management.hpp`): a node
//! merges its inputs' traces into its output (each node once), then appends its own
//! entry (name, its output sequence number, the samples it missed on its inputs, the
//! time it received the input).

/// The message's size in bytes.
pub const MESSAGE_LEN: usize = 4096;
/// Per-hop stats a message holds.
pub const STATS_CAPACITY: usize = 63;
/// Bytes of a stats entry.
const STATS_LEN: usize = 64;
/// Bytes of a node name in an entry (NUL-terminated).
const NAME_LEN: usize = 48;
/// Where the stats start (after the 8-byte count).
const STATS_AT: usize = 8;
/// Where the data starts.
const DATA_AT: usize = STATS_AT + STATS_CAPACITY * STATS_LEN;

/// One hop's entry of a message's trace.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Hop {
    /// The node.
    pub node: String,
    /// When it received what it made this from (ns, system clock); a sensor: when it
    /// fired.
    pub timestamp: u64,
    /// Its output's sequence number.
    pub sequence: u32,
    /// The samples it missed on its inputs before this one.
    pub dropped: u32,
}

/// A 4 KiB message.
#[derive(Clone, PartialEq, Eq)]
pub struct Message {
    bytes: Box<[u8; MESSAGE_LEN]>,
}

impl std::fmt::Debug for Message {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.hops()).finish()
    }
}

impl Default for Message {
    fn default() -> Self {
        Self { bytes: Box::new([0; MESSAGE_LEN]) }
    }
}

/// Bytes that are not a message.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MessageError {
    /// Not 4,096 of them.
    #[error("a Message4kb is {MESSAGE_LEN} bytes, not {0}")]
    Length(usize),
    /// A count of stats past the capacity.
    #[error("a Message4kb holds at most {STATS_CAPACITY} stats, not {0}")]
    Count(u64),
}

impl Message {
    /// The message in `bytes`.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MessageError> {
        let array: [u8; MESSAGE_LEN] =
            bytes.try_into().map_err(|_| MessageError::Length(bytes.len()))?;
        let m = Self { bytes: Box::new(array) };
        if m.count() > STATS_CAPACITY as u64 {
            return Err(MessageError::Count(m.count()));
        }
        Ok(m)
    }

    /// Its bytes.
    pub fn as_bytes(&self) -> &[u8; MESSAGE_LEN] {
        &self.bytes
    }

    fn count(&self) -> u64 {
        u64::from_le_bytes(self.bytes[..8].try_into().unwrap_or([0; 8]))
    }

    fn set_count(&mut self, n: u64) {
        self.bytes[..8].copy_from_slice(&n.to_le_bytes());
    }

    fn entry(&self, i: usize) -> &[u8] {
        &self.bytes[STATS_AT + i * STATS_LEN..STATS_AT + (i + 1) * STATS_LEN]
    }

    fn name_of(entry: &[u8]) -> &[u8] {
        let name = &entry[16..16 + NAME_LEN];
        let end = name.iter().position(|b| *b == 0).unwrap_or(NAME_LEN);
        &name[..end]
    }

    /// The trace, first hop first.
    pub fn hops(&self) -> Vec<Hop> {
        (0..self.count() as usize)
            .map(|i| {
                let e = self.entry(i);
                Hop {
                    node: String::from_utf8_lossy(Self::name_of(e)).into_owned(),
                    timestamp: u64::from_le_bytes(e[0..8].try_into().unwrap_or([0; 8])),
                    sequence: u32::from_le_bytes(e[8..12].try_into().unwrap_or([0; 4])),
                    dropped: u32::from_le_bytes(e[12..16].try_into().unwrap_or([0; 4])),
                }
            })
            .collect()
    }

    /// The hop of `node` in the trace, if it is there.
    pub fn hop(&self, node: &str) -> Option<Hop> {
        self.hops().into_iter().find(|h| h.node == node)
    }

    /// The last hop's sequence number (its publisher's), 0 for an empty trace.
    pub fn sequence(&self) -> u32 {
        match self.count() as usize {
            0 => 0,
            n => u32::from_le_bytes(self.entry(n - 1)[8..12].try_into().unwrap_or([0; 4])),
        }
    }

    /// Adds the entries of `source`'s trace whose node is not in this one yet
    /// (upstream's `merge_history_into_sample`), as many as fit.
    pub fn merge_history(&mut self, source: &Message) {
        for i in 0..source.count() as usize {
            let n = self.count() as usize;
            if n >= STATS_CAPACITY {
                return;
            }
            let e = source.entry(i);
            let name = Self::name_of(e);
            if (0..n).any(|k| Self::name_of(self.entry(k)) == name) {
                continue;
            }
            let at = STATS_AT + n * STATS_LEN;
            self.bytes[at..at + STATS_LEN].copy_from_slice(e);
            self.set_count(n as u64 + 1);
        }
    }

    /// Appends `node`'s own entry (upstream's `set_sample`), unless the trace is full.
    pub fn push_hop(&mut self, node: &str, sequence: u32, dropped: u32, timestamp: u64) {
        let n = self.count() as usize;
        if n >= STATS_CAPACITY {
            return;
        }
        let at = STATS_AT + n * STATS_LEN;
        let e = &mut self.bytes[at..at + STATS_LEN];
        e.fill(0);
        e[0..8].copy_from_slice(&timestamp.to_le_bytes());
        e[8..12].copy_from_slice(&sequence.to_le_bytes());
        e[12..16].copy_from_slice(&dropped.to_le_bytes());
        let name = node.as_bytes();
        let len = name.len().min(NAME_LEN - 1);
        e[16..16 + len].copy_from_slice(&name[..len]);
        self.set_count(n as u64 + 1);
    }

    /// Writes the work's result into the data (so no compiler drops the work).
    pub fn set_result(&mut self, result: i64) {
        self.bytes[DATA_AT..DATA_AT + 8].copy_from_slice(&result.to_le_bytes());
    }
}

/// The samples missed on an input whose last sequence number was `last` and whose new
/// message carries `current` (upstream's `get_missed_samples_and_update_seq_nr`);
/// updates `last`.
pub fn missed(last: &mut u32, current: u32) -> u32 {
    let gap = if current > *last { current - *last - 1 } else { 0 };
    *last = current;
    gap
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_trace_merges_each_node_once_and_reads_back() {
        let mut front = Message::default();
        front.push_hop("FrontLidarDriver", 7, 0, 100);
        let mut rear = Message::default();
        rear.push_hop("RearLidarDriver", 9, 1, 110);
        let mut fused = Message::default();
        fused.merge_history(&front);
        fused.merge_history(&rear);
        fused.merge_history(&front); // already there
        fused.push_hop("PointCloudFusion", 3, 2, 120);
        let hops = fused.hops();
        assert_eq!(hops.len(), 3);
        assert_eq!(
            hops[0],
            Hop { node: "FrontLidarDriver".into(), timestamp: 100, sequence: 7, dropped: 0 }
        );
        assert_eq!(fused.sequence(), 3);
        assert_eq!(fused.hop("RearLidarDriver").map(|h| h.dropped), Some(1));
        let back = Message::from_bytes(fused.as_bytes()).unwrap();
        assert_eq!(back, fused);
        assert_eq!(Message::from_bytes(&[0; 12]), Err(MessageError::Length(12)));
        let mut last = 3;
        assert_eq!(missed(&mut last, 7), 3);
        assert_eq!(missed(&mut last, 7), 0);
        assert_eq!(last, 7);
    }

    #[test]
    fn a_full_trace_takes_no_more() {
        let mut m = Message::default();
        for i in 0..70 {
            m.push_hop(&format!("n{i}"), i, 0, u64::from(i));
        }
        assert_eq!(m.hops().len(), STATS_CAPACITY);
    }
}
