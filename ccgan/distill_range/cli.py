"""The command line of `python -m ccgan.distill_range`: its flags, its presets, the start
translators (checked, then widened to take the condition) and the files it writes."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import mjx_arm  # noqa: F401  (before jax: sets the XLA CPU flag)
from ccgan import checkpoint
from ccgan.cli import add_config_flags, cli_parser, config_from_args, lock_output_dir
from ccgan.distill.config import DistillConfig
from ccgan.distill_range.config import RangeConfig
from ccgan.media_range import MEDIA_RANGE, N_CONDITION, MediaRange
from ccgan.models import with_condition_inputs, with_hidden
from ccgan.translator import (
    TRANSLATORS_DIR,
    TRUST_FLAG,
    Translator,
    check_labels,
    translator_from_checkpoint,
)
from mjx_arm import constants

#: The method a conditioned translator file records (`ccgan.translator.METHODS`).
METHOD = "distill_range"
#: The default start translators: the committed chain's distilled D_c translators (three
#: seeds), the nearest to the teacher of any (held-out X_err 0.29 cm at D_c, k = 15). Their G_c
#: is widened to take the condition with zero weights (`ccgan.models.with_condition_inputs`),
#: so every medium starts from D_c's translation.
START_RUN = TRANSLATORS_DIR / "ccgan_sim"
START_SEEDS = (0, 1, 2)
#: Settings for the range on one GPU (`--quick` off): 24 training media (`RangeConfig`'s
#: defaults), each with 10 + 10 training and 1 + 1 held-out programs of 60 s, the per-pair
#: distillation's programs and planner (`ccgan.adapt.CHAIN_SETTINGS`): 480 training programs,
#: twice the per-pair stage's 240, and as many Adam steps per epoch over them.
PAPER_SETTINGS = (
    "--duration-s 60 --n-train 10 --n-train-full 10 --n-val 1 --n-val-full 1"
    " --teacher-shard 256 --window-s 60 --batch-size 80 --iterations 1 --teacher-substeps 2"
    " --learning-rate 1e-3 --final-lr-factor 0.02 --epochs 1840 --eval-every 460"
    " --generator-unroll 10 --score-substeps 5"
).split()
#: A tiny run to try the path on a CPU in a few minutes (not a useful translator): 3 training
#: media in a narrower range (r 2-5, s 0.8-1), whose rule gives k = 5 or 10, so that the MJX
#: tracker compiles twice (about 90 s each on one core), 2 training and 1 held-out program of
#: 2 s each, 3 epochs; 2 held-out media, a corner and one inside.
QUICK_SETTINGS = (
    "--drag-ratio-range 2 5 --stiffness-range 0.8 1 --n-media 3 --held-out 2 1 3.2 0.9"
    " --duration-s 2 --n-train 2 --n-val 1 --epochs 3 --batch-size 2 --eval-every 1"
    " --iterations 1 --teacher-substeps 5 --window-s 2 --generator-unroll 2 --score-substeps 5"
).split()
#: DistillConfig fields without a flag here: k is the rule's per medium (not set, not chosen
#: among candidates), the teacher is the MJX tracker, which plans one step ahead.
FIXED = ("hold_factor", "k_candidates", "k_choice_seconds", "teacher_backend", "horizon_steps")
#: DistillConfig fields set here from the range, without a flag: one set of training splits
#: per training medium.
FROM_RANGE = ("train_sets",)


def build_parser(doc: str = __doc__) -> argparse.ArgumentParser:
    """The options of `python -m ccgan.distill_range` (`doc`: its help's description, the
    package's docstring)."""
    p = cli_parser("ccgan.distill_range", doc)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--model", default=str(constants.TRANSLATOR_MODEL_PATH), help="the chain's MJCF")
    p.add_argument(
        "--translators",
        nargs="+",
        default=[str(START_RUN / f"translator_seed{s}.ckpt") for s in START_SEEDS],
        help="start translators (D_s -> one medium, of --model's arm), one per seed",
    )
    p.add_argument("--seeds", type=int, nargs="+", help="seed of each file (default 0, 1, ...)")
    p.add_argument(
        TRUST_FLAG, action="store_true", help="accept start translators that record no labels"
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="tiny settings (QUICK_SETTINGS), to try the path on a CPU in minutes; without it"
        " the one-GPU settings (PAPER_SETTINGS). A preset goes before the flags given, which"
        " override it: the defaults shown below are the fields' own, under the preset",
    )
    p.add_argument(
        "--teacher-ks",
        type=int,
        nargs="+",
        default=[],
        metavar="K",
        help="plan only the media of these k into --out/teacher.npz and stop: a part, so that"
        " processes planning different k run at once on one GPU (the tracker is latency-bound);"
        " the run that trains reads the parts with --teacher-from",
    )
    p.add_argument(
        "--teacher-from",
        nargs="+",
        default=[],
        metavar="DIR",
        help="folders of parts (runs with --teacher-ks and the same settings) whose teacher.npz"
        " shards join --out's before anything is planned; one planned otherwise is skipped",
    )
    p.add_argument(
        "--generator-hidden",
        type=int,
        metavar="H",
        help="LSTM units per layer of the conditioned G_c (default: the start's, 32): a wider G"
        " starts computing the start's translation (`ccgan.models.with_hidden`), its new units"
        " free to fit the media the start's cannot",
    )
    add_config_flags(p, RangeConfig)
    add_config_flags(p, DistillConfig, skip=FIXED + FROM_RANGE)
    return p


def parse(argv: list[str] | None, doc: str = __doc__):
    """(parser, arguments, RangeConfig, DistillConfig) of a command line: the preset
    (`QUICK_SETTINGS` with --quick, else `PAPER_SETTINGS`) first, so that every flag given
    overrides it. Bad settings, and an --out another process writes, are usage errors (status
    2), before any work."""
    argv = list(sys.argv[1:] if argv is None else argv)
    p = build_parser(doc)
    a = p.parse_args((QUICK_SETTINGS if "--quick" in argv else PAPER_SETTINGS) + argv)
    range_config, config = configs_from_args(p, a)
    if a.seeds is not None and len(a.seeds) != len(a.translators):
        p.error("give one seed per translator file")
    seeds = a.seeds if a.seeds is not None else list(range(len(a.translators)))
    if len(set(seeds)) != len(seeds):
        p.error(f"--seeds must be distinct, got {seeds}")
    a.seeds = seeds
    lock_output_dir(p, "--out", a.out)  # one writer per folder: its teacher.npz is rewritten
    return p, a, range_config, config


def configs_from_args(p: argparse.ArgumentParser, a) -> tuple[RangeConfig, DistillConfig]:
    """(RangeConfig, DistillConfig) of parsed flags: n_train etc. per medium, the MJX teacher."""
    range_config = config_from_args(p, a, RangeConfig)
    a.train_sets = range_config.n_media  # n_train etc. are per medium
    config = config_from_args(p, a, DistillConfig, skip=FIXED)
    return range_config, dataclasses.replace(config, teacher_backend="mjx")


def preset_configs(quick: bool = False) -> tuple[RangeConfig, DistillConfig]:
    """The configs a run of `python -m ccgan.distill_range` with no other flags uses (its
    preset: `QUICK_SETTINGS` or `PAPER_SETTINGS`), without a folder to lock: for studies
    that read a run's teacher (`studies.range_fit`)."""
    p = build_parser()
    a = p.parse_args([*(QUICK_SETTINGS if quick else PAPER_SETTINGS), "--out", "unused"])
    return configs_from_args(p, a)


def start_translators(
    p: argparse.ArgumentParser, a, model_hash: str
) -> tuple[list, list[Translator]]:
    """(the start files' (tree, meta), their translators widened to take the condition).

    Each file must be a translator of one pair (a conditioned one cannot start another), from
    "source", of the arm of --model (`model_hash`); every problem is a usage error."""
    sources, translators = [], []
    for path in a.translators:
        try:
            source = checkpoint.load(path)
            check_labels(
                source[1],
                path,
                source_domain="source",
                model_hash=model_hash,
                trust_unlabelled=a.trust_unlabelled_translators,
            )
            translator = translator_from_checkpoint(source, path)
        except checkpoint.CheckpointError as err:
            p.error(f"--translators: {err} (--model {a.model})")
        if translator.conditioned:
            p.error(f"--translators: {path} is conditioned already; start from one of one pair")
        generator, params = with_condition_inputs(
            translator.generator, translator.g_c_params, N_CONDITION
        )
        if a.generator_hidden is not None:
            if a.generator_hidden < generator.hidden:
                p.error(
                    f"--generator-hidden {a.generator_hidden}: at least the start's"
                    f" {generator.hidden} ({path})"
                )
            generator, params = with_hidden(generator, params, a.generator_hidden, len(sources))
        translators.append(
            dataclasses.replace(translator, generator=generator, g_c_params=params, f_c_params=None)
        )
        sources.append(source)
    return sources, translators


def conditioned_checkpoint(
    source: tuple[dict, dict],
    translator: Translator,
    g_c_params,
    media_range: MediaRange,
    model_hash: str,
    record: dict,
) -> tuple[dict, dict]:
    """(tree, meta) of a conditioned translator file from its start file `source`.

    The tree holds G_c only (the start's F_c modelled D_c alone); the metadata keeps the
    start's (its k, bounds, config), with the conditioned generator's shape, the range
    (`MEDIA_RANGE`: `MediaRange.to_dict`), the labels (method `METHOD`, "source" ->
    `MEDIA_RANGE`, the arm's model hash) and this stage's `record` under "finetune" (the
    start's stages moved to "finetune_earlier", as `ccgan.stage.finetuned_checkpoint` does)."""
    _, meta = source
    earlier = list(meta.get("finetune_earlier", [])) + (
        [meta["finetune"]] if "finetune" in meta else []
    )
    generator = translator.generator
    new_meta = meta | {
        "generator": {
            "hidden": generator.hidden,
            "fc": generator.fc,
            "per_sample": generator.per_sample,
            "residual": generator.residual,
            "n_condition": generator.n_condition,
        },
        MEDIA_RANGE: media_range.to_dict(),
        "method": METHOD,
        "source_domain": "source",
        "target_domain": MEDIA_RANGE,
        "model_hash": model_hash,
        "finetune": record,
    }
    if earlier:
        new_meta["finetune_earlier"] = earlier
    return {"g_c": g_c_params}, new_meta


def writer(out: Path, sources, translators, seeds, media_range, model_hash, run: dict):
    """`write(params, history)`: each seed's conditioned translator file (translator_seed<s>
    .ckpt, translator.ckpt naming the first) and distill_range.json, rewritten at every
    validation (atomically)."""

    def write(params, history) -> None:
        for s_i, seed in enumerate(seeds):
            record = run | {
                "seed": seed,
                "complete": history["complete"],
                "best_epoch": history["best_epoch"][s_i],
                "val_x_err_cm_before": history["val_x_err_cm_before"][s_i],
                "val_x_err_cm_best": history["best_val_x_err_cm"][s_i],
                "started_from": {
                    "method": sources[s_i][1].get("method"),
                    "path": run["sources"][s_i],
                    "sha256": checkpoint.payload_sha256(run["sources"][s_i]),
                },
            }
            tree, meta = conditioned_checkpoint(
                sources[s_i], translators[s_i], params[s_i], media_range, model_hash, record
            )
            checkpoint.save(out / f"translator_seed{seed}.ckpt", tree, meta)
        checkpoint.link_first_seed(out, f"translator_seed{seeds[0]}.ckpt")
        text = json.dumps(run | {"history": history}, indent=2)
        tmp = out / "distill_range.json.tmp"
        tmp.write_text(text)
        tmp.replace(out / "distill_range.json")

    return write
