"""CCGAN-GP training (and the WCGAN-GP baseline) from babbling files: `python -m ccgan.train`.

First trains the forward models F_s and F_c (`ccgan.forward_stage`), then the CCGAN against the
frozen F_c (`ccgan.training_run.train_and_evaluate`, whose pure step and epoch functions are
`ccgan.trainer`'s). Every option and data file is checked before any work: the files of each slot
must belong together, and no trajectory may be both trained on and held out
(`ccgan.data.check_slot_splits`). The settings (`TrainConfig`) live in `ccgan.config`, the flags
made from them in `ccgan.cli`.

The paper's setting in the reference rod: babble with ``python -m mjx_arm.babble --backend rod``
(files labelled with the rod's model hash) and train with ``--k-choice-simulator rod``: k is
then chosen in `mjx_arm.load_rod(target domain)` as the authors' code chooses it in its own
simulator (`ccgan.sim_choice`: one padded batch per scoring on a GPU, ~80-100 s at k up to 30),
and the translator files record the rod's model hash. Rod data with k chosen in the chain (or
the chain's data in the rod), one slot's rod data beside the other's chain data, chain
--forward-data beside rod data, and --model with rod data are refused before any work.

The names a training script needs stay importable from here (`make_train`, `train_and_evaluate`,
`train_forward_models`, `METRICS`, ...).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from pathlib import Path

import numpy as np

# Imports marked F401 keep the library's API importable as ccgan.train.<name> (the one import a
# training script needs).
from ccgan import checkpoint
from ccgan.best_generators import BestGenerators, simulator_choice_hook  # noqa: F401
from ccgan.cli import (
    add_config_flags,
    add_data_flags,
    cli_parser,
    config_from_args,
    data_from_args,
    describe_arm,
    lock_output_dir,
)
from ccgan.config import (
    FEEDBACK_IMPLS,
    K_CHOICE_PROGRAMS,
    K_CHOICE_SIMULATORS,
    TrainConfig,
    check_forward_config,
)
from ccgan.data import TranslationData, check_unseen, read_domain
from ccgan.forward import ForwardConfig
from ccgan.forward_stage import (  # noqa: F401
    FORWARD_FILES,
    copy_forward_models,
    forward_meta,
    forward_splits,
    train_forward_models,
)
from ccgan.run_files import (  # noqa: F401
    data_fingerprint,
    read_rows,
    resume_expectation,
    write_rows,
)
from ccgan.trainer import (  # noqa: F401
    METRICS,
    Trainer,
    TrainState,
    check_data,
    generator,
    init_each,
    make_train,
    make_trainer,
    resolved_feedback_impl,
)
from ccgan.training_run import train_and_evaluate  # noqa: F401
from tracking.config import ConfigError  # noqa: F401  (kept importable as ccgan.train.ConfigError)


def load_npz(*paths: str | os.PathLike):
    """Concatenated (pressures [N, T, 3] bar, poses [N, T, 6], bounds) of one domain's files.

    The files are read and checked by `ccgan.data.read_domain` (one domain, one arm, one program
    length; a corrupt file raises `mjx_arm.dataset.DatasetError` naming it); the bounds span
    every file's. List the validation file last (the last `n_val` trajectories are held out).
    """
    d = read_domain(paths)
    return d.pressures_bar, d.poses, d.bounds


def check_k_choice_simulator(parser, args, config: TrainConfig, d_c) -> None:
    """Usage error unless k is chosen in the simulator the data came from (with --k-choice
    simulator): rod data (`mjx_arm.babble --backend rod`, model hash "rod-...") need
    --k-choice-simulator rod, the chain's need chain. A translator whose k was chosen in another
    simulator than its data's would be tuned for a world it was not trained in, and its file's
    model hash (the data's) would not say where k came from."""
    from ccgan.sim_choice import simulator_of

    if config.k_choice != "simulator" or args.forward_only:
        return
    data_sim = simulator_of(d_c.model_hash)
    if data_sim != config.k_choice_simulator:
        rod = "the reference rod (mjx_arm.babble --backend rod)"
        where = rod if data_sim == "rod" else "the chain (an MJCF)"
        parser.error(
            f"--k-choice-simulator {config.k_choice_simulator}: the data were simulated by"
            f" {where}, model hash {d_c.model_hash}; choose k in the data's simulator with"
            f" --k-choice-simulator {data_sim} (or --k-choice forward)"
        )


def simulator_choice_from_args(parser, args, config: TrainConfig, data: TranslationData, d_c):
    """The `ccgan.sim_choice.SimulatorChoice` of --k-choice simulator: the target domain's arm
    from --model (default `models/softarm.xml`), which must be the arm the data came from; with
    --k-choice-simulator rod, the reference rod in the target domain (`mjx_arm.load_rod`), whose
    model hash the data must carry (`check_k_choice_simulator` has checked the simulator)."""
    import mjx_arm
    from ccgan.sim_choice import SimulatorChoice

    label = None if args.no_progress else "k in the simulator"
    if config.k_choice_simulator == "rod":
        rod = mjx_arm.load_rod(d_c.domain)
        if d_c.model_hash != rod.model_hash:
            parser.error(
                f"--k-choice-simulator rod scores k in the reference rod (model hash"
                f" {rod.model_hash}), but the data come from a rod with hash {d_c.model_hash}"
                " (other physical values): babble again with python -m mjx_arm.babble"
                " --backend rod"
            )
        source_rod = None
        if config.k_choice_programs == "shape_like":
            source_rod = mjx_arm.load_rod("source")
        return SimulatorChoice(rod, data, config, progress=label, source_arm=source_rod)
    arm = mjx_arm.load(args.model, domain=d_c.domain)
    if d_c.model_hash is not None and d_c.model_hash != arm.model_hash:
        parser.error(
            f"--k-choice simulator scores k on {arm.path} (model hash {arm.model_hash}), but the"
            f" data come from an arm with hash {d_c.model_hash}: pass that arm's MJCF as --model"
        )
    arm = arm.planning_copy(config.k_choice_substeps)
    source_arm = None
    if config.k_choice_programs == "shape_like":
        source_arm = mjx_arm.load(args.model, domain="source")
    return SimulatorChoice(arm, data, config, progress=label, source_arm=source_arm)


def forward_splits_from_args(parser, args, config: TrainConfig, data, d_s, d_c) -> dict:
    """`forward_splits` of --forward-window and --forward-data (usage errors for bad ones)."""
    from mjx_arm.dataset import DatasetError

    window = args.forward_window or config.window_length
    if window < 1:
        parser.error(f"--forward-window must be at least 1, got {window}")
    forward_c = None
    if args.forward_data:
        try:
            forward_c = read_domain(args.forward_data, "constrained")
        except DatasetError as err:
            parser.error(f"--forward-data: {err}")
        if forward_c.model_hash != d_c.model_hash:  # another arm, or the rod beside the chain
            parser.error(
                f"--forward-data {', '.join(forward_c.paths)}: simulated by"
                f" {describe_arm(forward_c)}, but --constrained by {describe_arm(d_c)}; F_c must"
                " learn the arm the CCGAN's data come from"
            )
        try:  # F_c is scored on the CCGAN's held-out D_c programs: it must not train on them
            check_unseen(d_c, config.n_val, forward_c, "--forward-data")
        except DatasetError as err:
            parser.error(str(err))
        if forward_c.domain != d_c.domain:
            parser.error(
                f"--forward-data holds domain {forward_c.domain!r}, --constrained {d_c.domain!r}"
            )
    shortest = min(d.pressures_bar.shape[1] for d in (d_s, forward_c or d_c))
    if window > shortest:
        parser.error(
            f"--forward-window {window} is longer than the programs F_s / F_c train on"
            f" ({shortest} steps)"
        )
    try:
        return forward_splits(data, d_s, d_c, config, window, forward_c)
    except ValueError as err:
        parser.error(f"--forward-window / --forward-data: {err}")


def build_parser() -> argparse.ArgumentParser:
    """The options of `python -m ccgan.train`."""
    parser = cli_parser("ccgan.train", __doc__)
    add_data_flags(parser)
    parser.add_argument(
        "--workdir",
        default="runs/ccgan_train",
        help="output folder: state.ckpt, metrics.csv, forward_*.ckpt, translator*.ckpt",
    )
    parser.add_argument(
        "--seeds", type=int, nargs="+", default=[0], help="PRNG seeds, trained together"
    )
    parser.add_argument(
        "--no-resume",
        action="store_true",
        help="train afresh instead of continuing from the workdir's checkpoints",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.add_argument(
        "--forward-only", action="store_true", help="train F_s and F_c, then stop (no GAN)"
    )
    parser.add_argument(
        "--forward-from",
        metavar="DIR",
        default=None,
        help="take F_s and F_c from DIR (a --forward-only workdir) instead of training them;"
        " they must have been trained on the same data with the same --forward-* options",
    )
    parser.add_argument(
        "--forward-data",
        nargs="+",
        default=None,
        metavar="NPZ",
        help="D_c babbling files that F_c trains on instead of --constrained's training programs"
        " (the same arm and domain; e.g. holds long enough for the slow arm to settle)",
    )
    parser.add_argument(
        "--forward-window",
        type=int,
        default=0,
        help="control steps per F_s / F_c training window (0: --window-length); with"
        " --forward-open-loop, about the feedback horizon window_length x k",
    )
    add_config_flags(parser, ForwardConfig, prefix="forward-")
    add_config_flags(
        parser,
        TrainConfig,
        choices={
            "feedback_impl": FEEDBACK_IMPLS,
            "k_choice_programs": K_CHOICE_PROGRAMS,
            "k_choice_simulator": K_CHOICE_SIMULATORS,
        },
    )
    return parser


def main(argv=None) -> None:
    """CLI: `python -m ccgan.train --source S.npz... --constrained C.npz... --workdir DIR [...]`.

    Every option and every data file is checked before anything is computed or written; a bad
    one exits with status 2 and a message naming it.
    """
    from ccgan import data as data_lib
    from mjx_arm.dataset import DatasetError

    parser = build_parser()
    args = parser.parse_args(argv)
    config = config_from_args(parser, args, TrainConfig)
    fconf = config_from_args(
        parser, args, ForwardConfig, prefix="forward-", check=check_forward_config
    )
    if len(set(args.seeds)) != len(args.seeds):
        parser.error(f"--seeds must be distinct, got {args.seeds}")
    lock_output_dir(parser, "--workdir", args.workdir)  # one trainer per workdir
    d_s, d_c = data_from_args(parser, args)
    check_k_choice_simulator(parser, args, config, d_c)
    try:
        split_notes = data_lib.check_slot_splits(config.n_val, d_s, d_c)
    except DatasetError as err:
        parser.error(str(err))
    for note in split_notes:
        print(f"NOTE: {note}", file=sys.stderr)

    from mjx_arm.machine import enable_compilation_cache

    try:
        data = data_lib.prepare(
            d_s.pressures_bar,
            d_s.poses,
            d_c.pressures_bar,
            d_c.poses,
            config.window_length,
            config.n_val,
            config.stride,
            bounds=data_lib.union_bounds(d_s.bounds, d_c.bounds),
        )
        check_data(config, data)
    except ValueError as err:
        parser.error(f"the data do not suit the options: {err}")
    splits = forward_splits_from_args(parser, args, config, data, d_s, d_c)
    k_choice = None
    if config.k_choice == "simulator" and not args.forward_only:
        k_choice = simulator_choice_from_args(parser, args, config, data, d_c)
    enable_compilation_cache()
    workdir = Path(args.workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    f_meta = forward_meta(fconf, data, splits)
    fc_path = workdir / "forward_c.ckpt"
    if args.forward_from is not None:
        copy_forward_models(parser, Path(args.forward_from), workdir, f_meta)
    elif args.no_resume or not all((workdir / name).exists() for name in FORWARD_FILES):
        train_forward_models(
            fconf, data, workdir, progress=not args.no_progress, resume=not args.no_resume,
            splits=splits, f_meta=f_meta,
        )  # fmt: skip
    fc_params, _ = checkpoint.load(fc_path, expect=f_meta)
    if args.forward_only:
        return
    # SIGTERM (a time limit, experiments.stages at its deadline) stops the run after the epoch in
    # progress, with a checkpoint to resume from; exit status 143 says it is unfinished.
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    state, _ = train_and_evaluate(
        config,
        data,
        fc_params,
        workdir,
        seeds=tuple(args.seeds),
        resume=not args.no_resume,
        forward_model=fconf.model,
        progress=not args.no_progress,
        model_hash=d_s.model_hash,
        stop=stop,
        domains=(d_s.domain, d_c.domain),
        k_choice=k_choice,
    )
    epochs_done = int(np.asarray(state.epoch)[0])
    if epochs_done < config.epochs and stop.is_set():
        print(f"stopped at epoch {epochs_done}: rerun to resume", file=sys.stderr)
        sys.exit(128 + signal.SIGTERM)
    if epochs_done < config.epochs:  # not stopped: --patience ended it, its best written
        print(
            f"trained {epochs_done} of at most {config.epochs} epochs: {config.patience}"
            " scoring(s) in a row improved no seed (--patience)"
        )


if __name__ == "__main__":
    main()
