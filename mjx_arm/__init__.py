"""The soft pneumatic arm in MuJoCo and MJX."""

import os as _os
from importlib import metadata as _metadata


def _jaxlib_version() -> tuple[int, ...]:
    try:
        return tuple(int(x) for x in _metadata.version("jaxlib").split(".")[:2])
    except (_metadata.PackageNotFoundError, ValueError):
        return (0, 0)


# MJX on a deep kinematic chain is exponentially slow on XLA's CPU fusion emitters (jaxlib 0.10).
# The flag must be in place before JAX creates its CPU backend, so it is set here, at import,
# appended to any flags. jaxlib 0.11 no longer knows the flag and aborts on it, so it is set only
# for older jaxlib.
CPU_FUSION_FLAG = "--xla_cpu_use_fusion_emitters=false"
CPU_FUSION_FLAG_NEEDED = _jaxlib_version() < (0, 11)
if CPU_FUSION_FLAG_NEEDED and CPU_FUSION_FLAG not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = (_os.environ.get("XLA_FLAGS", "") + " " + CPU_FUSION_FLAG).strip()

# Off-screen rendering: without a display, GLFW cannot make a context; EGL can. MuJoCo reads the
# variable when it is first imported, which is here for every user of the package. Where no EGL
# library exists (e.g. a headless GPU node without libEGL), MuJoCo would fail to import with
# MUJOCO_GL=egl, so the variable is left alone and only rendering is unavailable.
if not _os.environ.get("DISPLAY") and "MUJOCO_GL" not in _os.environ:
    import ctypes.util as _ctypes_util

    if _ctypes_util.find_library("EGL"):
        _os.environ["MUJOCO_GL"] = "egl"

import contextlib as _contextlib  # noqa: E402
import io as _io  # noqa: E402

# mujoco.mjx prints a notice when the optional MJX-Warp backend is absent; keep stdout clean.
with _contextlib.redirect_stdout(_io.StringIO()):
    from mujoco import mjx as _mjx  # noqa: E402, F401

from mjx_arm.arm import Arm, SimState, SimulationDivergedError, load  # noqa: E402
from mjx_arm.checks import ModelValidationError, check_pressures, validate_model  # noqa: E402
from mjx_arm.constants import (  # noqa: E402
    CHAMBER_ACTUATORS,
    CONTROL_HZ,
    P_MAX_BAR,
    P_MIN_BAR,
    TIP_SITE,
)
from mjx_arm.domains import CONSTRAINED, DOMAINS, SOURCE, Domain  # noqa: E402


def __getattr__(name):
    # Lazy, so `python -m mjx_arm.model_gen` does not import its own module twice.
    if name in ("ArmParams", "generate_xml"):
        from mjx_arm import model_gen

        return getattr(model_gen, name)
    raise AttributeError(f"module 'mjx_arm' has no attribute {name!r}")


__all__ = [
    "Arm",
    "ArmParams",
    "CHAMBER_ACTUATORS",
    "CONSTRAINED",
    "CONTROL_HZ",
    "DOMAINS",
    "Domain",
    "ModelValidationError",
    "P_MAX_BAR",
    "P_MIN_BAR",
    "SOURCE",
    "SimState",
    "SimulationDivergedError",
    "TIP_SITE",
    "check_pressures",
    "generate_xml",
    "load",
    "validate_model",
]
