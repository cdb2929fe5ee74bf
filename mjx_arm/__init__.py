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

# JAX's persistent compilation cache, so that a second process does not compile the same rollout
# again (minutes on the CPU, 43-81 s per batch shape on an H100). Its key holds the jaxlib version,
# the backend and XLA_FLAGS, so stale entries are never used. SOFTARM_JAX_CACHE=0 turns it off,
# SOFTARM_JAX_CACHE=/path moves it; a cache directory set through JAX itself is left alone.
COMPILATION_CACHE_ENV = "SOFTARM_JAX_CACHE"
CACHE_MIN_COMPILE_TIME_S = 1.0  # JAX's default: the many small programs are not worth a file
CACHE_MIN_ENTRY_BYTES = 0  # JAX's default: no size threshold


def _compilation_cache_dir() -> str | None:
    """The cache folder from SOFTARM_JAX_CACHE and XDG_CACHE_HOME; None when turned off."""
    setting = _os.environ.get(COMPILATION_CACHE_ENV, "").strip()
    if setting.lower() in ("0", "off", "false", "no", "none"):
        return None
    if setting and setting.lower() not in ("1", "on", "true", "yes"):
        return _checked_cache_dir(setting)
    cache_home = _os.environ.get("XDG_CACHE_HOME") or _os.path.join(
        _os.path.expanduser("~"), ".cache"
    )
    return _os.path.join(cache_home, "softarm-ccgan", "jax")


def _checked_cache_dir(setting: str) -> str:
    """SOFTARM_JAX_CACHE's folder, `~` expanded, refused (ValueError, at import) when a `~user`
    names no user (it would make a folder called `~user` in the working directory) or the folder
    cannot be written or made."""
    path = _os.path.expanduser(setting)
    if path.startswith("~"):
        raise ValueError(
            f"{COMPILATION_CACHE_ENV}={setting!r}: {path.split('/')[0]!r} names no user, so"
            " the path does not expand; give an absolute path, ~/..., or 0 to turn the cache off"
        )
    path = _os.path.abspath(path)
    existing = path
    while not _os.path.exists(existing) and _os.path.dirname(existing) != existing:
        existing = _os.path.dirname(existing)
    if not _os.path.isdir(existing) or not _os.access(existing, _os.W_OK | _os.X_OK):
        raise ValueError(
            f"{COMPILATION_CACHE_ENV}={setting!r}: cannot write or make {path} ({existing} is"
            " not a writable folder); give a writable folder, or 0 to turn the cache off"
        )
    return path


def _enable_compilation_cache() -> str | None:
    import jax

    if jax.config.jax_compilation_cache_dir:  # JAX_COMPILATION_CACHE_DIR or the user's own
        return jax.config.jax_compilation_cache_dir
    path = _compilation_cache_dir()
    if path is not None:
        jax.config.update("jax_compilation_cache_dir", path)
        for name, value in (
            ("jax_persistent_cache_min_compile_time_secs", CACHE_MIN_COMPILE_TIME_S),
            ("jax_persistent_cache_min_entry_size_bytes", CACHE_MIN_ENTRY_BYTES),
        ):
            if name.upper() not in _os.environ:  # JAX's own variable wins
                jax.config.update(name, value)
    return path


COMPILATION_CACHE_DIR = _enable_compilation_cache()

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
    if name in ("RodArm", "load_rod"):  # the reference rod as an arm (imports model_gen too)
        from mjx_arm import rod_arm

        return getattr(rod_arm, name)
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
    "RodArm",
    "SOURCE",
    "SimState",
    "SimulationDivergedError",
    "TIP_SITE",
    "check_pressures",
    "generate_xml",
    "load",
    "load_rod",
    "validate_model",
]
