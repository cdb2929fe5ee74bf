"""Held commands: the stretch baseline and the D_c rollouts every method's commands go through.

The constrained arm is slower than the source arm, so a D_s program is tracked in D_c by holding
each source step's command for k control periods (k >= 1, the stretch factor; every translator's
output has the same form, one command per source step held k periods). A D_c program is then
[T * k, 3] commands (bar) for T source steps, and its pose at the end of each source step's k
periods, every k-th pose, is what is compared with the D_s target [T, 6].
"""

from __future__ import annotations

import hashlib
import sys

import numpy as np
from tqdm import tqdm

from mjx_arm.constants import CONTROL_HZ
from mjx_arm.machine import usable_cores
from tracking import metrics


def stretch(pressures_bar: np.ndarray, k: int) -> np.ndarray:
    """Holds each command k control periods: [..., T, 3] -> [..., T * k, 3] (bar)."""
    return np.repeat(np.asarray(pressures_bar), k, axis=-2)


def every_kth(poses_c: np.ndarray, k: int) -> np.ndarray:
    """The pose at the end of each source step's k periods: [..., T * k, 6] -> [..., T, 6]."""
    return poses_c[..., k - 1 :: k, :]


def run_dc(arm_c, commands_c: np.ndarray, k: int, backend: str) -> np.ndarray:
    """D_c rollout(s) from rest of commands [..., T * k, 3] (bar) on backend "c" (MuJoCo C) or
    "mjx"; returns every k-th pose, [..., T, 6] (m, unit d3)."""
    return every_kth(arm_c.rollout(commands_c, backend=backend), k)


#: Chunk of `rollout_grouped(padded=True)` on an arm that names no call size of its own.
PADDED_CHUNK = 512


def hold_last(commands: list[np.ndarray]) -> np.ndarray:
    """Programs [N_i, 3] (bar) padded to the longest by holding each one's last command:
    [B, max N_i, 3]. A simulator is causal, so the first N_i poses of a padded program are the
    unpadded program's."""
    longest = max(len(c) for c in commands)
    return np.stack([np.concatenate([c, np.repeat(c[-1:], longest - len(c), 0)]) for c in commands])


def _announce(label: str | None, n: int, sim_s: float, longest_s: float) -> None:
    """One line on stderr before a rod call that no progress bar can follow (minutes on a GPU)."""
    if label:

        def shown(s: float) -> str:
            return f"{s:,.0f}" if s >= 100 else f"{s:.1f}"

        tqdm.write(
            f"{label}: the rod runs {n} trajectories together ({shown(sim_s)} simulated s, the"
            f" longest {shown(longest_s)} s)",
            file=sys.stderr,
        )


def rollout_grouped(
    arm,
    jobs: list[tuple[np.ndarray, int]],
    backend: str,
    progress: str | None = None,
    padded: bool | None = None,
) -> list[np.ndarray]:
    """Poses of many (commands [T * k, 3] bar, k) jobs, every k-th pose ([T, 6] each).

    Jobs of the same command length and k run as batched rollouts (MuJoCo C: one thread per
    trajectory; MJX: one vmapped call per group), so a many-core machine runs them side by side.
    With `progress` (the bar's label) a progress bar counts trajectories; on MuJoCo C each group
    then runs in batches of two trajectories per core, so the bar moves every few seconds (the
    main job's 245 60 s trajectories at k = 10 take about 1.5 s each on 2 cores) and the poses
    are the same, as every trajectory is simulated on its own. MJX keeps one call per group
    (another batch size would compile again).

    The reference rod (`mjx_arm.RodArm`, backend "rod") is latency-bound: on a GPU one call
    costs about its longest trajectory's time whatever the batch up to ~64, and on the host's
    devices (`mjx_arm.rod_arm.host_devices`) a call of a few trajectories per device costs about
    its longest too. So there (`padded` None and `RodArm.call_size` not None, or `padded` True)
    every job runs in as few calls as it can: programs sorted by length, chunks of at most
    `call_size` (512 when padded is forced on an arm without one), each program padded to its
    chunk's longest by holding its last command (`hold_last`); the rod is causal, so each job's
    poses are its own first T * k, every k-th kept. Each call is announced on stderr with
    `progress`, as the bar moves only between calls. On one CPU device (cost ~ total simulated
    seconds) the rod runs one group at a time like the chain, in batches of two trajectories per
    core with `progress`.

    Jobs with equal commands and k are simulated once and share the poses (copies): the
    simulator is deterministic and every trajectory runs on its own, so a deterministic method's
    repetitions (the periodicity test) and its seeds cost one rollout.
    """
    groups: dict[tuple, dict[bytes, list[int]]] = {}
    for i, (cmd, k) in enumerate(jobs):
        cmd = np.ascontiguousarray(cmd, dtype=np.float64)
        same = groups.setdefault((cmd.shape, int(k)), {})
        same.setdefault(hashlib.sha256(cmd.tobytes()).digest(), []).append(i)
    copies_of = {c[0]: c for same in groups.values() for c in same.values()}
    out: list[np.ndarray | None] = [None] * len(jobs)

    def keep(first: int, poses: np.ndarray) -> int:
        for n, i in enumerate(copies_of[first]):
            out[i] = poses if n == 0 else poses.copy()
        return len(copies_of[first])

    call_size = arm.call_size() if backend == "rod" else None
    if padded is None:
        padded = call_size is not None
    with tqdm(total=len(jobs), desc=progress, unit="traj", disable=not progress) as bar:
        if padded:
            chunk = call_size or PADDED_CHUNK
            _rollout_padded(arm, jobs, sorted(copies_of), backend, progress, keep, bar, chunk)
            return out
        for (_, k), same in groups.items():
            index = [copies[0] for copies in same.values()]
            small = progress and backend in ("c", "rod")
            batch = 2 * usable_cores() if small else len(index)
            for start in range(0, len(index), max(batch, 1)):
                part = index[start : start + batch]
                poses = run_dc(arm, np.stack([jobs[i][0] for i in part]), k, backend)
                bar.update(sum(keep(first, p) for first, p in zip(part, poses, strict=True)))
    return out


