"""Settings dataclasses as command lines: one flag per field, its help the field's documentation.

`add_config_flags` turns a dataclass into flags (`field_docs` reads each field's `#:` comment or
docstring for its help), `config_from_args` reads them back and turns a `ConfigError` into a
usage error naming the flag; `cli_parser` and `HelpFormatter` give every `python -m ccgan.*` the
same look; `add_data_flags` / `data_from_args` are the shared --source/--constrained/--model.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import re
import textwrap
from pathlib import Path

from mjx_arm import run_folder
from tracking.config import ConfigError


def _first_sentence(text: str) -> str:
    text = " ".join(text.split())
    return re.split(r'(?<=[a-z0-9)\]])\.\s+(?=[A-Z"`])', text, maxsplit=1)[0]


def field_docs(cls) -> dict[str, str]:
    """{field: the first sentence of its documentation} for a dataclass, for `--help`.

    A field is documented by `#:` comment lines right above it or by a string right below it
    (both styles occur in this package); the documentation stays in one place, the class.
    """
    src = textwrap.dedent(inspect.getsource(cls))
    lines = src.splitlines()
    body = next(n for n in ast.parse(src).body if isinstance(n, ast.ClassDef)).body
    docs = {}
    for i, node in enumerate(body):
        if not (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)):
            continue
        after = body[i + 1] if i + 1 < len(body) else None
        if isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant):
            text = str(after.value.value)
        else:
            comments, j = [], node.lineno - 2
            while j >= 0 and lines[j].strip().startswith("#:"):
                comments.insert(0, lines[j].strip()[2:])
                j -= 1
            text = " ".join(comments)
        docs[node.target.id] = _first_sentence(text)
    return docs


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default, except where there is none to show (None, a switch off)."""

    def _get_help_string(self, action):
        if action.default is None or (action.nargs == 0 and action.default is False):
            return action.help
        return super()._get_help_string(action)


def cli_parser(module: str, doc: str) -> argparse.ArgumentParser:
    """The parser of `python -m <module>`: its name, the first line of `doc`, shown defaults."""
    return argparse.ArgumentParser(
        prog=f"python -m {module}",
        description=doc.strip().splitlines()[0],
        formatter_class=HelpFormatter,
    )


def _boolean(text: str) -> bool:
    """A flag value "true"/"false" (or "1"/"0", any case) as a bool."""
    value = {"true": True, "1": True, "false": False, "0": False}.get(text.lower())
    if value is None:
        raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")
    return value


def add_config_flags(
    parser: argparse.ArgumentParser,
    cls,
    skip: tuple[str, ...] = (),
    prefix: str = "",
    choices: dict[str, tuple] | None = None,
) -> None:
    """Adds one flag per field of the dataclass `cls`: `--<prefix><field-name>`.

    Each flag's help is the field's documentation (`field_docs`), its default the field's;
    bools become switches, tuples take several values. Read them back with `config_from_args`.

    Args:
      parser: the parser (the flags go into a group named after `cls`).
      cls: a dataclass with defaults.
      skip: fields without a flag (they keep their defaults).
      prefix: flag prefix, e.g. "forward-" for `--forward-epochs`.
      choices: {field: allowed values}.
    """
    docs = field_docs(cls)
    doc = (cls.__doc__ or "").strip().splitlines()
    group = parser.add_argument_group(cls.__name__, doc[0] if doc else None)
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        flag = "--" + (prefix + f.name).replace("_", "-")
        kw = {
            "dest": (prefix + f.name).replace("-", "_"),
            "default": f.default,
            "help": docs.get(f.name, "").replace("%", "%%") or f.name.replace("_", " "),
        }
        if f.type in ("bool", bool):
            # A switch; one that is on by default also gets --no-<name> to turn it off.
            action = argparse.BooleanOptionalAction if f.default is True else "store_true"
            group.add_argument(flag, action=action, **kw)
        elif "tuple" in str(f.type):
            typ = {"float": float, "bool": _boolean}.get(str(f.type)[6:-1].split(",")[0], int)
            # tuple[float, float] takes exactly two values; tuple[int, ...] one or more.
            nargs = "+" if "..." in str(f.type) else str(f.type).count(",") + 1
            group.add_argument(flag, type=typ, nargs=nargs, **kw | {"default": list(f.default)})
        else:
            typ = {"int": int, "float": float}.get(str(f.type), type(f.default))
            group.add_argument(flag, type=typ, choices=(choices or {}).get(f.name), **kw)
    for old, new in getattr(cls, "RENAMED_FIELDS", {}).items():
        if new not in skip:
            # The old flag, hidden: same destination, so it sets the renamed field.
            action = next(
                a for a in group._group_actions if a.dest == (prefix + new).replace("-", "_")
            )
            group.add_argument(
                "--" + (prefix + old).replace("_", "-"),
                dest=action.dest,
                type=action.type,
                nargs=action.nargs,
                help=argparse.SUPPRESS,
            )


