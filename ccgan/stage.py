"""The fine-tune stage of G_c (`ccgan.distill`): its loop, command line and translator files.

A stage starts from trained translators (one per seed), trains every seed's G_c side by side
(their parameters stacked on a leading axis and vmapped), scores them on held-out programs in the
MuJoCo C simulator and keeps each one's best iterate (`BestIterates`), so a stage that makes
things worse writes the original. `validated_loop` is that loop, with its stopping rules (a
non-finite loss, a wall-clock budget). `stage_parser` and `start_stage` are its command line
(--translators, --seeds, --out, --model, --domain), checked before any simulation, and
`Stage.write` its output: translator checkpoints with G_c replaced and the stage recorded in
their metadata under "finetune" (`finetuned_checkpoint`; the key every fine-tuned translator
file carries, the retired `ccgan.finetune`'s too: docs/ccgan_study.md), and the history as JSON.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import mjx_arm  # noqa: F401  (before jax: sets the XLA CPU flag)
from ccgan import checkpoint
from ccgan.cli import check_output_dir, cli_parser
from ccgan.data import PRESSURE_DIM, denormalise_pressure
from ccgan.translator import (
    TRUST_FLAG,
    Translator,
    check_labels,
    describe_labels,
    is_rod_trained,
    translator_from_checkpoint,
    translator_labels,
)
from mjx_arm import constants
from mjx_arm.domains import IDENTIFIED


def generator_commands(translator: Translator, g_params, samples_s):
    """G_c's D_c commands [B, T, 3] (bar, one per source step) for normalised D_s samples
    [B, T, 9] (`ccgan.data.samples`); differentiable in g_params."""
    out = translator.generator.apply(g_params, samples_s)
    return denormalise_pressure(out[..., :PRESSURE_DIM])


def common_k(translators: list[Translator]) -> int:
    """The hold factor k every translator shares.

    Raises:
      ValueError: no translators, or they disagree on k.
    """
    if not translators:
        raise ValueError("need at least one translator")
    k = translators[0].k
    if any(t.k != k for t in translators):
        raise ValueError(f"translators disagree on k: {[t.k for t in translators]}")
    return k


def keep_better(best_params, params, better: np.ndarray):
    """Stacked parameters [M, ...]: params where better [M] is True, else best_params."""
    import jax
    import jax.numpy as jnp

    return jax.tree.map(
        lambda b, p: jnp.where(better.reshape((-1,) + (1,) * (p.ndim - 1)), p, b),
        best_params,
        params,
    )


@dataclasses.dataclass(frozen=True)
class BestIterates:
    """The best iterate so far of each of M members trained side by side, by a held-out score.

    Attributes:
      params: the members' parameters, stacked on a leading axis [M, ...].
      score: [M] held-out score (cm; lower is better).
      step: [M] the step (or epoch) each iterate comes from; 0: the starting parameters.
    """

    params: Any
    score: np.ndarray
    step: np.ndarray

    @classmethod
    def start(cls, params, score: np.ndarray) -> BestIterates:
        """The starting parameters [M, ...], scored [M], as the best so far (step 0)."""
        return cls(params, score, np.zeros(len(score), int))

    def update(self, step: int, params, score: np.ndarray) -> BestIterates:
        """Takes each member's new iterate (params [M, ...], score [M]) where it scores lower."""
        better = score < self.score
        return BestIterates(
            params=keep_better(self.params, params, better),
            score=np.where(better, score, self.score),
            step=np.where(better, step, self.step),
        )

    def take(self, members) -> list[dict]:
        """The best parameters of the given member indices, each as a tree of NumPy arrays."""
        import jax

        return [jax.tree.map(lambda x, m=m: np.asarray(x[m]), self.params) for m in members]


def validated_loop(
    n: int,
    params,
    opt_state,
    best: BestIterates,
    train_once,
    validate,
    report,
    *,
    config,
    t0: float,
    desc: str,
    unit: str,
    progress: bool = True,
    log=print,
    stop=None,
    start: int = 1,
) -> BestIterates:
    """The loop of a fine-tune stage: n steps (or epochs) of training, validated now and then.

    Iteration i = start..n (start > 1: a run resumed after iteration start - 1) runs
    `train_once(i, params, opt_state) -> (params, opt_state, loss [M])`.
    After every `config.eval_every`-th iteration, the last, and one that ran out of time, it
    scores the parameters with `validate(i, params) -> score [M]` (cm), keeps each member's best
    iterate and calls `report(best)` (unless None; e.g. to write the best iterates, so that a
    killed run keeps its progress). It stops early, keeping the best iterates so far, at a
    non-finite loss or once `config.max_wall_s` seconds (0: no limit) have passed since `t0`
    (`time.perf_counter()`), or once `stop` (a `threading.Event`, e.g. set by SIGTERM) is set.

    Args:
      params, opt_state: the members' parameters [M, ...] and optimiser state to start from.
      best: the best iterates before training (`BestIterates.start`).
      config: the stage's settings (their `eval_every` and `max_wall_s`).
      desc, unit: the progress bar's label and unit ("step" or "epoch", also in the log).

    Returns:
      the best iterates.
    """
    from tqdm.auto import tqdm

    bar = tqdm(
        range(start, n + 1), disable=not progress, desc=desc, unit=unit, initial=start - 1, total=n
    )
    for i in bar:
        params, opt_state, loss = train_once(i, params, opt_state)
        if not np.isfinite(loss).all():
            log(f"{unit} {i}: non-finite loss {loss}; stopping, keeping the best iterate")
            break
        out_of_time = config.max_wall_s > 0 and time.perf_counter() - t0 > config.max_wall_s
        stopped = stop is not None and stop.is_set()
        if i % config.eval_every == 0 or i == n or out_of_time or stopped:
            score = validate(i, params)
            best = best.update(i, params, score)
            bar.set_postfix(loss=float(loss.mean()), val_cm=float(score.mean()))
            if report is not None:
                report(best)
        if out_of_time or stopped:
            why = f"max_wall_s = {config.max_wall_s} s reached" if out_of_time else "asked to stop"
            log(f"stopping after {unit} {i}: {why}")
            break
    bar.close()
    return best