def _rollout_padded(arm, jobs, index: list[int], backend, progress, keep, bar, chunk) -> None:
    """`rollout_grouped`'s padded calls: jobs `index` (one per distinct job) longest first, in
    chunks of at most `chunk` of equal size, each padded to its longest (`hold_last`)."""
    index = sorted(index, key=lambda i: -len(jobs[i][0]))
    n_calls = -(-len(index) // chunk)
    size = -(-len(index) // max(n_calls, 1))
    period_s = 1.0 / CONTROL_HZ
    for start in range(0, len(index), max(size, 1)):
        part = index[start : start + size]
        commands = [np.asarray(jobs[i][0], np.float64) for i in part]
        program = hold_last(commands)
        _announce(
            progress,
            len(part),
            sum(len(c) for c in commands) * period_s,
            program.shape[1] * period_s,
        )
        poses = arm.rollout(program, backend=backend)
        for i, p in zip(part, poses, strict=True):
            cmd, k = jobs[i]
            bar.update(keep(i, every_kth(p[: len(cmd)], int(k))))


def choose_stretch_k(
    arm_s, arm_c, program_bar: np.ndarray, candidates, backend: str = "c", progress: bool = True
) -> tuple[int, dict[int, float]]:
    """The stretch factor with the lowest mean X_err on a program (never a test program).

    Args:
      arm_s, arm_c: the D_s and D_c arms.
      program_bar: [T, 3] D_s commands (bar), e.g. `mjx_arm.programs.validation_program`.
      candidates: stretch factors k >= 1 to try.
      backend: simulator of the rollouts, "c" or "mjx", or "rod" with `mjx_arm.RodArm`s: then
        the candidates run through `rollout_grouped` (on a GPU one padded batch, which costs
        about the longest candidate's time instead of their sum).
      progress: show a progress bar over the candidates.

    Returns:
      (k, {candidate k: mean X_err (cm) of the program held k periods per step}).
    """
    target = arm_s.rollout(program_bar, backend=backend)
    errors = {}
    if backend == "rod":
        ks = list(dict.fromkeys(int(k) for k in candidates))
        label = "stretch k on the validation program" if progress else None
        jobs = [(stretch(program_bar, k), k) for k in ks]
        for k, poses in zip(ks, rollout_grouped(arm_c, jobs, backend, label), strict=True):
            errors[k] = float(metrics.position_error_cm(poses, target).mean())
        return min(errors, key=errors.get), errors
    bar = tqdm(
        candidates, desc="stretch k on the validation program", unit="k", disable=not progress
    )
    for k in bar:
        poses = run_dc(arm_c, stretch(program_bar, k), k, backend)
        errors[int(k)] = float(metrics.position_error_cm(poses, target).mean())
    return min(errors, key=errors.get), errors
