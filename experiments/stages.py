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
"""

from __future__ import annotations

import ctypes
import dataclasses
import datetime
import functools
import hashlib
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

from mjx_arm.dataset import sha256_file
from mjx_arm.machine import cpu_model

MANIFEST = "stage.json"
PARTIAL_SUFFIX = ".partial"
ATTEMPTS_SUFFIX = ".attempts.json"
PLACEHOLDER = re.compile(r"\{([a-z_]+)(?::([a-z0-9_]+))?\}")


STOP_GRACE_S = 60.0  # a stopped command's time to end its epoch and write a checkpoint
STAGE_LOG = "stage.log"  # a command's output, when several run at once
# Environment variables by which a caller already chose how JAX takes GPU memory.
GPU_MEMORY_POLICY = (
    "XLA_PYTHON_CLIENT_PREALLOCATE",
    "XLA_PYTHON_CLIENT_MEM_FRACTION",
    "XLA_PYTHON_CLIENT_ALLOCATOR",
)


class StageError(RuntimeError):
    """A stage cannot run or be trusted: a failed command, missing inputs, a mismatched folder."""


class DeadlineReached(RuntimeError):
    """The run's time ran out; the stage's partial folder stays for the next run."""


@dataclasses.dataclass(frozen=True)
class Stage:
    """One command of the chain.

    Attributes:
      name: folder name of its outputs under the run folder.
      module: the module run as `python -m module`.
      args: its arguments. `{dir}` is the stage's own (partial) folder, `{stage:NAME}` the
        finished folder of stage NAME (which makes NAME an input), `{file:PATH}` a file of the
        repository whose hash joins the key (the arm's MJCF).
      about: one line for the report: what the stage makes.
      gpu: the stage keeps an accelerator busy (a training). With several stages at once, at
        most one such stage runs on each GPU, the others beside it being stages that are not:
        trainings sharing one GPU finish fewer epochs together than one after another
        (bench/results/h200/sharing.md). Not part of the stage's key.
    """

    name: str
    module: str
    args: tuple[str, ...]
    about: str = ""
    gpu: bool = False

    @property
    def inputs(self) -> tuple[str, ...]:
        """Names of the stages whose outputs this one reads, in order of first mention."""
        names = []
        for arg in self.args:
            for kind, value in PLACEHOLDER.findall(arg):
                if kind == "stage" and value not in names:
                    names.append(value)
        return tuple(names)

    def files(self) -> tuple[str, ...]:
        """Repository files named by `{file:PATH}`."""
        out = []
        for arg in self.args:
            out += re.findall(r"\{file:([^}]+)\}", arg)
        return tuple(out)


def load_config(path: str | os.PathLike) -> tuple[dict, list[Stage]]:
    """Reads a chain's config: a JSON object with "stages", a list of {name, module, args, about,
    gpu} (args: one shell-quoted string, or a list; about and gpu optional).

    Raises:
      StageError: a malformed config, a repeated stage name, or a stage that reads a stage
        defined after it (or not at all).
    """
    path = Path(path)
    try:
        config = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise StageError(f"cannot read the config {path}: {err}") from err
    stages, seen = [], set()
    for i, raw in enumerate(config.get("stages", [])):
        try:
            stage = Stage(
                name=raw["name"],
                module=raw["module"],
                args=tuple(
                    shlex.split(raw["args"])
                    if isinstance(raw["args"], str)
                    else [str(a) for a in raw["args"]]
                ),
                about=raw.get("about", ""),
                gpu=raw.get("gpu", False),
            )
        except (KeyError, TypeError) as err:
            raise StageError(f"{path}: stage {i} lacks {err} (name, module, args)") from err
        if not isinstance(stage.gpu, bool):
            raise StageError(f"{path}: stage {stage.name}: gpu must be true or false")
        if not re.fullmatch(r"[a-z][a-z0-9_]*", stage.name) or stage.name in seen:
            raise StageError(f"{path}: stage name {stage.name!r} is not a new lower-case name")
        missing = [n for n in stage.inputs if n not in seen]
        if missing:
            raise StageError(f"{path}: stage {stage.name} reads {missing}, not defined before it")
        seen.add(stage.name)
        stages.append(stage)
    if not stages:
        raise StageError(f"{path}: no stages")
    return config, stages


def file_hashes(folder: Path) -> dict[str, str]:
    """{relative path: sha256} of every file under folder but the manifest."""
    return {
        str(p.relative_to(folder)): sha256_file(p)
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != MANIFEST
    }


def digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:16]


class Chain:
    """The stages of one run folder: their state, keys and commands.

    Args:
      stages: in order; each reads only stages before it.
      out: the run folder.
      repo: the folder `{file:...}` paths and the commands are relative to.
    """

    def __init__(self, stages: list[Stage], out: Path, repo: Path):
        self.stages = {s.name: s for s in stages}
        self.out, self.repo = Path(out), Path(repo)

    def folder(self, name: str) -> Path:
        return self.out / name

    def partial(self, name: str) -> Path:
        return self.out / (name + PARTIAL_SUFFIX)

    def attempts_path(self, name: str) -> Path:
        """Where a partial folder's key and attempts are kept: beside it, not in the command's
        own folder."""
        return self.out / (name + ATTEMPTS_SUFFIX)

    def log_path(self, name: str) -> Path:
        """The command's output while it runs beside other stages."""
        return self.out / (name + ".log")

    def manifest(self, name: str) -> dict | None:
        """A finished stage's `stage.json`, None when there is none.

        Raises:
          StageError: it is not JSON, or lacks what this chain writes there (the message names
            the file and how to rerun the stage).
        """
        path = self.folder(name) / MANIFEST
        if not path.exists():
            return None
        try:
            manifest = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise StageError(f"{path} is corrupt ({err}): give --redo {name}") from err
        kinds = {"key": dict, "files": dict, "attempts": list, "wall_s": (int, float)}
        fields = manifest if isinstance(manifest, dict) else {}
        bad = [k for k, kind in kinds.items() if not isinstance(fields.get(k), kind)]
        if bad:
            raise StageError(
                f"{path} lacks {', '.join(repr(k) for k in bad)} (not a manifest this chain"
                f" wrote): give --redo {name}"
            )
        return manifest

    def outputs_digest(self, name: str) -> str:
        """The digest of a finished stage's files, as its manifest records them."""
        manifest = self.manifest(name)
        if manifest is None:
            raise StageError(f"stage {name} has not finished in {self.out}: run it first")
        return digest(manifest["files"])

    def key(self, name: str) -> dict:
        """What a stage's outputs depend on: its command, named files and its inputs' outputs."""
        stage = self.stages[name]
        files = {}
        for rel in stage.files():
            path = self.repo / rel
            if not path.is_file():
                raise StageError(f"stage {name} names {rel}, which is not a file")
            files[rel] = sha256_file(path)[:16]
        return {
            "module": stage.module,
            "args": list(stage.args),
            "files": files,
            "inputs": {n: self.outputs_digest(n) for n in stage.inputs},
        }

    def command(self, name: str, folder: Path) -> list[str]:
        """The stage's argv with its placeholders filled in; `folder` is where it writes."""

        def fill(match: re.Match) -> str:
            kind, value = match.group(1), match.group(2)
            if kind == "dir" and value is None:
                return str(folder)
            if kind == "stage":
                return str(self.folder(value))
            raise StageError(f"stage {name}: unknown placeholder {match.group(0)}")

        args = [re.sub(r"\{file:([^}]+)\}", r"\1", a) for a in self.stages[name].args]
        return [sys.executable, "-m", self.stages[name].module] + [
            PLACEHOLDER.sub(fill, a) for a in args
        ]

    def status(self, name: str) -> str:
        """done (whole and current), stale (made from other inputs), partial, or todo."""
        manifest = self.manifest(name)
        if manifest is not None:
            if manifest["key"] != self.key(name):
                return "stale"
            if file_hashes(self.folder(name)) != manifest["files"]:
                raise StageError(
                    f"the files of {self.folder(name)} differ from its manifest: something "
                    "changed them after the stage finished; remove the folder or --redo "
                    f"{name}"
                )
            return "done"
        return "partial" if self.partial(name).exists() else "todo"


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


