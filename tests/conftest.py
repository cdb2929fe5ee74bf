"""Shared fixtures: arms are loaded once per session (loading settles the arm at rest)."""

import dataclasses

import pytest

import mjx_arm  # noqa: F401  (sets the XLA CPU flag before jax starts)
from mjx_arm import ArmParams, generate_xml


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
