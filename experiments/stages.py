"""A chain of commands run as stages: each is skipped when its outputs match their inputs.

A stage is one command of the project (`python -m mjx_arm.babble ...`, `python -m ccgan.train
...`) that writes one folder. Its key is a hash of the command, of the files it names outside the
run (the arm's MJCF) and of the outputs of the stages it reads. A finished stage's folder holds
`stage.json`: the key, the sha256 of every file it wrote, the command and its wall time. A later
run skips the stage when the key is the same and every file still has its hash; it refuses a
folder made from other inputs (a changed config, a rerun upstream stage) unless told to redo it,
and then keeps the old folder beside the new one.

A stage runs in `<stage>.partial/` and is renamed into place only when its command succeeds, so
a folder without `.partial` is always whole. A command that stops part-way (a device call's time
limit) leaves `.partial/` with the key it was started with; the next run with the same key
continues in it (`ccgan.train` resumes from its checkpoints), and one with another key refuses
it. Wall times add up over the attempts.

This module runs stages (one at a time, or several at once with `--jobs`); `experiments.chain`
holds the stages, their keys and checks, `experiments.attempt` one command's run. Their names
are importable from here too.
"""

from __future__ import annotations

import json
import os
import subprocess
import time

from experiments.attempt import (
    STOP_GRACE_S,
    Attempt,
    _attempts_to_continue,
    _move_aside,
    die_with_parent,
    jax_device,
    machine,
    stop_all,
)
from experiments.chain import (
    ATTEMPTS_SUFFIX,
    MANIFEST,
    PARTIAL_SUFFIX,
    PLACEHOLDER,
    STAGE_LOG,
    Chain,
    DeadlineReached,
    Stage,
    StageError,
    check_before_running,
    digest,
    file_hashes,
    has_manifest,
    load_config,
    shown_command,
    upstream,
)
from mjx_arm.machine import usable_cores
from mjx_arm.rod_arm import HOST_DEVICES_FLAG

__all__ = [
    "ATTEMPTS_SUFFIX",
    "MANIFEST",
    "PARTIAL_SUFFIX",
    "PLACEHOLDER",
    "STAGE_LOG",
    "STOP_GRACE_S",
    "Attempt",
    "Chain",
    "DeadlineReached",
    "Stage",
    "StageError",
    "check_before_running",
    "die_with_parent",
    "digest",
    "file_hashes",
    "has_manifest",
    "load_config",
    "machine",
    "run_stage",
    "run_stages",
    "shown_command",
    "stop_all",
    "upstream",
]

# Environment variables by which a caller already chose how JAX takes GPU memory.
GPU_MEMORY_POLICY = (
    "XLA_PYTHON_CLIENT_PREALLOCATE",
    "XLA_PYTHON_CLIENT_MEM_FRACTION",
    "XLA_PYTHON_CLIENT_ALLOCATOR",
)


def _begin(chain: Chain, name: str, redo: bool, log) -> tuple[dict, list[dict]] | None:
    """Checks a stage before its command runs: None when it is done (skipped), else its key and
    the attempts it continues.

    Raises:
      StageError: its inputs are not finished, or its folder was made from other inputs (without
        `redo`).
    """
    stage = chain.stages[name]
    try:
        status = chain.status(name)
    except StageError:
        if not redo:
            raise
        status = "broken"  # changed files or an unreadable manifest: rerun, old folder kept aside
    if status == "done" and not redo:
        log(f"[{name}] done: skipped (outputs match their inputs)")
        return None
    if status == "stale" and not redo:
        raise StageError(
            f"{chain.folder(name)} was made from other inputs (config or upstream outputs "
            f"changed): give --redo {name} to rerun it (the old folder is kept beside it)"
        )
    key = chain.key(name)
    attempts = _attempts_to_continue(chain, name, key, redo, log)
    chain.partial(name).mkdir(parents=True, exist_ok=True)
    log(f"[{name}] {stage.about}\n[{name}] $ {shown_command(chain, name)}")
    return key, attempts


