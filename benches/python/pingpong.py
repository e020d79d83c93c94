"""The Python rows of esgm-bench: one hop from a Python process to a Python subscriber
in another process, through esgm's package, iceoryx2's or Zenoh's.

esgm-bench (benches/src/scenarios/python_peer.rs) starts two of these, a `pong` and
then a `ping`, with the same transport, payload and wait:

    python pingpong.py ROLE --transport esgm|iceoryx2|zenoh --kind small|image
                       --wait spin|event --domain NAME [--port P]
                       [--samples N --warmup N]

Each leg is the same user-level work: the sender stamps a payload it made beforehand
(a RobotState's three doubles, or a 640x480 RGB frame written into a loan of the
transport's shared memory) with its sequence number and sends it; the hop ends when the
subscriber in the other process holds the received sample and has read what a consumer
reads (`x`, or one pixel at each end of the frame, checked). The pong answers every
ping the same way, so half the round trip, timed by the ping on its own monotonic clock
(`time.perf_counter_ns`), is one hop, as in the Rust cross-process rows.

The payload of each leg is made before the timer starts: the ping makes it just before
(timed apart, as the producer's write), the pong while it waits. For images the pong
says on a third channel (`ready`) that its reply frame is written and it waits, and the
ping starts its timer only then, so no frame is written during a hop.

`spin` polls without blocking (esgm: `recv(0)`, which raises TimeoutError when nothing
is there; iceoryx2: `receive()`; Zenoh: `try_recv()`), `event` blocks (esgm:
`recv(timeout)`; iceoryx2: an event listener the sender notifies; Zenoh: `recv()`).
Before an `event` hop the ping busy-waits 50 us so that the blocked pong is asleep, as
esgm-bench's EVENT_GAP does for the Rust rows.

The ping also reads the clock when its send call returns (one read inside the hop) and
notes the median time that call took: where a row's time goes, the sender's call or the
way to the other process and back.

Output of the ping, on stdout: one line per measured hop, `<one-way ns> <write ns>`,
then `note <text>` lines; of the pong, `note <text>` lines. Failures go to stderr with
a non-zero exit. Every wait has a timeout, and the whole process has one
(`faulthandler.dump_traceback_later`, which fires without the GIL), so a hang in a
library call (Zenoh's blocking `recv()` has no timeout) ends the process too.
"""

import argparse
import faulthandler
import importlib
import sys
import time

HELLO = 0
STOP = -1
# How long a peer may be silent before the run is given up.
PEER_TIMEOUT_S = 10.0
# How long the first answer may take (the peer process starts and connects).
START_TIMEOUT_S = 60.0
# Before an `event` hop: long enough for the blocked receiver to be asleep.
EVENT_GAP_NS = 50_000
# Start-up pings: the first wait, doubled up to the last.
HELLO_EVERY_S = 0.005
HELLO_EVERY_MAX_S = 0.2


class Failed(Exception):
    """The run cannot go on; the message says why."""


def next_message(poll, wait, mode, what):
    """The next message through `poll` (spin) or `wait(timeout)` (event), or Failed
    after PEER_TIMEOUT_S."""
    deadline = time.monotonic() + PEER_TIMEOUT_S
    if mode == "spin":
        spins = 0
        while True:
            got = poll()
            if got is not None:
                return got
            spins += 1
            if spins & 0xFFF == 0 and time.monotonic() > deadline:
                raise Failed(f"no {what} within {PEER_TIMEOUT_S} s")
    while True:
        got = wait(max(deadline - time.monotonic(), 0.0))
        if got is not None:
            return got
        if time.monotonic() > deadline:
            raise Failed(f"no {what} within {PEER_TIMEOUT_S} s")


def poll_for(poll, seconds):
    """The next message through `poll` within `seconds` (checked every millisecond), or
    None: the start-up's wait, the same for every transport."""
    deadline = time.monotonic() + seconds
    while True:
        got = poll()
        if got is not None or time.monotonic() > deadline:
            return got
        time.sleep(0.001)


def busy_wait_ns(ns):
    start = time.perf_counter_ns()
    while time.perf_counter_ns() - start < ns:
        pass


