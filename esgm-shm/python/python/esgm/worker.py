"""A computational unit or sensor written in Python, served as a worker of a system.

A system file names it, and the supervisor (`esgm up`, `esgm apply`) runs this module
as the worker's process, restarts it when it dies, and keeps its output for
`esgm logs`:

    [[unit]]
    name = "BlobDetection"
    python = "examples/blobs.py:BlobDetection"   # FILE:CLASS, relative to the file

By hand, the same worker is

    python -m esgm.worker unit examples/blobs.py:BlobDetection --name BlobDetection

The class is instantiated without arguments and says its types as class attributes:
a unit has `compute(inputs, qtime)`, `output_type` and `input_types` (the seed's
`add_comp_unit`); a sensor has `get_current_value(qtime)` and `output_type` (the
seed's `add_sensor_interface`). The supervisor passes the domain (`ESGM_DOMAIN`), the
process's name (`ESGM_WORKER`) and the declared name (`ESGM_NAME`) in the environment.

An exception raised by `compute` or `get_current_value` is logged with its traceback
and counted in the worker's statistics (`esgm stats`); the worker carries on. The
worker ends when its system does (the coordinator gone), with status 0; a file or
class it cannot use ends it with status 2 and one line saying what is wrong."""

import argparse
import importlib.util
import logging
import os
import sys

import esgm

LOG = logging.getLogger("esgm.worker")

#: Exit status of a worker whose file, class or types cannot be used: the supervisor
#: restarts it, and `esgm logs` shows the line that says why.
UNUSABLE = 2


class Unusable(Exception):
    """The declared file or class cannot serve as the unit or sensor."""


def load_class(target):
    """The class `CLASS` of `FILE.py:CLASS`. The file's directory comes first on the
    module path, so that it imports its neighbours as it would run as a script."""
    path, sep, name = target.rpartition(":")
    if not sep or not path or not name.isidentifier():
        raise Unusable(f"`{target}` is not FILE.py:CLASS")
    path = os.path.abspath(path)
    if not os.path.isfile(path):
        raise Unusable(f"{path} does not exist")
    directory = os.path.dirname(path)
    if directory not in sys.path:
        sys.path.insert(0, directory)
    module_name = os.path.splitext(os.path.basename(path))[0]
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise Unusable(f"{path} is not a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    spec.loader.exec_module(module)
    cls = getattr(module, name, None)
    if not isinstance(cls, type):
        raise Unusable(f"{path} has no class `{name}`")
    return cls


def types_of(cls, kind):
    """`(output_type, input_types)` a class declares; input types only for a unit."""
    method = "compute" if kind == "unit" else "get_current_value"
    if not callable(getattr(cls, method, None)):
        raise Unusable(f"class `{cls.__name__}` has no {method} method, which a {kind} needs")
    output = getattr(cls, "output_type", None)
    if not isinstance(output, str) or not output:
        raise Unusable(f'class `{cls.__name__}` must say its output type: output_type = "Blob"')
    if kind == "sensor":
        return output, None
    inputs = getattr(cls, "input_types", None)
    if not isinstance(inputs, (list, tuple)) or not inputs or not all(isinstance(i, str) for i in inputs):
        raise Unusable(f'class `{cls.__name__}` must say its input types: input_types = ["Image"]')
    return output, list(inputs)


def serve(kind, target, name, domain=None):
    """Registers the class of `target` as the unit or sensor `name` in the system of
    `domain` and serves it until the system ends."""
    cls = load_class(target)
    output, inputs = types_of(cls, kind)
    instance = cls()
    system = esgm.connect(domain)
    if kind == "unit":
        system.add_comp_unit(name, output, inputs, instance)
    else:
        system.add_sensor_interface(name, output, instance)
    LOG.info("serving %s %s from %s (%s%s)", kind, name, target,
             f"{', '.join(inputs)} -> " if inputs else "", output)
    system.serve()
    LOG.info("the system has ended; %s %s stops", kind, name)


def main(argv=None):
    parser = argparse.ArgumentParser(
        prog="python -m esgm.worker",
        description="Serve a unit or sensor written in Python as a worker of an esgm system.")
    parser.add_argument("kind", choices=["unit", "sensor"])
    parser.add_argument("target", metavar="FILE.py:CLASS")
    parser.add_argument("--name", default=os.environ.get("ESGM_NAME"),
                        help="the registered name (default: ESGM_NAME, else the class's name)")
    parser.add_argument("--domain", help="the system's domain (default: ESGM_DOMAIN, else esgm)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=os.environ.get("ESGM_PY_LOG", "INFO").upper(), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    name = args.name or args.target.rpartition(":")[2]
    try:
        serve(args.kind, args.target, name, args.domain)
    except Unusable as e:
        LOG.error("%s %s: %s", args.kind, name, e)
        return UNUSABLE
    except esgm.EsgmError as e:
        LOG.error("%s %s: %s: %s", args.kind, name, type(e).__name__, e)
        return 1
    except KeyboardInterrupt:
        LOG.info("interrupted; %s %s stops", args.kind, name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
