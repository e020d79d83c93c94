"""A unit written in Python, named in a system file (`[[unit]] python =
"blobs.py:BlobDetection"`), runs as a worker the supervisor keeps running: it computes
what the built-in Rust unit computes, comes back after `kill -9`, and a unit that
raises has its tracebacks in `esgm logs` and its failures counted in `esgm stats`; a
sensor written in Python is sampled the same way.

Everything is done through the `esgm` command (`ESGM_BIN`), in a domain of the test's
own; this process never connects, so `esgm down` at the end stops only the system."""

import json
import os
import signal
import subprocess
import sys
import time
import uuid

import pytest

EXAMPLES = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "examples"))

FLAKY = '''
class Flaky:
    """Fails every other call."""
    output_type = "BlobSeq"
    input_types = ["BlobSeq"]
    calls = 0

    def compute(self, inputs, qtime):
        self.calls += 1
        if self.calls % 2:
            raise RuntimeError(f"flaky call {self.calls}")
        return ("flaky", inputs[0].valid_time, {"items": []})
'''

SYSTEM = '''
[[sensor]]
name = "camera"
camera = "synthetic"
seed = 7
blobs = 3
width = 160
height = 120

[[sensor]]
name = "pycam"
python = "{examples}/tutorial.py:Camera"
interpreter = "{python}"

[[unit]]
name = "PyBlobs"
python = "{examples}/blobs.py:BlobDetection"
interpreter = "{python}"

[[unit]]
name = "BlobDetection"

[[unit]]
name = "Flaky"
python = "flaky.py:Flaky"
interpreter = "{python}"

[[trajectory]]
name = "images"
sampled = "camera"
period = "100ms"
policy = {{ cache = 50 }}

[[trajectory]]
name = "blobs"
computed = "PyBlobs"
inputs = ["images"]
policy = {{ cache = 50 }}

[[trajectory]]
name = "rust_blobs"
computed = "BlobDetection"
inputs = ["images"]
policy = {{ cache = 50 }}

[[trajectory]]
name = "pyimages"
sampled = "pycam"
period = "200ms"

[[trajectory]]
name = "flaky"
computed = "Flaky"
inputs = ["blobs"]
'''


@pytest.fixture
def cli():
    """`esgm` in a domain of this test's own, stopped (with its workers) afterwards."""
    binary = os.environ.get("ESGM_BIN")
    if not binary:
        pytest.fail("ESGM_BIN must name the esgm command (esgm-cli's python_api test sets it)")
    domain = f"pysup{uuid.uuid4().hex[:8]}"

    def run(*args, check=True):
        out = subprocess.run([binary, "--domain", domain, *args], capture_output=True, text=True, timeout=60)
        if check and out.returncode != 0:
            pytest.fail(f"esgm {' '.join(args)} failed ({out.returncode}):\n{out.stdout}{out.stderr}")
        return out

    run("up", "--detach")
    try:
        yield run
    finally:
        run("down", check=False)


