"""The Python rows through esgm's own package (`esgm`, built from this checkout):
`esgm.connect` in both processes, each adding to a primitive trajectory it created
(`ping`, `pong`, and `ready` for images) and subscribed to the other's.

A leg: `Trajectory.add` of a RobotState's attributes (a dict), or of an Image whose
pixels were written into `Trajectory.image_buffer` (a loan of the trajectory's shared
memory) before; until the other process's `Subscription.recv` returned the Sample and
the reader read `x`, or a pixel at each end of `sample["image_data"]` (a read-only numpy
array over the writer's shared memory). The sequence number is the valid time."""

import time

import esgm

import frames

# Samples each trajectory keeps: a controller's few latest (as in connect-small).
CACHE = 4
START_TIMEOUT_S = 60.0


def created(system, name):
    """Trajectory `name` once the other process has created it."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        try:
            return system.get_entity_trajectory_structure(name)
        except esgm.NoSuchEntityStructure:
            if time.monotonic() > deadline:
                raise TimeoutError(f"trajectory {name} was not created within {START_TIMEOUT_S} s")
            time.sleep(0.005)


class Ends:
    """This process's side of the ping-pong (see pingpong.py for the interface)."""

    def __init__(self, role, kind, wait, domain, port):
        self.image = kind == "image"
        self.system = esgm.connect(domain, host=f"bench-python-{role}")
        type_name = "Image" if self.image else "RobotState"
        policy = {"cache": CACHE}
        create = self.system.create_primitive_entity_trajectory_structure
        self.ready_in = self.ready_out = None
        if role == "ping":
            self.out = create("ping", type_name, policy)
            # The pong subscribes to ours before it creates its own (and `ready` first):
            # once `pong` exists, both subscriptions do.
            self.sub = created(self.system, "pong").subscribe()
            if self.image:
                self.ready_in = created(self.system, "ready").subscribe()
        else:
            self.sub = created(self.system, "ping").subscribe()
            if self.image:
                self.ready_out = create("ready", "RobotState", policy)
            self.out = create("pong", type_name, policy)
        self.seeds = frames.Seeds()
        self.last_address = None

    def prepare(self):
        if not self.image:
            return {"x": frames.X, "y": frames.Y, "dir": frames.DIR}
        buffer = self.out.image_buffer(frames.WIDTH, frames.HEIGHT)
        buffer.array.fill(self.seeds.next())
        return buffer

    def send(self, message, seq):
        if self.image:
            attributes = {"width": frames.WIDTH, "height": frames.HEIGHT, "format": 0,
                          "image_data": message}
            outcome = self.out.add("camera", seq, attributes)
        else:
            outcome = self.out.add("robot", seq, message)
        if outcome != "added":
            raise RuntimeError(f"{self.out.name}: structure {seq} was not added: {outcome}")

    def _read(self, sample):
        if self.image:
            pixels = sample["image_data"]
            frames.check_ends(int(pixels[0, 0, 0]), int(pixels[-1, -1, -1]), "esgm")
            self.last_address = pixels.__array_interface__["data"][0]
        else:
            float(sample["x"])
        return sample.valid_time

    def poll(self):
        try:
            sample = self.sub.recv(0)
        except TimeoutError:
            return None
        return self._read(sample)

    def wait(self, timeout):
        try:
            sample = self.sub.recv(timeout)
        except TimeoutError:
            return None
        return self._read(sample)

    def signal_ready(self, seq):
        self.ready_out.add("ready", seq, {"x": 0.0, "y": 0.0, "dir": 0.0})

    def poll_ready(self):
        try:
            return self.ready_in.recv(0).valid_time
        except TimeoutError:
            return None

    def wait_ready(self, timeout):
        try:
            return self.ready_in.recv(timeout).valid_time
        except TimeoutError:
            return None

    def last_read_in_shared_memory(self):
        return None if self.last_address is None else frames.in_shared_memory(self.last_address)

    def what_is_read(self):
        return "pixels"

    def send_call(self):
        return "Trajectory.add"

    def describe(self):
        return ("esgm.connect on both sides; Trajectory.add -> Subscription.recv; primitive "
                f"trajectories with a cache of {CACHE}; spin polls recv(0) (TimeoutError when "
                "empty), event blocks in recv(timeout)")

    def close(self):
        # The connection goes when the process ends; nothing to flush (every add was
        # answered).
        pass
