"""Types declared from Python, on both runtimes: from a dataclass (nested ones and
lists of them become frames), or from a dict of sorts; samples convert back to the
dataclass."""

import dataclasses
from typing import List

import pytest

import esgm


def test_a_dataclass_is_a_type_and_samples_convert_back(system, unique):
    Point = dataclasses.make_dataclass(unique + "Point", [("x", float), ("y", float)])
    Track = dataclasses.make_dataclass(
        unique + "Track",
        [("label", str), ("score", float), ("valid", bool), ("ids", List[int]), ("points", List[Point]), ("head", Point)],
    )
    assert system.create_type(Track) == unique + "Track"
    assert unique + "Point" in system.entity_structure_type_names()
    t = system.create_primitive_entity_trajectory_structure(unique, unique + "Track")
    track = Track("car", 0.9, True, [1, 2], [Point(1.0, 2.0)], Point(3.0, 4.0))
    as_dict = {
        "label": "car", "score": 0.9, "valid": True, "ids": [1, 2],
        "points": [{"name": "p0", "x": 1.0, "y": 2.0}], "head": {"name": "head", "x": 3.0, "y": 4.0},
    }
    t.add("track1", 5, as_dict)
    system.flush(10)
    s = t.get_latest()
    assert s["points"] == [{"name": "p0", "x": 1.0, "y": 2.0}]
    back = s.to(Track)
    assert (back.label, back.score, back.valid, back.ids) == (track.label, track.score, track.valid, track.ids)


def test_a_type_from_sorts_and_refusals_that_name_the_field(system, unique):
    system.create_entity_structure_type(unique, {"count": "Long", "blobs": "EntityFrameSeq<Blob>"})
    described = system.get_entity_structure_type(unique)
    assert [a["name"] for a in described["attributes"]] == ["count", "blobs"]
    with pytest.raises(TypeError, match="`weird`"):
        system.create_entity_structure_type(unique + "b", {"weird": "Complex"})
    Odd = dataclasses.make_dataclass(unique + "Odd", [("z", complex)])
    with pytest.raises(TypeError, match=r"Odd\.z"):
        system.create_type(Odd)
    with pytest.raises(TypeError, match="dataclass"):
        system.create_type(int)


def test_geometric_sorts_are_tuples(system, unique):
    system.create_entity_structure_type(
        unique, {"pose": "PositionAltitudeRotation", "points": "Pos2Seq", "v": "Vec", "at": "Position"})
    t = system.create_primitive_entity_trajectory_structure(unique, unique)
    attributes = {"pose": (1.0, 2.0, 3.0, 0.1, 0.2, 0.3), "points": [(1.0, 2.0), (3.0, 4.0)],
                  "v": (0.5, 0.0, -0.5), "at": (58.4, 15.6)}
    t.add("drone", 3, attributes)
    system.flush(10)
    assert t.get_latest().to_dict() == attributes
    with pytest.raises(TypeError, match="`v` takes 3 floats"):
        t.add("drone", 4, {**attributes, "v": (1.0, 2.0)})
