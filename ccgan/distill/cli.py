"""Fine-tuning G_c by imitation of a simulator-based teacher (receding-horizon tracking).

Differentiating the tracking error through the MJX rollout is slow and reaches only a short
window from rest. Here the simulator acts once, ahead of training: the
receding-horizon tracker `tracking.mpc.track` computes, in MuJoCo C, D_c commands that make the
arm in D_c follow the D_s poses of shape-like programs (`mjx_arm.programs.shape_like_programs`,
never the five test shapes), over their whole length. G_c is then trained to reproduce those
commands:

    D_s program p_s [T, 3] --D_s sim--> x_s [T, 6] --tracking.mpc.track (D_c sim)--> c* [T, 3]
    loss = mean_t(w_t (G_c(p_s, x_s)_t - c*_t)^2) over pressures normalised to [0, 1],
           w_t = head_weight in the first window_s seconds, 1 after (normalised to mean 1)

starting from a trained (or fine-tuned) translator, with Adam. Every `eval_every` epochs each
seed's G_c is scored in the MuJoCo C simulator on held-out programs: the mean of the X_err (cm)
over their first `window_s` seconds and over their whole length. Each seed's best iterate by that
score is written (the starting translator counts), so imitation that makes tracking worse writes
the original. The teacher's commands are cached in the output folder (`teacher.npz`, reused
while everything that made them matches, `ccgan.distill.teacher.teacher_cache_key`, and grown
when more programs are asked for), so a rerun trains without recomputing them; a cache made
otherwise (another domain, k, arm or planner) is moved aside and planned again.

The files are translator checkpoints (`ccgan.stage.Stage.write`: metadata "finetune" holds
this stage; earlier stages stay in "finetune_earlier"), rewritten at every validation
("complete": false until the run ends), so a killed run keeps its best iterates. Their method
is "distill" when the start translators are CCGAN-GP's and "distill_from_<method>" otherwise
(e.g. "distill_from_wcgan"), and each records the file it started from ("started_from").

    python -m ccgan.distill \\
        --translators results/paper/rerun_2026-11-27/run/ccgan/translator_seed{0,1,2}.ckpt \\
        --seeds 0 1 2 --hold-factor 15 --out runs/ccgan_distilled

The CLI simulates the arm of `--model` (default the I-Support arm,
`mjx_arm.constants.TRANSLATOR_MODEL_PATH`, models/softarm.xml, the one the committed
translators were trained on).

Taught on an identified arm (`--teach-domain FILE`: an identify.json of `python -m
mjx_arm.identify`, or ``{"domain": {...}}``), the teacher plans, the iterates are scored and k
is chosen (`--k-candidates`) in that arm, `mjx_arm.load(--model, domain=<the file's Domain>)`,
never in the true target; the files are still labelled for `--domain`, the target they are
meant for, and record what they were taught on ("taught_domain" in their "finetune" record:
the file, its sha256, the Domain and its physical values), so that `eval.shapes` scores them as
the data-only translator (`ccgan_ident`), not the privileged one (`ccgan_sim`):

    python -m ccgan.distill --translators ... --domain constrained \\
        --teach-domain out/identify/identify.json --k-candidates 10 15 20 --out runs/ident
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

import mjx_arm  # (before jax: sets the XLA CPU flag)
from ccgan import checkpoint
from ccgan.cli import add_config_flags
from ccgan.distill.config import DistillConfig
from ccgan.distill.teacher import (
    _stop_check,
    adopt_teacher,
    read_cache_key,
    teacher_cache_key,
    teacher_data,
)
from ccgan.stage import Stage, common_k, stage_parser
from ccgan.translator import TAUGHT_DOMAIN
from mjx_arm import domains

#: DistillConfig fields without a flag here: a pair trains on one set of training splits.
PAIR_FIXED = ("train_sets",)
#: The method of a distilled file whose start translators are CCGAN-GP's; other starts give
#: f"{DISTILLED}_from_<their method>" (`ccgan.translator.METHODS` lists them).
DISTILLED = "distill"


def build_parser() -> argparse.ArgumentParser:
    """The options of `python -m ccgan.distill`."""
    p = stage_parser("ccgan.distill", __doc__, translators_required=False)
    add_config_flags(p, DistillConfig, skip=PAIR_FIXED)
    p.add_argument(
        "--teacher-only",
        action="store_true",
        help="plan the teacher's commands into --out/teacher.npz and stop (a later run with the"
        " same flags trains on them): to split a long run into calls. Needs no --translators"
        " when --hold-factor is given, so a chain can plan while its translators train",
    )
    p.add_argument(
        "--teacher-from",
        metavar="FILE",
        help="start from the teacher cache FILE (the teacher.npz of a --teacher-only run with"
        " the same settings, k, arm and domain), copied into --out unless --out has its own; one"
        " planned otherwise, or truncated, is refused before any work",
    )
    p.add_argument(
        "--teach-domain",
        metavar="FILE",
        help="teach in the arm of this Domain file (an identify.json of python -m"
        ' mjx_arm.identify, or {"domain": {...}}): the teacher plans, the iterates are scored'
        " and --k-candidates chooses k there, not in --domain; the files are labelled for"
        " --domain and record the file (default: taught in --domain itself)",
    )
    return p


def start_method(meta: dict) -> str:
    """The method the translator a file holds was first made by: its recorded method, where a
    distilled file counts as its own start's ("distill" -> "ccgan", "distill_from_wcgan" ->
    "wcgan"), and for a file without labels (trusted) its training config's baseline flag."""
    method = meta.get("method")
    if method is None:
        return "wcgan" if meta.get("config", {}).get("baseline") else "ccgan"
    if method == DISTILLED:
        return "ccgan"
    return method.removeprefix(f"{DISTILLED}_from_")


