"""What the Python rows carry and how a reader checks it: a RobotState's three doubles,
or a 640x480 RGB frame whose pixels are all one value (1 to 255, changing with every
frame), so a reader that sees two different values at the ends, or zeros, has a torn
or unwritten frame; and where a reader's bytes lie."""

WIDTH = 640
HEIGHT = 480
CHANNELS = 3
PIXEL_BYTES = WIDTH * HEIGHT * CHANNELS
# The RobotState every small leg carries (its sequence travels apart).
X, Y, DIR = 1.5, -2.25, 0.5


class Seeds:
    """The value of each next frame's pixels: 1, 2, ..., 255, 1, ..."""

    def __init__(self):
        self.last = 0

    def next(self):
        self.last = self.last % 255 + 1
        return self.last


def check_ends(first, last, what):
    """Fails on a frame whose two end pixels differ or were never written."""
    if first != last or first == 0:
        raise ValueError(f"{what}: a torn or unwritten frame (first pixel {first}, last {last})")


def in_shared_memory(address):
    """Whether `address` lies in a mapping of a /dev/shm file of this process."""
    with open("/proc/self/maps") as maps:
        for line in maps:
            fields = line.split()
            if len(fields) < 6 or not fields[5].startswith("/dev/shm/"):
                continue
            start, end = (int(x, 16) for x in fields[0].split("-"))
            if start <= address < end:
                return True
    return False
