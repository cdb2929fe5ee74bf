"""One attempt of a stage's command: started into the stage's partial folder, recorded beside
it, stopped at a deadline, and killed with the chain however the chain dies.

A command that stops part-way (a device call's time limit) leaves `.partial/` with the key it was
started with; the next run with the same key continues in it, and one with another key refuses
it (or with --redo moves it aside).
"""

from __future__ import annotations

import ctypes
import datetime
import functools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from experiments.chain import Chain, StageError
from mjx_arm.machine import cpu_model

STOP_GRACE_S = 60.0  # a stopped command's time to end its epoch and write a checkpoint


def _started_with(path: Path) -> tuple[dict | None, list[dict]]:
    """The key a partial folder was started with and its earlier attempts (None, [] if none)."""
    if not path.exists():
        return None, []
    record = json.loads(path.read_text())
    return record["key"], record["attempts"]


def _move_aside(folder: Path) -> Path:
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    aside = folder.with_name(f"{folder.name}.replaced-{stamp}")
    folder.rename(aside)
    return aside


def _attempts_to_continue(chain: Chain, name: str, key: dict, redo: bool, log) -> list[dict]:
    """The earlier attempts of a partial folder started with this key; a folder started with
    another key is refused, or with `redo` moved aside (then no attempts)."""
    started_key, attempts = _started_with(chain.attempts_path(name))
    if started_key is None or started_key == key:
        return attempts
    partial = chain.partial(name)
    if not redo:
        raise StageError(
            f"{partial} was started with other inputs: remove it or give --redo {name}"
        )
    if partial.exists():
        log(f"[{name}] the unfinished folder is kept as {_move_aside(partial).name}")
    return []


class Attempt:
    """One run of a stage's command into its partial folder, started at construction.

    The attempt (start, wall time) is recorded beside the folder before the command starts, so a
    machine lost mid-stage still leaves the key the folder belongs to, and again when it ends.

    Args:
      log_path: where the command's stdout and stderr go (appended); None: this process's own.
      env: the command's environment; None: this process's.
      jobs: how many stages the run let share the machine (recorded with the machine: wall
        times depend on both).
      device: the accelerator the command was given, recorded (its env sets it).
    """

    def __init__(
        self,
        chain: Chain,
        name: str,
        key: dict,
        attempts: list[dict],
        log_path: Path | None = None,
        env: dict | None = None,
        jobs: int = 1,
        device: str | None = None,
    ):
        self.chain, self.name, self.key, self.attempts = chain, name, key, attempts
        self.entry = {
            "started": datetime.datetime.now().isoformat(timespec="seconds"),
            "wall_s": None,
            "jobs": jobs,  # the most stages the run let share the machine
            "machine": machine(),  # a stage resumed on another machine names each one
        }
        if device is not None:
            self.entry["device"] = device  # the accelerator it was given (CUDA_VISIBLE_DEVICES)
        attempts.append(self.entry)
        self._write()
        self.start = time.perf_counter()
        self.log_file = open(log_path, "a") if log_path is not None else None  # noqa: SIM115
        self.process = subprocess.Popen(
            chain.command(name, chain.partial(name)),
            cwd=chain.repo,
            env=env,
            stdout=self.log_file,
            stderr=subprocess.STDOUT if self.log_file else None,
            # Its own session: a terminal's Ctrl-C reaches the chain only, which stops the
            # command as at the deadline; and it dies with the chain, even a killed one.
            start_new_session=True,
            preexec_fn=die_with_parent(),
        )

    def _write(self) -> None:
        path = self.chain.attempts_path(self.name)
        path.write_text(json.dumps({"key": self.key, "attempts": self.attempts}, indent=1) + "\n")

    def elapsed_s(self) -> float:
        return time.perf_counter() - self.start

    def close(self) -> int:
        """Records the wall time; returns the exit status (the command must have ended)."""
        self.entry["wall_s"] = round(self.elapsed_s(), 1)
        self._write()
        if self.log_file is not None:
            self.log_file.close()
        return self.process.returncode

    def stop(self) -> None:
        """SIGTERM, then SIGKILL after `STOP_GRACE_S`: a training command writes its checkpoint."""
        stop_all([self])


PR_SET_PDEATHSIG = 1  # prctl(2): the signal a process gets when its parent dies


def die_with_parent(sig: int = signal.SIGTERM):
    """A `subprocess.Popen` preexec_fn by which the child gets `sig` when this process dies,
    however it dies (`kill -9` included); None where Linux's prctl is missing.

    SIGTERM, as at the deadline: a training ends its epoch and checkpoints (its run folder's
    lock keeps a second trainer out meanwhile); a command without a handler ends at once.
    """
    if not sys.platform.startswith("linux"):
        return None
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl  # looked up here: not after the fork
    except (OSError, AttributeError):
        return None
    parent = os.getpid()

    def preexec() -> None:
        prctl(PR_SET_PDEATHSIG, sig)
        if os.getppid() != parent:  # the parent died before prctl took effect
            os.kill(os.getpid(), sig)

    return preexec


def stop_all(attempts: list[Attempt]) -> None:
    """Stops several commands at once: SIGTERM to all, then SIGKILL to those still running
    `STOP_GRACE_S` later (one grace period for all, not one each)."""
    for attempt in attempts:
        attempt.process.terminate()
    end = time.monotonic() + STOP_GRACE_S
    for attempt in attempts:
        try:
            attempt.process.wait(timeout=max(0.0, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            attempt.process.kill()
            attempt.process.wait()
        attempt.close()


@functools.cache
def jax_device() -> str:
    """JAX's default backend and first device, e.g. "gpu (NVIDIA H100 80GB HBM3)", asked in a
    child process ("unknown" if that fails): a JAX backend started here would hold accelerator
    memory that the stages' own processes need."""
    probe = "import jax; d = jax.devices()[0]; print(f'{jax.default_backend()} ({d.device_kind})')"
    try:
        return (
            subprocess.run(
                [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120
            ).stdout.strip()
            or "unknown"
        )
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"


def machine() -> str:
    """The host's CPU and JAX's first device (`jax_device`)."""
    return f"{cpu_model()}, {os.cpu_count()} cores; JAX: {jax_device()}"