def finetuned_checkpoint(source: tuple[dict, dict], g_c_params, finetune_meta: dict):
    """(tree, meta) of a source translator checkpoint (`checkpoint.load`'s pair) with G_c
    replaced and `finetune_meta` added to its metadata.

    A source that was itself fine-tuned keeps its record: the metadata's "finetune" is this
    stage, "finetune_earlier" lists the earlier stages, oldest first.
    """
    tree, meta = source
    earlier = list(meta.get("finetune_earlier", [])) + (
        [meta["finetune"]] if "finetune" in meta else []
    )
    stages = {"finetune": finetune_meta} | ({"finetune_earlier": earlier} if earlier else {})
    return dict(tree) | {"g_c": g_c_params}, meta | stages


def save_finetuned(path, source_path, g_c_params, finetune_meta: dict) -> Path:
    """Writes `finetuned_checkpoint` of the translator file at `source_path` to `path`."""
    tree, meta = finetuned_checkpoint(checkpoint.load(source_path), g_c_params, finetune_meta)
    return checkpoint.save(path, tree, meta)


def stage_parser(
    module: str, doc: str, translators_required: bool = True
) -> argparse.ArgumentParser:
    """A parser with the flags of a fine-tune stage's CLI (`ccgan.distill`): --translators,
    --seeds, --out, --model, --domain; `start_stage` checks and loads them.
    `translators_required` False leaves --translators to the CLI (`ccgan.distill --teacher-only`
    plans without any)."""
    p = cli_parser(module, doc)
    p.add_argument(
        "--translators", nargs="+", required=translators_required, help="translator checkpoints"
    )
    p.add_argument("--seeds", type=int, nargs="+", help="seed of each file (default 0, 1, ...)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument(
        "--model",
        default=str(constants.TRANSLATOR_MODEL_PATH),
        help="MJCF of the arm to simulate: the one the translators were trained on (the"
        " committed translators: models/softarm.xml)",
    )
    p.add_argument(
        "--domain",
        default="constrained",
        choices=[*sorted(d for d in mjx_arm.DOMAINS if d != "source"), IDENTIFIED],
        help="D_c domain (mjx_arm.DOMAINS): the one the translators translate into;"
        f" {IDENTIFIED!r}: an arm known only by its data, the one the --teach-domain file"
        " describes (`ccgan.distill`; the files are then labelled for it)",
    )
    p.add_argument(
        "--start-domain",
        default=None,
        choices=sorted(d for d in mjx_arm.DOMAINS if d != "source"),
        help="the domain the --translators were trained for (default: --domain; constrained"
        f" for --domain {IDENTIFIED}). Another"
        " domain's translators only start the stage: what it writes is labelled with --domain"
        " (e.g. the aged arm's distillation started from the D_c CCGAN-GP)",
    )
    p.add_argument(
        "--start-rod-trained",
        action="store_true",
        help="the --translators were trained on the reference rod's data (mjx_arm.babble"
        " --backend rod; their arm is the rod's, not --model's): they only start the stage, which"
        " teaches them in --model's arm (issue 50's data-only translator for the rod starts from"
        " the CCGAN-GP trained on the rod's babbling). Without it such files are refused",
    )
    p.add_argument(
        TRUST_FLAG,
        action="store_true",
        help="accept translator files that do not record their method, domains and arm (the"
        " solid-disc arm's); the labels they do record are still checked",
    )
    return p


