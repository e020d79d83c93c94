//! The DDS ends of the `ros2-*` rows (feature `ros2`): a ROS 2 publisher or subscriber
//! on `ros2-client` (RustDDS), the crate `esgm-ros2` is built on, with the node, topic
//! names and QoS `esgm ros2` uses (`esgm_ros2::node`: reliable, keep last 10,
//! volatile), so the raw hop and the bridge's differ only by the bridge.
//!
//! Each end is `esgm-bench` in a peer role, started inside the measurement's network
//! namespace, talking to the measuring process by lines:
//! - the **publisher** reads a sequence number per line on stdin, makes that message
//!   (a `geometry_msgs/msg/Pose2D` whose `x` is the number, or a 640×480 `rgb8`
//!   `sensor_msgs/msg/Image` stamped with it, its pixels the frame pattern of the
//!   other image rows), reads the system clock and publishes it; at the end of stdin it
//!   prints `sent <seq> <ns>` for every message, so no output competes with a hop;
//! - the **subscriber** waits for each message (`spin`: `Subscription::take` in a
//!   loop; `event`: blocked in a mio `Poll` on the subscription, how a ROS 2 program
//!   on ros2-client waits), reads what a consumer reads (the `x`, a pixel at each end,
//!   checked), reads the clock and prints `held <seq> <ns>`: the measuring process
//!   paces the next message on it. It ends when its stdin ends.

use std::io::BufRead as _;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

use anyhow::{Context as _, anyhow, bail};
use esgm_core::{Clock as _, SystemClock};
use esgm_ros2::mapping::{RosType, esgm_time, ros_time};
use esgm_ros2::msgs;
use esgm_ros2::node::{self, TopicQos, message_type_name, topic_name};
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use ros2_client::{Publisher, Subscription};
use serde::Serialize;
use serde::de::DeserializeOwned;

use super::ipc_payload::{IMAGE_HEIGHT, IMAGE_NAME, IMAGE_WIDTH, Kind};
use super::ipc_payload::{check_frame, pattern};
use crate::patience::SLICE;
use crate::peer_role::PeerRole;
use crate::wait_mode::WaitMode;

/// The topic of every row (each measurement has its own network namespace, so its own
/// DDS domain).
pub const TOPIC: &str = "/esgm_bench";
/// The peer argument of the publisher.
pub const PUBLISHER: &str = "dds-publisher";
/// The peer argument of the subscriber.
pub const SUBSCRIBER: &str = "dds-subscriber";
/// The longest a DDS end waits for its next message or command: discovery, the
/// bridge's start and the other rows' set-up fit well within it.
pub const WAIT_AT_MOST: Duration = Duration::from_secs(60);
/// Polls between two looks at the clock while spinning.
const POLLS_PER_CHECK: u32 = 4096;

/// A message the rows carry: made from a sequence number, read back as one.
trait Carried: Serialize + DeserializeOwned + Send + 'static {
    /// Its ROS 2 type.
    const ROS_TYPE: RosType;
    /// Message number `seq`.
    fn make(seq: i64) -> anyhow::Result<Self>;
    /// Its number, after reading what a consumer reads (fails on a torn image).
    fn read(&self) -> anyhow::Result<i64>;
}

impl Carried for msgs::Pose2D {
    const ROS_TYPE: RosType = RosType::Pose2D;

    fn make(seq: i64) -> anyhow::Result<Self> {
        let x = seq as f64;
        Ok(msgs::Pose2D { x, y: 0.5 * x, theta: 90f64.to_radians() })
    }

    fn read(&self) -> anyhow::Result<i64> {
        Ok(self.x as i64)
    }
}

impl Carried for msgs::Image {
    const ROS_TYPE: RosType = RosType::Image;

