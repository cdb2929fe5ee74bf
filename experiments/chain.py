"""The chain's stages and their state: the config, each stage's key, folders and manifest, and
what must be current before a run starts.

A stage is one command of the project (`python -m mjx_arm.babble ...`, `python -m ccgan.train
...`) that writes one folder. Its key is a hash of the command, of the files it names outside the
run (the arm's MJCF) and of the outputs of the stages it reads. A finished stage's folder holds
`stage.json`: the key, the sha256 of every file it wrote, the command and its wall time.
`experiments.stages` runs them; `experiments.attempt` runs one command.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import shlex
import sys
from pathlib import Path

from mjx_arm.dataset import sha256_file

MANIFEST = "stage.json"
PARTIAL_SUFFIX = ".partial"
ATTEMPTS_SUFFIX = ".attempts.json"
PLACEHOLDER = re.compile(r"\{([a-z_]+)(?::([a-z0-9_]+))?\}")
STAGE_LOG = "stage.log"  # a command's output, when several run at once


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


def shown_command(chain: Chain, name: str) -> str:
    """The stage's command as a person would run it by hand: into the stage's folder (the chain
    writes to .partial first and renames it into place)."""
    return shlex.join(["python", *chain.command(name, chain.folder(name))[1:]])


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
