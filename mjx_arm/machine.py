"""The machine a result was measured on (for the headers of result files), and its compile cache."""

import os
import platform
from pathlib import Path


def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (falls back to `platform.processor()`)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


#: Environment variable that sets how many threads this process's MuJoCo C rollouts use.
THREADS_ENV = "SOFTARM_THREADS"


def usable_cores() -> int:
    """Threads for this process's MuJoCo C rollouts and receding-horizon tracking.

    $SOFTARM_THREADS when set; else the cores the process may run on (its CPU affinity: what a
    cluster job or `taskset` allots, where os.cpu_count() would name every core of the node and
    start a thread for each); else os.cpu_count().

    Raises:
      ValueError: $SOFTARM_THREADS is not a positive integer.
    """
    asked = os.environ.get(THREADS_ENV)
    if asked:
        if not asked.strip().isdigit() or int(asked) < 1:
            raise ValueError(f"${THREADS_ENV}={asked!r}: give a positive number of threads")
        return int(asked)
    if hasattr(os, "sched_getaffinity"):
        return max(len(os.sched_getaffinity(0)), 1)
    return os.cpu_count() or 1


#: Environment variable JAX reads for its persistent compilation cache folder.
CACHE_ENV = "JAX_COMPILATION_CACHE_DIR"


def enable_compilation_cache(path: str | os.PathLike | None = None) -> str | None:
    """Turns on JAX's persistent compilation cache for runs on an accelerator; returns its folder.

    The command-line tools call this before their first compilation, so that a second run on the
    same kind of GPU reads its compiled programs from disk instead of compiling again (the oracle's
    Adam step on an H200: 165 s compiling, 60 s from the cache; README, "The full table"). Without
    `path`, left alone (returns None) on the CPU, where compiling is fast and the tests run, and
    where `JAX_COMPILATION_CACHE_DIR` is set (JAX reads it itself; it is returned).

    Args:
      path: cache folder, used on any backend (e.g. `mjx_arm.babble --cache-dir`); default on an
        accelerator: $XDG_CACHE_HOME/softarm/jax, else ~/.cache/softarm/jax.
    """
    import jax

    if path is not None:
        jax.config.update("jax_compilation_cache_dir", str(path))
        return str(path)
    if os.environ.get(CACHE_ENV):
        return os.environ[CACHE_ENV]
    if jax.default_backend() == "cpu":
        return None
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    path = Path(base) / "softarm" / "jax"
    jax.config.update("jax_compilation_cache_dir", str(path))
    return str(path)
