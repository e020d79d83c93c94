#!/usr/bin/env python3
"""Decodes the ROS 2 views of an esgm recording (`esgm record --ros2`) with the ROS 2
MCAP decoder from PyPI (mcap-ros2-support), which knows nothing of esgm: it parses the
`ros2msg` schema text and decodes each `cdr` message by it, as rosbag2's readers do.

Usage: read_ros2.py FILE.mcap

Prints one JSON object: {topic: {"schema": name, "count": n, "first": fields}} for
every channel in the `cdr` encoding, where `fields` is the first message as a dict
(nested messages as dicts, `uint8[]` as its length and first and last byte).
On any failure it prints one line naming the file and the problem to stderr and exits 1.
"""

import json
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def plain(value):
    if isinstance(value, (bytes, bytearray)):
        data = bytes(value)
        return {"length": len(data), "first": data[0] if data else None, "last": data[-1] if data else None}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, "__slots__"):
        return {k: plain(getattr(value, k)) for k in value.__slots__}
    return value


def main():
    path = sys.argv[1]
    out = {}
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            ros2_topics = [
                c.topic for c in reader.get_summary().channels.values() if c.message_encoding == "cdr"
            ]
            for schema, channel, _message, decoded in reader.iter_decoded_messages(topics=ros2_topics):
                entry = out.setdefault(channel.topic, {"schema": schema.name, "count": 0, "first": None})
                if entry["first"] is None:
                    entry["first"] = plain(decoded)
                entry["count"] += 1
    except Exception as e:  # noqa: BLE001 - any failure is the file's
        print(f"{path}: {type(e).__name__}: {e}", file=sys.stderr)
        sys.exit(1)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
