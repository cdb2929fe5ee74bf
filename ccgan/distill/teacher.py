"""The teacher: the receding-horizon tracker's D_c commands for the distillation's programs.

The programs (`_splits`: shape-like at its scale and at full scale, and babbling, each a
training and a held-out split) are simulated in D_s for their targets, then planned by
`tracking.mpc` (MuJoCo C) or `tracking.mpc_mjx` (MJX) in the D_c arm. The commands are cached
(`teacher.npz`) under a key (`teacher_cache_key`) that records everything that made them: the
settings, k, the arm's model hash, its domain (name and values), the program families and the
planner's settings. A cache under another key is never read, and never silently overwritten:
it is moved aside (`set_aside`) before the teacher plans again.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import threading
import time
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

import mjx_arm  # (before jax: sets the XLA CPU flag)
from ccgan.checkpoint import differences
from ccgan.distill.config import DistillConfig
from ccgan.translator import load_translator
from mjx_arm.atomic import link_or_copy, write_atomically
from mjx_arm.babble import BabbleConfig
from mjx_arm.programs import babble_programs, shape_like_programs
from mjx_arm.rollout_c import SimulationDivergedError
from tracking import mpc, mpc_mjx
from tracking.metrics import position_error_cm


def _next_shard(pending: list, size: int) -> list:
    """Takes the next shard off `pending` [(split, programs [N, T, 3])]: `size` programs,
    across splits in order (0: the first split's whole rest, one split per shard)."""
    if size == 0:
        return [pending.pop(0)]
    shard = []
    while pending and size > 0:
        split, programs = pending[0]
        shard.append((split, programs[:size]))
        if len(programs) <= size:
            pending.pop(0)
        else:
            pending[0] = (split, programs[size:])
        size -= len(shard[-1][1])
    return shard


def _stop_check(config: DistillConfig, t0: float, stop: threading.Event | None):
    """`should_stop()` for the teacher: True once `config.max_wall_s` (0: no limit) seconds
    have passed since t0 (`time.perf_counter()`) or `stop` is set."""

    def should_stop() -> bool:
        late = config.max_wall_s > 0 and time.perf_counter() - t0 > config.max_wall_s
        return late or (stop is not None and stop.is_set())

    return should_stop


def _programs(config: DistillConfig, family: str, split: str, n: int) -> np.ndarray:
    """The first n programs [n, T, 3] (bar) of a split; program i is the same whatever n is."""
    if family == "babbling":
        spec = BabbleConfig(seed=config.seed, duration_s=config.duration_s)
        return babble_programs(spec, np.arange(n), domain="distill", split=split)
    full_scale = family == "shape_like_full"
    return shape_like_programs(
        n, config.duration_s, seed=config.seed, split=f"distill/{split}", full_scale=full_scale
    )


def _splits(config: DistillConfig) -> tuple:
    """(split, programs, family) of the teacher's data, in the order they are stored: the
    training splits, then the held-out ones; the families are shape-like at its scale, at full
    scale, and babbling."""
    return (
        ("train", config.n_train, "shape_like"),
        ("train_full", config.n_train_full, "shape_like_full"),
        ("train_babble", config.n_train_babble, "babbling"),
        ("val", config.n_val, "shape_like"),
        ("val_full", config.n_val_full, "shape_like_full"),
        ("val_babble", config.n_val_babble, "babbling"),
    )


def held_out_programs(config: DistillConfig) -> np.ndarray:
    """The held-out programs [V, T, 3] (bar) that pick a run's iterate, as `teacher_data`'s
    "p_val" holds them; rebuilt from the settings alone, without the teacher (studies score
    other commands on them)."""
    return np.concatenate(
        [
            _programs(config, family, split, n)
            for split, n, family in _splits(config)
            if split.startswith("val") and n > 0
        ]
    )


def source_poses(config: DistillConfig, arm_s, programs: np.ndarray) -> np.ndarray:
    """The D_s poses [N, T, 6] (m, unit d3) of programs [N, T, 3] (bar) that the teacher tracks:
    from the chain's D_s arm `arm_s` in MuJoCo C, or from the reference rod in D_s (float64)
    with `config.source_simulator` "rod"."""
    if config.source_simulator == "rod":
        return mjx_arm.load_rod("source").rollout(programs)
    return arm_s.rollout(programs, backend="c")


def corrected_targets(
    config: DistillConfig, arm_c, programs: np.ndarray, targets: np.ndarray, k: int, log=print
) -> np.ndarray:
    """The teacher's targets [N, T, 6] corrected by the target's own rollouts (one step of
    iterative learning control, `DistillConfig.correction_translator`): x_s - (rod(u0) -
    arm(u0)) at every k-th period, u0 the correction translator's commands for programs
    [N, T, 3] (bar) and their D_s poses `targets` [N, T, 6] (m, unit d3), the rod in
    `config.correction_domain` and `arm_c` the arm the teacher plans in (MuJoCo C, its own
    timestep).

    Raises:
      ValueError: the correction translator holds another k than the teacher's.
    """
    translator = load_translator(config.correction_translator)
    if translator.k != k:
        raise ValueError(
            f"correction_translator {config.correction_translator} holds k = {translator.k},"
            f" the teacher k = {k}: its rollouts would not be the ones the teacher corrects"
        )
    t0 = time.perf_counter()
    commands = np.stack(
        [translator.translate(p, x)[0] for p, x in zip(programs, targets, strict=True)]
    )
    t_translate = time.perf_counter() - t0
    # The arm's MuJoCo C rollouts run on the host's cores while the rod runs (on the GPU where
    # there is one): mujoco.rollout releases the GIL, so the two take the longer one's time,
    # not their sum (256 programs of 1,200 s on one H200: the rod 134 s, the arm about 300 s;
    # studies/results/h200/rod_correction/rod_teacher.log).
    with ThreadPoolExecutor(max_workers=1) as pool:
        arm_future = pool.submit(arm_c.rollout, commands, backend="c")
        rod = mjx_arm.load_rod(config.correction_domain, dtype=config.correction_dtype)
        try:
            on_target = rod.rollout(commands)[:, k - 1 :: k]
        except SimulationDivergedError as err:
            if config.correction_dtype == "float64":
                raise
            log(f"correction: {err}; all of them again in float64")
            exact = mjx_arm.load_rod(config.correction_domain, dtype="float64")
            on_target = exact.rollout(commands)[:, k - 1 :: k]
        t_rod = time.perf_counter() - t0 - t_translate
        in_arm = arm_future.result()[:, k - 1 :: k]
    difference = on_target - in_arm
    log(
        f"correction: {len(programs)} programs in the rod ({config.correction_domain},"
        f" {config.correction_dtype}) and the arm, tip RMS between them"
        f" {100 * np.sqrt(np.mean(np.sum(difference[..., :3] ** 2, -1))):.3f} cm"
        f" (translation {t_translate:.0f} s, then the rod {t_rod:.0f} s with the arm beside it;"
        f" {time.perf_counter() - t0:.0f} s in all)"
    )
    return targets - difference


def correction_path(cache: Path) -> Path:
    """Where the corrected targets are kept, beside the teacher cache: the target's rollouts
    take minutes (546 s for 256 programs of 60 s at k = 20 on one H200, the rod's 6 million
    sequential steps), so a run stopped while the teacher plans does not repeat them."""
    return cache.with_name(cache.stem + "_correction.npz")


def cached_corrected_targets(
    config: DistillConfig,
    arm_c,
    programs: np.ndarray,
    targets: np.ndarray,
    k: int,
    key: str,
    cache: Path | None,
    log=print,
) -> np.ndarray:
    """`corrected_targets`, read from `correction_path(cache)` when it holds this shard's
    (the same teacher key and programs: entries are named by the programs' sha256), else
    computed and added to it. An unreadable file, or one of another key, is replaced."""
    if cache is None:
        return corrected_targets(config, arm_c, programs, targets, k, log)
    path = correction_path(cache)
    # Entries are named by the programs alone: their D_s poses follow from them and the key
    # (which names the source simulator), but not to the bit across machines (the rod's float64
    # D_s paths of one shard differed by 2e-14 m between two H200 runs, so an entry named by
    # them was never found again and the 300 s of rollouts were repeated).
    digest = hashlib.sha256(np.ascontiguousarray(programs, np.float64).tobytes()).hexdigest()[:32]
    entries = {}
    try:
        if read_cache_key(path) == key:
            entries = cache_arrays(path)
    except ValueError:  # none yet, or unreadable: replaced
        pass
    if f"t_{digest}" in entries:
        log(f"correction: {len(programs)} programs read from {path}")
        return entries[f"t_{digest}"]
    tracked = corrected_targets(config, arm_c, programs, targets, k, log)
    entries[f"t_{digest}"] = tracked
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(path, lambda f: np.savez_compressed(f, key=key, **entries))
    return tracked


def planner_config(config: DistillConfig) -> mpc.MpcConfig:
    """The tracker's settings the teacher plans with (the rest at `tracking.mpc`'s defaults)."""
    return mpc.MpcConfig(horizon_steps=config.horizon_steps, iterations=config.iterations)


def teacher_cache_key(config: DistillConfig, k: int, arm_c) -> str:
    """The key a teacher cache (`teacher.npz`) is stored under (JSON): everything its commands
    depend on. `DistillConfig.teacher_key`'s settings, k, the D_c arm's model hash ("model")
    and domain (its name and values: the aged arm's commands are not the constrained arm's), the
    family of each split's programs and every setting of the planner. Not the program counts:
    the cache grows."""
    key = config.teacher_key() | {
        "k": k,
        "model": arm_c.model_hash,
        "domain": dataclasses.asdict(arm_c.domain),
        "programs": {split: family for split, _, family in _splits(config)},
        "planner": dataclasses.asdict(planner_config(config)),
    }
    return json.dumps(key, sort_keys=True)


def key_differences(stored: str, key: str) -> str:
    """The fields where a cache's stored key differs from `key`, as one line ("domain.name:
    stored 'aged', this run 'constrained'; ..."); both are `teacher_cache_key` JSON texts."""
    try:
        stored_fields = json.loads(stored)
    except ValueError:
        stored_fields = stored
    return "; ".join(differences(stored_fields, json.loads(key)))


def read_cache_key(path: Path) -> str:
    """The key stored in the teacher cache `path`, after checking every array's CRC (a cache
    cut short by a full disk or a lost transfer fails here, before any planning or training).

    Raises:
      ValueError: one line naming `path` and what is wrong: missing, not a (complete) npz, a
        damaged array, or no key.
    """
    if not path.is_file():
        raise ValueError(f"{path} is not a teacher cache (no such file)")
    try:
        with zipfile.ZipFile(path) as archive:
            damaged = archive.testzip()
        if damaged is not None:
            raise ValueError(f"its array {damaged} is damaged")
        with np.load(path) as f:
            return str(f["key"])
    except KeyError:
        raise ValueError(f"{path} is not a teacher cache (it holds no key)") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise ValueError(
            f"{path} is not a readable teacher cache (truncated or corrupt: {err})"
        ) from None


def set_aside(cache: Path, stored: str, log=print) -> Path:
    """Renames a cache planned under another key (`stored`) so that this run's plans do not
    overwrite it: `teacher.npz` -> `teacher.<its domain>-<8 hex of its key>.npz`, beside it. The
    MJX teacher's progress (`teacher_partial.npz`) of that run goes with it. Returns the new
    path."""
    try:
        domain = json.loads(stored).get("domain", {}).get("name", "other")
    except (ValueError, AttributeError):
        domain = "other"
    tag = f"{domain}-{hashlib.sha256(stored.encode()).hexdigest()[:8]}"
    aside = cache.with_name(f"{cache.stem}.{tag}{cache.suffix}")
    cache.replace(aside)
    partial = partial_path(cache)
    if partial.exists():
        partial.replace(partial.with_name(f"{partial.stem}.{tag}{partial.suffix}"))
    log(f"{cache}: moved to {aside}")
    return aside


def partial_path(cache: Path) -> Path:
    """Where the MJX teacher keeps a stopped shard's progress, beside the cache."""
    return cache.with_name(cache.stem + "_partial.npz")


def adopt_teacher(source: Path, cache: Path, key: str, log=print) -> bool:
    """Copies the teacher cache `source` (another run's `teacher.npz`, e.g. a chain stage that
    only planned) to `cache`, unless `cache` holds this run's own already (perhaps grown); an
    unreadable `cache` is replaced, one of another key is set aside (`set_aside`). Returns
    whether it copied.

    Raises:
      ValueError: (one line) `source` is missing, truncated or corrupt (`read_cache_key`), or
        was planned under another key: the message names the differing fields. Using it would
        plan everything again, silently, or teach another arm's commands.
    """
    stored = read_cache_key(source)
    if stored != key:
        raise ValueError(
            f"{source} was planned with other settings: {key_differences(stored, key)}"
        )
    if cache.exists():
        try:
            own = read_cache_key(cache)
        except ValueError:
            own = None  # unreadable: holds nothing to keep
        if own == key:
            return False
        if own is not None:
            set_aside(cache, own, log)
    link_or_copy(source, cache)
    return True


def _read_cache(cache: Path, key: str, log) -> dict[str, np.ndarray]:
    """The arrays of the cache at `cache` when it was planned under `key`; else {} (none, or
    unreadable: planned again and overwritten; another key's: set aside, then planned again)."""
    if not cache.exists():
        return {}
    try:
        stored = read_cache_key(cache)
    except ValueError as err:
        log(f"{err}; recomputing")
        return {}
    if stored != key:
        log(f"{cache} was made with other settings ({key_differences(stored, key)}); recomputing")
        set_aside(cache, stored, log)
        return {}
    return cache_arrays(cache)


def cache_arrays(path: Path) -> dict[str, np.ndarray]:
    """Every array of a cache file but its key (read its key first: `read_cache_key`)."""
    with np.load(path) as f:
        return {name: f[name] for name in f.files if name != "key"}


def teacher_data(
    config: DistillConfig,
    arm_s,
    arm_c,
    k: int,
    cache: Path | None,
    log=print,
    progress=False,
    should_stop=None,
):
    """Programs, D_s targets and teacher commands of the train and val splits.

    Program i of a split is the same whatever the split's size (`shape_like_programs`), and the
    teacher plans each program on its own, so the cache grows: a run asking for more programs
    than it holds computes only the missing ones; one asking for fewer reads a prefix.

    With the MJX teacher, `should_stop()` (checked between chunks of source steps) stops a
    shard part-way: its simulator states go to `teacher_partial.npz` beside the cache, and the
    next run goes on from there (`tracking.mpc_mjx.TrackingStopped` is raised).

    Returns:
      dict of float32 arrays, each split followed by its full-amplitude and babbling parts
      ("train" has n_train + n_train_full + n_train_babble programs, "val" the same of val):
      "p_train" [N, T, 3] and "p_val" (bar), "x_train" [N, T, 6] and
      "x_val" (m, unit d3), "c_train" [N, T, 3] and "c_val" (teacher commands per source step,
      bar), "t_train" [N, T, 6] and "t_val" (the poses the teacher tracked: x, or with
      `DistillConfig.correction_translator` x corrected by the target's rollouts), plus
      "teacher_val_x_err_cm" [n_val] (the teacher's own held-out X_err against t_val).
    """
    key = teacher_cache_key(config, k, arm_c)
    splits = _splits(config)
    store = {} if cache is None else _read_cache(cache, key, log)
    mpc_cfg = planner_config(config)
    track, resumable = mpc.track, {}
    if config.teacher_backend == "mjx":
        partial = None if cache is None else partial_path(cache)
        track, resumable = mpc_mjx.track, {"resume": partial, "should_stop": should_stop}
    plan_arm = arm_c.planning_copy(config.teacher_substeps)
    pending = []  # (split, its programs not planned yet), in the splits' order
    for split, n, family in splits:
        have = len(store.get(f"p_{split}", ()))
        if n == 0:
            continue
        if have >= n:
            log(f"teacher: {n} {split} programs read from {cache}")
            continue
        pending.append((split, _programs(config, family, split, n)[have:]))
    total, planned = sum(len(programs) for _, programs in pending), 0
    while pending:
        shard = _next_shard(pending, config.teacher_shard)
        t0 = time.perf_counter()
        programs = np.concatenate([piece for _, piece in shard])
        targets = source_poses(config, arm_s, programs)
        tracked = targets
        if config.correction_translator:
            tracked = cached_corrected_targets(config, arm_c, programs, targets, k, key, cache, log)
        commands, _ = track(plan_arm, tracked, k, programs, mpc_cfg, progress=progress, **resumable)
        new = {"p": programs, "x": targets, "c": commands[:, k - 1 :: k]}
        if config.correction_translator:
            new["t"] = tracked
        first = 0
        for split, piece in shard:
            for name, value in new.items():
                value = value[first : first + len(piece)].astype(np.float32)
                old = store.get(f"{name}_{split}", np.zeros((0,) + value.shape[1:], np.float32))
                store[f"{name}_{split}"] = np.concatenate([old, value])
            first += len(piece)
        planned += len(programs)
        what = " + ".join(f"{len(piece)} new {split} programs" for split, piece in shard)
        log(
            f"teacher ({config.teacher_backend}): {what} of {config.duration_s} s"
            f" ({time.perf_counter() - t0:.0f} s), {planned} of {total}"
        )
        if cache is not None:  # kept after each shard: a run stopped later plans the rest
            cache.parent.mkdir(parents=True, exist_ok=True)
            write_atomically(cache, lambda f: np.savez_compressed(f, key=key, **store))
    data = {}
    parts = ("p", "x", "c", "t") if config.correction_translator else ("p", "x", "c")
    for part in parts:
        for joined in ("train", "val"):
            pieces = [
                store[f"{part}_{split}"][:n]
                for split, n, _ in splits
                if split.split("_")[0] == joined and n > 0
            ]
            data[f"{part}_{joined}"] = np.concatenate(pieces)
    if not config.correction_translator:
        data["t_train"], data["t_val"] = data["x_train"], data["x_val"]
    score_arm = arm_c.planning_copy(config.score_substeps)
    poses = score_arm.rollout(np.repeat(data["c_val"], k, axis=1), backend="c")[:, k - 1 :: k]
    data["teacher_val_x_err_cm"] = position_error_cm(poses, data["t_val"]).mean(-1)
    return data