def until(what, probe, seconds=60):
    """`probe()`'s first truthy answer, polled; fails naming `what` after `seconds`."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        answer = probe()
        if answer:
            return answer
        time.sleep(0.1)
    pytest.fail(f"timed out after {seconds} s waiting for {what}")


def latest(cli, trajectory):
    out = cli("latest", trajectory, "--json", check=False)
    return json.loads(out.stdout) if out.returncode == 0 else None


def at(cli, trajectory, valid_time):
    out = cli("at", trajectory, str(valid_time), "--json", check=False)
    return json.loads(out.stdout) if out.returncode == 0 else None


def worker(cli, process):
    for line in cli("ps", "--json").stdout.splitlines():
        record = json.loads(line)
        if record["spec"]["name"] == process:
            return record
    pytest.fail(f"no process {process} in esgm ps")


def sizes(sample):
    return sorted(item["attributes"]["size"] for item in sample["attributes"]["items"])


def test_a_python_unit_in_a_system_file_is_supervised(cli, tmp_path):
    (tmp_path / "flaky.py").write_text(FLAKY)
    (tmp_path / "system.toml").write_text(SYSTEM.format(examples=EXAMPLES, python=sys.executable))
    cli("apply", str(tmp_path / "system.toml"))

    # The numpy unit finds the blobs the Rust unit finds, on the same image: one the
    # Rust unit computed, which the Python unit computes too (it runs on every image
    # since it started; the Rust unit may have started later, and never computed the
    # Python unit's first images).
    until("a blob sequence from the Python unit", lambda: latest(cli, "blobs"))
    theirs = until("a blob sequence from the Rust unit", lambda: latest(cli, "rust_blobs"))
    ours = until("the Python unit's blobs at the same time", lambda: at(cli, "blobs", theirs["valid_time"]))
    assert len(sizes(ours)) > 0 and sizes(ours) == sizes(theirs), (ours, theirs)

    # A sensor written in Python is sampled as well.
    frame = until("a frame of the Python camera", lambda: latest(cli, "pyimages"))
    assert (frame["attributes"]["width"], frame["attributes"]["height"]) == (160, 120), frame

    # kill -9: the supervisor starts it again, and it computes again.
    before = worker(cli, "unit-PyBlobs")
    os.kill(before["status"]["pid"], signal.SIGKILL)
    killed_at = time.time_ns()
    after = until("the unit's restart", lambda: (lambda w: w if w["status"]["restarts"] >= 1
                                                  and w["status"]["pid"] not in (None, before["status"]["pid"])
                                                  else None)(worker(cli, "unit-PyBlobs")))
    assert "SIGKILL" in after["status"]["last_exit"], after
    fresh = until("blobs computed after the restart",
                  lambda: (lambda s: s if s and s["valid_time"] > killed_at else None)(latest(cli, "blobs")))
    assert sizes(fresh) == sizes(until("the Rust unit's blobs", lambda: at(cli, "rust_blobs", fresh["valid_time"])))

    # A unit that raises: its traceback in esgm logs, its failures counted; it carries on.
    logs = until("the flaky unit's traceback in esgm logs",
                 lambda: (lambda o: o if "RuntimeError: flaky call" in o else None)(cli("logs", "unit-Flaky").stdout))
    assert "Traceback (most recent call last)" in logs and "flaky.py" in logs, logs
    until("a flaky output", lambda: latest(cli, "flaky"))
    stats = {json.loads(line).get("trajectory"): json.loads(line) for line in cli("stats", "--json").stdout.splitlines()}
    counted = stats["flaky"]["worker"]
    assert counted["failures"] > 0 and counted["outputs"] > 0, counted
    assert "calls of unit `Flaky` failed" in cli("stats").stdout
    assert worker(cli, "unit-Flaky")["status"]["restarts"] == 0


def test_a_python_unit_that_cannot_be_used_is_refused_at_apply(cli, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(f'[[unit]]\nname = "Nope"\npython = "missing.py:Nope"\ninterpreter = "{sys.executable}"\n')
    out = cli("apply", str(bad), check=False)
    assert out.returncode != 0 and "missing.py does not exist" in out.stderr, out.stderr
    bad.write_text(f'[[unit]]\nname = "Nope"\npython = "blobs.py"\ninterpreter = "{sys.executable}"\n')
    out = cli("apply", str(bad), check=False)
    assert out.returncode != 0 and "FILE.py:CLASS" in out.stderr, out.stderr


def test_the_worker_names_a_class_without_its_types(tmp_path):
    (tmp_path / "untyped.py").write_text("class Untyped:\n    def compute(self, inputs, qtime):\n        return None\n")
    out = subprocess.run([sys.executable, "-m", "esgm.worker", "unit", f"{tmp_path}/untyped.py:Untyped"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and 'output_type = "Blob"' in out.stderr, out.stderr
    out = subprocess.run([sys.executable, "-m", "esgm.worker", "unit", f"{tmp_path}/untyped.py:Missing"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "has no class `Missing`" in out.stderr, out.stderr