def ping(ends, args):
    """The measuring side: see the module docs."""
    image = args.kind == "image"
    # Start-up: a structure sent before the pong subscribed never reaches it, so ping
    # ever less often until one is answered.
    started = time.monotonic()
    every = HELLO_EVERY_S
    while True:
        ends.send(ends.prepare(), HELLO)
        if poll_for(ends.poll, every) is not None:
            break
        if time.monotonic() - started > START_TIMEOUT_S:
            raise Failed(f"no answer to the first ping within {START_TIMEOUT_S} s")
        every = min(every * 2, HELLO_EVERY_MAX_S)
    # Let the pong answer the start-up pings still queued, and forget the answers.
    time.sleep(0.05)
    while ends.poll() is not None:
        pass
    ready_after = HELLO - 1
    if image:
        while (signal := ends.poll_ready()) is not None:
            ready_after = max(ready_after, signal)

    out = []
    send_calls = []
    in_place = None
    total = args.warmup + args.samples
    for seq in range(1, total + 1):
        if image:
            while ready_after < seq - 1:
                signal = next_message(ends.poll_ready, ends.wait_ready, args.wait, "ready signal")
                ready_after = max(ready_after, signal)
        making = time.perf_counter_ns()
        message = ends.prepare()
        made = time.perf_counter_ns() - making
        if args.wait == "event":
            busy_wait_ns(EVENT_GAP_NS)
        start = time.perf_counter_ns()
        ends.send(message, seq)
        sent = time.perf_counter_ns() - start
        while True:
            got = next_message(ends.poll, ends.wait, args.wait, f"answer to ping {seq}")
            if got == seq:
                break
        round_trip = time.perf_counter_ns() - start
        if seq > args.warmup:
            out.append(f"{round_trip // 2} {made}")
            send_calls.append(sent)
        if seq == total:
            in_place = ends.last_read_in_shared_memory()
    ends.send(ends.prepare(), STOP)
    out.append(f"note {ends.describe()}")
    send_calls.sort()
    out.append(f"note the ping's send call ({ends.send_call()}) returned after p50 "
               f"{send_calls[len(send_calls) // 2] / 1000:.1f} us, p99 "
               f"{send_calls[len(send_calls) * 99 // 100] / 1000:.1f} us (inside the round trip)")
    if in_place is not None:
        where = "in place in a /dev/shm mapping" if in_place else "from a copy on the heap"
        out.append(f"note the ping read the last answer's {ends.what_is_read()} {where}")
    print("\n".join(out), flush=True)


def pong(ends, args):
    """The answering side: see the module docs."""
    image = args.kind == "image"
    pings = early = 0
    last = HELLO
    in_place = None
    while True:
        message = ends.prepare()
        got = ends.poll()
        if got is None:
            if image:
                ends.signal_ready(last)
            got = next_message(ends.poll, ends.wait, args.wait, "ping")
        elif got > HELLO:
            early += 1
        if got == STOP:
            break
        ends.send(message, got)
        last = got
        if got > HELLO:
            pings += 1
            in_place = ends.last_read_in_shared_memory()
    notes = []
    if early:
        notes.append(f"{early} of {pings} pings (warm-up included) reached the pong before "
                     "its answer was made (those hops include part of its preparation)")
    if in_place is not None:
        where = "in place in a /dev/shm mapping" if in_place else "from a copy on the heap"
        notes.append(f"the pong read the last ping's {ends.what_is_read()} {where}")
    print("\n".join(f"note {n}" for n in notes), flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("role", choices=["ping", "pong"])
    parser.add_argument("--transport", choices=["esgm", "iceoryx2", "zenoh"], required=True)
    parser.add_argument("--kind", choices=["small", "image"], required=True)
    parser.add_argument("--wait", choices=["spin", "event"], required=True)
    parser.add_argument("--domain", required=True,
                        help="esgm domain, iceoryx2 service prefix, Zenoh key prefix")
    parser.add_argument("--port", type=int, help="Zenoh: the loopback TCP port the ping listens on")
    parser.add_argument("--samples", type=int, default=1000)
    parser.add_argument("--warmup", type=int, default=100)
    parser.add_argument("--timeout", type=float, default=300.0,
                        help="the whole process's limit, in seconds")
    args = parser.parse_args()
    faulthandler.dump_traceback_later(args.timeout, exit=True)
    transport = importlib.import_module(f"via_{args.transport}")
    try:
        ends = transport.Ends(args.role, args.kind, args.wait, args.domain, args.port)
        try:
            (ping if args.role == "ping" else pong)(ends, args)
        finally:
            ends.close()
    except Failed as e:
        print(f"{args.role} ({args.transport}, {args.kind}, {args.wait}): {e}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
