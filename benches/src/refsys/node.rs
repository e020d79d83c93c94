//! What each kind of node does with its messages, whatever carries them: the logic of
//! upstream's `nodes/rclcpp/{sensor,transform,fusion,cyclic,intersection,command}.hpp`
//! without the transport, so esgm, ROS 1's port and ROS 2's wire run the same nodes.
//! Each counts what it received, missed (sequence gaps on its inputs) and published,
//! and the two whose behaviour is a KPI keep their records: the hot path's sink (the
//! front lidar's timestamp and its own, per output) and the cyclic planner (when its
//! timer fired).

use super::cruncher::number_cruncher;
use super::message::{Message, missed};
use super::report::{HotPathRecord, NodeReport};
use super::topology::{HOT_PATH_ROOT, HOT_PATH_SINK};

/// Now on the host's system clock, in ns (upstream's `now_as_int`): every process
/// stamps the same timeline.
pub fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// A sensor: a fresh message every period.
#[derive(Debug, Clone)]
pub struct Sensor {
    name: &'static str,
    sequence: u32,
}

impl Sensor {
    /// The sensor `name`.
    pub fn new(name: &'static str) -> Self {
        Self { name, sequence: 0 }
    }

    /// Its message for this period.
    pub fn fire(&mut self) -> Message {
        let mut m = Message::default();
        m.push_hop(self.name, self.sequence, 0, now_ns());
        self.sequence += 1;
        m
    }

    /// What it did.
    pub fn report(&self) -> NodeReport {
        let mut r = NodeReport::new(self.name);
        r.published.push((self.name.to_owned(), u64::from(self.sequence)));
        r
    }
}

/// One input to one output, on every input (also each of the intersection's two).
#[derive(Debug, Clone)]
pub struct Transform {
    name: &'static str,
    input: &'static str,
    output: &'static str,
    crunch: u64,
    sequence: u32,
    last_input: u32,
    received: u64,
    dropped: u64,
    hot_path: Vec<HotPathRecord>,
}

impl Transform {
    /// Node `name` transforming `input` into `output` with `crunch` of work.
    pub fn new(name: &'static str, input: &'static str, output: &'static str, crunch: u64) -> Self {
        Self {
            name,
            input,
            output,
            crunch,
            sequence: 0,
            last_input: 0,
            received: 0,
            dropped: 0,
            hot_path: Vec::new(),
        }
    }

    /// Its output for `input` (received now).
    pub fn on_input(&mut self, input: &Message) -> Message {
        let timestamp = now_ns();
        let result = number_cruncher(self.crunch);
        let mut out = Message::default();
        out.merge_history(input);
        let dropped = missed(&mut self.last_input, input.sequence());
        self.received += 1;
        self.dropped += u64::from(dropped);
        out.push_hop(self.name, self.sequence, dropped, timestamp);
        out.set_result(result);
        self.sequence += 1;
        if self.name == HOT_PATH_SINK {
            if let Some(root) = input.hop(HOT_PATH_ROOT) {
                self.hot_path.push(HotPathRecord {
                    root_sequence: root.sequence,
                    root_timestamp: root.timestamp,
                    sink_timestamp: timestamp,
                });
            }
        }
        out
    }

    /// The topic it publishes.
    pub fn output(&self) -> &'static str {
        self.output
    }

    /// What it did (one report per connection of an intersection: merge them).
    pub fn report(&self) -> NodeReport {
        let mut r = NodeReport::new(self.name);
        r.published.push((self.output.to_owned(), u64::from(self.sequence)));
        r.received.push((self.input.to_owned(), self.received, self.dropped));
        r.hot_path.clone_from(&self.hot_path);
        r
    }
}

/// Two inputs to one output, once both have a message not used yet.
#[derive(Debug, Clone)]
pub struct Fusion {
    name: &'static str,
    inputs: [&'static str; 2],
    crunch: u64,
    cache: [Option<Message>; 2],
    last_input: [u32; 2],
    received: [u64; 2],
    dropped: [u64; 2],
    sequence: u32,
}

impl Fusion {
    /// Node `name` fusing `inputs` with `crunch` of work.
    pub fn new(name: &'static str, inputs: [&'static str; 2], crunch: u64) -> Self {
        Self {
            name,
            inputs,
            crunch,
            cache: [None, None],
            last_input: [0; 2],
            received: [0; 2],
            dropped: [0; 2],
            sequence: 0,
        }
    }

    /// Takes a message of input `index` (0 or 1); the output once both have one.
    pub fn on_input(&mut self, index: usize, input: Message) -> Option<Message> {
        let timestamp = now_ns();
        self.received[index] += 1;
        self.cache[index] = Some(input);
        let (Some(a), Some(b)) = (&self.cache[0], &self.cache[1]) else { return None };
        let result = number_cruncher(self.crunch);
        let gaps = [
            missed(&mut self.last_input[0], a.sequence()),
            missed(&mut self.last_input[1], b.sequence()),
        ];
        let mut out = Message::default();
        out.merge_history(a);
        out.merge_history(b);
        out.push_hop(self.name, self.sequence, gaps[0] + gaps[1], timestamp);
        out.set_result(result);
        self.dropped[0] += u64::from(gaps[0]);
        self.dropped[1] += u64::from(gaps[1]);
        self.sequence += 1;
        self.cache = [None, None];
        Some(out)
    }

