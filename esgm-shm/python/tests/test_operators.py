"""The operators of G2-G4 from Python, on both runtimes: sync (exact and within a
tolerance), merge, and trajectories sampled from fluent generators, with and without a
Python unit's temporal function (`compute_at`); every constructor takes a policy."""

import time

import pytest

import esgm

MS = 1_000_000


def robot(x):
    return {"x": float(x), "y": 0.0, "dir": 0.0}


def received(sub, n, seconds=20):
    """The next `n` samples of `sub`, or fails after `seconds`."""
    got, deadline = [], time.monotonic() + seconds
    while len(got) < n:
        left = deadline - time.monotonic()
        if left <= 0:
            pytest.fail(f"{len(got)} of {n} samples in {seconds} s")
        try:
            got.append(sub.recv(left))
        except TimeoutError:
            pass
    return got


def test_sync_pairs_samples_of_the_same_time(system, unique):
    a = system.create_primitive_entity_trajectory_structure(unique + "a", "RobotState")
    b = system.create_primitive_entity_trajectory_structure(unique + "b", "RobotState")
    exact = system.create_sync_entity_trajectory_structure(unique + "ab", [unique + "a", unique + "b"])
    near = system.create_sync_entity_trajectory_structure(
        unique + "near", [unique + "a", unique + "b"], tolerance=5, sync_policy="epsilon")
    subs = exact.subscribe(), near.subscribe()
    a.add("r", 1000, robot(1))
    b.add("r", 1000, robot(2))
    a.add("r", 2000, robot(3))
    b.add("r", 2003, robot(4))
    (state,) = received(subs[0], 1)
    assert (state.valid_time, state[unique + "a"]["x"], state[unique + "b"]["x"]) == (1000, 1.0, 2.0)
    states = received(subs[1], 2)
    assert [(s[unique + "a"]["x"], s[unique + "b"]["x"]) for s in states] == [(1.0, 2.0), (3.0, 4.0)]


def test_why_names_each_sync_inputs_drops(system, unique):
    """`why` says what a sync dropped, per input and reason (X2): a's 1000 is passed
    over by the set at 2000, and b's 1500 comes after that set."""
    a = system.create_primitive_entity_trajectory_structure(unique + "a", "RobotState")
    b = system.create_primitive_entity_trajectory_structure(unique + "b", "RobotState")
    ab = system.create_sync_entity_trajectory_structure(unique + "ab", [unique + "a", unique + "b"])
    sub = ab.subscribe()
    a.add("r", 1000, robot(1))
    a.add("r", 2000, robot(2))
    b.add("r", 2000, robot(3))
    received(sub, 1)
    b.add("r", 1500, robot(4))
    deadline = time.monotonic() + 20
    while True:
        why = ab.why()
        if why["sync"]["discarded"] == 2:
            break
        assert time.monotonic() < deadline, why
        time.sleep(0.05)
    dropped = {d["input"]: d for d in why["sync"]["dropped"]}
    assert (dropped[unique + "a"]["passed_over"], dropped[unique + "a"]["last"]) == (1, [1000, "passed_over"])
    assert (dropped[unique + "b"]["late"], dropped[unique + "b"]["last"]) == (1, [1500, "late"])
    assert any(f"the sync dropped 1 of `{unique}b`'s structure(s): 1 arrived after a later set" in r
               for r in why["reasons"]), why["reasons"]


def test_sync_words_are_checked(system, unique):
    system.create_primitive_entity_trajectory_structure(unique + "a", "RobotState")
    inputs = [unique + "a", unique + "a"]
    with pytest.raises(ValueError, match="needs a tolerance"):
        system.create_sync_entity_trajectory_structure(unique + "s", inputs, sync_policy="approximate")
    with pytest.raises(ValueError, match="unknown sync policy `closest`"):
        system.create_sync_entity_trajectory_structure(unique + "s", inputs, tolerance=5, sync_policy="closest")
    with pytest.raises(ValueError, match="exact sync has no tolerance"):
        system.create_sync_entity_trajectory_structure(unique + "s", inputs, tolerance=5, sync_policy="exact")