    fn make(seq: i64) -> anyhow::Result<Self> {
        let (width, height) = (IMAGE_WIDTH as u32, IMAGE_HEIGHT as u32);
        // rgb8, as the other image rows' frames (`ipc_payload::IMAGE_FORMAT`).
        let step = width * 3;
        let seed = seq as u8;
        let data = (0..(step * height) as usize).map(|k| pattern(k, seed)).collect();
        Ok(msgs::Image {
            header: msgs::Header { stamp: ros_time(seq)?, frame_id: IMAGE_NAME.to_owned() },
            height,
            width,
            encoding: "rgb8".to_owned(),
            is_bigendian: 0,
            step,
            data,
        })
    }

    fn read(&self) -> anyhow::Result<i64> {
        std::hint::black_box(check_frame(&self.data)?);
        Ok(esgm_time(self.header.stamp))
    }
}

/// The size of a row's message as DDS carries it (CDR, with its encapsulation header).
pub fn cdr_bytes(kind: Kind) -> anyhow::Result<u64> {
    let mut out = Vec::new();
    match kind {
        Kind::Small => esgm_ros2msg::cdr::encode_into(&msgs::Pose2D::make(0)?, &mut out)?,
        Kind::Image => esgm_ros2msg::cdr::encode_into(&msgs::Image::make(0)?, &mut out)?,
    }
    Ok(out.len() as u64)
}

/// The peer side of a `ros2-*` row: the DDS end `role.arg` names, for `kind`.
pub fn run_peer(role: &PeerRole, kind: Kind) -> anyhow::Result<Vec<String>> {
    match (role.arg.as_deref(), kind) {
        (Some(PUBLISHER), Kind::Small) => publish::<msgs::Pose2D>(),
        (Some(PUBLISHER), Kind::Image) => publish::<msgs::Image>(),
        (Some(SUBSCRIBER), Kind::Small) => subscribe::<msgs::Pose2D>(role.wait),
        (Some(SUBSCRIBER), Kind::Image) => subscribe::<msgs::Image>(role.wait),
        (other, _) => bail!("a ros2 peer is {PUBLISHER} or {SUBSCRIBER}, not {other:?}"),
    }
}

/// The node and the topic's QoS, as `esgm ros2` joins.
fn join<M: Carried>(
    name: &str,
) -> anyhow::Result<(node::RosNode, ros2_client::dds::rustdds::Topic)> {
    let ros = node::join(0, name)?;
    let profile = TopicQos::default().profile();
    let topic = ros
        .node
        .create_topic(&topic_name(TOPIC)?, message_type_name(M::ROS_TYPE), &profile)
        .map_err(|e| anyhow!("cannot create topic {TOPIC}: {e:?}"))?;
    Ok((ros, topic))
}

/// The publisher: see the module docs.
fn publish<M: Carried>() -> anyhow::Result<Vec<String>> {
    let (mut ros, topic) = join::<M>("bench_publisher")?;
    let publisher: Publisher<M> = ros
        .node
        .create_publisher(&topic, None)
        .map_err(|e| anyhow!("cannot create the publisher of {TOPIC}: {e:?}"))?;
    let commands = stdin_lines()?;
    let mut sent = Vec::new();
    loop {
        // The measuring process ends stdin when the row is done, or by exiting.
        let line = match commands.recv_timeout(WAIT_AT_MOST) {
            Ok(line) => line,
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
            Err(mpsc::RecvTimeoutError::Timeout) => {
                bail!("no command from the measuring process within {WAIT_AT_MOST:?}")
            }
        };
        let seq: i64 = line.trim().parse().with_context(|| format!("not a number: {line:?}"))?;
        let message = M::make(seq)?;
        let now = SystemClock.now();
        publisher.publish(message).map_err(|e| anyhow!("publishing {seq}: {e}"))?;
        sent.push(format!("sent {seq} {now}"));
    }
    Ok(sent)
}

