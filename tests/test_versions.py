"""The pins agree with the versions that made the results (docs/versions.md)."""

import os
import pathlib

import pytest
from packaging.requirements import Requirement

import mjx_arm

tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _jax_pins(extra: str, python_version: str) -> set[str]:
    """The jax specifiers an extra adds for a Python version, e.g. {"==0.10.2"}."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    pins = set()
    for line in project["optional-dependencies"][extra]:
        req = Requirement(line)
        if req.name == "jax" and (
            req.marker is None or req.marker.evaluate({"python_version": python_version})
        ):
            pins.add(str(req.specifier))
    return pins


def test_extras_pin_the_versions_of_the_results():
    # GPU tables: jax 0.11.2 on Python 3.12; CPU results and CI: jax 0.10.2.
    assert _jax_pins("gpu", "3.12") == {"==0.11.2"}
    assert _jax_pins("cpu", "3.11") == {"==0.10.2"}
    assert _jax_pins("dev", "3.12") == {"==0.10.2"}  # CI tests the CPU pin


def test_core_range_admits_both_versions():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    spec = next(Requirement(d) for d in project["dependencies"] if d.startswith("jax>"))
    assert spec.specifier.contains("0.10.2") and spec.specifier.contains("0.11.2")


def test_fusion_flag_only_for_jaxlib_that_knows_it():
    # jaxlib 0.11 aborts on the flag; 0.10 needs it for MJX's deep chain.
    from importlib import metadata

    major_minor = tuple(int(x) for x in metadata.version("jaxlib").split(".")[:2])
    assert mjx_arm.CPU_FUSION_FLAG_NEEDED == (major_minor < (0, 11))
    has_flag = mjx_arm.CPU_FUSION_FLAG in os.environ.get("XLA_FLAGS", "")
    assert has_flag == mjx_arm.CPU_FUSION_FLAG_NEEDED
