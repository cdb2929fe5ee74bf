"""`ccgan.distill_range`: one translator for a range of media, G_c conditioned on the target.

Issue 51. A translator of `ccgan.distill` belongs to one pair of media at one k. This stage
teaches one G_c for every medium of drag ratio r in [2, 30] and stiffness scale s in [0.6, 1]
(`mjx_arm.media`'s terms; the paper's D_c is (10, 1), the aged arm (10, 0.7)):

1. media (`ccgan.distill_range.media`): `--n-media` training media sampled over the range, each
   at least `--min-separation` from the held-out media (`--held-out`: the corners, D_c, the aged
   arm and two inside by default), which teach nothing and pick nothing. Each training medium's
   63% step time is measured in MuJoCo C and its k set by the rule k = 0.526 t63
   (`ccgan.media_range`);
2. teacher (`ccgan.distill_range.teacher`): the MJX receding-horizon tracker plans every
   medium's programs in that medium, all media of one k in one call (`tracking.mpc_mjx.track`
   with media);
3. imitation (`ccgan.distill_range.imitation`): the start translators' G_c, widened to take the
   condition (log r, log s scaled to [0, 1]) at every step with zero weights (so it starts as
   the start translator in every medium), is trained to reproduce the teacher's commands with
   `ccgan.distill`'s step, and each seed's iterate is picked by the held-out programs of the
   training media, each scored in its own medium at its own k (MuJoCo C).

Writes DIR/translator_seed<s>.ckpt (translator.ckpt: the first), labelled method
"distill_range", target domain "media_range", recording the range, the training and held-out
media and the fitted step-time model, and DIR/distill_range.json (the run and its history); the
teacher's commands are cached in DIR/teacher.npz, shard by shard. SIGTERM stops the teacher
after its chunk of source steps, or training after its epoch (its state in
DIR/training_state.npz), and exits 143: rerun the same command to go on. --max-wall-s stops the
teacher the same way, and training keeping the best iterate so far (as `ccgan.distill`).

    python -m ccgan.distill_range --out DIR            # the range on one GPU (PAPER_SETTINGS)
    python -m ccgan.distill_range --out DIR --quick    # a few minutes on a CPU, to try the path

The teacher can be planned in parts at once on one GPU (the tracker is latency-bound), each
part the media of some k, then read by the run that trains:

    python -m ccgan.distill_range --out DIR/part0 --teacher-ks 60 5 &    # ... one per part
    python -m ccgan.distill_range --out DIR/range --teacher-from DIR/part0 DIR/part1 ...

Any flag overrides its preset (e.g. --n-media 32 --epochs 900). Then:

    import ccgan, mjx_arm
    translator = ccgan.load_translator("DIR/translator.ckpt", method="distill_range",
                                       target_domain="media_range")
    commands_c, k = translator.translate(pressures_s, poses_s,
                                         target=mjx_arm.Domain(viscosity_scale=30.0,
                                                               stiffness_scale=0.8))
    commands_c, k = translator.translate(pressures_s, poses_s, target=(15.0, 0.8))

and `python -m eval.media_range --translators DIR/translator_seed*.ckpt --out PREFIX` scores it
against stretch only over media in the true simulator.
"""

from __future__ import annotations

import dataclasses
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

import mjx_arm
from ccgan.distill.config import DistillConfig
from ccgan.distill.imitation import (
    _resume_key,
    init_imitation,
    train_with_resume,
    with_generator_unroll,
)
from ccgan.distill.teacher import _stop_check
from ccgan.distill_range.config import RangeConfig
from ccgan.distill_range.imitation import (
    make_range_validation,
    range_data,
    start_history,
)
from ccgan.distill_range.media import (
    Medium,
    measure_media,
    media_range_of,
    medium_arm,
    sample_training_media,
)
from ccgan.distill_range.teacher import teacher_over_media
from ccgan.media_range import MediaRange
from ccgan.translator import Translator
from mjx_arm.identify_family import resolved_viscosity_scale
from tracking import mpc_mjx

__all__ = [
    "Medium",
    "RangeConfig",
    "distill_range",
    "main",
    "plan_media",
]


def plan_media(range_config: RangeConfig, arm_c, log=print) -> tuple[list[Medium], MediaRange]:
    """(the training media with their step times and k, the `MediaRange` a translator taught
    on them records): sampled (`sample_training_media`), measured in MuJoCo C on the arm of
    `arm_c`'s MJCF in each medium (`measure_media`)."""
    training = measure_media(arm_c, sample_training_media(range_config), log)
    return training, media_range_of(range_config, training, resolved_viscosity_scale(arm_c))


