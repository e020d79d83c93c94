"""Reads a directory as ROS 2 tools do, with independent libraries: rosbags' rosbag2
Reader (metadata.yaml: topics, types, counts) and AnyReader (every message
deserialized with the definitions the bag carries), and the ROS 2 MCAP decoder
(mcap-ros2-support's read_ros2_messages over the bag's file, no topic filtered out).
Prints one JSON object: {"message_count", "topics": {topic: {type, count}},
"decoded": {topic: n}, "mcap_ros2": n, "first": {topic: fields of the first message}}.

    python check_bag.py BAG_DIR
"""

import json
import sys
from pathlib import Path

from mcap_ros2.reader import read_ros2_messages
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader


def fields(message):
    """The plain fields of a message (numbers and strings), for the test to check."""
    out = {}
    for name in getattr(message, "__dataclass_fields__", {}):
        value = getattr(message, name)
        if isinstance(value, (int, float, str)):
            out[name] = value
        elif hasattr(value, "__len__") and not isinstance(value, (bytes, str)):
            out[name + "_len"] = len(value)
    return out


def main():
    bag = Path(sys.argv[1])
    out = {"topics": {}, "decoded": {}, "first": {}}
    with Reader(bag) as reader:
        out["message_count"] = reader.message_count
        for c in reader.connections:
            out["topics"][c.topic] = {"type": c.msgtype, "count": c.msgcount}
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages():
            message = reader.deserialize(raw, conn.msgtype)
            out["decoded"][conn.topic] = out["decoded"].get(conn.topic, 0) + 1
            out["first"].setdefault(conn.topic, fields(message))
    files = sorted(bag.glob("*.mcap"))
    out["mcap_ros2"] = sum(1 for f in files for _ in read_ros2_messages(str(f)))
    print(json.dumps(out))


if __name__ == "__main__":
    main()
