"""Writes a rosbag2 directory with rosbags, an independent ROS 2 library, as a robot's
`ros2 bag record -s mcap` would: /camera/image_raw (sensor_msgs/msg/Image, 4x2 rgb8,
first pixel (i, 20, 30)) and /odom_pose (geometry_msgs/msg/Pose2D, x = i), COUNT
messages each, stamped 1,700,000,000 s + i * 100 ms, and /chatter (std_msgs/msg/String),
which esgm does not map.

    python write_bag.py BAG_DIR COUNT
"""

import sys

import numpy
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore


def main():
    path, count = sys.argv[1], int(sys.argv[2])
    ts = get_typestore(Stores.ROS2_HUMBLE)
    Image = ts.types["sensor_msgs/msg/Image"]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    Pose2D = ts.types["geometry_msgs/msg/Pose2D"]
    String = ts.types["std_msgs/msg/String"]
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        camera = writer.add_connection("/camera/image_raw", Image.__msgtype__, typestore=ts)
        pose = writer.add_connection("/odom_pose", Pose2D.__msgtype__, typestore=ts)
        chatter = writer.add_connection("/chatter", String.__msgtype__, typestore=ts)
        for i in range(count):
            t = 1_700_000_000_000_000_000 + i * 100_000_000
            stamp = Time(sec=t // 1_000_000_000, nanosec=t % 1_000_000_000)
            pixels = numpy.zeros(4 * 2 * 3, dtype=numpy.uint8)
            pixels[:3] = [i, 20, 30]
            image = Image(
                header=Header(stamp=stamp, frame_id="cam"),
                height=2, width=4, encoding="rgb8", is_bigendian=0, step=12, data=pixels,
            )
            writer.write(camera, t, ts.serialize_cdr(image, Image.__msgtype__))
            writer.write(pose, t, ts.serialize_cdr(Pose2D(x=float(i), y=0.0, theta=0.0), Pose2D.__msgtype__))
            writer.write(chatter, t, ts.serialize_cdr(String(data=f"hello {i}"), String.__msgtype__))


if __name__ == "__main__":
    main()