    /// The sequence numbers of the messages it used last, per input: a transport that
    /// hands over the latest of both on every update offers only the new ones.
    pub fn used(&self) -> [u32; 2] {
        self.last_input
    }

    /// What it did.
    pub fn report(&self) -> NodeReport {
        let mut r = NodeReport::new(self.name);
        r.published.push((self.name.to_owned(), u64::from(self.sequence)));
        for i in 0..2 {
            r.received.push((self.inputs[i].to_owned(), self.received[i], self.dropped[i]));
        }
        r
    }
}

/// Six inputs to one output on a timer, with what arrived since the last tick.
#[derive(Debug, Clone)]
pub struct Cyclic {
    name: &'static str,
    inputs: Vec<&'static str>,
    crunch: u64,
    cache: Vec<Option<Message>>,
    last_input: Vec<u32>,
    received: Vec<u64>,
    dropped: Vec<u64>,
    sequence: u32,
    fired: Vec<u64>,
}

impl Cyclic {
    /// Node `name` over `inputs` with `crunch` of work per tick.
    pub fn new(name: &'static str, inputs: &[&'static str], crunch: u64) -> Self {
        let n = inputs.len();
        Self {
            name,
            inputs: inputs.to_vec(),
            crunch,
            cache: vec![None; n],
            last_input: vec![0; n],
            received: vec![0; n],
            dropped: vec![0; n],
            sequence: 0,
            fired: Vec::new(),
        }
    }

    /// Keeps the latest message of input `index`.
    pub fn on_input(&mut self, index: usize, input: Message) {
        self.received[index] += 1;
        self.cache[index] = Some(input);
    }

    /// The sequence number of the message of input `index` it used last.
    pub fn used(&self, index: usize) -> u32 {
        self.last_input[index]
    }

    /// Its output for this tick.
    pub fn on_timer(&mut self) -> Message {
        let timestamp = now_ns();
        self.fired.push(timestamp);
        let result = number_cruncher(self.crunch);
        let mut out = Message::default();
        let mut dropped = 0;
        for i in 0..self.cache.len() {
            if let Some(m) = self.cache[i].take() {
                let gap = missed(&mut self.last_input[i], m.sequence());
                self.dropped[i] += u64::from(gap);
                dropped += gap;
                out.merge_history(&m);
            }
        }
        out.push_hop(self.name, self.sequence, dropped, timestamp);
        out.set_result(result);
        self.sequence += 1;
        out
    }

    /// What it did.
    pub fn report(&self) -> NodeReport {
        let mut r = NodeReport::new(self.name);
        r.published.push((self.name.to_owned(), u64::from(self.sequence)));
        for i in 0..self.inputs.len() {
            r.received.push((self.inputs[i].to_owned(), self.received[i], self.dropped[i]));
        }
        r.planner_fired.clone_from(&self.fired);
        r
    }
}

/// A sink.
#[derive(Debug, Clone)]
pub struct Command {
    name: &'static str,
    input: &'static str,
    last_input: u32,
    received: u64,
    dropped: u64,
}

impl Command {
    /// Sink `name` of `input`.
    pub fn new(name: &'static str, input: &'static str) -> Self {
        Self { name, input, last_input: 0, received: 0, dropped: 0 }
    }

    /// Takes a message.
    pub fn on_input(&mut self, input: &Message) {
        self.received += 1;
        self.dropped += u64::from(missed(&mut self.last_input, input.sequence()));
    }

    /// What it did.
    pub fn report(&self) -> NodeReport {
        let mut r = NodeReport::new(self.name);
        r.received.push((self.input.to_owned(), self.received, self.dropped));
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hot_path_sink_records_the_front_lidars_time() {
        let mut front = Sensor::new("FrontLidarDriver");
        let mut oce = Transform::new(
            "ObjectCollisionEstimator",
            "EuclideanClusterDetector",
            "ObjectCollisionEstimator",
            10,
        );
        let m = front.fire();
        let out = oce.on_input(&m);
        assert_eq!(out.hops().len(), 2);
        let r = oce.report();
        assert_eq!(r.hot_path.len(), 1);
        assert!(r.hot_path[0].sink_timestamp >= r.hot_path[0].root_timestamp);
    }

    #[test]
    fn a_fusion_fires_once_both_inputs_arrived_and_counts_gaps() {
        let mut a = Sensor::new("A");
        let mut b = Sensor::new("B");
        let mut f = Fusion::new("F", ["A", "B"], 10);
        assert!(f.on_input(0, a.fire()).is_none());
        let _skipped = a.fire(); // never delivered: a gap on input 0
        assert!(f.on_input(0, a.fire()).is_none());
        let out = f.on_input(1, b.fire()).expect("both arrived");
        assert_eq!(out.hop("F").map(|h| h.dropped), Some(1));
        assert_eq!(f.report().received[0], ("A".to_owned(), 2, 1));
        assert!(f.on_input(1, b.fire()).is_none(), "input 0 has nothing new");
    }
}
