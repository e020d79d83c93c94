#!/usr/bin/env python3
"""Writes a ROS 2 bag as rosbag2 does (the ROS 2 MCAP profile: `ros2msg` schemas,
`cdr` messages), with the writer of mcap-ros2-support from PyPI, which knows nothing
of esgm: the message definitions below are ROS 2's own, written here by hand.

Usage: write_ros2_bag.py FILE.mcap

It writes:
  /camera/image_raw  sensor_msgs/msg/Image      3 images 4x3 rgb8, stamp 1000 s + i ms,
                                                pixel k of image i = (k + 7 i) % 251,
                                                then 1 image in encoding `yuv422`
  /odom2d            geometry_msgs/msg/Pose2D   2 poses, x = i, y = -i, theta = pi/2,
                                                logged at 2000 s + i ms
  /chatter           std_msgs/msg/String        1 message (a type esgm does not map)
and prints what it wrote as one JSON object.
"""

import json
import math
import sys

from mcap_ros2.writer import Writer

IMAGE = """std_msgs/Header header
uint32 height
uint32 width
string encoding
uint8 is_bigendian
uint32 step
uint8[] data
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""

POSE2D = """float64 x
float64 y
float64 theta
"""

STRING = "string data\n"


def main():
    path = sys.argv[1]
    with open(path, "wb") as f:
        writer = Writer(f)
        image = writer.register_msgdef("sensor_msgs/msg/Image", IMAGE)
        pose = writer.register_msgdef("geometry_msgs/msg/Pose2D", POSE2D)
        string = writer.register_msgdef("std_msgs/msg/String", STRING)
        w, h = 4, 3
        for i in range(3):
            stamp = {"sec": 1000, "nanosec": i * 1_000_000}
            data = bytes((k + 7 * i) % 251 for k in range(w * h * 3))
            message = {"header": {"stamp": stamp, "frame_id": "camera"}, "height": h, "width": w,
                       "encoding": "rgb8", "is_bigendian": 0, "step": w * 3, "data": data}
            log = 1_500_000_000_000 + i
            writer.write_message("/camera/image_raw", image, message, log_time=log, publish_time=log, sequence=i)
        odd = {"header": {"stamp": {"sec": 1001, "nanosec": 0}, "frame_id": "camera"}, "height": h, "width": w,
               "encoding": "yuv422", "is_bigendian": 0, "step": w * 2, "data": bytes(w * h * 2)}
        writer.write_message("/camera/image_raw", image, odd, log_time=1_500_000_000_010, publish_time=1_500_000_000_010)
        for i in range(2):
            log = 2_000_000_000_000 + i * 1_000_000
            writer.write_message("/odom2d", pose, {"x": float(i), "y": -float(i), "theta": math.pi / 2},
                                 log_time=log, publish_time=log, sequence=i)
        writer.write_message("/chatter", string, {"data": "hello"}, log_time=3_000_000_000_000,
                             publish_time=3_000_000_000_000)
        writer.finish()
    print(json.dumps({"/camera/image_raw": 4, "/odom2d": 2, "/chatter": 1}))


if __name__ == "__main__":
    try:
        main()
    except Exception as e:  # one line naming the file and the problem
        print(f"write_ros2_bag.py: {sys.argv[1:]}: {type(e).__name__}: {e}", file=sys.stderr)
        sys.exit(1)
