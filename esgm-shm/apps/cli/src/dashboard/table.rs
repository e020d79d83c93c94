//! What `esgm top` shows of a [`Snapshot`]: which rows (a filter), in which order (a
//! sort key), as cells of text. The dashboard and the plain table use the same cells,
//! so `esgm top --once` prints what the dashboard shows.

use std::collections::BTreeMap;

use super::{ProcessRow, Snapshot, TrajectoryRow};
use crate::show::ms;

/// The order of the trajectory table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum SortKey {
    /// By name.
    #[default]
    Name,
    /// By kind, then name.
    Kind,
    /// Highest rate first.
    Rate,
    /// Largest p99 add delay first.
    Delay,
    /// Most losses and violations first.
    Drops,
    /// Most bytes held first.
    Bytes,
}

impl SortKey {
    /// Every key, in the order the dashboard's `s` cycles through them.
    pub const ALL: [SortKey; 6] = [
        SortKey::Name,
        SortKey::Kind,
        SortKey::Rate,
        SortKey::Delay,
        SortKey::Drops,
        SortKey::Bytes,
    ];

    /// The key after this one.
    pub fn next(self) -> Self {
        let i = Self::ALL.iter().position(|k| *k == self).unwrap_or(0);
        Self::ALL[(i + 1) % Self::ALL.len()]
    }

    /// Its name, as `--sort` takes it.
    pub fn as_str(self) -> &'static str {
        match self {
            SortKey::Name => "name",
            SortKey::Kind => "kind",
            SortKey::Rate => "rate",
            SortKey::Delay => "delay",
            SortKey::Drops => "drops",
            SortKey::Bytes => "bytes",
        }
    }
}

/// How the tables are cut and ordered.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Shape {
    /// The trajectory order.
    pub sort: SortKey,
    /// Reverse the order.
    pub reverse: bool,
    /// Only trajectories and processes whose name (or a trajectory's type or kind)
    /// contains this, ignoring case.
    pub filter: String,
}

impl Shape {
    fn keeps(&self, fields: &[&str]) -> bool {
        let filter = self.filter.to_lowercase();
        filter.is_empty() || fields.iter().any(|f| f.to_lowercase().contains(&filter))
    }

    /// The trajectory rows to show, in order.
    pub fn trajectories<'a>(&self, snapshot: &'a Snapshot) -> Vec<&'a TrajectoryRow> {
        let mut rows: Vec<&TrajectoryRow> = snapshot
            .trajectories
            .iter()
            .filter(|t| self.keeps(&[&t.name, &t.type_name, &t.kind]))
            .collect();
        rows.sort_by(|a, b| {
            let by_name = a.name.cmp(&b.name);
            match self.sort {
                SortKey::Name => by_name,
                SortKey::Kind => a.kind.cmp(&b.kind).then(by_name),
                SortKey::Rate => b.rate_hz.total_cmp(&a.rate_hz).then(by_name),
                SortKey::Delay => b.add_delay_p99.cmp(&a.add_delay_p99).then(by_name),
                SortKey::Drops => b.dropped().cmp(&a.dropped()).then(by_name),
                SortKey::Bytes => b.bytes.cmp(&a.bytes).then(by_name),
            }
        });
        if self.reverse {
            rows.reverse();
        }
        rows
    }

    /// The process rows to show (the coordinator first, then by name).
    pub fn processes<'a>(&self, snapshot: &'a Snapshot) -> Vec<&'a ProcessRow> {
        snapshot.processes.iter().filter(|p| self.keeps(&[&p.name])).collect()
    }
}

/// Column headers of the trajectory table.
pub const TRAJECTORY_HEADER: [&str; 11] = [
    "trajectory",
    "kind",
    "type",
    "rate Hz",
    "added",
    "p50 ms",
    "p99 ms",
    "losses",
    "violations",
    "subs",
    "bytes",
];

/// Column headers of the process table.
pub const PROCESS_HEADER: [&str; 6] = ["process", "pid", "cpu %", "rss", "restarts", "last exit"];

/// `lost=3 reset=1`, or `-`.
fn causes(counts: &BTreeMap<String, u64>) -> String {
    if counts.is_empty() {
        return "-".into();
    }
    counts.iter().map(|(c, n)| format!("{c}={n}")).collect::<Vec<_>>().join(" ")
}

/// `512 B`, `1.5 KiB`, `3.2 MiB`, `1.0 GiB`.
pub fn bytes(n: u64) -> String {
    const UNITS: [&str; 4] = ["KiB", "MiB", "GiB", "TiB"];
    if n < 1024 {
        return format!("{n} B");
    }
    let mut v = n as f64 / 1024.0;
    let mut unit = 0;
    while v >= 1024.0 && unit + 1 < UNITS.len() {
        v /= 1024.0;
        unit += 1;
    }
    format!("{v:.1} {}", UNITS[unit])
}

fn or_dash<T>(v: Option<T>, f: impl Fn(T) -> String) -> String {
    v.map_or_else(|| "-".to_owned(), f)
}

/// A trajectory's cells, in [`TRAJECTORY_HEADER`]'s order.
pub fn trajectory_cells(t: &TrajectoryRow) -> [String; 11] {
    [
        t.name.clone(),
        t.kind.clone(),
        t.type_name.clone(),
        format!("{:.1}", t.rate_hz),
        t.added.to_string(),
        ms(t.add_delay_p50).to_string(),
        ms(t.add_delay_p99).to_string(),
        causes(&t.losses),
        causes(&t.violations),
        t.subscribers.to_string(),
        or_dash(t.bytes, bytes),
    ]
}

