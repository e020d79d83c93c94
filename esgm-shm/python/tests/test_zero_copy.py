"""Images without copies, across processes (the connected runtime):

- a producer writes a frame into a loan of the trajectory's shared memory: the array
  `image_buffer` gives lies in a `/dev/shm` mapping of the producer;
- a reader in another process gets the frame as a numpy array whose data lies in a
  `/dev/shm` mapping of the reader (the writer's chunk, not a copy);
- that array stays valid and unchanged after the sample object is gone, after the
  trajectory is destroyed and after the reader's connection is closed."""

import subprocess
import sys
import textwrap

import numpy as np

import esgm

WIDTH, HEIGHT = 640, 480


def in_shared_memory(address):
    """True if `address` lies in a mapping of a /dev/shm file of this process."""
    with open("/proc/self/maps") as maps:
        for line in maps:
            parts = line.split()
            start, end = (int(x, 16) for x in parts[0].split("-"))
            if start <= address < end:
                return len(parts) >= 6 and parts[5].startswith("/dev/shm/")
    return False


READER = textwrap.dedent(
    """
    import gc, sys
    import esgm
    from test_zero_copy import in_shared_memory

    domain, name = sys.argv[1], sys.argv[2]
    e = esgm.connect(domain, host="zero-copy-reader")
    t = e.get_entity_trajectory_structure(name)
    sub = t.subscribe()
    print("subscribed", flush=True)
    s = sub.recv(30)
    a = s["image_data"]
    print("got", a.shape, in_shared_memory(a.__array_interface__["data"][0]), flush=True)
    sys.stdin.readline()  # the writer destroyed the trajectory
    del s, sub, t, e
    gc.collect()
    ok = a.shape == (480, 640, 3) and int(a[0, 0, 0]) == 11 and int(a[479, 639, 2]) == 99
    print("after", ok, not a.flags.writeable, flush=True)
    """
)


def test_frames_cross_processes_without_copies_and_outlive_their_trajectory(domain):
    e = esgm.connect(domain, host="zero-copy-writer")
    images = e.create_primitive_entity_trajectory_structure("zero_copy_images", "Image")
    buffer = images.image_buffer(WIDTH, HEIGHT)
    frame = buffer.array
    assert frame.shape == (HEIGHT, WIDTH, 3) and frame.flags.writeable
    assert in_shared_memory(frame.__array_interface__["data"][0]), "the loan is shared memory"

    reader = subprocess.Popen(
        [sys.executable, "-c", READER, domain, "zero_copy_images"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        cwd=__import__("os").path.dirname(__file__),
    )
    try:
        assert reader.stdout.readline().strip() == "subscribed"
        frame[:] = 0
        frame[0, 0, 0] = 11
        frame[HEIGHT - 1, WIDTH - 1, 2] = 99
        images.add("camera", 1, {"width": WIDTH, "height": HEIGHT, "format": 0, "image_data": buffer})
        assert not frame.flags.writeable, "after the add the pixels are the sample's"
        got = reader.stdout.readline().split()
        assert got == ["got", "(480,", "640,", "3)", "True"], got
        e.destroy_entity_trajectory_structure("zero_copy_images")
        reader.stdin.write("go\n")
        reader.stdin.flush()
        assert reader.stdout.readline().split() == ["after", "True", "True"]
        assert reader.wait(30) == 0
    finally:
        if reader.poll() is None:
            reader.kill()


def resident_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / (1 << 20)


def test_frames_written_into_loans_are_freed(system, unique):
    """A buffer's array views the buffer, which must not hold the array in a cycle the
    collector cannot see: 200 frames of 900 KiB written and added in a loop leave the
    process about where it started."""
    images = system.create_primitive_entity_trajectory_structure(unique, "Image", policy={"cache": 2})
    before = resident_mb()
    for i in range(200):
        buffer = images.image_buffer(640, 480)
        with buffer as frame:
            frame[0, 0, 0] = i % 256
        images.add("camera", i + 1, {"width": 640, "height": 480, "format": 0, "image_data": buffer})
    system.flush(10)
    grown = resident_mb() - before
    # A leak keeps every frame: 200 x 0.88 MiB = 176 MiB. The cache holds 2.
    assert grown < 60, f"resident memory grew by {grown:.0f} MiB over 200 frames"
    assert images.get_latest()["image_data"][0, 0, 0] == 199 % 256