def test_merge_interleaves_and_keeps_its_cache(system, unique):
    a = system.create_primitive_entity_trajectory_structure(unique + "a", "RobotState")
    b = system.create_primitive_entity_trajectory_structure(unique + "b", "RobotState")
    m = system.create_merge_entity_trajectory_structure(unique + "m", [unique + "a", unique + "b"],
                                                        policy={"cache": 2})
    sub = m.subscribe()
    a.add("r", 10, robot(1))
    b.add("r", 20, robot(2))
    a.add("r", 30, robot(3))
    assert [s["x"] for s in received(sub, 3)] == [1.0, 2.0, 3.0]
    assert [s["x"] for s in m.get_between(0, 100)] == [2.0, 3.0]
    with pytest.raises(esgm.InvalidType):
        system.create_primitive_entity_trajectory_structure(unique + "img", "Image")
        system.create_merge_entity_trajectory_structure(unique + "bad", [unique + "a", unique + "img"])


class Sum:
    """The sum of its inputs' x at a time: a temporal function (`compute_at`)."""

    def compute(self, inputs, qtime):
        return None

    def compute_at(self, inputs, t):
        return ("sum", t, robot(sum(s["x"] for s in inputs)))


def test_generators_are_sampled_and_a_python_function_of_them(system, unique):
    a = system.create_primitive_entity_trajectory_structure(unique + "a", "RobotState")
    b = system.create_primitive_entity_trajectory_structure(unique + "b", "RobotState")
    system.add_comp_unit(unique + "Sum", "RobotState", ["RobotState", "RobotState"], Sum())
    # `a` rises linearly by 1 every 10 ms over the next 10 s; `b` holds 5.
    t0 = time.time_ns()
    a.add("r", t0, robot(0))
    a.add("r", t0 + 10_000 * MS, robot(1000))
    b.add("r", t0, robot(5))
    end = t0 + 5_000 * MS
    values = system.create_generated_entity_trajectory_structure(
        unique + "g", [unique + "a:linear"], 25 * MS, end=end)
    function = system.create_generated_entity_trajectory_structure(
        unique + "f", [unique + "a:linear", unique + "b:most-recent"], 50 * MS,
        unit=unique + "Sum", end=end, policy={"cache": 10})
    g, f = values.subscribe(), function.subscribe()
    # Sampled from now on: every sample is the generators' value at its valid time.
    for s in received(g, 3):
        assert s["x"] == pytest.approx((s.valid_time - t0) / (10 * MS)), s.valid_time - t0
    for s in received(f, 2):
        assert s["x"] == pytest.approx(5 + (s.valid_time - t0) / (10 * MS)), s.valid_time - t0
    for name in ["g", "f"]:
        system.destroy_entity_trajectory_structure(unique + name)


def test_generator_words_are_checked(system, unique):
    system.create_primitive_entity_trajectory_structure(unique + "a", "RobotState")
    with pytest.raises(ValueError, match="did you mean `linear`"):
        system.create_generated_entity_trajectory_structure(unique + "g", [unique + "a:lineer"], 10 * MS)
    with pytest.raises(ValueError, match="at least one"):
        system.create_generated_entity_trajectory_structure(unique + "g", [], 10 * MS)


def test_computed_and_sampled_take_a_policy(system, unique):
    source = system.create_primitive_entity_trajectory_structure(unique, "RobotState")
    system.add_comp_unit(unique + "Copy", "RobotState", ["RobotState"], Copy())
    copied = system.create_computed_entity_trajectory_structure(
        unique + "c", unique + "Copy", [unique], policy={"cache": 1})
    sub = copied.subscribe()
    for i in range(1, 4):
        source.add("r", i, robot(i))
    assert [s["x"] for s in received(sub, 3)] == [1.0, 2.0, 3.0]
    system.flush(10)
    assert [s["x"] for s in copied.get_between(0, 10)] == [3.0]
    with pytest.raises(ValueError, match="policy `cache`"):
        system.create_entity_trajectory_structure(unique + "s", unique + "Copy", 10 * MS, policy={"cache": -1})


class Copy:
    def compute(self, inputs, qtime):
        s = inputs[0]
        return ("copy", s.valid_time, robot(s["x"]))
