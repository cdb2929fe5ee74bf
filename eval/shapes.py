"""The evaluation's command line and its five test shapes.

`python -m eval.shapes` scores every method on the paper's five shapes in the D_c simulator (this
module's `main`; `python -m eval.shapes --help` lists the options): the flags become an
`eval.pipeline.EvalConfig`, checked before any work, and `eval.pipeline.evaluate` does the work.

`--simulator {chain,rod}` picks what scores the table. "chain" (the default) is the fitted
MuJoCo arm, on `--backend`. "rod" is the reference Cosserat rod (`mjx_arm.load_rod`, the paper's
law, float64): the paper's Table I in the paper's own kind of simulator. Then the D_s targets are
the rod's own D_s path, stretch only's k is chosen in the rod, every method's D_c commands run in
the rod in --target-domain, translators trained on the chain or on the rod's data are both
scored (the report says which), and the tracker (--methods mpc) plans in the chain's MuJoCo C
towards the rod's targets, its commands then run in the rod. The oracle, --render and --backend
mjx are usage errors with the rod (the oracle differentiates through MJX of the chain, videos
draw the chain's model); without --methods the oracle is left out. The rod is latency-bound: on
a GPU each batch costs about its longest program's time (every rod call is announced), so a
60 s table is a GPU job; on a 2-core CPU it simulates 25-37 s per second: use --duration and
--no-robustness there (`eval.rod`).

`--target-domain-file JSON` scores in the medium of a Domain file instead of --target-domain
(`eval.target`); `--methods ... ccgan_range --range-path CKPT` scores the conditioned translator
over a range of media in this run's medium, at its rule's k.

The pressure programs themselves are pure functions of time and live below every layer that
draws them, in `mjx_arm.programs` (the circle, rectangle, damped circle, ellipse and kite, each
a [T, 3] array of chamber commands in bar at 10 Hz; the validation program; the random
shape-like programs of the distillation). They are re-exported here under their old names, for
users of `eval.shapes`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from ccgan.cli import HelpFormatter
from ccgan.translator import DEFAULT_PATH, LINEAR_TRANSLATORS_DIR, TRANSLATORS_DIR, TRUST_FLAG
from eval.methods import (
    CCGAN_SIM_DEFAULT_PATH,
    DEFAULT_METHODS,
    IDENT_DEFAULT_PATH,
    METHOD_ALIASES,
    METHOD_NAMES,
    METHODS,
    PATH_FLAGS,
    RANGE_DEFAULT_PATH,
    WCGAN_DEFAULT_PATH,
    TranslatorError,
)
from eval.pipeline import (
    CPU_NOISE_STDS,
    RESULTS_DIR,
    RUNS_DIR,
    EvalConfig,
    default_methods,
    default_noise_stds,
    evaluate,
    is_main_job,
    quick,
)
from eval.rod import SIMULATORS
from eval.simulate import MPC_RESULT, ORACLE_PROGRESS, ORACLE_START
from mjx_arm import constants, programs, run_folder
from mjx_arm.atomic import link_or_copy
from mjx_arm.programs import (
    AMPLITUDE_BAR,
    CHAMBER_ANGLES_RAD,
    CONTROL_HZ,
    P_HIGH_BAR,
    P_LOW_BAR,
    P_MID_BAR,
    PERIOD_S,
    PERIODIC_SHAPES,
    SHAPE_LIKE_KINDS,
    SHAPES,
    circle,
    damped_circle,
    ellipse,
    kite,
    pressures_from_bend,
    rectangle,
    shape_like_program,
    shape_like_programs,
    times_s,
    validation_program,
)
from tracking.config import ConfigError
from tracking.oracle import OracleConfig

__all__ = [
    "AMPLITUDE_BAR",
    "CHAMBER_ANGLES_RAD",
    "CONTROL_HZ",
    "FLAGS",
    "PERIODIC_SHAPES",
    "PERIOD_S",
    "P_HIGH_BAR",
    "P_LOW_BAR",
    "P_MID_BAR",
    "SHAPES",
    "SHAPE_LIKE_KINDS",
    "build_parser",
    "circle",
    "damped_circle",
    "ellipse",
    "kite",
    "main",
    "parse_args",
    "pressures_from_bend",
    "rectangle",
    "shape_like_program",
    "shape_like_programs",
    "times_s",
    "validation_program",
]

#: EvalConfig fields (OracleConfig's as "oracle.<field>") -> the flag that sets them, so a
#: ConfigError becomes a usage error that names the flag.
FLAGS = {
    "shapes": "--shapes",
    "methods": "--methods",
    "seeds": "--seeds",
    "out_dir": "--out",
    "backend": "--backend",
    "simulator": "--simulator",
    "duration_s": "--duration",
    "hold_factors": "--hold-factors",
    "robust_methods": "--robust-methods",
    "model_path": "--model",
    "target_domain": "--target-domain",
    "target_domain_file": "--target-domain-file",
    "taught_medium_rtol": "--taught-medium-rtol",
    **{f"{method}_path": flag for method, flag in PATH_FLAGS.items()},
    "oracle.steps": "--oracle-steps",
    "oracle.learning_rate": "--oracle-lr",
    "oracle.init": "--oracle-init",
    "oracle.horizon_s": "--oracle-horizon",
    "oracle.substeps": "--oracle-substeps",
    "oracle.held": "--oracle-per-period",
}


#: The files a run keeps in its folder to resume (`eval.simulate`), which `--caches-from` reads.
RESUME_CACHES = (MPC_RESULT, ORACLE_START, ORACLE_PROGRESS)


def build_parser() -> argparse.ArgumentParser:
    """The `python -m eval.shapes` parser: one line of help per option, with its default."""
    p = argparse.ArgumentParser(
        prog="python -m eval.shapes",
        formatter_class=HelpFormatter,
        description=(
            "Trajectory-tracking evaluation in D_c: the five shapes, each method's D_c commands"
            " scored in the simulator. The main job (`--render` and every other default) REWRITES"
            " the committed results in results/ (shapes.md, shapes.json, plots, videos); --quick"
            f" and any other settings write a new folder {RUNS_DIR}/<quick|custom>-<time>/ unless"
            " --out names one. Every option is checked before any work."
        ),
    )
    _add_run_options(p)
    _add_arm_options(p)
    _add_oracle_options(p)
    return p


def _add_run_options(p: argparse.ArgumentParser) -> None:
    """What runs and where it goes: shapes, methods, seeds, output, simulator, lengths."""
    p.add_argument(
        "--shapes",
        nargs="+",
        default=list(programs.SHAPES),
        choices=list(programs.SHAPES),
        metavar="SHAPE",
        help=f"shapes to track, of {', '.join(programs.SHAPES)}",
    )
    p.add_argument(
        "--methods",
        nargs="+",
        default=None,
        choices=[*METHODS, *METHOD_ALIASES],
        metavar="METHOD",
        help=f"methods to score, of {', '.join(METHODS)} ({_aliases_help()}; default: "
        + " ".join(DEFAULT_METHODS)
        + ", less the oracle and WCGAN-GP on"
        " a CPU)",
    )
    p.add_argument(
        "--seeds",
        metavar="SEED",
        nargs="+",
        type=int,
        default=[0, 1, 2],
        help="seeds (>= 0): noise draws, and trained models per seed",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        help=f"output folder (default: {RESULTS_DIR}/ for the main job, else a new"
        f" {RUNS_DIR}/<quick|custom>-<time>/)",
    )
    p.add_argument(
        "--caches-from",
        metavar="DIR",
        default=None,
        help="start from another run folder's resume caches (the tracker's commands, the"
        " oracle's start and progress; with --out): each is linked into --out unless --out has"
        " its own, and one made from other inputs (to the bit: targets simulated on another"
        " CPU may differ) is not used. A chain plans the oracle in"
        " an early stage and the table reads it (default: none, every cache made here)",
    )
    p.add_argument(
        "--backend",
        "--device",
        dest="backend",
        choices=["c", "mjx"],
        default="c",
        help="simulator of every rollout but the oracle's: MuJoCo C or MJX",
    )
    p.add_argument(
        "--simulator",
        choices=list(SIMULATORS),
        default=EvalConfig.simulator,
        help="what scores the table: the fitted chain (on --backend) or the reference Cosserat"
        " rod (the paper's law, float64; the tracker still plans in the chain; no oracle, no"
        " --render; a GPU job at 60 s)",
    )
    p.add_argument(
        "--duration",
        metavar="SECONDS",
        type=float,
        default=EvalConfig.duration_s,
        help="length of each shape program (s)",
    )
    p.add_argument(
        "--hold-factors",
        metavar="K",
        nargs="+",
        type=int,
        default=list(EvalConfig.hold_factors),
        help="hold factors k >= 1 (control periods each source command is held) tried",
    )
    p.add_argument("--render", action="store_true", help="write MP4 videos")
    p.add_argument(
        "--quick",
        action="store_true",
        help="smoke run: programs of at most 10 s, first seed, 10 s validation, 2 repetitions;"
        f" into a new {RUNS_DIR}/quick-<time>/ unless --out; marked on every plot and in shapes.md",
    )
    p.add_argument("--no-robustness", action="store_true", help="skip noise/periodicity tests")
    p.add_argument(
        "--robust-methods",
        nargs="+",
        metavar="METHOD",
        default=list(EvalConfig.robust_methods),
        help="methods of the noise and periodicity tests, where run (of stretch and the"
        " translators; stretch and the distilled translator each add minutes on 2 cores)",
    )
    p.add_argument(
        "--noise-stds",
        nargs="+",
        type=float,
        metavar="STD",
        default=None,
        help="noise levels of the noise test (std on pressure / 3.5 bar; default"
        f" {' '.join(map(str, EvalConfig.noise_stds))}, on a CPU"
        f" {' '.join(map(str, CPU_NOISE_STDS))})",
    )


def _aliases_help() -> str:
    """ "ccgan_sim is the distilled translator, also named distilled" for the help."""
    return "; ".join(
        f"{key} is the {METHOD_NAMES[key]} translator, also named {alias}"
        for alias, key in METHOD_ALIASES.items()
    )


def _method_keys(names: list[str]) -> list[str]:
    """Method names as given on the command line -> their keys (`METHOD_ALIASES`), in order (a
    repeated one stays repeated, for EvalConfig to refuse)."""
    return [METHOD_ALIASES.get(n, n) for n in names]


def _shown(path: Path) -> str:
    """`path` as the help shows it: relative to the repository."""
    return str(path.relative_to(constants.ROOT))


def _add_arm_options(p: argparse.ArgumentParser) -> None:
    """The arm, the target domain and the translator checkpoints."""
    p.add_argument(
        "--model",
        metavar="MJCF",
        default=EvalConfig.model_path,
        help=f"MJCF file of the arm; by default {_shown(constants.TRANSLATOR_MODEL_PATH)}, the"
        " I-Support arm under the paper's law, which the committed translators were trained on"
        f" ({_shown(constants.LINEAR_LAW_MODEL_PATH)}: the previous, linear-law arm, whose"
        f" translators are in {_shown(LINEAR_TRANSLATORS_DIR)}/;"
        f" {_shown(constants.SOLID_MODEL_PATH)}: the solid-disc arm)",
    )
    p.add_argument(
        "--target-domain",
        default=EvalConfig.target_domain,
        choices=["constrained", "aged"],
        help="D_c: the paper's viscous medium, or the aged arm (stiffness x0.7, same medium);"
        " the default translators translate into the medium and are refused for aged: give the"
        f" aged pair's (e.g. --distilled-path {_shown(TRANSLATORS_DIR)}"
        "/aged_sim/translator.ckpt) or leave them out with --methods",
    )
    p.add_argument(
        "--target-domain-file",
        metavar="JSON",
        default=None,
        help="D_c instead of --target-domain: the chain in the Domain of this file (an"
        ' identify.json or {"domain": {...}}), which scores the table, picks stretch only\'s k'
        " and runs every method; shapes.md records it. Translators must be labelled"
        " 'identified' and taught on the same fields (ccgan.adapt's), or be ccgan_range; leave"
        " the committed ones out with --methods. Not with --simulator rod (default:"
        " --target-domain)",
    )
    p.add_argument(
        "--taught-medium-rtol",
        type=float,
        default=EvalConfig.taught_medium_rtol,
        metavar="R",
        help="with --target-domain-file: score 'identified' translators taught on a medium whose"
        " numeric Domain fields are within R (relative) of the file's, e.g. 0.05 to score a"
        " translator built from a target's data (its identified medium) in the true medium"
        " (default: %(default)s, the same fields only)",
    )
    p.add_argument(
        "--ccgan-path",
        metavar="CKPT",
        default=None,
        help="CCGAN-GP translator checkpoint (default:"
        f" $CCGAN_TRANSLATOR, else {_shown(DEFAULT_PATH)}, skipped if absent)",
    )
    p.add_argument(
        "--wcgan-path",
        metavar="CKPT",
        default=None,
        help=f"WCGAN-GP translator checkpoint (default: {_shown(WCGAN_DEFAULT_PATH)}, skipped"
        " if absent)",
    )
    p.add_argument(
        "--distilled-path",
        "--ccgan-sim-path",
        dest="distilled_path",
        metavar="CKPT",
        default=None,
        help="distilled translator checkpoint (ccgan.distill; its file labelled 'distill')"
        f" (default: {_shown(CCGAN_SIM_DEFAULT_PATH)}, skipped if absent)",
    )
    p.add_argument(
        "--identified-path",
        metavar="CKPT",
        default=None,
        help="translator distilled on an arm identified from the target's data (ccgan.distill"
        " --teach-domain; labelled 'distill' for --target-domain, recording its Domain file),"
        " scored as ccgan_ident in the true --target-domain at the k it holds (default:"
        f" {_shown(IDENT_DEFAULT_PATH)}, skipped if absent)",
    )
    p.add_argument(
        "--range-path",
        metavar="CKPT",
        default=None,
        help="conditioned translator over a range of media (ccgan.distill_range; labelled"
        " 'distill_range' for 'media_range', translator_seed<s>.ckpt beside it), scored as"
        " ccgan_range in this run's D_c (--target-domain or --target-domain-file) at its rule's"
        " k; a medium outside its range is refused (default:"
        f" {_shown(RANGE_DEFAULT_PATH)}, skipped if absent)",
    )
    p.add_argument(
        TRUST_FLAG,
        action="store_true",
        help="score translator files that do not record their method, domains and arm (the"
        " solid-disc arm's, results/solid/translators/); a file labelled for another method,"
        " domain or arm is refused either way",
    )


def _add_oracle_options(p: argparse.ArgumentParser) -> None:
    """The oracle's settings (`tracking.oracle.OracleConfig`)."""
    p.add_argument(
        "--oracle-per-period",
        action="store_true",
        help="oracle with a free command per control period (not held k periods)",
    )
    p.add_argument(
        "--oracle-steps",
        metavar="N",
        type=int,
        default=OracleConfig.steps,
        help="the oracle's Adam steps (>= 1)",
    )
    p.add_argument(
        "--oracle-lr",
        metavar="LR",
        type=float,
        default=OracleConfig.learning_rate,
        help="the oracle's Adam step size on the sigmoid logits",
    )
    p.add_argument(
        "--oracle-init",
        choices=["mpc", "stretch"],
        default=OracleConfig.init,
        help="the oracle's start: the mpc commands or the stretch program",
    )
    p.add_argument(
        "--oracle-horizon",
        metavar="SECONDS",
        type=float,
        default=OracleConfig.horizon_s,
        help="seconds optimised by the oracle; <= 0 for the whole program",
    )
    p.add_argument(
        "--oracle-substeps",
        metavar="N",
        type=int,
        default=OracleConfig.substeps,
        help="physics steps per control period of the arm the oracle differentiates through"
        " (0: the arm's own; its commands are scored in the arm itself): studies.planning_arm",
    )


