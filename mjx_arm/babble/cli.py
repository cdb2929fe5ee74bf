"""The command line of ``python -m mjx_arm.babble``: parse and check the options, then `run`.

Every option is checked before any simulation (a bad value, an inconsistent configuration, a
missing model or an unusable output folder is a usage error, exit 2); defaults are the paper's
(`mjx_arm.babble.PAPER`). The library (`mjx_arm.babble`) does not import this module, so
``python -m mjx_arm.babble`` (the package's ``__main__``) imports each module once.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import time
from collections.abc import Sequence
from pathlib import Path

import jax

from mjx_arm import checks, dataset, domains, machine, run_folder
from mjx_arm.babble import (
    BACKENDS,
    C_MAX_CHUNK,
    PAPER,
    PROGRAM_FAMILIES,
    BabbleConfig,
    NotEnoughMemoryError,
    check_memory,
    run,
)
from mjx_arm.babble.rod import GPU_MAX_BATCH as ROD_GPU_MAX_BATCH


def _int_at_least(low: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {value}")
        return value

    return parse


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds > 0, got {text}")
    return value


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows every default, except None ones: their help says what None means."""

    def _get_help_string(self, action):
        if action.default is None:
            return action.help
        return super()._get_help_string(action)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m mjx_arm.babble``; defaults are the paper's (`PAPER`)."""
    p = argparse.ArgumentParser(
        prog="python -m mjx_arm.babble",
        description="Simulate pseudo-random pressure programs and save babbling datasets"
        " (one folder per run: <domain>_<split>.npz files and manifest.json).",
        formatter_class=_HelpFormatter,
    )
    _add_program_options(p)
    _add_run_options(p)
    _add_distributed_options(p)
    p.add_argument(
        "--cache-dir",
        help="JAX persistent compilation cache folder (default on an accelerator:"
        " ~/.cache/softarm/jax, see mjx_arm.machine.enable_compilation_cache)",
    )
    p.add_argument("--no-progress", action="store_true", help="hide the simulation progress bar")
    return p


def _add_program_options(p: argparse.ArgumentParser) -> None:
    """What to babble: domains, trajectories, their length, seed and holds."""
    p.add_argument(
        "--preset", choices=["paper"], help="paper: 50 + 3 x 60 s in both domains (the defaults)"
    )
    p.add_argument(
        "--domain",
        default="both",
        help=f"{', '.join(domains.DOMAINS)}, both (= source,constrained) or a comma list such as"
        " source,aged (one shared task-space normalisation over the listed domains)",
    )
    p.add_argument(
        "--domain-file",
        nargs="+",
        default=[],
        metavar="JSON",
        help='media off the pair, babbled after --domain\'s: each a {"domain": {"name": ...,'
        " <Domain fields>}} file (e.g. 5x D_s's drag), its files named by its name and its"
        " programs from that name's stream",
    )
    p.add_argument(
        "--n", type=_int_at_least(0), default=PAPER.n_train, help="training trajectories per domain"
    )
    p.add_argument(
        "--n-val",
        type=_int_at_least(0),
        default=PAPER.n_val,
        help="validation trajectories per domain",
    )
    p.add_argument(
        "--duration",
        type=_positive_seconds,
        default=PAPER.duration_s,
        help="seconds per trajectory",
    )
    p.add_argument(
        "--seed", type=_int_at_least(0), default=PAPER.seed, help="root seed of the programs"
    )
    p.add_argument(
        "--programs",
        choices=PROGRAM_FAMILIES,
        default=PAPER.programs,
        help="babbling (held random targets, the paper's) or shape_like (random ellipses,"
        " polygons, staircases and phase jumps, never a test shape; --hold-* unused)",
    )
    p.add_argument(
        "--hold-min", type=_positive_seconds, default=PAPER.hold_min_s, help="shortest hold (s)"
    )
    p.add_argument(
        "--hold-max", type=_positive_seconds, default=PAPER.hold_max_s, help="longest hold (s)"
    )