def shown_command(chain: Chain, name: str) -> str:
    """The stage's command as a person would run it by hand: into the stage's folder (the chain
    writes to .partial first and renames it into place)."""
    return shlex.join(["python", *chain.command(name, chain.folder(name))[1:]])


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
    the caller chose a policy."""
    env = dict(os.environ)
    if jobs > 1 and not any(k in env for k in GPU_MEMORY_POLICY):
        env["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
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


def upstream(chain: Chain, names) -> list[str]:
    """Every stage that the named ones read, directly or through other stages, in chain order."""
    needed, todo = set(), list(names)
    while todo:
        for name in chain.stages[todo.pop()].inputs:
            if name not in needed:
                needed.add(name)
                todo.append(name)
    return [n for n in chain.stages if n in needed]


def has_manifest(chain: Chain, name: str) -> bool:
    """Whether a stage's folder holds a readable manifest (whether or not it is current)."""
    try:
        return chain.manifest(name) is not None
    except StageError:
        return False


def _not_current(chain: Chain, name: str) -> str | None:
    """Why a stage's folder cannot be used as it is (None: it can, or there is none yet): what
    a plain run would refuse when it came to it."""
    try:
        status = chain.status(name)
    except StageError as err:
        return str(err)
    if status == "stale":
        return "made from other inputs (the config or an upstream stage's outputs changed)"
    return None


