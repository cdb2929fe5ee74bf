"""Held commands: the stretch baseline and the D_c rollouts every method's commands go through.

The constrained arm is slower than the source arm, so a D_s program is tracked in D_c by holding
each source step's command for k control periods (k >= 1, the stretch factor; every translator's
output has the same form, one command per source step held k periods). A D_c program is then
[T * k, 3] commands (bar) for T source steps, and its pose at the end of each source step's k
periods, every k-th pose, is what is compared with the D_s target [T, 6].
"""

from __future__ import annotations

import hashlib

import numpy as np
from tqdm import tqdm

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


def rollout_grouped(
    arm, jobs: list[tuple[np.ndarray, int]], backend: str, progress: str | None = None
) -> list[np.ndarray]:
    """Poses of many (commands [T * k, 3] bar, k) jobs, every k-th pose ([T, 6] each).

    Jobs of the same command length and k run as batched rollouts (MuJoCo C: one thread per
    trajectory; MJX: one vmapped call per group), so a many-core machine runs them side by side.
    With `progress` (the bar's label) a progress bar counts trajectories; on MuJoCo C each group
    then runs in batches of two trajectories per core, so the bar moves every few seconds (the
    main job's 245 60 s trajectories at k = 10 take about 1.5 s each on 2 cores) and the poses
    are the same, as every trajectory is simulated on its own. MJX keeps one call per group
    (another batch size would compile again).

    Jobs with equal commands and k are simulated once and share the poses (copies): the
    simulator is deterministic and every trajectory runs on its own, so a deterministic method's
    repetitions (the periodicity test) and its seeds cost one rollout.
    """
    groups: dict[tuple, dict[bytes, list[int]]] = {}
    for i, (cmd, k) in enumerate(jobs):
        cmd = np.ascontiguousarray(cmd, dtype=np.float64)
        same = groups.setdefault((cmd.shape, int(k)), {})
        same.setdefault(hashlib.sha256(cmd.tobytes()).digest(), []).append(i)
    out: list[np.ndarray | None] = [None] * len(jobs)
    with tqdm(total=len(jobs), desc=progress, unit="traj", disable=not progress) as bar:
        for (_, k), same in groups.items():
            index = [copies[0] for copies in same.values()]
            copies_of = {copies[0]: copies for copies in same.values()}
            batch = 2 * usable_cores() if progress and backend == "c" else len(index)
            for start in range(0, len(index), max(batch, 1)):
                part = index[start : start + batch]
                poses = run_dc(arm, np.stack([jobs[i][0] for i in part]), k, backend)
                for first, p in zip(part, poses, strict=True):
                    for n, i in enumerate(copies_of[first]):
                        out[i] = p if n == 0 else p.copy()
                bar.update(sum(len(copies_of[first]) for first in part))
    return out


def choose_stretch_k(
    arm_s, arm_c, program_bar: np.ndarray, candidates, backend: str = "c", progress: bool = True
) -> tuple[int, dict[int, float]]:
    """The stretch factor with the lowest mean X_err on a program (never a test program).

    Args:
      arm_s, arm_c: the D_s and D_c arms.
      program_bar: [T, 3] D_s commands (bar), e.g. `mjx_arm.programs.validation_program`.
      candidates: stretch factors k >= 1 to try.
      backend: simulator of the rollouts, "c" or "mjx".
      progress: show a progress bar over the candidates.

    Returns:
      (k, {candidate k: mean X_err (cm) of the program held k periods per step}).
    """
    target = arm_s.rollout(program_bar, backend=backend)
    errors = {}
    bar = tqdm(
        candidates, desc="stretch k on the validation program", unit="k", disable=not progress
    )
    for k in bar:
        poses = run_dc(arm_c, stretch(program_bar, k), k, backend)
        errors[int(k)] = float(metrics.position_error_cm(poses, target).mean())
    return min(errors, key=errors.get), errors