def config_from_args(
    parser: argparse.ArgumentParser,
    args,
    cls,
    skip: tuple[str, ...] = (),
    prefix: str = "",
    check=None,
):
    """The `cls` instance of flags added by `add_config_flags`; invalid values are usage errors.

    Args:
      parser, args: the parser and its parsed arguments.
      cls, skip, prefix: as given to `add_config_flags`.
      check: optional callable(config) raising ConfigError, for classes without their own.

    Returns:
      The config. A `ConfigError` (from the class or `check`) exits with `parser.error`
      (status 2) naming the flag, before the caller starts any work.
    """
    kw = {}
    for f in dataclasses.fields(cls):
        if f.name not in skip:
            v = getattr(args, (prefix + f.name).replace("-", "_"))
            kw[f.name] = tuple(v) if isinstance(v, list) else v
    try:
        config = cls(**kw)
        if check is not None:
            check(config)
    except ConfigError as err:
        parser.error(f"--{(prefix + err.field).replace('_', '-')} {err.problem}")
    return config


def check_output_dir(parser: argparse.ArgumentParser, flag: str, path) -> None:
    """Usage error unless `path` is a folder or can be made one (no file on its way)."""
    for part in (Path(path), *Path(path).parents):
        if part.exists() and not part.is_dir():
            parser.error(f"{flag} {path}: {part} exists and is not a folder")


def lock_output_dir(parser: argparse.ArgumentParser, flag: str, path):
    """`check_output_dir`, then this process's lock on the folder until it ends (the lock file
    beside it: the folder holds only what the command writes); another live writer of the same
    folder is a usage error naming its pid (`mjx_arm.run_folder`).

    Returns:
      The held `mjx_arm.run_folder.FolderLock`.
    """
    check_output_dir(parser, flag, path)
    try:
        run_folder.check_writable_folder(path)
        return run_folder.lock_folder(path, beside=True)
    except (OSError, run_folder.FolderBusyError) as err:
        parser.error(f"{flag}: {err}")


def add_data_flags(parser: argparse.ArgumentParser) -> None:
    """--source, --constrained (babbling .npz files) and --model; read with `data_from_args`."""
    parser.add_argument(
        "--source", nargs="+", required=True, help="D_s dataset files (train, then val)"
    )
    parser.add_argument(
        "--constrained",
        nargs="+",
        required=True,
        help="D_c dataset files (train, then val) of one non-source domain: constrained, aged...",
    )
    parser.add_argument(
        "--model",
        default=None,
        help="MJCF of the arm the data must come from (its model hash is checked);"
        " default: any, as long as every file agrees. Not with the rod's data (babbled with"
        " --backend rod), which no MJCF made",
    )


def describe_arm(d) -> str:
    """ "the reference rod (model hash rod-...)" or "the chain of model hash ..." for a
    `ccgan.data.DomainData` (what simulated its files)."""
    from ccgan.sim_choice import simulator_of

    if simulator_of(d.model_hash) == "rod":
        return f"the reference rod (model hash {d.model_hash})"
    return f"the chain of model hash {d.model_hash}"


def data_from_args(parser: argparse.ArgumentParser, args):
    """The (D_s, D_c) `ccgan.data.DomainData` of `add_data_flags`' flags.

    Unreadable, mixed or wrong-arm files and an unloadable --model are usage errors (status 2)
    with the message naming the files, instead of a traceback. The rod's data
    (`mjx_arm.babble --backend rod`) and the chain's are told apart by their model hashes: one
    slot's rod files beside the other's chain files, or --model (an MJCF) with rod files, are
    refused with a message that says so.
    """
    import mjx_arm
    from ccgan.data import read_domain
    from ccgan.sim_choice import simulator_of
    from mjx_arm.dataset import DatasetError

    model_hash = None
    if args.model is not None:
        try:
            model_hash = mjx_arm.load(args.model).model_hash
        except (FileNotFoundError, ValueError) as err:
            parser.error(f"--model {args.model}: {err}")
    try:  # each slot on its own first: whether the rod or the chain made it
        slots = {
            flag: read_domain(paths, slot)
            for flag, paths, slot in (
                ("--source", args.source, "source"),
                ("--constrained", args.constrained, "constrained"),
            )
        }
    except DatasetError as err:
        parser.error(str(err))
    sims = {flag: simulator_of(d.model_hash) for flag, d in slots.items()}
    if len(set(sims.values())) > 1:
        parser.error(
            "one slot holds the reference rod's data and the other the chain's: "
            + "; ".join(
                f"{flag} {', '.join(d.paths)}: {describe_arm(d)}" for flag, d in slots.items()
            )
            + ". Train on one simulator's data (mjx_arm.babble --backend rod for both, or a"
            " chain backend for both)"
        )
    if model_hash is not None and "rod" in sims.values():
        parser.error(
            f"--model {args.model}: the data were simulated by the reference rod"
            f" ({slots['--source'].model_hash}), which no MJCF made; leave --model out"
        )
    for flag, d in slots.items():  # as `read_translation_files`, each slot read once
        if model_hash is not None and d.model_hash != model_hash:
            parser.error(
                f"{flag} {', '.join(d.paths)}: simulated with model {d.model_hash}, expected"
                f" {model_hash} (--model {args.model} has model hash {model_hash})"
            )
    d_s, d_c = slots["--source"], slots["--constrained"]
    if d_s.model_hash != d_c.model_hash:
        parser.error(
            "source and constrained files come from different arms (model hashes differ:"
            f" another MJCF, e.g. another segment count): {', '.join(d_s.paths)}"
            f" ({d_s.model_hash}) vs {', '.join(d_c.paths)} ({d_c.model_hash})"
        )
    return d_s, d_c