def distilled_method(start: str) -> str:
    """The method a distilled file records for a start translator first made by `start`."""
    return DISTILLED if start == "ccgan" else f"{DISTILLED}_from_{start}"


def record_lineage(p: argparse.ArgumentParser, a: argparse.Namespace, stage: Stage) -> None:
    """Labels what the stage writes by what it starts from: the run's method
    (`distilled_method`), and each seed's file's "started_from" {"method": the start file's
    recorded method, "path": as given, "sha256": its payload's digest}, carried into the file's
    metadata with its start's (`ccgan.stage.Stage.write` keeps a source's metadata).

    Start translators of different methods are a usage error: one stage writes one method."""
    starts = {start_method(meta) for _, meta in stage.sources}
    if len(starts) > 1:
        p.error(f"--translators were made by different methods {sorted(starts)}: one per run")
    stage.run["method"] = distilled_method(starts.pop()) if starts else DISTILLED
    paths = a.translators or []
    for s_i, (path, (tree, meta)) in enumerate(zip(paths, stage.sources, strict=True)):
        started_from = {
            "method": meta.get("method", start_method(meta)),
            "path": str(path),
            "sha256": checkpoint.payload_sha256(path),
        }
        stage.sources[s_i] = (tree, meta | {"started_from": started_from})


def check_teacher_from(p: argparse.ArgumentParser, a: argparse.Namespace) -> None:
    """Refuses a --teacher-from file that is missing, truncated or corrupt (a usage error, one
    line), before the translators and arms are loaded."""
    if a.teacher_from:
        try:
            read_cache_key(Path(a.teacher_from))
        except ValueError as err:
            p.error(f"--teacher-from: {err}")


def read_teach_domain(p: argparse.ArgumentParser, a) -> domains.DomainFile | None:
    """--teach-domain's Domain (`mjx_arm.domains.read_domain_file`), None without the flag; a
    missing or unreadable file is a usage error (one line), before any arm is loaded."""
    if not a.teach_domain:
        return None
    try:
        return domains.read_domain_file(a.teach_domain)
    except (OSError, ValueError) as err:
        p.error(f"--teach-domain: {err}")


