"""Shared fixtures: arms are loaded once per session (loading settles the arm at rest)."""

import dataclasses
import os

import pytest

# The persistent compilation cache stays off in tests (set before mjx_arm turns it on at import):
# no test reads or writes the user's cache, and timings do not depend on an earlier run.
# tests/test_compile_cache.py checks the cache in subprocesses of its own.
os.environ["SOFTARM_JAX_CACHE"] = "0"

import mjx_arm  # noqa: E402, F401  (sets the XLA CPU flag before jax starts)
from mjx_arm import ArmParams, generate_xml  # noqa: E402


@pytest.fixture(scope="session")
def source_arm():
    return mjx_arm.load(domain="source")


@pytest.fixture(scope="session")
def constrained_arm():
    return mjx_arm.load(domain="constrained")


@pytest.fixture(scope="session")
def small_xml():
    """A 3-segment arm: cheap to compile, for tests that only need some arm."""
    return generate_xml(dataclasses.replace(ArmParams(), n_segments=3))