def distill_range(
    translators: list[Translator],
    arm_s,
    arm_c,
    training: list[Medium],
    media_range: MediaRange,
    config: DistillConfig,
    cache: Path | None = None,
    progress: bool = True,
    log=print,
    on_validation=None,
    stop: threading.Event | None = None,
    resume: Path | None = None,
    teacher_from: tuple[Path, ...] = (),
) -> tuple[list[dict], dict]:
    """Trains each conditioned translator's G_c to reproduce the teacher's commands over media.

    Args:
      translators: conditioned translators (`ccgan.models.with_condition_inputs`; the same
        generator shape and bounds), one per seed.
      arm_s, arm_c: the D_s arm and the D_c arm of the same MJCF (the teacher's family base).
      training: the training media with their k (`plan_media`).
      media_range: the range recorded with them: the condition's scaling.
      config: settings (as `ccgan.distill`'s; n_train etc. per medium, teacher_backend "mjx").
      cache, on_validation, stop, resume: as `ccgan.distill.distill`'s.
      teacher_from: caches of teacher parts (`teacher_over_media`'s) to start from.

    Returns:
      (best G_c parameters per translator, history: "train_loss" [epochs, S], "val" {epoch:
      {"score", "window", "whole"} [S], "by_medium" [S, M]} cm, "teacher_val_x_err_cm" and
      "stretch_val_x_err_cm" ({"score", "by_medium" [M]}), "media" [M] (r, s, t63_s, k),
      "best_epoch" [S], "best_val_x_err_cm" [S], "val_x_err_cm_before" [S], "wall_s",
      "complete").
    """
    t0 = time.perf_counter()
    translators = with_generator_unroll(translators, config.generator_unroll)
    should_stop = _stop_check(config, t0, stop)
    teacher = teacher_over_media(
        config, training, arm_s, arm_c, cache, log, progress, should_stop,
        teacher_from=teacher_from,
    )  # fmt: skip
    data = range_data(teacher, training, media_range, translators[0].bounds, config.window_s)
    step, stacked, opt_state = init_imitation(translators, config, data)
    score_arms = [
        medium_arm(arm_c, m.drag_ratio, m.stiffness_scale).planning_copy(config.score_substeps)
        for m in training
    ]
    validate = make_range_validation(translators[0], score_arms, training, data)
    media_key = [[m.drag_ratio, m.stiffness_scale, m.k] for m in training]
    key = _resume_key(config, media_key, stacked)

    def start_line(history: dict) -> str:
        return (
            f"held-out X_err (cm; mean over {len(training)} training media): before"
            f" {np.round(history['val'][0]['score'], 4).tolist()}; teacher"
            f" {history['teacher_val_x_err_cm']['score']:.4f}; stretch only"
            f" {history['stretch_val_x_err_cm']['score']:.4f}"
        )

    return train_with_resume(
        config, step, stacked, opt_state, data, len(data.s_train), validate,
        lambda: start_history(score_arms, training, data), start_line,
        key=key, resume=resume, on_validation=on_validation, t0=t0, desc="distill_range",
        progress=progress, log=log, stop=stop,
    )  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    """CLI: `python -m ccgan.distill_range --out DIR [--quick] [flags]` (the module doc)."""
    from ccgan.distill_range import cli
    from mjx_arm.machine import cpu_model, enable_compilation_cache

    p, a, range_config, config = cli.parse(argv, __doc__)
    try:
        arm_s, arm_c = (mjx_arm.load(a.model, domain=d) for d in ("source", "constrained"))
    except (FileNotFoundError, ValueError) as err:
        p.error(f"--model {a.model}: {err}")
    sources, translators = cli.start_translators(p, a, arm_c.model_hash)
    enable_compilation_cache()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    import jax

    dev = jax.devices()[0]
    training, media_range = plan_media(range_config, arm_c)
    run = {
        "command": "python -m ccgan.distill_range "
        + " ".join(sys.argv[1:] if argv is None else argv),
        "machine": f"{cpu_model()}; JAX device: {dev.platform} ({dev.device_kind})",
        "range_config": dataclasses.asdict(range_config),
        "config": dataclasses.asdict(config),
        "model": str(a.model),
        "model_hash": arm_c.model_hash,
        "method": cli.METHOD,
        "sources": [str(x) for x in a.translators],
        "seeds": a.seeds,
        "media_range": media_range.to_dict(),
    }
    write = cli.writer(out, sources, translators, a.seeds, media_range, arm_c.model_hash, run)
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    parts = tuple(Path(d) / "teacher.npz" for d in a.teacher_from)
    try:
        if a.teacher_ks:  # a part of the teacher, then stop
            ks = sorted({m.k for m in training})
            if set(a.teacher_ks) - set(ks):
                p.error(f"--teacher-ks {a.teacher_ks}: the training media's k are {ks}")
            t0 = time.perf_counter()
            teacher_over_media(
                config, training, arm_s, arm_c, out / "teacher.npz", progress=True,
                should_stop=_stop_check(config, t0, stop), only_ks=tuple(a.teacher_ks),
                teacher_from=parts,
            )  # fmt: skip
            print(
                f"wrote {out / 'teacher.npz'}: k {a.teacher_ks} ({time.perf_counter() - t0:.0f} s)"
            )
            return
        params, history = distill_range(
            translators, arm_s, arm_c, training, media_range, config,
            cache=out / "teacher.npz", on_validation=write, stop=stop,
            resume=out / "training_state.npz", teacher_from=parts,
        )  # fmt: skip
    except mpc_mjx.TrackingStopped as err:
        print(f"teacher: {err}: rerun the same command to go on", file=sys.stderr)
        sys.exit(128 + signal.SIGTERM)
    finally:
        signal.signal(signal.SIGTERM, previous)
    write(params, history)
    print(
        f"wrote {out}: held-out X_err (cm, mean over {len(training)} training media) before"
        f" {np.round(history['val_x_err_cm_before'], 4).tolist()} -> best"
        f" {np.round(history['best_val_x_err_cm'], 4).tolist()} at epochs"
        f" {history['best_epoch']}; teacher {history['teacher_val_x_err_cm']['score']:.4f};"
        f" stretch only {history['stretch_val_x_err_cm']['score']:.4f};"
        f" {history['wall_s']:.1f} s"
    )
    if stop.is_set():
        print("stopped by SIGTERM: rerun the same command to go on", file=sys.stderr)
        sys.exit(128 + signal.SIGTERM)
