"""`ccgan.distill`: G_c fine-tuned by imitation of the simulator's receding-horizon tracker.

The stage's jobs, one module each:
- `config`: `DistillConfig`, its settings;
- `teacher`: the programs, the teacher's commands for them and their cache (`teacher.npz`,
  keyed by everything that made it);
- `hold`: the hold factor k: set, the translators' own, or chosen in the teaching arm;
- `imitation`: the training data, the Adam step, the held-out score and a stopped run's
  training state;
- `cli`: the command line's parser and its checks (`python -m ccgan.distill`, whose help is
  `ccgan.distill.cli`'s docstring) and what it writes (the lineage of each file).

`distill` (the library call) and `main` (the command) are here, where every name they compose
is the package's own: a caller may replace one of them (a test spies on `make_validation`).
"""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

import mjx_arm  # noqa: F401  (before jax: sets the XLA CPU flag)
from ccgan.cli import config_from_args
from ccgan.distill.cli import (
    PAIR_FIXED,
    adopt_teacher_from,
    build_parser,
    check_teacher_from,
    plan_teacher_only,
    read_teach_domain,
    record_lineage,
    summary,
    teach_on,
    writer,
)
from ccgan.distill.config import ConfigError, DistillConfig
from ccgan.distill.hold import choose_hold_factor
from ccgan.distill.imitation import (
    ImitationData,
    _new_history,
    _resume_key,
    head_weights,
    imitation_data,
    init_imitation,
    make_validation,
    train_with_resume,
    window_and_whole_x_err_cm,
    with_generator_unroll,
)
from ccgan.distill.teacher import (
    _stop_check,
    adopt_teacher,
    held_out_programs,
    read_cache_key,
    teacher_cache_key,
    teacher_data,
)
from ccgan.stage import common_k, start_stage
from ccgan.translator import Translator
from tracking import mpc, mpc_mjx

__all__ = [
    "ConfigError",
    "DistillConfig",
    "ImitationData",
    "adopt_teacher",
    "build_parser",
    "choose_hold_factor",
    "distill",
    "head_weights",
    "held_out_programs",
    "imitation_data",
    "init_imitation",
    "main",
    "make_validation",
    "mpc",
    "mpc_mjx",
    "read_cache_key",
    "start_stage",
    "teacher_cache_key",
    "teacher_data",
    "window_and_whole_x_err_cm",
    "with_generator_unroll",
]


def distill(
    translators: list[Translator],
    arm_s,
    arm_c,
    config: DistillConfig,
    cache: Path | None = None,
    progress: bool = True,
    log=print,
    on_validation=None,
    stop: threading.Event | None = None,
    resume: Path | None = None,
    hold: tuple[int, dict | None] | None = None,
) -> tuple[list[dict], dict]:
    """Trains each translator's G_c to reproduce the teacher's commands.

    Args:
      translators: trained translators (the same generator shape; the same k unless
        `config.hold_factor` sets one or `config.k_candidates` chooses one), one per seed.
      arm_s, arm_c: the D_s arm and the D_c arm the teacher plans in and the iterates are scored
        in: the target itself, or an arm identified from its data (`ccgan.distill
        --teach-domain`).
      config: settings.
      cache: file for the teacher's commands (read when its key matches, `teacher_cache_key`;
        else planned and written, a cache of another key first moved aside).
      on_validation: optional callable(best parameters per translator, history), called after
        every validation but the first with the best iterates so far (e.g. to write them, so
        that a killed run keeps its progress); the history then has "complete": False.
      stop: once set (e.g. by SIGTERM), the teacher stops after its chunk of source steps
        (`TrackingStopped`) or training after its epoch, as at `config.max_wall_s`.
      resume: a file for the training state: written when `stop` stops training (after that
        epoch's validation), read at the start when saved for the same settings and
        translators, so that a stopped run goes on from its next epoch instead of from the
        start (a distillation of 240 epochs takes 200-250 s of one H100, longer than what a
        deadline leaves of a 10-minute call); removed when training ends otherwise.
      hold: (k, how it was chosen) from `choose_hold_factor`, when the caller has it already
        (the command line chooses once for its teacher and its training); None: chosen here.

    Returns:
      (best G_c parameters per translator, history: "train_loss" [epochs, S] (weighted mean
      squared normalised pressure error), "val" {epoch: {"score", "window", "whole"} [S] cm},
      "teacher_val_x_err_cm" and "stretch_val_x_err_cm" (whole, window), "best_epoch" [S]
      (0: the original was best),
      "best_val_x_err_cm" [S], "val_x_err_cm_before" [S] (at this k), "k", "wall_s", and
      "k_choice" where k was chosen (`choose_hold_factor`'s record)).
    """
    k, k_choice = hold or choose_hold_factor(config, translators, arm_s, arm_c, log)
    n_train = config.n_train_programs  # >= batch_size (DistillConfig checks)
    t0 = time.perf_counter()
    translators = with_generator_unroll(translators, config.generator_unroll)

    should_stop = _stop_check(config, t0, stop)
    data = imitation_data(
        config, translators[0], arm_s, arm_c, k, cache, log, progress, should_stop
    )
    step, stacked, opt_state = init_imitation(translators, config, data)
    score_arm = arm_c.planning_copy(config.score_substeps)
    validate = make_validation(translators[0], score_arm, k, data)
    key = _resume_key(config, k, stacked)

    def new_history() -> dict:
        history = _new_history(score_arm, k, data)
        if k_choice is not None:
            history["k_choice"] = k_choice
        return history

    def start_line(history: dict) -> str:
        teacher = history["teacher_val_x_err_cm"]
        return (
            f"held-out X_err (cm; mean of first {config.window_s} s and whole): before"
            f" {np.round(history['val'][0]['score'], 4).tolist()}; teacher: window"
            f" {teacher['window']:.4f}, whole {teacher['whole']:.4f}"
        )

    return train_with_resume(
        config, step, stacked, opt_state, data, n_train, validate, new_history, start_line,
        key=key, resume=resume, on_validation=on_validation, t0=t0, desc="distill",
        progress=progress, log=log, stop=stop,
    )  # fmt: skip