def parse_args(argv: list[str] | None = None) -> EvalConfig:
    """EvalConfig from command-line flags (see --help); a setting EvalConfig refuses exits with
    a usage error naming its flag, before any work."""
    p = build_parser()
    a = p.parse_args(argv)
    if a.out is not None:
        try:
            run_folder.check_writable_folder(a.out)
        except OSError as err:
            p.error(f"--out: {err}")
    methods = default_methods() if a.methods is None else _method_keys(a.methods)
    if a.methods is None and a.simulator == "rod":
        methods = tuple(m for m in methods if m != "oracle")
    noise_stds = default_noise_stds() if a.noise_stds is None else a.noise_stds
    horizon = None if a.oracle_horizon is not None and a.oracle_horizon <= 0 else a.oracle_horizon
    try:
        cfg = EvalConfig(
            shapes=tuple(a.shapes),
            methods=tuple(methods),
            seeds=tuple(a.seeds),
            duration_s=a.duration,
            backend=a.backend,
            simulator=a.simulator,
            hold_factors=tuple(a.hold_factors),
            render=a.render,
            robustness=not a.no_robustness,
            robust_methods=tuple(_method_keys(a.robust_methods)),
            noise_stds=tuple(noise_stds),
            out_dir=a.out,
            model_path=a.model,
            ccgan_path=a.ccgan_path,
            wcgan_path=a.wcgan_path,
            ccgan_sim_path=a.distilled_path,
            ccgan_ident_path=a.identified_path,
            ccgan_range_path=a.range_path,
            trust_unlabelled_translators=a.trust_unlabelled_translators,
            target_domain=a.target_domain,
            target_domain_file=a.target_domain_file,
            taught_medium_rtol=a.taught_medium_rtol,
            oracle=OracleConfig(
                steps=a.oracle_steps,
                learning_rate=a.oracle_lr,
                horizon_s=horizon,
                held=not a.oracle_per_period,
                init=a.oracle_init,
                substeps=a.oracle_substeps,
            ),
        )
        cfg = quick(cfg) if a.quick else cfg
    except ConfigError as err:
        p.error(f"{FLAGS.get(err.field, err.field)} {err.problem}")
    if a.out is None:
        _check_default_folder(p, cfg)
    if a.methods is None and a.simulator == "rod":
        print(
            "NOTE: --simulator rod leaves the oracle out (it optimises through MJX of the chain)"
            + ("; WCGAN-GP is left out on a CPU" if "wcgan" not in methods else "")
            + "."
        )
    elif a.methods is None and "oracle" not in methods:
        print(
            "NOTE: the oracle and WCGAN-GP are left out by default on CPU (the oracle's MJX"
            " gradients: ~8 min more on 2 cores with --oracle-steps 10); add them with"
            " --methods ... oracle wcgan."
        )
    return cfg


