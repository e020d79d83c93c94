"""Computational units and sensors written in Python, on both runtimes: esgm calls
them on its workers; an exception is logged with its traceback and counted, and never
stops the unit."""

import logging
import time


def robot(x):
    return {"x": float(x), "y": 2.0, "dir": 90.0}


class Doubler:
    """Doubles x; raises on negative inputs, has nothing to say for zero."""

    def compute(self, inputs, qtime):
        s = inputs[0]
        if s["x"] < 0:
            raise ValueError("a negative x")
        if s["x"] == 0:
            return None
        return ("doubled", s.valid_time, {"x": 2 * s["x"], "y": s["y"], "dir": s["dir"]})


class Counter:
    """Counts its calls."""

    def __init__(self):
        self.calls = 0

    def get_current_value(self, qtime):
        self.calls += 1
        return ("counter", qtime, robot(self.calls))


def test_a_python_unit_computes_and_survives_its_exceptions(system, unique, caplog):
    caplog.set_level(logging.ERROR, logger="esgm")
    source = system.create_primitive_entity_trajectory_structure(unique, "RobotState")
    system.add_comp_unit(unique + "Doubler", "RobotState", ["RobotState"], Doubler())
    doubled = system.create_computed_entity_trajectory_structure(unique + "d", unique + "Doubler", [unique])
    sub = doubled.subscribe()
    source.add("robot", 1, robot(1))
    first = sub.recv(20)
    assert (first.name, first.valid_time, first["x"]) == ("doubled", 1, 2.0)
    source.add("robot", 2, robot(-1))  # raises: logged, counted, no output
    source.add("robot", 3, robot(0))   # None: no output this time
    source.add("robot", 4, robot(5))
    after = sub.recv(20)
    assert (after.valid_time, after["x"]) == (4, 10.0)
    deadline = time.monotonic() + 10
    while "ValueError: a negative x" not in caplog.text and time.monotonic() < deadline:
        time.sleep(0.02)
    assert "ValueError: a negative x" in caplog.text and "Traceback" in caplog.text


def test_a_python_sensor_is_sampled(system, unique):
    counter = Counter()
    system.add_sensor_interface(unique + "Counter", "RobotState", counter)
    sampled = system.create_entity_trajectory_structure(unique + "s", unique + "Counter", 20_000_000)
    deadline = time.monotonic() + 20
    while sampled.stats()["stored"] < 3:
        assert time.monotonic() < deadline, sampled.stats()
        time.sleep(0.02)
    xs = [s["x"] for s in sampled.get_between(0, 2**62)]
    assert xs[:3] == [1.0, 2.0, 3.0] and counter.calls >= 3


def test_lineage_and_why_from_python(system, unique):
    """A unit's output names the input it was made from (X1), and `why` says what the
    unit did when it stopped producing (X2): here, raised."""
    source = system.create_primitive_entity_trajectory_structure(unique, "RobotState")
    system.add_comp_unit(unique + "Doubler", "RobotState", ["RobotState"], Doubler())
    doubled = system.create_computed_entity_trajectory_structure(unique + "d", unique + "Doubler", [unique])
    sub = doubled.subscribe()
    source.add("robot", 1, robot(1))
    out = sub.recv(20)
    inputs = out.lineage["inputs"]
    assert [(i["trajectory"], i["valid_time"]) for i in inputs] == [(unique, 1)]
    assert inputs[0]["add_time"] == source.get_latest().add_time
    assert out.lineage["complete"] is False
    assert source.get_latest().lineage is None
    since = out.add_time + 1
    source.add("robot", 2, robot(-1))
    deadline = time.monotonic() + 20
    while True:
        why = doubled.why(since)
        if any("a negative x" in r for r in why["reasons"]):
            break
        assert time.monotonic() < deadline, why
        time.sleep(0.05)
    assert why["inputs"][0]["trajectory"] == unique
    assert why["recent_calls"][-1]["outcome"] in ("failed", "panicked")
