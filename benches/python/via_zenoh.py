"""The Python rows through Zenoh's Python package (PyPI `eclipse-zenoh`, pinned in
requirements.txt) with its shared-memory transport.

Two sessions, one per process, joined directly over loopback TCP (the ping listens on
the port esgm-bench found free, the pong connects; multicast scouting off), with shared
memory enabled: the sender allocates a buffer from its `ShmProvider`, writes the
payload into it before the hop (the sequence in its first 8 bytes, then a RobotState's
three doubles or the frame's 921,600 bytes) and `put`s it; only its descriptor crosses
the TCP link. The receiver reads `sample.payload`: Zenoh's Python API gives a received
payload's bytes only as a copy (`to_bytes()`; its `ZShm` has no buffer protocol), so
the reader copies, then reads `x` or a pixel at each end of the copy. `spin` polls the
subscriber's queue (`try_recv()`), `event` blocks on it (`recv()`, which takes no
timeout: pingpong.py's process limit bounds it)."""

import json
import struct

import zenoh
from zenoh import shm

import frames

SEQ = struct.Struct("<q")
STATE = struct.Struct("<ddd")
# Buffers the provider holds: a buffer is free again only once both processes dropped
# it, which Zenoh learns asynchronously.
IN_FLIGHT = 32


def session(port, listen):
    config = zenoh.Config()
    endpoints = json.dumps([f"tcp/127.0.0.1:{port}"])
    config.insert_json5("listen/endpoints" if listen else "connect/endpoints", endpoints)
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("transport/shared_memory/enabled", "true")
    return zenoh.open(config)


class Ends:
    """This process's side of the ping-pong (see pingpong.py for the interface)."""

    def __init__(self, role, kind, wait, domain, port):
        if port is None:
            raise ValueError("zenoh needs --port")
        self.image = kind == "image"
        self.session = session(port, role == "ping")
        prefix = f"esgm-bench/{domain}"
        mine, theirs = ("ping", "pong") if role == "ping" else ("pong", "ping")
        self.publisher = self.session.declare_publisher(f"{prefix}/{mine}")
        self.subscriber = self.session.declare_subscriber(f"{prefix}/{theirs}")
        self.ready_publisher = self.ready_subscriber = None
        if self.image:
            if role == "pong":
                self.ready_publisher = self.session.declare_publisher(f"{prefix}/ready")
            else:
                self.ready_subscriber = self.session.declare_subscriber(f"{prefix}/ready")
        self.size = SEQ.size + (frames.PIXEL_BYTES if self.image else STATE.size)
        self.layout = self.size
        self.provider = shm.ShmProvider.default_backend(-(-self.size * IN_FLIGHT // 4096) * 4096)
        self.policy = shm.BlockOn(shm.GarbageCollect())
        self.seeds = frames.Seeds()
        self.frames = {}
        self.last = None

    def prepare(self):
        buffer = self.provider.alloc(self.layout, policy=self.policy)
        if self.image:
            seed = self.seeds.next()
            pixels = self.frames.get(seed)
            if pixels is None:
                pixels = self.frames.setdefault(seed, bytes([seed]) * frames.PIXEL_BYTES)
            buffer[SEQ.size:] = pixels
        else:
            buffer[SEQ.size:] = STATE.pack(frames.X, frames.Y, frames.DIR)
        return buffer

    def send(self, message, seq):
        message[0:SEQ.size] = SEQ.pack(seq)
        self.publisher.put(message)

    def _read(self, sample):
        data = sample.payload.to_bytes()
        (seq,) = SEQ.unpack_from(data, 0)
        if self.image:
            frames.check_ends(data[SEQ.size], data[-1], "zenoh")
        else:
            STATE.unpack_from(data, SEQ.size)
        self.last = (sample, data)
        return seq

    def poll(self):
        sample = self.subscriber.try_recv()
        return None if sample is None else self._read(sample)

    def wait(self, timeout):
        return self._read(self.subscriber.recv())

    def signal_ready(self, seq):
        self.ready_publisher.put(SEQ.pack(seq))

    def poll_ready(self):
        sample = self.ready_subscriber.try_recv()
        return None if sample is None else SEQ.unpack(sample.payload.to_bytes())[0]

    def wait_ready(self, timeout):
        return SEQ.unpack(self.ready_subscriber.recv().payload.to_bytes())[0]

    def last_read_in_shared_memory(self):
        if self.last is None or not self.image:
            return None
        import numpy as np
        data = self.last[1]
        return frames.in_shared_memory(np.frombuffer(data, np.uint8).__array_interface__["data"][0])

    def arrived_in_shared_memory(self):
        return self.last is not None and self.last[0].payload.as_shm() is not None

    def what_is_read(self):
        return "pixels"

    def send_call(self):
        return "Publisher.put"

    def describe(self):
        from importlib.metadata import version
        shared = "in" if self.arrived_in_shared_memory() else "NOT in"
        return (f"eclipse-zenoh {version('eclipse-zenoh')} Python, peers over loopback TCP with "
                f"shared memory on (the last answer arrived {shared} a Zenoh shared-memory "
                "buffer); the payload written into a ShmProvider buffer before the hop; the "
                "reader copies it (to_bytes(): the API has no view of received bytes); spin "
                "polls try_recv(), event blocks in recv()")

    def close(self):
        self.last = None
        self.session.close()