@dataclasses.dataclass
class Stage:
    """What a fine-tune stage's CLI loaded: its translators (each file read once), the arms, the
    output folder and the run record every written file carries."""

    seeds: list[int]
    sources: list[tuple[dict, dict]]
    translators: list[Translator]
    arm_s: object
    arm_c: object
    out: Path
    run: dict

    def write(
        self, params, per_seed_meta: list[dict], history: dict, json_name: str, k: int | None = None
    ) -> None:
        """Writes each seed's translator file (G_c replaced, the stage's record added to its
        metadata; k, the hold factor, replaced when given) and the history, atomically.

        Each file is labelled (`ccgan.translator.LABELS`) as this stage's: its method, source
        -> this stage's domain, and the arm simulated here."""
        labels = {
            "method": self.run["method"],
            "source_domain": "source",
            "target_domain": self.run["domain"],
            "model_hash": self.run["model_hash"],
        }
        for s_i, (seed, source) in enumerate(zip(self.seeds, self.sources, strict=True)):
            meta = self.run | {"seed": seed} | per_seed_meta[s_i]
            tree, file_meta = finetuned_checkpoint(source, params[s_i], meta)
            file_meta = file_meta | labels
            if k is not None:
                file_meta = file_meta | {"k": int(k)}
            checkpoint.save(self.out / f"translator_seed{seed}.ckpt", tree, file_meta)
        checkpoint.link_first_seed(self.out, f"translator_seed{self.seeds[0]}.ckpt")
        tmp = self.out / f"{json_name}.tmp"
        tmp.write_text(json.dumps(self.run | {"history": history}, indent=2))
        tmp.replace(self.out / json_name)


def trained_model_hash(meta: dict) -> str | None:
    """The `Arm.model_hash` a translator file says it was trained or last refined on, or None
    (files written before the hash was recorded)."""
    return meta.get("finetune", {}).get("model_hash") or meta.get("model_hash")


def start_stage(p: argparse.ArgumentParser, a, module: str, config: dict, argv) -> Stage:
    """Checks and loads what `stage_parser`'s flags name; `module` and `config` go into the run
    record. Every problem (seeds, output folder, an unreadable translator or MJCF, translators
    recorded on another arm, or for a domain other than --start-domain (default --domain), or
    recording neither without --trust-unlabelled-translators) is a usage error (status 2)
    before any simulation starts."""
    import jax

    from mjx_arm.machine import cpu_model, enable_compilation_cache

    paths = a.translators or []
    seeds = a.seeds if a.seeds is not None else list(range(len(paths)))
    if len(seeds) != len(paths):
        p.error("give one seed per translator file")
    if len(set(seeds)) != len(seeds):
        p.error(f"--seeds must be distinct, got {seeds}")
    check_output_dir(p, "--out", a.out)
    try:
        sources = [checkpoint.load(path) for path in paths]  # read once, rewritten often
        translators = [
            translator_from_checkpoint(src, path) for src, path in zip(sources, paths, strict=True)
        ]
    except checkpoint.CheckpointError as err:
        p.error(f"--translators: {err}")
    identified = a.domain == IDENTIFIED
    if identified and not getattr(a, "teach_domain", None):
        p.error(f"--domain {IDENTIFIED} needs --teach-domain: the file that describes that arm")
    # An identified arm has no built-in domain: the translators it starts from name theirs
    # (default constrained), and `ccgan.distill` replaces the arm loaded here with the file's.
    start_domain = a.start_domain or ("constrained" if identified else a.domain)
    try:
        arm_s, arm_c = (
            mjx_arm.load(a.model, domain=d)
            for d in ("source", start_domain if identified else a.domain)
        )
    except (FileNotFoundError, ValueError) as err:  # ModelValidationError is a ValueError
        p.error(f"--model {a.model}: {err}")
    rod_start = getattr(a, "start_rod_trained", False)
    for path, (_, meta) in zip(paths, sources, strict=True):
        try:
            labels = check_labels(
                meta,
                path,
                source_domain="source",
                target_domain=start_domain,
                model_hash=None if rod_start else arm_c.model_hash,
                trust_unlabelled=a.trust_unlabelled_translators,
            )
            if rod_start and not is_rod_trained(labels):
                p.error(
                    f"--translators: {path} is a {describe_labels(labels)}, not trained on the"
                    " reference rod's data: drop --start-rod-trained"
                )
        except checkpoint.CheckpointError as err:
            why = (
                "; it was trained on the reference rod's data (mjx_arm.babble --backend rod),"
                " and this stage simulates the chain of --model"
                if is_rod_trained(translator_labels(meta))
                else ""
            )
            p.error(f"--translators: {err} (--model {a.model}, --start-domain {start_domain}){why}")
    enable_compilation_cache()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    dev = jax.devices()[0]
    run = {
        "command": f"python -m {module} " + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": f"{cpu_model()}; JAX device: {dev.platform} ({dev.device_kind})",
        "config": config,
        "model": str(a.model),
        "model_hash": arm_c.model_hash,
        "domain": a.domain,
        "start_domain": start_domain,
        "start_rod_trained": rod_start,
        "method": module.rsplit(".", 1)[-1],
        "sources": [str(x) for x in paths],
        "seeds": seeds,
    }
    return Stage(seeds, sources, translators, arm_s, arm_c, out, run)
