"""The CCGAN-GP study: Optuna over the training settings, each trial scored in the D_c simulator.

`python -m ccgan.tune --source S_train.npz S_val.npz --constrained C_train.npz C_val.npz
--model models/softarm.xml --forward-workdir DIR --n-trials 64 --trials-per-batch 16` searches the
loss weights (adversarial is the reference, 1), both learning rates, the window length, the critic
steps and the generator kind. A trial's value is the held-out tracking error in the target-domain
simulator: its G_c translates the held-out D_s programs, each command is held k periods from rest
in the D_c arm, every k-th pose is compared with the D_s poses, and k is chosen there from
`--hold-factors` (`ccgan.sim_choice`, as the authors' code chooses it). The five shapes are never
used.

Trials run in batches (`--trials-per-batch`): Optuna's ask/tell hands out a batch, whose settings
differ only in numbers, so they train as one vmapped program (`ccgan.batch`). Each batch takes
one structural combination (window length, critic steps, generator kind), in turn; TPE samples
the numbers with the structure fixed (`optuna.samplers.PartialFixedSampler`). Every
`--stretch-every` epochs each live trial is scored and reported; the median pruner stops those
below the median of the finished trials at that epoch, which spares their simulator rollouts.

The study lives in Optuna's own storage (`--storage`: an SQLite file, or with a `.log` suffix a
journal file that processes on several machines can share), so trials can run in several
processes or on several machines; rerunning the command adds `--n-trials` more. The sampler's seed
is `--seed` plus the trials stored. Writes `tune.md`, `tune.json` and `tune_history.png` into
`--report-dir`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import sys
import time
from pathlib import Path

import jax
import optuna

from ccgan import data as data_lib
from ccgan import forward as forward_lib
from ccgan.cli import (
    add_config_flags,
    add_data_flags,
    check_output_dir,
    cli_parser,
    config_from_args,
    data_from_args,
)
from ccgan.config import TrainConfig, check_forward_config

# Imports marked F401 keep the study's API importable as ccgan.tune.<name>.
from ccgan.tune_report import structure_lines, summary, write_report  # noqa: F401
from ccgan.tune_study import (  # noqa: F401
    NUMERIC,
    STRUCTURAL,
    TUNED,
    ForwardCache,
    SearchSpace,
    n_stored,
    run_study,
    storage_url,
    suggest,
)
from mjx_arm.dataset import DatasetError
from mjx_arm.machine import cpu_model


def build_parser() -> argparse.ArgumentParser:
    """The options of `python -m ccgan.tune`."""
    parser = cli_parser("ccgan.tune", __doc__)
    add_data_flags(parser)
    parser.add_argument(
        "--storage", default="runs/tune/tune.db", help="SQLite file, or a .log journal file"
    )
    parser.add_argument("--study-name", default="ccgan", help="the study's name in --storage")
    parser.add_argument("--n-trials", type=int, default=16, help="trials to add in this run")
    parser.add_argument(
        "--trials-per-batch", type=int, default=8, help="trials trained as one vmapped program"
    )
    parser.add_argument("--seed", type=int, default=0, help="sampler and training seed")
    parser.add_argument("--timeout-s", type=float, default=None, help="no new batch after this")
    parser.add_argument(
        "--backend", choices=("c", "mjx"), default="c", help="simulator of the scoring rollouts"
    )
    parser.add_argument(
        "--report-dir", default="runs/tune", help="folder for tune.md, .json, _history.png"
    )
    parser.add_argument(
        "--forward-workdir", default=None, help="reuse DIR/forward_c.ckpt (a ccgan.train workdir)"
    )
    parser.add_argument("--note", default="", help="a paragraph put at the top of tune.md")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="rewrite the report of the stored study from --storage and --report-dir/tune.json"
        " (the run's command, machine and times kept); run no trial",
    )
    add_config_flags(parser, forward_lib.ForwardConfig, prefix="forward-")
    add_config_flags(parser, SearchSpace, prefix="space-")
    add_config_flags(parser, TrainConfig, skip=TUNED)
    # A reduced budget per trial, scored (and pruned) twice.
    parser.set_defaults(epochs=50, stretch_every=25)
    return parser


def main(argv=None) -> None:
    """CLI: `python -m ccgan.tune --source S.npz... --constrained C.npz... [--n-trials N ...]`.

    Every option and data file is checked before any trial runs (usage errors, status 2).
    """
    import mjx_arm

    parser = build_parser()
    args = parser.parse_args(argv)
    if args.report_only:
        old = Path(args.report_dir) / "tune.json"
        if not old.is_file() or not Path(args.storage).is_file():
            parser.error(f"--report-only needs {old} and --storage {args.storage}")
        extra = json.loads(old.read_text())
        study = optuna.load_study(study_name=args.study_name, storage=storage_url(args.storage))
        note = extra.pop("note", "")
        paths = write_report(summary(study, extra), args.report_dir, note)
        print("wrote", ", ".join(str(p) for p in paths.values()))
        return
    base = config_from_args(parser, args, TrainConfig, skip=TUNED)
    if base.k_choice_simulator != "chain":
        parser.error(
            "--k-choice-simulator rod: a study scores its trials in the chain's D_c arm only;"
            " train on the rod's data with python -m ccgan.train --k-choice-simulator rod"
        )
    fconf = config_from_args(
        parser, args, forward_lib.ForwardConfig, prefix="forward-", check=check_forward_config
    )
    space = config_from_args(parser, args, SearchSpace, prefix="space-")
    if args.n_trials < 1:
        parser.error(f"--n-trials must be >= 1, got {args.n_trials}")
    if args.trials_per_batch < 1:
        parser.error(f"--trials-per-batch must be >= 1, got {args.trials_per_batch}")
    if args.timeout_s is not None and not args.timeout_s > 0:
        parser.error(f"--timeout-s must be > 0, got {args.timeout_s}")
    check_output_dir(parser, "--report-dir", args.report_dir)
    check_output_dir(parser, "--storage's folder", Path(args.storage).parent)
    if Path(args.storage).is_dir():
        parser.error(f"--storage {args.storage} is a folder, not a storage file")
    if args.forward_workdir is not None:
        fc = Path(args.forward_workdir) / "forward_c.ckpt"
        if not fc.is_file():
            parser.error(f"--forward-workdir {args.forward_workdir}: no {fc}")
    d_s, d_c = data_from_args(parser, args)
    try:
        split_notes = data_lib.check_slot_splits(base.n_val, d_s, d_c)
    except DatasetError as err:
        parser.error(str(err))
    for note in split_notes:
        print(f"NOTE: {note}", file=sys.stderr)
    try:
        arm_c = mjx_arm.load(args.model, domain=d_c.domain)
    except (FileNotFoundError, ValueError) as err:
        parser.error(f"--model {args.model}: {err}")
    if arm_c.model_hash != d_c.model_hash:
        parser.error(
            f"the trials are scored in {arm_c.path} (model hash {arm_c.model_hash}), but the"
            f" data come from an arm with hash {d_c.model_hash}: pass that arm's MJCF as --model"
        )
    bounds = data_lib.union_bounds(d_s.bounds, d_c.bounds)

    from mjx_arm.machine import enable_compilation_cache

    enable_compilation_cache()
    start = time.perf_counter()
    n_before = n_stored(args.storage, args.study_name)
    study = run_study(
        base,
        (d_s.pressures_bar, d_s.poses, d_c.pressures_bar, d_c.poses, bounds),
        arm_c,
        args.storage,
        args.study_name,
        args.n_trials,
        space,
        fconf,
        args.forward_workdir,
        args.seed,
        args.timeout_s,
        args.trials_per_batch,
        args.backend,
        progress=not args.no_progress,
        arm_s=mjx_arm.load(args.model, domain="source")
        if base.k_choice_programs == "shape_like"
        else None,
    )
    extra = {
        "command": "python -m ccgan.tune " + shlex.join(sys.argv[1:] if argv is None else argv),
        "machine": cpu_model(),
        "device_kind": jax.devices()[0].device_kind,
        "wall_time_s": time.perf_counter() - start,
        "new_trials": len(study.trials) - n_before,
        "storage": str(args.storage),
        "seed": args.seed,
        "base_config": base.to_dict(),
        "forward_config": dataclasses.asdict(fconf),
        "search_space": dataclasses.asdict(space),
    }
    paths = write_report(summary(study, extra), args.report_dir, args.note)
    print("wrote", ", ".join(str(p) for p in paths.values()))


if __name__ == "__main__":
    main()