def _finish(chain: Chain, name: str, key: dict, attempts: list[dict], log) -> dict:
    """Writes the manifest of a stage whose command succeeded and moves its folder into place;
    a log kept beside the partial folder moves in with it."""
    partial = chain.partial(name)
    log_path = chain.log_path(name)
    if log_path.exists():
        log_path.rename(partial / STAGE_LOG)
    manifest = {
        "stage": name,
        "about": chain.stages[name].about,
        "key": key,
        "command": shown_command(chain, name),
        "machine": machine(),
        "attempts": attempts,
        "wall_s": round(sum(a["wall_s"] or 0.0 for a in attempts), 1),
        "files": file_hashes(partial),
    }
    (partial / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
    target = chain.folder(name)
    if target.exists():
        log(f"[{name}] the earlier folder is kept as {_move_aside(target).name}")
    partial.rename(target)
    chain.attempts_path(name).unlink()
    log(f"[{name}] finished in {manifest['wall_s']:.0f} s")
    return manifest


def _failed(chain: Chain, name: str, rc: int) -> StageError:
    return StageError(
        f"stage {name} failed (exit status {rc}); {chain.partial(name)} is kept, and a rerun "
        "with the same config continues in it"
    )


def run_stage(
    chain: Chain, name: str, redo: bool = False, deadline_s: float | None = None, log=print
) -> dict:
    """Runs one stage unless it is done, its output shown here; returns its manifest.

    Args:
      deadline_s: seconds the command may run before it is stopped (SIGTERM, then SIGKILL after
        `STOP_GRACE_S`) and `DeadlineReached` raised; None: no limit.

    Raises:
      StageError: its inputs are not finished, its folder was made from other inputs (without
        `redo`), or its command failed (the partial folder stays for a resume).
    """
    begun = _begin(chain, name, redo, log)
    if begun is None:
        return chain.manifest(name)
    attempt = Attempt(chain, name, *begun)
    try:
        attempt.process.wait(timeout=deadline_s)
    except subprocess.TimeoutExpired:
        attempt.stop()
        raise DeadlineReached(
            f"stage {name} stopped at the deadline; rerun to continue it"
        ) from None
    except BaseException:
        attempt.stop()  # Ctrl-C or SIGTERM to this run: as at the deadline
        raise
    rc = attempt.close()
    if rc != 0:
        raise _failed(chain, name, rc)
    return _finish(chain, name, *begun, log)


def _child_env(jobs: int) -> dict:
    """The commands' environment. With several at once on one accelerator, each JAX process
    takes GPU memory as it needs it instead of preallocating most of it (JAX's default), unless
    the caller chose a policy. On an accelerator each process also gets one JAX CPU device per
    usable core (`mjx_arm.rod_arm.HOST_DEVICES_FLAG`), unless XLA_FLAGS names a count: the
    reference rod then runs on the host's cores, where latency-bound processes run side by side,
    instead of time-slicing the GPU (`mjx_arm.rod_arm.host_devices`); nothing else uses them."""
    env = dict(os.environ)
    if jobs > 1 and not any(k in env for k in GPU_MEMORY_POLICY):
        env["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
    flags = env.get("XLA_FLAGS", "")
    on_accelerator = jax_device().split(" ")[0] not in ("cpu", "unknown")
    if on_accelerator and HOST_DEVICES_FLAG not in flags:
        env["XLA_FLAGS"] = f"{flags} {HOST_DEVICES_FLAG}={usable_cores()}".strip()
    return env


def run_stages(
    chain: Chain,
    names: list[str],
    jobs: int = 1,
    redo: tuple[str, ...] = (),
    deadline_s: float | None = None,
    log=print,
    poll_s: float = 1.0,
    status_every_s: float = 60.0,
    devices: tuple[str, ...] = (),
) -> None:
    """Runs the named stages, up to `jobs` at once, each as soon as its inputs are done.

    With `devices` (GPU ids), each command sees one of them (`CUDA_VISIBLE_DEVICES`), the one
    running the fewest stages: stages on different GPUs run truly side by side, while stages
    sharing one GPU take turns on it. Without, every command sees every GPU.

    With one job and no devices the commands' output is shown here; otherwise each command writes
    `NAME.log` beside its folder (kept in the folder as `stage.log` when it finishes) and a line
    every `status_every_s` says what runs. After a failure no new stage starts; those running
    finish. At the deadline every running command is stopped.

    Raises:
      StageError: a named stage reads a stage that is neither named nor done; a stage's folder
        was made from other inputs; a command failed (the first failure; all are logged).
      DeadlineReached: the deadline came first; unfinished stages keep their partial folders.
    """
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs}")
    check_before_running(chain, names, redo)
    if jobs == 1 and not devices:
        start = time.monotonic()
        for i, name in enumerate(names):
            log(f"== stage {i + 1}/{len(names)}: {name}")
            left = None if deadline_s is None else deadline_s - (time.monotonic() - start)
            if left is not None and left <= 0:
                raise DeadlineReached(f"the deadline came before stage {name}")
            run_stage(chain, name, redo=name in redo, deadline_s=left, log=log)
        return
    scheduler = _Scheduler(chain, names, jobs, redo, log, _child_env(jobs), devices)
    scheduler.run(deadline_s, poll_s, status_every_s)


class _Scheduler:
    """`run_stages` with several commands at once."""

    def __init__(self, chain, names, jobs, redo, log, env, devices=()):
        self.chain, self.jobs, self.redo, self.log, self.env = chain, jobs, redo, log, env
        self.waiting = list(names)
        self.running: dict[str, tuple[Attempt, dict, list]] = {}
        self.failures: list[StageError] = []
        self.devices = {str(d): 0 for d in devices}  # GPU id -> stages running on it
        # GPU id ("" without --devices: the one accelerator) -> gpu stages running on it
        self.gpu_busy = {d: 0 for d in self.devices} if self.devices else {"": 0}

    def ready(self) -> list[str]:
        chain = self.chain
        return [n for n in self.waiting if all(chain.manifest(i) for i in chain.stages[n].inputs)]

    def launch(self) -> None:
        """Starts ready stages while there is room; a skipped (done) stage can make others
        ready at once."""
        skipped = True
        while skipped:
            skipped = False
            for name in self.ready():
                if len(self.running) >= self.jobs or self.failures:
                    return
                if self.chain.stages[name].gpu and self._free_gpu() is None:
                    continue  # waits for a GPU without a training; others may start
                self.waiting.remove(name)
                begun = _begin(self.chain, name, name in self.redo, self.log)
                if begun is None:
                    skipped = True
                    continue
                self._start(name, begun)

    def _free_gpu(self) -> str | None:
        """A GPU no gpu stage runs on, the least busy first ("" for the one accelerator)."""
        free = [d for d, n in self.gpu_busy.items() if n == 0]
        return min(free, key=lambda d: self.devices.get(d, 0)) if free else None

    def _start(self, name: str, begun: tuple[dict, list[dict]]) -> None:
        log_path = self.chain.log_path(name)
        env, device = self.env, None
        if self.chain.stages[name].gpu:
            gpu = self._free_gpu()  # launch() made sure there is one
            self.gpu_busy[gpu] += 1
            device = gpu or None  # "": the one accelerator, no CUDA_VISIBLE_DEVICES
        elif self.devices:
            device = min(self.devices, key=self.devices.get)  # the least busy, first on a tie
        if device is not None:
            self.devices[device] += 1
            env = env | {"CUDA_VISIBLE_DEVICES": device}
        attempt = Attempt(
            self.chain, name, *begun, log_path=log_path, env=env, jobs=self.jobs, device=device
        )
        on = "" if device is None else f" on GPU {device}"
        self.log(f"[{name}] started{on}; its output goes to {log_path}")
        self.running[name] = (attempt, *begun)

    def _release(self, name: str, attempt: Attempt) -> None:
        device = attempt.entry.get("device")
        if device is not None:
            self.devices[device] -= 1
        if self.chain.stages[name].gpu:
            self.gpu_busy[device or ""] -= 1

    def reap(self) -> None:
        for name, (attempt, key, attempts) in list(self.running.items()):
            if attempt.process.poll() is None:
                continue
            del self.running[name]
            self._release(name, attempt)
            rc = attempt.close()
            if rc == 0:
                _finish(self.chain, name, key, attempts, self.log)
            else:
                self.failures.append(_failed(self.chain, name, rc))
                self.log(f"[{name}] {self.failures[-1]} (log: {self.chain.log_path(name)})")

    def run(self, deadline_s, poll_s, status_every_s) -> None:
        start = last_status = time.monotonic()
        try:
            self.launch()
            while self.running:
                time.sleep(poll_s)
                self.reap()
                self.launch()
                now = time.monotonic()
                if deadline_s is not None and now - start >= deadline_s and self.running:
                    stop_all([attempt for attempt, _, _ in self.running.values()])
                    names = ", ".join(self.running)
                    self.running.clear()
                    raise DeadlineReached(f"stage(s) {names} stopped at the deadline")
                if now - last_status >= status_every_s:
                    last_status = now
                    self.log(
                        "running: "
                        + ", ".join(
                            f"{n} {a.elapsed_s():.0f} s" for n, (a, _, _) in self.running.items()
                        )
                    )
        except BaseException:
            # A refused stage, Ctrl-C or SIGTERM to this run: the running commands stop as at
            # the deadline, so a training keeps its last epoch.
            stop_all([attempt for attempt, _, _ in self.running.values()])
            self.running.clear()
            raise
        if self.failures:
            raise self.failures[0]
        if self.waiting:
            raise StageError(f"not run: {', '.join(self.waiting)}")