def teach_on(p: argparse.ArgumentParser, a, stage: Stage, taught: domains.DomainFile) -> Stage:
    """The stage with its D_c arm replaced by the arm of `taught` (the same --model), in which
    the teacher plans and the iterates are scored; its labels stay --domain's (the target the
    files are meant for). The run record (each file's "finetune", distill.json) gains
    "taught_domain": `taught.record()` and "values", the taught arm's physical values
    (`mjx_arm.domains.physical_values`), which `eval.shapes` sets beside the true target's. The
    true target (`stage.arm_c` until here) teaches nothing. An arm that cannot be loaded in the
    file's Domain is a usage error."""
    try:
        arm = mjx_arm.load(a.model, domain=taught.domain)
    except (FileNotFoundError, ValueError, RuntimeError) as err:
        p.error(f"--teach-domain {a.teach_domain}: --model {a.model} in its Domain: {err}")
    values = domains.physical_values(arm.mj_model, stage.arm_s.mj_model, arm.domain)
    stage.run[TAUGHT_DOMAIN] = taught.record() | {"values": values}
    return dataclasses.replace(stage, arm_c=arm)


def adopt_teacher_from(
    p: argparse.ArgumentParser, a, config: DistillConfig, stage: Stage, k: int | None = None
):
    """Copies --teacher-from into --out (`adopt_teacher`) for k (None: the set or the
    translators' own); one planned under another key is a usage error naming the differing
    fields."""
    k = k or config.hold_factor or common_k(stage.translators)
    key = teacher_cache_key(config, k, stage.arm_c)
    try:
        if adopt_teacher(Path(a.teacher_from), stage.out / "teacher.npz", key):
            print(f"teacher: started from {a.teacher_from}")
    except ValueError as err:
        p.error(f"--teacher-from: {err}")


def plan_teacher_only(config: DistillConfig, stage: Stage, stop, k: int | None = None) -> None:
    """--teacher-only: plans the teacher's commands into --out/teacher.npz at k (None: the set
    or the translators' own) and says so."""
    k = k or config.hold_factor or common_k(stage.translators)
    should_stop = _stop_check(config, time.perf_counter(), stop)
    data = teacher_data(
        config, stage.arm_s, stage.arm_c, k, stage.out / "teacher.npz", progress=True,
        should_stop=should_stop,
    )  # fmt: skip
    print(
        f"wrote {stage.out / 'teacher.npz'}: {len(data['p_train'])} training and"
        f" {len(data['p_val'])} held-out programs; the teacher's held-out X_err"
        f" {data['teacher_val_x_err_cm'].mean():.4f} cm"
    )


def writer(stage: Stage):
    """`write(params, history)`: the best translators so far and the history (rewritten at
    every validation)."""

    def write(params, history) -> None:
        per_seed = [
            {
                "complete": history["complete"],
                "best_epoch": history["best_epoch"][s_i],
                "val_x_err_cm_before": history["val_x_err_cm_before"][s_i],
                "val_x_err_cm_best": history["best_val_x_err_cm"][s_i],
                "started_from": stage.sources[s_i][1].get("started_from"),
            }
            | ({"k_choice": history["k_choice"]} if "k_choice" in history else {})
            for s_i in range(len(stage.seeds))
        ]
        stage.write(params, per_seed, history, "distill.json", k=history["k"])

    return write


def summary(out: Path, history: dict) -> str:
    """The line `main` prints at the end of a distillation."""
    return (
        f"wrote {out}: held-out X_err (cm) before"
        f" {np.round(history['val_x_err_cm_before'], 4).tolist()} -> best"
        f" {np.round(history['best_val_x_err_cm'], 4).tolist()} at epochs"
        f" {history['best_epoch']}; teacher {history['teacher_val_x_err_cm']};"
        f" stretch only {history['stretch_val_x_err_cm']}; "
        f"{history['wall_s']:.1f} s"
    )