def main(argv=None) -> None:
    """CLI: `python -m ccgan.distill --translators A.ckpt [B.ckpt ...] --out DIR`."""
    p = build_parser()
    a = p.parse_args(argv)
    if not a.translators and not a.teacher_only:
        p.error("--translators is required (only --teacher-only plans without translators)")
    config = config_from_args(p, a, DistillConfig, skip=PAIR_FIXED)
    if not a.translators and config.hold_factor == 0 and not config.k_candidates:
        p.error("--teacher-only without --translators needs --hold-factor (k) or --k-candidates")
    check_teacher_from(p, a)
    taught = read_teach_domain(p, a)
    stage = start_stage(p, a, "ccgan.distill", dataclasses.asdict(config), argv)
    record_lineage(p, a, stage)
    if taught is not None:
        stage = teach_on(p, a, stage, taught)
    if config.hold_factor == 0 and not config.k_candidates:
        try:
            common_k(stage.translators)
        except ValueError as err:
            p.error(f"{err}: give --hold-factor or --k-candidates")
    # Chosen once, in the arm the teacher plans in: the teacher's key and the training need it.
    hold = choose_hold_factor(config, stage.translators, stage.arm_s, stage.arm_c)
    if a.teacher_from:
        adopt_teacher_from(p, a, config, stage, hold[0])

    # SIGTERM (a time limit, experiments.stages at its deadline) stops the teacher after its
    # chunk of source steps (its progress kept) or training after its epoch (its best iterates
    # written); exit status 143 says the run is unfinished: rerun the same command to go on.
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        _run(a, config, stage, stop, hold)
    except mpc_mjx.TrackingStopped as err:
        print(f"teacher: {err}: rerun the same command to go on", file=sys.stderr)
        sys.exit(128 + signal.SIGTERM)
    finally:
        signal.signal(signal.SIGTERM, previous)
    if stop.is_set():
        print("stopped by SIGTERM: rerun the same command to go on", file=sys.stderr)
        sys.exit(128 + signal.SIGTERM)


def _run(
    a: argparse.Namespace, config: DistillConfig, stage, stop: threading.Event, hold: tuple
) -> None:
    """`main`'s work: the teacher only, or the whole distillation, at `hold`'s k
    (`choose_hold_factor`)."""
    if a.teacher_only:
        plan_teacher_only(config, stage, stop, hold[0])
        return
    write = writer(stage)
    params, history = distill(
        stage.translators,
        stage.arm_s,
        stage.arm_c,
        config,
        cache=stage.out / "teacher.npz",
        on_validation=write,
        stop=stop,
        resume=stage.out / "training_state.npz",
        hold=hold,
    )
    write(params, history)
    print(summary(stage.out, history))
