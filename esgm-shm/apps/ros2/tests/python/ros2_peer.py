"""A stand-in ROS 2 node for esgm-ros2's tests: the `cyclonedds` package from PyPI,
with IDL types named as ROS 2 names them (`sensor_msgs::msg::dds_::Image_` on topic
`rt/camera/image_raw`), talks the wire of a ROS 2 node on rmw_cyclonedds. It shares no
code with esgm or with ros2-client.

Usage:
  ros2_peer.py publish-images TOPIC COUNT [UNCONVERTIBLE]
      waits for a reader, publishes COUNT 4x3 rgb8 images (stamp = 1000 s + i ms,
      frame "camera", pixel k of image i = (k + 7 i) % 251), then waits for the
      reader to acknowledge them (after UNCONVERTIBLE more in an encoding esgm has
      no format for); prints `published COUNT`.
  ros2_peer.py publish-blob-seqs TOPIC COUNT
      waits for a reader, publishes COUNT esgm_msgs/msg/BlobSeq (stamp 2000 s + i ms,
      blobs ("b<k>", k, -k, 10 i + k), k = 1, 2), waits for acknowledgements; prints
      `published COUNT`.
  ros2_peer.py publish-best-effort TOPIC SECONDS
      publishes 1x1 images best effort for SECONDS (prints `publishing` first): a
      reliable reader cannot match it.
  ros2_peer.py read-poses TOPIC COUNT TIMEOUT_S
      reads COUNT geometry_msgs/msg/Pose2D and prints each as a JSON line.
  ros2_peer.py read-blob-seqs TOPIC COUNT TIMEOUT_S
      reads COUNT esgm_msgs/msg/BlobSeq, the message `esgm ros2 msg BlobSeq` defines
      (declared here from that definition, as rosidl would generate it), and prints
      each as a JSON line.
"""

import json
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Qos, Policy
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int32, int64, sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header
    height: uint32
    width: uint32
    encoding: str
    is_bigendian: uint8
    step: uint32
    data: sequence[uint8]


@dataclass
class Pose2D(IdlStruct, typename="geometry_msgs::msg::dds_::Pose2D_"):
    x: float64
    y: float64
    theta: float64


@dataclass
class BlobFrame(IdlStruct, typename="esgm_msgs::msg::dds_::BlobFrame_"):
    name: str
    x: int64
    y: int64
    size: int64


@dataclass
class BlobSeq(IdlStruct, typename="esgm_msgs::msg::dds_::BlobSeq_"):
    header: Header
    items: sequence[BlobFrame]


# ROS 2's default QoS: reliable, keep last 10, volatile.
QOS = Qos(
    Policy.Reliability.Reliable(duration(seconds=1)),
    Policy.History.KeepLast(10),
    Policy.Durability.Volatile,
)


def dds_topic(ros_topic):
    return "rt" + ros_topic


def wait_for(condition, timeout, what):
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            sys.exit(f"ros2_peer: {what} within {timeout} s")
        time.sleep(0.02)


def publish_images(topic, count, unconvertible=0):
    """`count` 4x3 rgb8 images, then `unconvertible` in an encoding esgm has no format
    for (which the bridge must count, not store)."""
    dp = DomainParticipant(0)
    writer = DataWriter(dp, Topic(dp, dds_topic(topic), Image), qos=QOS)
    wait_for(lambda: len(writer.get_matched_subscriptions()) > 0, 20, "no reader matched")
    w, h = 4, 3
    for i in range(count):
        data = [(k + 7 * i) % 251 for k in range(w * h * 3)]
        stamp = Time(sec=1000, nanosec=i * 1_000_000)
        writer.write(Image(Header(stamp, "camera"), h, w, "rgb8", 0, w * 3, data))
        time.sleep(0.01)
    for i in range(unconvertible):
        stamp = Time(sec=2000, nanosec=i)
        writer.write(Image(Header(stamp, "camera"), h, w, "bayer_weird16", 0, w * 2, [0] * (w * h * 2)))
    writer.wait_for_acks(duration(seconds=10))
    print(f"published {count}", flush=True)


def publish_blob_seqs(topic, count):
    """Waits for a reader, publishes COUNT esgm_msgs/msg/BlobSeq (stamp 2000 s + i ms,
    frame "camera", blobs ("b<k>", k, -k, 10 i + k) for k in 1..=2), and waits for them
    to be acknowledged; prints `published COUNT`."""
    dp = DomainParticipant(0)
    writer = DataWriter(dp, Topic(dp, dds_topic(topic), BlobSeq), qos=QOS)
    wait_for(lambda: len(writer.get_matched_subscriptions()) > 0, 20, "no reader matched")
    for i in range(count):
        items = [BlobFrame(f"b{k}", k, -k, 10 * i + k) for k in (1, 2)]
        writer.write(BlobSeq(Header(Time(sec=2000, nanosec=i * 1_000_000), "camera"), items))
        time.sleep(0.01)
    writer.wait_for_acks(duration(seconds=10))
    print(f"published {count}", flush=True)


def publish_best_effort(topic, seconds):
    """Publishes images best effort for `seconds`: a reliable reader cannot match it
    (DDS delivers nothing, which the bridge must say). Prints `publishing` first."""
    dp = DomainParticipant(0)
    qos = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(10), Policy.Durability.Volatile)
    writer = DataWriter(dp, Topic(dp, dds_topic(topic), Image), qos=qos)
    print("publishing", flush=True)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        writer.write(Image(Header(Time(sec=1, nanosec=0), "camera"), 1, 1, "rgb8", 0, 3, [1, 2, 3]))
        time.sleep(0.05)


def read(topic, kind, count, timeout, show):
    dp = DomainParticipant(0)
    reader = DataReader(dp, Topic(dp, dds_topic(topic), kind), qos=QOS)
    print("reading", flush=True)
    got = 0
    deadline = time.monotonic() + timeout
    while got < count:
        if time.monotonic() > deadline:
            sys.exit(f"ros2_peer: {got} of {count} messages within {timeout} s")
        for message in reader.take(N=count):
            print(json.dumps(show(message)), flush=True)
            got += 1
        time.sleep(0.01)


def read_poses(topic, count, timeout):
    read(topic, Pose2D, count, timeout, lambda p: {"x": p.x, "y": p.y, "theta": p.theta})


def read_blob_seqs(topic, count, timeout):
    def show(m):
        stamp = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
        items = [[b.name, b.x, b.y, b.size] for b in m.items]
        return {"stamp": stamp, "frame": m.header.frame_id, "items": items}

    read(topic, BlobSeq, count, timeout, show)


def main():
    mode = sys.argv[1]
    if mode == "publish-images":
        publish_images(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]) if len(sys.argv) > 4 else 0)
    elif mode == "publish-blob-seqs":
        publish_blob_seqs(sys.argv[2], int(sys.argv[3]))
    elif mode == "publish-best-effort":
        publish_best_effort(sys.argv[2], float(sys.argv[3]))
    elif mode == "read-poses":
        read_poses(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]))
    elif mode == "read-blob-seqs":
        read_blob_seqs(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]))
    else:
        sys.exit(f"ros2_peer: unknown mode {mode}")


if __name__ == "__main__":
    main()
