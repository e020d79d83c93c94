"""Fixtures of the esgm Python tests: each semantic test runs on both runtimes, the
embedded one (`esgm.InProcess()`) and a system of processes (`esgm.connect(domain)`).

`ESGM_TEST_DOMAIN` names a domain whose coordinator runs (esgm-cli's python_api test
starts one in a domain of its own, runs pytest, and stops it)."""

import os
import uuid

import pytest

import esgm


@pytest.fixture(scope="session")
def domain():
    """The domain of a running coordinator, which the caller started (and stops after
    pytest: `esgm down` stops every process attached to the domain, this one too)."""
    name = os.environ.get("ESGM_TEST_DOMAIN")
    if not name:
        pytest.fail("ESGM_TEST_DOMAIN must name a domain with a running coordinator "
                    "(esgm-cli's python_api test starts one: cargo test -p esgm-cli --test python_api)")
    return name


@pytest.fixture(params=["in_process", "connected"])
def system(request):
    """The ESGM on either runtime."""
    if request.param == "in_process":
        return esgm.InProcess()
    return esgm.connect(request.getfixturevalue("domain"))


@pytest.fixture
def unique():
    """A name no other test uses (the connected runtime shares one domain)."""
    return f"t{uuid.uuid4().hex[:10]}"
