"""The seed's tutorial in Python (chapters 8-10), the main program step by step: a
camera is sampled into `images`, blob detection (numpy) computes `blobs`, blob
selection the `current_blob`, and the driving direction is computed from it and the
robot's state, which a robot loop pushes while following that direction.

    python tutorial.py                      # everything in this process (esgm.InProcess)
    python tutorial.py --domain D --setup   # the same pipeline in domain D (its units
                                            # and camera run here, on D's workers)
    python tutorial.py --domain D           # read the system `esgm demo --domain D` runs,
                                            # and check its blobs with this numpy detector

It prints the robot's states and the directions it followed, and ends with a summary
line `tutorial: N directions` (exit 1 if none came)."""

import argparse
import math
import sys
import time

import numpy as np

import esgm
from blobs import BlobDetection, BlobSelection, detect

WIDTH, HEIGHT = 160, 120
FOV_DEG = 60.0          # the camera's horizontal field of view
MAX_SPEED = 1.0         # m/s, for a blob far away
STOP_SIZE = 900.0       # pixels: a blob this large is close enough to stop


class Camera:
    """A synthetic scene: bright squares drifting over a dark floor (the sensor)."""

    output_type = "Image"

    def get_current_value(self, qtime):
        t = qtime / 1e9
        frame = np.full((HEIGHT, WIDTH, 3), 20, dtype=np.uint8)
        for i, (speed, size) in enumerate([(0.3, 10), (0.5, 6), (0.2, 14)]):
            cx = int((0.5 + 0.4 * math.sin(speed * t + 2 * i)) * WIDTH)
            cy = int((0.5 + 0.3 * math.cos(speed * t + i)) * HEIGHT)
            frame[max(cy - size, 0):cy + size, max(cx - size, 0):cx + size] = 250
        return ("camera", qtime, {"width": WIDTH, "height": HEIGHT, "format": 0, "image_data": frame})


class Steering:
    """RobotState, Blob -> DrivingDirection: head for the blob, slower as it grows."""

    def compute(self, inputs, qtime):
        robot, blob = inputs
        if robot.valid_time < blob.valid_time:
            return None  # the seed's rule: wait for a state as new as the blob
        bearing = -((blob["x"] + 0.5 - WIDTH / 2) * FOV_DEG / WIDTH)
        speed = MAX_SPEED * (1 - min(blob["size"] / STOP_SIZE, 1.0))
        return ("direction", blob.valid_time, {"dir": (robot["dir"] + bearing) % 360.0, "speed": speed})


def set_up(system):
    """The seed's main program: register, then create the trajectories."""
    system.add_sensor_interface("camera", "Image", Camera())
    system.add_comp_unit("BlobDetection", "BlobSeq", ["Image"], BlobDetection())
    system.add_comp_unit("BlobSelection", "Blob", ["BlobSeq"], BlobSelection())
    system.add_comp_unit("DrivingDirection", "DrivingDirection", ["RobotState", "Blob"], Steering())
    system.create_entity_trajectory_structure("images", "camera", 100_000_000, cache_size=5)
    system.create_computed_entity_trajectory_structure("blobs", "BlobDetection", ["images"])
    system.create_computed_entity_trajectory_structure("current_blob", "BlobSelection", ["blobs"])
    robot = system.create_primitive_entity_trajectory_structure("robot_state", "RobotState")
    system.create_computed_entity_trajectory_structure(
        "driving_direction", "DrivingDirection", ["robot_state", "current_blob"])
    return robot


def drive(system, robot, seconds):
    """The robot: every 100 ms, turn toward the latest direction and move; returns
    how many directions it followed."""
    directions = system.get_entity_trajectory_structure("driving_direction")
    x, y, heading, followed = 0.0, 0.0, 0.0, 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        now = time.time_ns()
        robot.add("robot", now, {"x": x, "y": y, "dir": heading})
        try:
            d = directions.get_latest()
            heading, speed = d["dir"], d["speed"]
            x += 0.1 * speed * math.cos(math.radians(heading))
            y += 0.1 * speed * math.sin(math.radians(heading))
            followed += 1
            print(f"{(now % 10**11) / 1e9:9.3f}  x={x:6.2f} y={y:6.2f} heading={heading:6.1f} speed={speed:4.2f}")
        except esgm.ValueNotAvailable:
            pass
        time.sleep(0.1)
    return followed


def watch(system, seconds):
    """Against `esgm demo`'s processes: follow their directions, and check their blobs
    against this detector on the same image (valid time for valid time)."""
    directions = system.get_entity_trajectory_structure("driving_direction").subscribe()
    images = system.get_entity_trajectory_structure("images")
    blobs = system.get_entity_trajectory_structure("blobs")
    seen, end = 0, time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            d = directions.recv(1.0)
        except TimeoutError:
            continue
        seen += 1
        print(f"direction at {d.valid_time}: {d['dir']:6.1f} deg, speed {d['speed']:.2f}")
    image = images.get_latest()
    theirs = sorted(b["size"] for b in blobs.get_at(image.valid_time)["items"])
    ours = sorted(size for _, _, size in detect(image["image_data"]))
    print(f"blob sizes at {image.valid_time}: system {theirs}, numpy {ours}")
    if theirs != ours:
        print("tutorial: the numpy detector disagrees with the system's")
        return 0
    return seen


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--domain", help="a running system's domain (default: in this process)")
    parser.add_argument("--setup", action="store_true", help="set the pipeline up in --domain")
    parser.add_argument("--seconds", type=float, default=5.0)
    a = parser.parse_args()
    if a.domain and not a.setup:
        n = watch(esgm.connect(a.domain), a.seconds)
    else:
        system = esgm.connect(a.domain) if a.domain else esgm.InProcess()
        n = drive(system, set_up(system), a.seconds)
    print(f"tutorial: {n} directions")
    return 0 if n > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