def _add_run_options(p: argparse.ArgumentParser) -> None:
    """How and where: backend, batch size, model and output folder."""
    p.add_argument(
        "--backend",
        choices=BACKENDS,
        default=PAPER.backend,
        help="mjx, c (MuJoCo C on all cores), auto (c when JAX runs on the CPU) or rod (the"
        " reference Cosserat rod, float64, instead of the chain: ~100-1,000x slower, files"
        " marked as the rod's; mjx_arm.babble.rod)",
    )
    p.add_argument(
        "--chunk",
        type=_int_at_least(1),
        default=PAPER.chunk,
        help=f"trajectories per device call (MuJoCo C: at most {C_MAX_CHUNK}; rod: at most"
        f" {ROD_GPU_MAX_BATCH} on a GPU, two per core on a CPU, four per device on the host's"
        " devices: mjx_arm.rod_arm.host_devices)",
    )
    p.add_argument(
        "--model",
        help="MJCF file (default: the committed models/softarm.xml); not with --backend rod",
    )
    p.add_argument(
        "--out",
        default="out/babble",
        help="output folder, written as a whole; an earlier run's folder is replaced",
    )


def _add_distributed_options(p: argparse.ArgumentParser) -> None:
    """One process of a multi-process run (`jax.distributed.initialize`)."""
    p.add_argument(
        "--distributed",
        action="store_true",
        help="one process of a multi-process run: call jax.distributed.initialize() (with the"
        " three options below, or from SLURM / Open MPI / JAX_COORDINATOR_ADDRESS)",
    )
    p.add_argument(
        "--coordinator",
        metavar="HOST:PORT",
        help="with --distributed: process 0's address, the same on every process (default:"
        " JAX_COORDINATOR_ADDRESS or the cluster's)",
    )
    p.add_argument(
        "--num-processes",
        type=_int_at_least(1),
        help="with --distributed: processes in the run (default: the cluster's)",
    )
    p.add_argument(
        "--process-id",
        type=_int_at_least(0),
        help="with --distributed: this process's index, 0 .. num-processes - 1; process 0 writes"
        " --out (default: the cluster's)",
    )


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Parses and checks the command line before any work: a bad option, an inconsistent
    configuration, a missing model or an unusable output folder is a usage error (exit 2).

    Returns:
      The namespace, with the checked `BabbleConfig` as ``config``.
    """
    p = build_parser()
    args = p.parse_args(argv)
    try:
        args.config = config_from_args(args)
    except ValueError as err:
        p.error(str(err))
    try:
        check_distributed_args(args)
        check_rod_args(args)
    except ValueError as err:
        p.error(str(err))
    try:
        check_memory(args.config)
    except NotEnoughMemoryError as err:
        p.error(str(err))
    if args.model is not None:
        try:
            check_model_file(args.model)
        except (OSError, ValueError) as err:
            p.error(f"--model {args.model}: {err}")
    try:
        dataset.check_output_folder(args.out)
    except OSError as err:
        p.error(f"--out: {err}")
    return args


def check_model_file(path: str) -> None:
    """Reads, compiles and checks the MJCF at `path` as `mjx_arm.load` will (no settling, no
    simulation), so a bad model is refused before any work.

    Raises:
      FileNotFoundError: no file. ModelValidationError (a ValueError): not an MJCF text file
        (e.g. an .npz dataset), does not compile, or lacks what the arm API needs (a timestep
        that is not positive included), or its valve numerics are unusable.
    """
    if not Path(path).is_file():
        raise FileNotFoundError("no such MJCF file")
    mj_model, _, source, _ = checks.read_model(path, None)
    checks.validate_model(mj_model, source)
    checks.valve_params(mj_model, source)


#: Variables from which `jax.distributed.initialize()` finds the coordinator by itself: JAX's
#: own, and the cluster environments it detects (SLURM, Open MPI, MPICH/PMI).
COORDINATOR_ENV = ("JAX_COORDINATOR_ADDRESS", "SLURM_JOB_ID", "OMPI_MCA_orte_hnp_uri", "PMI_RANK")


def check_rod_args(args: argparse.Namespace) -> None:
    """Raises ValueError for what --backend rod cannot do.

    --model is refused rather than recorded as unused: the rod is made from the arm's physical
    values (`mjx_arm.model_gen.ArmParams`), not from an MJCF, so a run that named one would look
    as though its data came from that model. --distributed is refused: the rod runs on one
    process's default device (`mjx_arm.babble.rod`), and a GPU run of the long D_c set already
    takes one call.
    """
    if args.backend != "rod":
        return
    if args.model is not None:
        raise ValueError(
            f"--model {args.model}: --backend rod simulates the reference rod, which is made from"
            " the arm's physical values, not from an MJCF; leave --model out (its files carry"
            " the rod's model hash)"
        )
    if args.distributed:
        raise ValueError("--distributed: --backend rod runs in one process (one GPU call per set)")


def check_distributed_args(args: argparse.Namespace) -> None:
    """Raises ValueError unless the multi-process options are consistent (--distributed needs
    a coordinator: --coordinator, or one that JAX finds in `COORDINATOR_ENV`)."""
    given = [
        f"--{name.replace('_', '-')}"
        for name in ("coordinator", "num_processes", "process_id")
        if getattr(args, name) is not None
    ]
    if given and not args.distributed:
        raise ValueError(f"{' and '.join(given)}: only with --distributed")
    if args.coordinator is not None:
        host, _, port = args.coordinator.rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(f"--coordinator must be HOST:PORT, got {args.coordinator!r}")
    if (args.num_processes is None) != (args.process_id is None):
        raise ValueError("give --num-processes and --process-id together")
    if args.process_id is not None and args.process_id >= args.num_processes:
        raise ValueError(
            f"--process-id must be < --num-processes ({args.num_processes}), got {args.process_id}"
        )
    if (
        args.distributed
        and args.coordinator is None
        and not any(os.environ.get(name) for name in COORDINATOR_ENV)
    ):
        raise ValueError(
            "--distributed needs a coordinator: give --coordinator HOST:PORT with"
            " --num-processes and --process-id, or run under SLURM / Open MPI, or set"
            " JAX_COORDINATOR_ADDRESS"
        )


def read_babble_domain(path: str) -> domains.Domain:
    """The Domain of a ``{"domain": {"name": ..., <fields>}}`` file under its own name
    (`mjx_arm.domains.read_domain_file` with `keep_name`: a babbled medium is a truth, and its
    files and streams carry its name).

    Raises:
      ValueError: one line naming the flag and the file's problem.
    """
    try:
        return domains.read_domain_file(path, keep_name=True).domain
    except (FileNotFoundError, ValueError) as err:
        raise ValueError(f"--domain-file: {err}") from None


def config_from_args(args: argparse.Namespace) -> BabbleConfig:
    """Builds the BabbleConfig of parsed arguments (their defaults are `PAPER`'s).

    Raises:
      ValueError: the options are inconsistent (e.g. a domain twice, holds min > max).
    """
    names = ("source", "constrained") if args.domain == "both" else args.domain.split(",")
    names = tuple(name.strip() for name in names)
    names += tuple(read_babble_domain(path) for path in args.domain_file)
    return dataclasses.replace(
        PAPER,
        seed=args.seed,
        n_train=args.n,
        n_val=args.n_val,
        duration_s=args.duration,
        hold_min_s=args.hold_min,
        hold_max_s=args.hold_max,
        domains=names,
        backend=args.backend,
        chunk=args.chunk,
        programs=args.programs,
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Runs ``python -m mjx_arm.babble`` with `argv` (default: sys.argv[1:]): prints each file
    written and a JSON summary (wall seconds, processes, devices, files) on process 0.

    Returns:
      0 (exit status); a bad command line exits 2 before any work (`parse_args`).
    """
    args = parse_args(argv)
    if args.distributed:
        # Cross-process collectives on the CPU: jax 0.10.2's default, set in case another is.
        if not os.environ.get("JAX_CPU_COLLECTIVES_IMPLEMENTATION"):
            jax.config.update("jax_cpu_collectives_implementation", "gloo")
        jax.distributed.initialize(
            coordinator_address=args.coordinator,
            num_processes=args.num_processes,
            process_id=args.process_id,
        )
    lock = None
    if not args.distributed or jax.process_index() == 0:  # the one process that writes
        try:  # beside the folder, which a run replaces as a whole
            lock = run_folder.lock_folder(args.out, beside=True)
        except run_folder.FolderBusyError as err:
            build_parser().error(f"--out: {err}")
    try:
        machine.enable_compilation_cache(args.cache_dir or None)
        start = time.perf_counter()
        paths = run(args.config, args.out, model_path=args.model, progress=not args.no_progress)
    finally:
        if lock is not None:
            lock.release()
    for path in paths:
        print(path)
    if paths:
        summary = {
            "seconds": round(time.perf_counter() - start, 2),
            "processes": jax.process_count(),
            "devices": jax.device_count(),
            "files": [str(p) for p in paths],
        }
        print(json.dumps(summary))
    return 0
