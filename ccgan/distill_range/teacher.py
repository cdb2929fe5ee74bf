"""The teacher over media: the MJX tracker's commands for programs in many media at once.

Every training medium gets its own programs: `DistillConfig.n_train` (and `n_train_full`,
`n_train_babble`) training and `n_val` (...) held-out programs per medium, from streams of their
own ("range_<split>", never the per-pair distillation's). They are simulated in D_s for their
targets, then planned by `tracking.mpc_mjx.track(..., media=(family, theta))`: each program in
its medium's model (`mjx_arm.identify_family.DomainFamily` of the D_c arm over viscosity and
stiffness, theta = log(viscosity scale, s)), every medium of one k in one call (k is one per
call), in shards of `teacher_shard` programs. The commands are cached in `teacher.npz` under a
key of everything that made them, shard by shard, so a stopped run (SIGTERM, `max_wall_s`)
plans only what is missing.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from ccgan.distill.config import DistillConfig
from ccgan.distill.teacher import (
    _programs,
    _read_cache,
    _splits,
    cache_arrays,
    key_differences,
    planner_config,
    read_cache_key,
)
from ccgan.distill_range.media import Medium
from mjx_arm.atomic import write_atomically
from mjx_arm.identify_family import DomainFamily, resolved_viscosity_scale
from mjx_arm.media import viscosity_scale_of
from tracking import mpc_mjx

#: The Domain fields the teacher's media differ in (the family's parameters, in this order).
FIT = ("viscosity_scale", "stiffness_scale")


def range_programs(config: DistillConfig, n_media: int) -> tuple[np.ndarray, ...]:
    """Every program of the teacher, split by split (`ccgan.distill.teacher._splits`' order):
    (programs [N, T, 3] bar float32, medium [N] index of each one's medium, is_val [N] bool).
    Medium m gets programs m n .. (m + 1) n - 1 of each split's stream (n per medium)."""
    programs, medium, is_val = [], [], []
    for split, n, family in _splits(config):
        if n == 0:
            continue
        programs.append(_programs(config, family, f"range_{split}", n * n_media))
        medium.append(np.repeat(np.arange(n_media), n))
        is_val.append(np.full(n * n_media, split.startswith("val")))
    return np.concatenate(programs), np.concatenate(medium), np.concatenate(is_val)


def range_teacher_key(config: DistillConfig, media: list[Medium], arm_c) -> str:
    """The key (JSON) of a teacher cache over media: `DistillConfig.teacher_key`'s settings,
    the media (r, s, k), the D_c arm's model hash and domain, each split's program family and
    count per medium (they set which programs a medium gets), the planner's settings."""
    key = config.teacher_key() | {
        "media": [[m.drag_ratio, m.stiffness_scale, m.k] for m in media],
        "model": arm_c.model_hash,
        "domain": dataclasses.asdict(arm_c.domain),
        "programs": {split: [family, n] for split, n, family in _splits(config)},
        "planner": dataclasses.asdict(planner_config(config)),
        "teacher_shard": config.teacher_shard,
    }
    return json.dumps(key, sort_keys=True)


def media_theta(arm_c, media: list[Medium], medium: np.ndarray) -> np.ndarray:
    """The family's log-parameters [N, 2] (log viscosity scale, log s) of each program's
    medium; `medium` [N] indexes `media`."""
    constrained = resolved_viscosity_scale(arm_c)
    per_medium = np.log(
        [[viscosity_scale_of(m.drag_ratio, constrained), m.stiffness_scale] for m in media]
    )
    return per_medium[medium]


def read_part(path: Path, key: str, log=print) -> dict[str, np.ndarray]:
    """The arrays of another run's teacher cache `path` when it was planned under `key`; else
    {} and a line saying why (missing, unreadable, or the differing fields). Unlike this run's
    own cache, a part is never moved or rewritten: it is another run's file."""
    try:
        stored = read_cache_key(path)
    except ValueError as err:
        log(f"teacher: {err}; not used")
        return {}
    if stored != key:
        log(f"teacher: {path} was planned otherwise ({key_differences(stored, key)}); not used")
        return {}
    return cache_arrays(path)


def _shards(indices: np.ndarray, size: int) -> list[np.ndarray]:
    """`indices` cut into pieces of `size` (0: one piece)."""
    if size == 0 or len(indices) <= size:
        return [indices]
    return [indices[i : i + size] for i in range(0, len(indices), size)]


def teacher_over_media(
    config: DistillConfig,
    media: list[Medium],
    arm_s,
    arm_c,
    cache: Path | None,
    log=print,
    progress: bool = False,
    should_stop=None,
    only_ks: tuple[int, ...] = (),
    teacher_from: tuple[Path, ...] = (),
) -> dict[str, np.ndarray]:
    """Programs, D_s targets and the teacher's commands, every program in its medium.

    The MJX tracker is bound by its steps' latency, so processes planning different k can share
    one GPU (two per-pair teachers at once on one H200 took 197 and 200 s,
    `studies/results/h200/rod_source/`; what that saves against one process is not measured).
    `only_ks` plans only the media of
    those k (a part: their commands are the only ones filled in); `teacher_from` reads the
    parts' caches (other runs' teacher.npz, each planned under this run's key), whose entries
    join this run's cache before anything is planned.

    Args:
      config: the settings (`teacher_backend` must be "mjx": only the MJX tracker plans many
        media in one program).
      media: the training media, each with its k.
      arm_s, arm_c: the D_s arm (targets) and the D_c arm of the same MJCF (the family's base;
        the teacher plans in its `planning_copy(config.teacher_substeps)`).
      cache: the teacher.npz to read and write (None: none).
      should_stop: called between chunks; True stops the tracker (`TrackingStopped`), its
        progress kept beside the cache.
      only_ks: plan only the media of these k (empty: every k).
      teacher_from: other caches of this key to take planned shards from (one of another key,
        or unreadable, is reported and skipped).

    Returns:
      {"p" [N, T, 3] bar, "x" [N, T, 6] (m, unit d3), "c" [N, T, 3] bar (the teacher's
      command per source step, held k periods), "medium" [N] int, "is_val" [N] bool}.

    Raises:
      ValueError: `config.teacher_backend` is not "mjx", or `only_ks` holds a k no medium has.
      TrackingStopped: `should_stop` said so.
    """
    if config.teacher_backend != "mjx":
        raise ValueError(f"the teacher over media plans in MJX, got {config.teacher_backend!r}")
    programs, medium, is_val = range_programs(config, len(media))
    key = range_teacher_key(config, media, arm_c)
    ks = sorted({m.k for m in media})
    if set(only_ks) - set(ks):
        raise ValueError(f"only_ks {sorted(only_ks)}: the media's k are {ks}")
    store = {} if cache is None else _read_cache(cache, key, log)
    joined = []
    for other in teacher_from:
        found = read_part(Path(other), key, log)
        new = sorted(name for name in found if name not in store)
        store.update({name: found[name] for name in new})
        joined += [f"{name} from {other}" for name in new if name.startswith("c_k")]
    if joined:
        log(f"teacher: {', '.join(joined)}")
        if cache is not None:
            cache.parent.mkdir(parents=True, exist_ok=True)
            write_atomically(cache, lambda f: np.savez_compressed(f, key=key, **store))
    if "x" in store:
        targets = store["x"]
    else:
        targets = arm_s.rollout(programs, backend="c").astype(np.float32)
        store.update(x=targets)
    plan_arm = arm_c.planning_copy(config.teacher_substeps)
    family = DomainFamily.of(plan_arm, fit=FIT)
    theta = media_theta(arm_c, media, medium)
    mpc_cfg = planner_config(config)
    commands = np.zeros_like(programs)
    planned_before = sorted(name for name in store if name.startswith("c_k"))
    if planned_before:
        log(f"teacher: {', '.join(planned_before)} read from {cache}")
    for k in ks:
        if only_ks and k not in only_ks:
            continue
        of_k = np.flatnonzero(np.isin(medium, [i for i, m in enumerate(media) if m.k == k]))
        for piece, shard in enumerate(_shards(of_k, config.teacher_shard)):
            name = f"c_k{k}_{piece}"
            if name not in store:
                t0 = time.perf_counter()
                partial = None if cache is None else cache.with_name(f"teacher_partial_{name}.npz")
                planned, info = mpc_mjx.track(
                    plan_arm, targets[shard], k, programs[shard], mpc_cfg, progress=progress,
                    resume=partial, should_stop=should_stop, log=log, media=(family, theta[shard]),
                )  # fmt: skip
                if not info["healthy"].all():
                    log(f"teacher: {int((~info['healthy']).sum())} programs at k = {k} diverged")
                store[name] = planned[:, k - 1 :: k].astype(np.float32)
                n_media = len({int(i) for i in medium[shard]})
                log(
                    f"teacher (mjx): {len(shard)} programs of {config.duration_s} s in {n_media}"
                    f" media at k = {k} ({time.perf_counter() - t0:.0f} s)"
                )
                if cache is not None:
                    cache.parent.mkdir(parents=True, exist_ok=True)
                    write_atomically(cache, lambda f: np.savez_compressed(f, key=key, **store))
            commands[shard] = store[name]
    return {"p": programs, "x": targets, "c": commands, "medium": medium, "is_val": is_val}
