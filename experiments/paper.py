"""The whole chain, from babbling to the table beside the paper's Table I, as one command.

    python -m experiments.paper --out DIR                 # every stage not yet done, in order
    python -m experiments.paper --out DIR --list          # each stage's state and command
    python -m experiments.paper --out DIR --stage ccgan   # run or resume one stage
    python -m experiments.paper --out DIR --deadline-s 540   # stop cleanly; rerun to continue
    python -m experiments.paper --out DIR --jobs 4           # independent stages at once
    python -m experiments.paper --out DIR --jobs 4 --devices 0 1 2 3   # one GPU each

The stages and every setting are in a committed config (`experiments/paper.json`; the tiny
`experiments/quick.json` runs the same chain on a CPU in minutes). The schedule is fixed there
before any shape is scored: iterates are picked on held-out programs inside each command, and
the five shapes appear only in the final tables. A finished stage is skipped while its outputs
match their inputs (`experiments.stages`); when all are done, DIR/paper.md reports the wall time
of each stage and the tables beside the paper's.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
from pathlib import Path

from experiments import report
from experiments.stages import (
    Chain,
    DeadlineReached,
    StageError,
    has_manifest,
    load_config,
    run_stages,
)
from mjx_arm.run_folder import FolderBusyError, check_writable_folder, lock_folder

REPO = Path(__file__).resolve().parent.parent
DEFAULT_CONFIG = REPO / "experiments" / "paper.json"
EXIT_STOPPED = 3  # the deadline came first: rerun the same command to continue


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m experiments.paper",
        description=__doc__.strip().splitlines()[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("--out", required=True, type=Path, help="run folder (one per config)")
    parser.add_argument("--config", type=Path, default=DEFAULT_CONFIG, help="the chain's stages")
    parser.add_argument(
        "--stage", nargs="+", default=None, help="run only these stages (their inputs must be done)"
    )
    parser.add_argument(
        "--redo",
        nargs="+",
        default=[],
        help="rerun these stages although done or made from other inputs (old folders are kept)",
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="run up to this many stages at once, each when its inputs are done (their outputs"
        ' go to DIR/NAME.log); stages marked "gpu" in the config take turns on each GPU, the'
        " others (babbling, planning, tracking on the host's cores) run beside them",
    )
    parser.add_argument(
        "--devices",
        nargs="+",
        default=[],
        help="GPU ids: each stage runs on one of them (CUDA_VISIBLE_DEVICES), the least busy, so"
        " stages on different GPUs run side by side; give --jobs at least as many",
    )
    parser.add_argument("--list", action="store_true", help="show the stages' state; run nothing")
    parser.add_argument(
        "--deadline-s",
        type=float,
        default=None,
        help="stop the running stage after this many seconds of the whole run (a positive, finite"
        " number; exit status 3; its folder stays and the same command continues it)",
    )
    return parser


def list_stages(chain: Chain) -> None:
    """Each stage's state; a done one with its wall time, a partial one with its attempts."""
    for name in chain.stages:
        try:
            status = chain.status(name)
        except StageError as err:
            status = f"broken ({err})"
        if status == "done":
            manifest = chain.manifest(name)
            status += f" ({manifest['wall_s']:.0f} s over {len(manifest['attempts'])} attempt(s))"
        if status == "partial" and chain.attempts_path(name).exists():
            attempts = json.loads(chain.attempts_path(name).read_text())["attempts"]
            wall_s = sum(a["wall_s"] or 0.0 for a in attempts)
            status += f" ({len(attempts)} attempt(s), {wall_s:.0f} s so far)"
        if status.startswith(("todo", "partial")):
            waiting = [n for n in chain.stages[name].inputs if not has_manifest(chain, n)]
            if waiting:
                status += f" (waits for {', '.join(waiting)})"
        print(f"{name:14s} {status}")
        print(f"{'':14s} {chain.stages[name].about}")


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        config, stages = load_config(args.config)
    except StageError as err:
        parser.error(str(err))
    chain = Chain(stages, args.out, REPO)
    unknown = [n for n in (args.stage or []) + args.redo if n not in chain.stages]
    if unknown:
        parser.error(f"unknown stage(s) {unknown}; the config has {list(chain.stages)}")
    if args.deadline_s is not None and not (math.isfinite(args.deadline_s) and args.deadline_s > 0):
        parser.error(
            f"--deadline-s must be a positive number of seconds, got {args.deadline_s}"
            " (leave it out for no deadline)"
        )
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    if args.out.exists() and not args.out.is_dir():
        parser.error(f"--out {args.out} exists and is not a folder")
    if args.list:
        list_stages(chain)
        return 0
    try:
        check_writable_folder(args.out)
        lock = lock_folder(args.out)  # one chain per run folder
    except (OSError, FolderBusyError) as err:
        parser.error(f"--out: {err}")
    with lock:
        return run(chain, config, args)


def run(chain: Chain, config: dict, args: argparse.Namespace) -> int:
    """Runs the selected stages of a checked command line; writes paper.md when every stage is
    done; returns the exit status."""
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    selected = args.stage or list(chain.stages)
    try:
        run_stages(
            chain,
            selected,
            jobs=args.jobs,
            redo=tuple(args.redo),
            deadline_s=args.deadline_s,
            devices=tuple(args.devices),
        )
    except DeadlineReached as err:
        print(f"stopped: {err}. Rerun the same command to continue.", file=sys.stderr)
        return EXIT_STOPPED
    except StageError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    not_done = [n for n in chain.stages if _status(chain, n) != "done"]
    if not not_done:
        path = report.write(chain, config, args.config)
        print(f"report: {path}")
    else:
        print(f"paper.md is written once every stage is done and current; not yet: {not_done}")
    return 0


def _status(chain: Chain, name: str) -> str:
    try:
        return chain.status(name)
    except StageError as err:
        return f"broken ({err})"


if __name__ == "__main__":
    sys.exit(main())
