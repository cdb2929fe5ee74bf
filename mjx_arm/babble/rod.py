"""Babbling in the reference rod (``python -m mjx_arm.babble --backend rod``).

The same programs (`mjx_arm.babble.family_programs`: the same seeds and streams as the chain's
backends), simulated by the reference Cosserat rod under the paper simulator's law
(`mjx_arm.load_rod(domain)`, float64) instead of the fitted chain. The files, their folder and
manifest have the chain's format; what tells them apart: every file's model hash is the rod's
(`RodArm.model_hash`, "rod-..." in every domain, never an MJCF's), and its config records
``"backend": "rod"``, ``"simulator": "rod"`` and the rod's dtype. `ccgan.train` reads the model
hash, so rod data never pass for the chain's (and are never mixed with them).

Cost. The rod is latency-bound (500 float64 physics steps of 2e-4 s per 0.1 s period, one after
the other): on a GPU a batch costs about its longest program, nearly whatever the batch up to
~64 (one H200: 7.7 simulated s per wall s at batch 1, ~400 at 64, ~1,090 at 512), so a GPU run
simulates each (domain, split) in as few calls as it can, of at most `GPU_MAX_BATCH`
trajectories (one compile per batch shape: the calls of a split are padded to one size). On a CPU
batching barely helps (2 cores: ~25 simulated s per wall s at batch 1, 28-37 at 4-8), so the run
costs about the total simulated time, and it goes in chunks of `cpu_chunk()` trajectories, which
move the progress bar every few seconds. The paper's preset (2 domains x 53 x 60 s) is ~6,400
simulated s: ~4 min on 2 CPU cores, four calls of ~10 s on one H200; the long D_c set
(``--domain constrained --n 400 --duration 120``) ~48,000 simulated s: ~25 min on 2 cores, one
call of ~1 min on one H200 (~1,000 simulated s/s at batch 400). When JAX has several host CPU
devices (`mjx_arm.rod_arm.host_devices`), the rod runs there instead, `RodArm.call_size`
trajectories a call split over them.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import jax
import numpy as np

from mjx_arm.machine import usable_cores
from mjx_arm.rod_arm import ACCELERATOR_BATCH

#: Largest rod batch per call on an accelerator (`mjx_arm.rod_arm.ACCELERATOR_BATCH`).
GPU_MAX_BATCH = ACCELERATOR_BATCH
#: The rod's floating-point type for babbling: the reference (float32 drifts from it).
DTYPE = "float64"


def cpu_chunk() -> int:
    """Trajectories per call on a CPU: two per usable core (batching gains ~1.1-1.5x there, and
    small chunks keep the progress bar moving)."""
    return max(1, 2 * usable_cores())


def batch_sizes(
    n: int, chunk: int, on_accelerator: bool | None = None, host_call: int | None = None
) -> list[int]:
    """The sizes of the calls that simulate n trajectories (sum n).

    Args:
      n: trajectories.
      chunk: the run's largest batch (`BabbleConfig.chunk`).
      on_accelerator: a GPU or TPU (default: JAX's default backend is not the CPU): calls of at
        most min(chunk, `GPU_MAX_BATCH`), as few as possible and as even as possible (the caller
        pads them to one size); on a CPU, calls of min(chunk, `cpu_chunk()`), the last shorter.
      host_call: the rod runs on the host's devices (`mjx_arm.rod_arm.host_devices`) with this
        `RodArm.call_size`: calls of min(chunk, host_call), the last shorter (a compile there
        costs ~1 s, less than padding a call); it overrides `on_accelerator`.
    """
    if n <= 0:
        return []
    if host_call is not None:
        size = max(1, min(chunk, host_call))
        return [size] * (n // size) + ([n % size] if n % size else [])
    if on_accelerator is None:
        on_accelerator = jax.default_backend() != "cpu"
    if on_accelerator:
        limit = max(1, min(chunk, GPU_MAX_BATCH))
        calls = math.ceil(n / limit)
        size = math.ceil(n / calls)
        return [size] * (n // size) + ([n % size] if n % size else [])
    size = max(1, min(chunk, cpu_chunk()))
    return [size] * (n // size) + ([n % size] if n % size else [])


def simulate_rod(
    rod,
    programs_bar: np.ndarray,
    *,
    chunk: int = 4096,
    progress: Callable[[int], None] | None = None,
    on_accelerator: bool | None = None,
) -> np.ndarray:
    """Poses of babbling programs in the rod, in the calls `batch_sizes` gives.

    On an accelerator every call is padded to the first call's size by repeating the last
    program (one compile per split); the padded rows are simulated and dropped. When the rod
    runs on the host's devices (`RodArm.placement() == "host"`, and `on_accelerator` not given)
    the calls are `RodArm.call_size` trajectories, unpadded.

    Args:
      rod: a `mjx_arm.RodArm` in its domain.
      programs_bar: [N, T, 3] commands (bar) at 10 Hz.
      chunk: the largest batch asked for (`BabbleConfig.chunk`).
      progress: called with the number of trajectories finished after each call.
      on_accelerator: as `batch_sizes`.

    Returns:
      [N, T, 6] float64 poses: tip position (m) then unit d3, from rest.

    Raises:
      SimulationDivergedError: a trajectory diverged (`RodArm.rollout`).
    """
    host_call = None
    if on_accelerator is None:
        host_call = rod.call_size() if rod.placement() == "host" else None
        on_accelerator = host_call is None and jax.default_backend() != "cpu"
    sizes = batch_sizes(programs_bar.shape[0], chunk, on_accelerator, host_call)
    poses = np.zeros(programs_bar.shape[:2] + (6,), np.float64)
    start = 0
    for size in sizes:
        part = programs_bar[start : start + size]
        if on_accelerator and size < sizes[0]:
            part = np.concatenate([part, np.repeat(part[-1:], sizes[0] - size, axis=0)])
        poses[start : start + size] = rod.rollout(np.asarray(part, np.float64))[:size]
        start += size
        if progress is not None:
            progress(size)
    return poses


def rod_config_fields() -> dict:
    """What a rod run adds to every file's config (and so to the manifest): the simulator and
    the rod's dtype, beside ``"backend": "rod"``."""
    return {"simulator": "rod", "rod_dtype": DTYPE}