/// The subscriber: see the module docs.
fn subscribe<M: Carried>(mode: WaitMode) -> anyhow::Result<Vec<String>> {
    let (mut ros, topic) = join::<M>("bench_subscriber")?;
    let mut subscription: Subscription<M> = ros
        .node
        .create_subscription(&topic, None)
        .map_err(|e| anyhow!("cannot create the subscription of {TOPIC}: {e:?}"))?;
    let poll = Poll::new().context("a mio poll for the subscription")?;
    poll.registry()
        .register(&mut subscription, Token(0), Interest::READABLE)
        .context("registering the subscription with mio")?;
    let mut waiter = Waiter { poll, events: Events::with_capacity(4), mode };
    let stop = stop_at_end_of_stdin()?;
    while let Some(message) = waiter.next(&subscription, &stop)? {
        let seq = message.read()?;
        let now = SystemClock.now();
        println!("held {seq} {now}");
    }
    Ok(Vec::new())
}

/// How the subscriber waits (see the module docs).
struct Waiter {
    poll: Poll,
    events: Events,
    mode: WaitMode,
}

impl Waiter {
    /// The next message, or `None` once `stop` is set; fails after [`WAIT_AT_MOST`]
    /// without one.
    fn next<M: Carried>(
        &mut self,
        subscription: &Subscription<M>,
        stop: &AtomicBool,
    ) -> anyhow::Result<Option<M>> {
        let mut since: Option<Instant> = None;
        let mut polls = 0u32;
        loop {
            // Taken before every wait: mio's readiness is edge-triggered.
            if let Some((message, _)) =
                subscription.take().map_err(|e| anyhow!("reading {TOPIC}: {e:?}"))?
            {
                return Ok(Some(message));
            }
            match self.mode {
                WaitMode::Spin => {
                    polls = polls.wrapping_add(1);
                    if polls % POLLS_PER_CHECK != 0 {
                        std::hint::spin_loop();
                        continue;
                    }
                }
                WaitMode::Block | WaitMode::SpinThenBlock => {
                    if let Err(e) = self.poll.poll(&mut self.events, Some(SLICE)) {
                        // EINTR: look again.
                        if e.kind() != std::io::ErrorKind::Interrupted {
                            return Err(e).context("waiting for a message");
                        }
                    }
                }
            }
            if stop.load(Ordering::Relaxed) {
                return Ok(None);
            }
            if since.get_or_insert_with(Instant::now).elapsed() > WAIT_AT_MOST {
                bail!("no message on {TOPIC} within {WAIT_AT_MOST:?}");
            }
        }
    }
}

/// The lines of stdin, read on a thread, so that waiting for one can have a timeout;
/// the channel ends with stdin (closed by the measuring process, or at its exit).
fn stdin_lines() -> anyhow::Result<mpsc::Receiver<String>> {
    let (tx, rx) = mpsc::channel();
    std::thread::Builder::new()
        .name("esgm-bench-stdin".into())
        .spawn(move || {
            // A read error ends stdin as its end does.
            for line in std::io::stdin().lock().lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    return;
                }
            }
        })
        .context("starting the thread that reads stdin")?;
    Ok(rx)
}

/// A flag set when stdin ends: nothing is sent to a subscriber but the end, so a
/// thread that does nothing else waits for it (it ends with the process otherwise).
fn stop_at_end_of_stdin() -> anyhow::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&stop);
    std::thread::Builder::new()
        .name("esgm-bench-stop".into())
        .spawn(move || {
            // A read error ends stdin as its end does.
            for _ in std::io::stdin().lock().lines().map_while(Result::ok) {}
            flag.store(true, Ordering::Relaxed);
        })
        .context("starting the thread that watches stdin")?;
    Ok(stop)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenarios::inproc_hop_image::PIXEL_BYTES;

    #[test]
    fn messages_carry_their_number_and_a_torn_frame_is_refused() {
        assert_eq!(msgs::Pose2D::make(7).unwrap().read().unwrap(), 7);
        let mut image = msgs::Image::make(300).unwrap();
        assert_eq!(image.read().unwrap(), 300);
        assert_eq!(image.data.len(), PIXEL_BYTES);
        assert!(cdr_bytes(Kind::Image).unwrap() > PIXEL_BYTES as u64);
        image.data[PIXEL_BYTES - 1] ^= 1;
        assert!(image.read().is_err());
    }
}