def _not_done(chain: Chain, name: str) -> str | None:
    """Why a stage cannot be read as it is (None: it is done, current and whole)."""
    why = _not_current(chain, name)
    if why is None and chain.status(name) != "done":
        why = "has not finished"
    return why


def check_before_running(chain: Chain, names, redo=()) -> None:
    """Refuses, before any work, what a plain run would refuse on its way: every stage that the
    named ones read, directly or not, and that is not named itself must be finished, current
    (its key matches the config and its inputs' outputs) and whole (its files match its
    manifest); a named stage that has finished must be current and whole unless it is in
    `redo`.

    Raises:
      StageError: naming each such stage, why, and the `--redo` that reruns it.
    """
    names = list(names)
    for name in names:
        missing = [n for n in chain.stages[name].inputs if n not in names and not chain.manifest(n)]
        if missing:
            raise StageError(f"stage {name} reads {missing}, which have not finished: run them too")
    problems = []
    for name in upstream(chain, names):
        if name not in names:
            why = _not_done(chain, name)
            if why is not None:
                readers = [n for n in names if name in upstream(chain, [n])]
                problems.append((name, f"{why} (read by {', '.join(readers)})"))
    for name in names:
        inputs_done = all(
            n not in redo and has_manifest(chain, n) for n in chain.stages[name].inputs
        )
        if name in redo or not has_manifest(chain, name) or not inputs_done:
            continue  # run afresh, or checked when its inputs are done
        why = _not_current(chain, name)
        if why is not None:
            problems.append((name, why))
    if problems:
        redo_names = " ".join(n for n, _ in problems)
        raise StageError(
            "not current, nothing run: "
            + "; ".join(f"stage {n}: {why}" for n, why in problems)
            + f". Rerun with --redo {redo_names} (with --stage, name them there too), or look"
            " at --list"
        )


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


@functools.cache
def machine() -> str:
    """The host's CPU and JAX's first device, asked in a child process: a JAX backend started
    here would hold accelerator memory that the stages' own processes need."""
    probe = "import jax; d = jax.devices()[0]; print(f'{jax.default_backend()} ({d.device_kind})')"
    try:
        device = subprocess.run(
            [sys.executable, "-c", probe], capture_output=True, text=True, timeout=120
        ).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        device = "unknown"
    return f"{cpu_model()}, {os.cpu_count()} cores; JAX: {device}"
