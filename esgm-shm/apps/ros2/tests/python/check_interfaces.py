"""Checks an interface package written by `esgm ros2 pkg` with an independent parser:
rosbags' `get_types_from_msg` parses every `.msg` (named `esgm_msgs/msg/<file>`), a
ROS 2 Humble type store registers them all together (so every field's type resolves:
std_msgs, builtin_interfaces, geometry_msgs and the package's own), and each message
is serialized to CDR from default values and read back. The package's package.xml and
CMakeLists.txt must name the package and every message. Prints one JSON object:
{"messages": {name: [field, ...]}} on success; raises otherwise.

    python check_interfaces.py DIR/esgm_msgs
"""

import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from rosbags.typesys import Stores, get_typestore, get_types_from_msg


def default(typestore, name):
    """A message of `name` with every field at its zero (sequences empty)."""
    cls = typestore.types[name]
    msgdef = typestore.get_msgdef(name)
    values = {}
    for field_name, (kind, detail) in msgdef.fields:
        kind = int(kind)
        if kind == 1:  # base type
            base = detail[0]
            values[field_name] = "" if base == "string" else (False if base == "bool" else 0)
        elif kind == 2:  # a message
            values[field_name] = default(typestore, detail)
        else:  # arrays and sequences: empty sequences here
            import numpy

            inner = detail[0]
            if int(inner[0]) == 1 and inner[1][0] not in ("string",):
                values[field_name] = numpy.array([], dtype=numpy.dtype(typestore_dtype(inner[1][0])))
            else:
                values[field_name] = []
    return cls(**values)


def typestore_dtype(base):
    return {
        "bool": "bool", "uint8": "uint8", "int8": "int8", "int16": "int16",
        "uint16": "uint16", "int32": "int32", "uint32": "uint32", "int64": "int64",
        "uint64": "uint64", "float32": "float32", "float64": "float64", "octet": "uint8",
        "byte": "uint8", "char": "uint8",
    }[base]


def main():
    package = Path(sys.argv[1])
    msgs = sorted((package / "msg").glob("*.msg"))
    assert msgs, f"no .msg file in {package}/msg"
    add = {}
    for path in msgs:
        add.update(get_types_from_msg(path.read_text(), f"esgm_msgs/msg/{path.stem}"))
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    typestore.register(add)
    out = {}
    for name in sorted(add):
        msgdef = typestore.get_msgdef(name)
        message = default(typestore, name)
        data = typestore.serialize_cdr(message, name)
        back = typestore.deserialize_cdr(data, name)
        assert type(back).__name__ == type(message).__name__
        out[name] = [f for f, _ in msgdef.fields]

    root = ET.parse(package / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3", root.attrib
    assert root.findtext("name") == "esgm_msgs"
    groups = [g.text for g in root.findall("member_of_group")]
    assert "rosidl_interface_packages" in groups, groups
    cmake = (package / "CMakeLists.txt").read_text()
    assert "project(esgm_msgs)" in cmake
    for path in msgs:
        assert f'"msg/{path.name}"' in cmake, path.name
    print(json.dumps({"messages": out}))


if __name__ == "__main__":
    main()
