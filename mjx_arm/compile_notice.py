"""One line on stderr before a long XLA compile, so that a silent minute is not taken for a hang.

A cold compile of the committed arm's jitted MJX rollout takes 47-92 s on an H100 for each new
batch shape, and minutes on a CPU, and prints nothing. `announce_compile` prints, once per
process for each compiled function and shape, what is being compiled and about how long it takes
the first time; JAX's persistent cache (`mjx_arm.COMPILATION_CACHE_DIR`) makes later processes
fast. Higher floors call it before the first call of their own jitted MJX functions.
"""

from __future__ import annotations

import sys
from collections.abc import Hashable
from typing import TextIO

import jax

#: About how long (s) a cold compile of the committed arm's MJX rollout takes, per JAX platform:
#: 47-92 s per batch shape on an H100 (bench/results/h100), several minutes on a 2-core CPU.
COLD_COMPILE_S = {"gpu": "45-90", "cuda": "45-90", "cpu": "60-300"}

_announced: set[Hashable] = set()


def announce_compile(
    key: Hashable,
    batch: int,
    steps: int,
    what: str = "the MJX rollout",
    stream: TextIO | None = None,
) -> bool:
    """Prints "compiling <what> for batch B x T steps (...)" to stderr the first time `key` is
    seen in this process, and nothing after.

    Args:
      key: what identifies one compilation, e.g. (id of the jitted function, input shape).
      batch: programs per call (B).
      steps: control periods per program (T).
      what: the compiled function, as the line names it.
      stream: where to print (sys.stderr when None).

    Returns:
      True when it printed (the first time for `key`).
    """
    if key in _announced:
        return False
    _announced.add(key)
    platform = jax.default_backend()
    seconds = COLD_COMPILE_S.get(platform, COLD_COMPILE_S["gpu"])
    cached = (
        "cached afterwards"
        if jax.config.jax_compilation_cache_dir
        else "the persistent cache is off (SOFTARM_JAX_CACHE), so every process compiles it"
    )
    print(
        f"compiling {what} for batch {batch} x {steps} steps (about {seconds} s the first time"
        f" on this machine's {platform}; {cached})",
        file=sys.stderr if stream is None else stream,
        flush=True,
    )
    return True
