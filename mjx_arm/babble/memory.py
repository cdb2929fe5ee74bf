"""The host memory a babbling run needs, estimated before any work, and the refusal of a run that
cannot fit (`check_memory`), which names the largest --n that does."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from mjx_arm import constants
from mjx_arm.babble.rod import GPU_MAX_BATCH as ROD_MAX_BATCH
from mjx_arm.rollout_c import C_CHUNK as C_MAX_CHUNK

#: A `mjx_arm.babble.BabbleConfig` (not imported: the package imports this module).
BabbleConfig = Any

#: Host memory of one MuJoCo C rollout chunk per trajectory (bytes): 3.3-3.8 MB measured for the
#: committed arm with its stretch-softening controls (bench/results/cpu/c_chunk_memory.md), with
#: a margin.
C_BYTES_PER_TRAJECTORY = 4_500_000
#: Fraction of the available memory a run may plan to use: the rest is for Python, JAX, MuJoCo
#: and the temporaries the estimate leaves out.
MEMORY_FRACTION = 0.8


class NotEnoughMemoryError(ValueError):
    """A babbling run would not fit the machine's available memory (`check_memory`)."""


def memory_estimate_bytes(config: BabbleConfig, backend: str | None = None) -> int:
    """Host memory a run of `config` needs at its peak (bytes), before any work.

    Every (domain, split) dataset is kept until the end ([n, T, 3] programs and [n, T, 6] poses,
    float32); the largest split's arrays once more while they are made and written; and what one
    chunk holds in flight, which depends on the backend: MuJoCo C simulates at most
    `C_MAX_CHUNK` trajectories per call, each holding its substep states
    (`C_BYTES_PER_TRAJECTORY`), whatever `config.chunk` is; MJX holds one chunk's programs and
    poses on the host (its states stay on the device); the rod ("rod", `mjx_arm.babble.rod`)
    holds at most `ROD_MAX_BATCH` (512; fewer on a CPU) trajectories' float64 programs and
    poses per call (its state, 20 elements per trajectory, is negligible).

    Args:
      config: the run.
      backend: "c", "mjx", "rod" or "auto" (the larger of c and mjx, without asking JAX for its
        backend, which a multi-process run must not do before `jax.distributed.initialize`);
        None: `config.backend`.
    """
    backend = config.backend if backend is None else backend
    if backend == "auto":
        return max(memory_estimate_bytes(config, b) for b in ("c", "mjx"))
    if backend not in ("c", "mjx", "rod"):
        raise ValueError(f"backend must be 'auto', 'mjx', 'c' or 'rod', got {backend!r}")
    per_trajectory = config.n_steps * (3 + constants.POSE_DIM) * 4
    splits = config.splits()
    kept = len(config.domains) * sum(splits.values()) * per_trajectory
    chunk = min(config.chunk, max(splits.values()))
    if backend == "c":
        in_flight = min(chunk, C_MAX_CHUNK) * C_BYTES_PER_TRAJECTORY
    elif backend == "rod":  # float64: twice float32's bytes, as programs, poses and their copy
        in_flight = min(chunk, ROD_MAX_BATCH) * per_trajectory * 2 * 2
    else:
        in_flight = chunk * per_trajectory
    return int(kept + max(splits.values()) * per_trajectory + in_flight)


def largest_n_train(config: BabbleConfig, budget_bytes: float, backend: str | None = None) -> int:
    """The most training trajectories per domain (--n) that keep `config`'s
    `memory_estimate_bytes` within `budget_bytes`, its other fields unchanged; 0 if none does."""

    def fits(n: int) -> bool:
        return (
            memory_estimate_bytes(dataclasses.replace(config, n_train=n), backend) <= budget_bytes
        )

    if not fits(1):
        return 0
    low, high = 1, max(config.n_train, 1)
    while low < high:  # the estimate grows with n: the largest n that fits, by bisection
        mid = (low + high + 1) // 2
        if fits(mid):
            low = mid
        else:
            high = mid - 1
    return low


def available_memory_bytes() -> int | None:
    """Memory this process may still take (bytes): Linux's MemAvailable, capped by a cgroup
    limit (a container's or a cluster job's) less its usage; None where neither is known."""
    found = []
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                found.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        used = Path("/sys/fs/cgroup/memory.current").read_text().strip()
        if limit != "max":
            found.append(int(limit) - int(used))
    except (OSError, ValueError):
        pass
    return min(found) if found else None


def check_memory(config: BabbleConfig, available: int | None = None) -> int:
    """Refuses a run whose `memory_estimate_bytes` exceeds MEMORY_FRACTION of the available
    memory (`available_memory_bytes` unless given); returns the estimate.

    Raises:
      NotEnoughMemoryError: naming the estimate, the memory available and what fits.
    """
    need = memory_estimate_bytes(config)
    available = available_memory_bytes() if available is None else available
    if available is not None and need > MEMORY_FRACTION * available:
        budget = MEMORY_FRACTION * available
        n_fit = largest_n_train(config, budget)
        if n_fit > 0:
            hint = (
                f"--n {n_fit} (training trajectories per domain, with --n-val {config.n_val})"
                " fits; babble fewer"
            )
        else:
            hint = "not even --n 1 fits; babble"
        raise NotEnoughMemoryError(
            f"{len(config.domains)} domain(s) x {sum(config.splits().values())} trajectories of"
            f" {config.duration_s:g} s need about {need / 1e9:.3g} GB of memory, but"
            f" {available / 1e9:.3g} GB are available ({MEMORY_FRACTION:.0%} of it may be"
            f" planned): {hint} or shorter ones (--duration), a smaller --chunk, or in several"
            " runs with other --seed values"
        )
    return need