def _check_default_folder(p: argparse.ArgumentParser, cfg: EvalConfig) -> None:
    """Without --out a run writes under the working directory (results/ for the main job, else
    a new folder under runs/): refuse, before any work, one that cannot be written there."""
    folder = RESULTS_DIR if is_main_job(cfg) else RUNS_DIR
    try:
        run_folder.check_writable_folder(folder)
    except OSError as err:
        p.error(
            f"no --out, so this run writes {folder}/ in the working directory {Path.cwd()}:"
            f" {err}; give --out DIR"
        )


def main(argv: list[str] | None = None) -> dict:
    """Thin entry point: parse flags, evaluate, print the wall time. A translator checkpoint
    that does not load ends the run with an error (exit status 1) before any work.

    A folder named by --out (or results/ for the main job) has one writer at a time: a second
    is a usage error naming the first's pid (`mjx_arm.run_folder`). A run into a folder that
    holds an earlier run's shapes.json removes, once its own report is written, the figures and
    videos listed there that it did not write again (other shapes, no --render), so no stale
    plot stays beside the new report; other files (the resume caches) are left as they are.
    """
    from mjx_arm.machine import enable_compilation_cache

    cfg = parse_args(argv)
    caches_from = build_parser().parse_args(argv).caches_from
    if caches_from is not None and cfg.out_dir is None:
        build_parser().error("--caches-from needs --out")
    folder = cfg.out_dir
    if folder is None and is_main_job(cfg):
        folder = RESULTS_DIR
    lock = None
    if folder is not None:
        try:  # the lock file beside the folder: the folder holds only what a run writes
            lock = run_folder.lock_folder(folder, beside=True)
        except run_folder.FolderBusyError as err:
            build_parser().error(f"--out: {err}")
    try:
        if caches_from is not None:
            try:
                adopted = adopt_caches(Path(caches_from), Path(folder))
            except FileNotFoundError as err:
                build_parser().error(f"--caches-from: {err}")
            print(f"caches from {caches_from}: {', '.join(adopted) or 'none new'}")
        earlier = _listed_outputs(folder)
        enable_compilation_cache()
        command = "python -m eval.shapes " + " ".join(sys.argv[1:] if argv is None else argv)
        t0 = time.perf_counter()
        try:
            results = evaluate(cfg, command=command.strip())
        except TranslatorError as err:
            raise SystemExit(f"python -m eval.shapes: error: {err}") from None
        stale = sorted(earlier - _listed_outputs(folder))
        for name in stale:
            (Path(folder) / name).unlink(missing_ok=True)
        if stale:
            print(f"removed the earlier run's {', '.join(stale)} (not made by this run)")
        print(f"total wall time: {time.perf_counter() - t0:.1f} s")
    finally:
        if lock is not None:
            lock.release()
    return results


