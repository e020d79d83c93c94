//! What every node of the reference system says when it stops, in a line-based text
//! form every system writes alike (the ROS 1 peer's C++ too), one file per node:
//!
//! ```text
//! node PointCloudFusion
//! published PointCloudFusion 99
//! received PointsTransformerFront 100 0
//! hot 41 1795000000000000000 1795000000012000000     # root sequence, root time, sink time
//! fired 1795000000100000000                             # a cyclic node's timer
//! ```

use std::fmt::Write as _;

/// One output of the hot path's sink: which front-lidar message it came from, when the
/// front lidar made it and when the sink received what it was made from (ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HotPathRecord {
    /// The front lidar's sequence number.
    pub root_sequence: u32,
    /// The front lidar's timestamp.
    pub root_timestamp: u64,
    /// The sink's timestamp.
    pub sink_timestamp: u64,
}

/// What one node did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeReport {
    /// Its name.
    pub node: String,
    /// Per output topic: messages published.
    pub published: Vec<(String, u64)>,
    /// Per input topic: messages received, and missed (sequence gaps).
    pub received: Vec<(String, u64, u64)>,
    /// The hot path's sink's records.
    pub hot_path: Vec<HotPathRecord>,
    /// A cyclic node's timer ticks (ns).
    pub planner_fired: Vec<u64>,
}

impl NodeReport {
    /// An empty report of `node`.
    pub fn new(node: &str) -> Self {
        Self { node: node.to_owned(), ..Self::default() }
    }

    /// Another report of the same node (an intersection's second connection) folded in.
    pub fn merge(&mut self, other: NodeReport) {
        self.published.extend(other.published);
        self.received.extend(other.received);
        self.hot_path.extend(other.hot_path);
        self.planner_fired.extend(other.planner_fired);
    }

    /// `reports` with those of one node folded into one (a node served by several
    /// processes: the intersection's two units on esgm), in the order nodes come first.
    pub fn by_node(reports: impl IntoIterator<Item = NodeReport>) -> Vec<NodeReport> {
        let mut out: Vec<NodeReport> = Vec::new();
        for r in reports {
            match out.iter_mut().find(|o| o.node == r.node) {
                Some(o) => o.merge(r),
                None => out.push(r),
            }
        }
        out
    }

    /// The report as text.
    pub fn to_text(&self) -> String {
        let mut s = format!("node {}\n", self.node);
        for (t, n) in &self.published {
            let _infallible = writeln!(s, "published {t} {n}");
        }
        for (t, n, d) in &self.received {
            let _infallible = writeln!(s, "received {t} {n} {d}");
        }
        for h in &self.hot_path {
            let _infallible =
                writeln!(s, "hot {} {} {}", h.root_sequence, h.root_timestamp, h.sink_timestamp);
        }
        for t in &self.planner_fired {
            let _infallible = writeln!(s, "fired {t}");
        }
        s
    }

    /// The report in `text`, or which line is not one.
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        let mut r = Self::default();
        for (i, line) in text.lines().enumerate() {
            let bad = || anyhow::anyhow!("line {}: `{line}` is not a node report's", i + 1);
            let words: Vec<&str> = line.split_whitespace().collect();
            let num = |k: usize| -> anyhow::Result<u64> {
                words.get(k).and_then(|w| w.parse().ok()).ok_or_else(bad)
            };
            match words.first().copied() {
                None => {}
                Some("node") => r.node = words.get(1).ok_or_else(bad)?.to_string(),
                Some("published") => {
                    r.published.push((words.get(1).ok_or_else(bad)?.to_string(), num(2)?))
                }
                Some("received") => {
                    r.received.push((words.get(1).ok_or_else(bad)?.to_string(), num(2)?, num(3)?));
                }
                Some("hot") => r.hot_path.push(HotPathRecord {
                    root_sequence: u32::try_from(num(1)?).map_err(|_| bad())?,
                    root_timestamp: num(2)?,
                    sink_timestamp: num(3)?,
                }),
                Some("fired") => r.planner_fired.push(num(1)?),
                Some(_) => return Err(bad()),
            }
        }
        if r.node.is_empty() {
            anyhow::bail!("a node report without its `node` line");
        }
        Ok(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_reads_back() {
        let mut r = NodeReport::new("BehaviorPlanner");
        r.published.push(("BehaviorPlanner".into(), 3));
        r.received.push(("LanePlanner".into(), 5, 1));
        r.hot_path.push(HotPathRecord { root_sequence: 1, root_timestamp: 10, sink_timestamp: 20 });
        r.planner_fired.push(99);
        assert_eq!(NodeReport::parse(&r.to_text()).unwrap(), r);
        assert!(NodeReport::parse("node X\nbogus 1\n").is_err());
        assert!(NodeReport::parse("published X 1\n").is_err());
    }

    #[test]
    fn reports_of_one_node_fold_into_one() {
        let part = |node: &str, topic: &str| {
            let mut r = NodeReport::new(node);
            r.published.push((topic.into(), 1));
            r
        };
        let merged = NodeReport::by_node([
            part("EuclideanClusterDetector", "EuclideanClusterDetector"),
            part("Visualizer", "Visualizer"),
            part("EuclideanClusterDetector", "EuclideanIntersection"),
        ]);
        assert_eq!(merged.len(), 2);
        assert_eq!(merged[0].published.len(), 2);
    }
}
