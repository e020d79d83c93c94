"""The seed's tutorial in Python (examples/tutorial.py) runs on both runtimes: in this
process, and set up in a system's domain with its camera and units served by the
script's process. (Against `esgm demo`'s own processes it is run by hand, as the
README says.)"""

import os
import subprocess
import sys

TUTORIAL = os.path.join(os.path.dirname(__file__), "..", "examples", "tutorial.py")


def run(*args):
    out = subprocess.run([sys.executable, TUTORIAL, "--seconds", "2", *args],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    last = out.stdout.strip().splitlines()[-1]
    assert last.startswith("tutorial: ") and int(last.split()[1]) > 0, out.stdout
    return out.stdout


def test_the_tutorial_runs_in_process():
    run()


def test_the_tutorial_runs_in_a_domain(domain):
    # A domain of its own is not needed: the shared one has no trajectories of these names.
    run("--domain", domain, "--setup")