def adopt_caches(source: Path, folder: Path) -> list[str]:
    """Links (or copies) the resume caches (`RESUME_CACHES`) of the run folder `source` into
    `folder`, each unless `folder` has its own. Returns the names adopted.

    A cache holds the fingerprint of what made it (arm, targets, start, k, settings), and a run
    with other settings ignores it and computes afresh, so adopting one never changes a result.

    Raises:
      FileNotFoundError: `source` is not a folder or holds none of the caches.
    """
    if not source.is_dir() or not any((source / n).is_file() for n in RESUME_CACHES):
        raise FileNotFoundError(f"{source} holds none of {', '.join(RESUME_CACHES)}")
    folder.mkdir(parents=True, exist_ok=True)
    adopted = []
    for name in RESUME_CACHES:
        if (source / name).is_file() and not (folder / name).exists():
            link_or_copy(source / name, folder / name)
            adopted.append(name)
    return adopted


def _listed_outputs(folder) -> set[str]:
    """The figures and videos that the run in `folder` (its shapes.json) lists; none when there
    is no readable shapes.json."""
    try:
        written = json.loads((Path(folder) / "shapes.json").read_text())
    except (TypeError, OSError, ValueError):
        return set()
    if not isinstance(written, dict):
        return set()
    names = [*(written.get("figures") or []), *(written.get("videos") or [])]
    return {n for n in names if isinstance(n, str) and n and Path(n).name == n}


if __name__ == "__main__":
    main()
