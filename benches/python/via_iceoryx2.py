"""The Python rows through iceoryx2's own Python package (PyPI `iceoryx2`, pinned in
requirements.txt): the same hop on the layer esgm is built on, with no structure, no
codec and no trajectory around it.

Each direction is an ipc publish-subscribe service (`ping`, `pong`, and `ready` for
images); a RobotState is a ctypes structure (the sequence beside x, y and dir), a frame
a slice of 921,600 bytes with the sequence in a user header. The sender writes its
payload into a loan (`loan_uninit`, `loan_slice_uninit`, viewed as a numpy array
without a copy) before the hop, stamps the sequence and sends; the receiver reads the
received sample in place (`x`, or a pixel at each end through a numpy view of the
payload), then releases it. `event` adds an event service per direction: the sender
notifies after sending, the receiver waits on its listener (`timed_wait`) when nothing
is there."""

import ctypes

import iceoryx2 as iox2
import numpy as np

import frames


class RobotState(ctypes.Structure):
    """The small payload: the sequence and a RobotState's three doubles."""

    _fields_ = [("seq", ctypes.c_int64), ("x", ctypes.c_double), ("y", ctypes.c_double),
                ("dir", ctypes.c_double)]

    @staticmethod
    def type_name():
        return "EsgmBenchRobotState"


class FrameHeader(ctypes.Structure):
    """The user header of a frame: its sequence and size."""

    _fields_ = [("seq", ctypes.c_int64), ("width", ctypes.c_int32), ("height", ctypes.c_int32)]

    @staticmethod
    def type_name():
        return "EsgmBenchFrameHeader"


class Channel:
    """One direction: a publish-subscribe service and, under `event`, an event service;
    this process's end of it (the sender's or the receiver's)."""

    def __init__(self, node, name, image, sending, event):
        self.image = image
        builder = node.service_builder(iox2.ServiceName.new(name))
        if image:
            builder = builder.publish_subscribe(iox2.Slice[ctypes.c_uint8]).user_header(FrameHeader)
        else:
            builder = builder.publish_subscribe(RobotState)
        self.service = builder.open_or_create()
        self.events = None
        if event:
            self.events = node.service_builder(iox2.ServiceName.new(name + "/event")).event().open_or_create()
        self.publisher = self.subscriber = self.notifier = self.listener = None
        if sending:
            publisher = self.service.publisher_builder()
            if image:
                publisher = publisher.initial_max_slice_len(frames.PIXEL_BYTES)
            self.publisher = publisher.create()
            if event:
                self.notifier = self.events.notifier_builder().create()
        else:
            self.subscriber = self.service.subscriber_builder().create()
            if event:
                self.listener = self.events.listener_builder().create()
        self.last_address = None

    def loan(self, seed):
        """A loan written with the payload (all but the sequence)."""
        if self.image:
            sample = self.publisher.loan_slice_uninit(frames.PIXEL_BYTES)
            pixels = np.frombuffer(sample.payload().as_memory_view(), dtype=np.uint8)
            pixels.fill(seed)
            header = sample.user_header().contents
            header.width, header.height = frames.WIDTH, frames.HEIGHT
        else:
            sample = self.publisher.loan_uninit()
            state = sample.payload().contents
            state.x, state.y, state.dir = frames.X, frames.Y, frames.DIR
        return sample

    def send(self, sample, seq):
        if self.image:
            sample.user_header().contents.seq = seq
        else:
            sample.payload().contents.seq = seq
        sample.assume_init().send()
        if self.notifier is not None:
            self.notifier.notify()

    def poll(self):
        """The sequence of the next sample, read and released; None if there is none."""
        sample = self.subscriber.receive()
        if sample is None:
            return None
        if self.image:
            seq = sample.user_header().contents.seq
            payload = sample.payload()
            pixels = np.frombuffer(payload.as_memory_view(), dtype=np.uint8)
            frames.check_ends(int(pixels[0]), int(pixels[-1]), "iceoryx2")
            self.last_address = payload.as_ptr()
        else:
            state = sample.payload().contents
            seq = state.seq
            float(state.x)
        sample.delete()
        return seq

    def wait(self, timeout):
        """poll, after blocking on the listener (at most `timeout` s) if nothing is there."""
        got = self.poll()
        if got is not None:
            return got
        self.listener.timed_wait(iox2.Duration.from_secs_f64(timeout))
        return self.poll()

    def close(self):
        for port in (self.publisher, self.subscriber, self.notifier, self.listener):
            if port is not None:
                port.delete()


class Ends:
    """This process's side of the ping-pong (see pingpong.py for the interface)."""

    def __init__(self, role, kind, wait, domain, port):
        iox2.set_log_level(iox2.LogLevel.Error)
        self.image = kind == "image"
        self.node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
        event = wait == "event"
        prefix = f"esgm-bench/{domain}"
        mine, theirs = ("ping", "pong") if role == "ping" else ("pong", "ping")
        self.out = Channel(self.node, f"{prefix}/{mine}", self.image, True, event)
        self.inp = Channel(self.node, f"{prefix}/{theirs}", self.image, False, event)
        self.ready = None
        if self.image:
            self.ready = Channel(self.node, f"{prefix}/ready", False, role == "pong", event)
        self.seeds = frames.Seeds()

    def prepare(self):
        return self.out.loan(self.seeds.next())

    def send(self, message, seq):
        self.out.send(message, seq)

    def poll(self):
        return self.inp.poll()

    def wait(self, timeout):
        return self.inp.wait(timeout)

    def signal_ready(self, seq):
        self.ready.send(self.ready.loan(0), seq)

    def poll_ready(self):
        return self.ready.poll()

    def wait_ready(self, timeout):
        return self.ready.wait(timeout)

    def last_read_in_shared_memory(self):
        address = self.inp.last_address
        return None if address is None else frames.in_shared_memory(address)

    def what_is_read(self):
        return "pixels"

    def send_call(self):
        return "assume_init().send() and notify"

    def describe(self):
        return (f"iceoryx2 {version()} Python, ipc publish-subscribe; the payload written into a "
                "loan before the hop, read in place; spin polls receive(), event blocks in "
                "an event listener the sender notifies")

    def close(self):
        for channel in (self.out, self.inp, self.ready):
            if channel is not None:
                channel.close()


def version():
    from importlib.metadata import version as of
    return of("iceoryx2")