/// A process's cells, in [`PROCESS_HEADER`]'s order.
pub fn process_cells(p: &ProcessRow) -> [String; 6] {
    [
        p.name.clone(),
        or_dash(p.pid, |p| p.to_string()),
        or_dash(p.cpu_percent, |c| format!("{c:.1}")),
        or_dash(p.rss_bytes, bytes),
        p.restarts.to_string(),
        p.last_exit.clone().unwrap_or_else(|| "-".into()),
    ]
}

/// Rows of cells as aligned text: the first `left` columns left-aligned, the rest
/// right-aligned, two spaces apart.
fn aligned<const N: usize>(header: [&str; N], rows: &[[String; N]], left: usize) -> String {
    let mut widths = header.map(str::len);
    for row in rows {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let mut out = String::new();
    let header = header.map(str::to_owned);
    for row in std::iter::once(&header).chain(rows) {
        let mut line = String::new();
        for (i, (cell, w)) in row.iter().zip(widths).enumerate() {
            let sep = if i == 0 { "" } else { "  " };
            let cell = if i < left { format!("{cell:<w$}") } else { format!("{cell:>w$}") };
            line.push_str(sep);
            line.push_str(&cell);
        }
        out.push_str(line.trim_end());
        out.push('\n');
    }
    out
}

/// The whole snapshot as plain text: the trajectory table, a blank line, the process
/// table.
pub fn plain(snapshot: &Snapshot, shape: &Shape) -> String {
    let trajectories: Vec<_> =
        shape.trajectories(snapshot).into_iter().map(trajectory_cells).collect();
    let processes: Vec<_> = shape.processes(snapshot).into_iter().map(process_cells).collect();
    let mut out = aligned(TRAJECTORY_HEADER, &trajectories, 3);
    if let Some(line) = summary(snapshot) {
        out.push_str(&line);
        out.push('\n');
    }
    out.push('\n');
    out.push_str(&aligned(PROCESS_HEADER, &processes, 1));
    out
}

/// `memory: 120 samples stored, 1.5 MiB (all processes)`, and why the figures are a
/// replica's if they are.
pub fn summary(snapshot: &Snapshot) -> Option<String> {
    let memory = snapshot.memory.map(|m| {
        format!(
            "memory: {} samples stored, {} held for reordering, {} (all processes)",
            m.stored_samples,
            m.held_samples,
            bytes(m.approx_bytes as u64)
        )
    });
    match (memory, &snapshot.note) {
        (Some(m), Some(n)) => Some(format!("{m}; {n}")),
        (Some(m), None) => Some(m),
        (None, Some(n)) => Some(n.clone()),
        (None, None) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(name: &str, rate_hz: f64, lost: u64) -> TrajectoryRow {
        TrajectoryRow {
            name: name.into(),
            kind: "primitive".into(),
            type_name: "RobotState".into(),
            rate_hz,
            added: 10,
            add_delay_p50: Some(1_500_000),
            add_delay_p99: None,
            losses: [("lost".to_owned(), lost)].into_iter().filter(|(_, n)| *n > 0).collect(),
            violations: BTreeMap::new(),
            subscribers: 1,
            stored: 10,
            bytes: Some(2048),
        }
    }

    fn snapshot() -> Snapshot {
        Snapshot {
            trajectories: vec![row("b", 5.0, 0), row("a", 30.0, 0), row("cam", 1.0, 7)],
            processes: vec![ProcessRow {
                name: "coordinator".into(),
                pid: Some(42),
                cpu_percent: Some(1.25),
                rss_bytes: Some(3 << 20),
                restarts: 0,
                last_exit: None,
            }],
            memory: Some(esgm_core::esgm::MemoryStats {
                trajectories: 3,
                stored_samples: 30,
                held_samples: 0,
                approx_bytes: 6144,
            }),
            note: None,
        }
    }

    fn names(shape: &Shape) -> Vec<String> {
        let s = snapshot();
        shape.trajectories(&s).into_iter().map(|t| t.name.clone()).collect()
    }

    #[test]
    fn sort_keys_and_reverse() {
        assert_eq!(names(&Shape::default()), ["a", "b", "cam"]);
        let rate = Shape { sort: SortKey::Rate, ..Shape::default() };
        assert_eq!(names(&rate), ["a", "b", "cam"]);
        let drops = Shape { sort: SortKey::Drops, reverse: true, ..Shape::default() };
        assert_eq!(names(&drops), ["b", "a", "cam"]);
        assert_eq!(SortKey::Bytes.next(), SortKey::Name);
    }

    #[test]
    fn the_filter_matches_names_types_and_kinds_ignoring_case() {
        assert_eq!(names(&Shape { filter: "CA".into(), ..Shape::default() }), ["cam"]);
        assert_eq!(names(&Shape { filter: "robotstate".into(), ..Shape::default() }).len(), 3);
        let s = snapshot();
        assert!(Shape { filter: "zz".into(), ..Shape::default() }.processes(&s).is_empty());
    }

    #[test]
    fn the_plain_table_has_every_column() {
        let text = plain(&snapshot(), &Shape::default());
        let mut lines = text.lines();
        let header = lines.next().unwrap_or_default();
        for h in TRAJECTORY_HEADER {
            assert!(header.contains(h), "{header}");
        }
        assert!(text.contains("lost=7"), "{text}");
        assert!(text.contains("2.0 KiB"), "{text}");
        assert!(text.contains("coordinator") && text.contains("3.0 MiB"), "{text}");
        assert!(text.contains("1.50"), "p50 in ms: {text}");
        assert!(
            text.contains("memory: 30 samples stored, 0 held for reordering, 6.0 KiB"),
            "{text}"
        );
    }

    #[test]
    fn byte_units() {
        assert_eq!(bytes(512), "512 B");
        assert_eq!(bytes(1536), "1.5 KiB");
        assert_eq!(bytes(921_600), "900.0 KiB");
    }
}
