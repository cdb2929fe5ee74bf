"""Trajectory-tracking evaluation of domain translation (paper Sec. "Evaluation Criteria").

For each shape: the D_s program [T, 3] (bar) runs in the D_s simulator and gives the target poses
[T, 6]. A method (`eval.methods`) turns (D_s pressures, target poses) into D_c commands
[T * k, 3] (each source step spread over k control periods); the D_c simulator runs them from
rest, and every k-th pose (the pose at the end of each source step's k periods) is compared with
the target: X_err (cm) and phi_err (rad), see `tracking.metrics`. Unlike the paper, which scored
through the learned forward model F_c, the errors here come from the simulator itself.

With EvalConfig.simulator "rod" the reference Cosserat rod (the paper's law, float64) scores
the table instead of the fitted chain: targets, stretch k and every D_c rollout (`eval.rod`).

With EvalConfig.target_domain_file D_c is the chain in a Domain read from a JSON file
(`eval.target`): every method runs there, by the same code as for a named domain.

This module holds what is evaluated (`EvalConfig`) and how (`evaluate`: load, plan, then the
simulator steps of `eval.simulate`, then write); the report is `eval.report`, the command line
`eval.shapes`.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np

import mjx_arm  # (before jax: sets the XLA CPU flag)
from eval import rod, target
from eval.methods import (
    DEFAULT_METHODS,
    METHOD_NAMES,
    METHODS,
    TRANSLATOR_METHODS,
    TranslatorMethod,
    check_translator_arms,
    load_translator,
    taught_domains,
    translator_source,
)
from eval.report import markdown_report, run_mark
from eval.simulate import (
    Plan,
    RunLog,
    command_and_roll_out,
    finish_oracle,
    robustness,
    run_mpc,
    score,
    start_oracle,
)
from eval.target import medium_note, read_target_file, target_file_record
from mjx_arm import constants, domains, programs
from tracking.config import check_duration, check_fields, check_ints, require
from tracking.held import choose_stretch_k, rollout_grouped
from tracking.oracle import OracleConfig

#: The main job's output folder, relative to the working directory (the README runs it from the
#: repository root): the committed results, which the main job regenerates.
RESULTS_DIR = "results"
#: Parent of the run folders that runs with other settings write when no output folder is given:
#: RUNS_DIR/quick-<time> for --quick, RUNS_DIR/custom-<time> otherwise, never results/.
RUNS_DIR = "runs"
#: What the report says of the arm at constants.TRANSLATOR_MODEL_PATH (the default model,
#: constants.DEFAULT_MODEL_PATH); which translators were scored on it is added from the files
#: loaded (`translators_note`), never from a constant that a later run would outdate.
ARM_NOTE = "the I-Support arm under the paper's Cosserat law (the default model)"
#: What the report says of the arm at constants.LINEAR_LAW_MODEL_PATH.
LINEAR_ARM_NOTE = (
    "the previous I-Support arm, fitted to the rod without stretch factors (the linear law),"
    " whose translators are in results/paper/run/ (give them with --ccgan-path, --wcgan-path,"
    " --distilled-path)"
)
#: What the report says of the arm at constants.SOLID_MODEL_PATH.
SOLID_ARM_NOTE = (
    "the earlier solid-disc arm, whose translators are in results/solid/translators/ (give them"
    " with --ccgan-path, --wcgan-path, --distilled-path)"
)


def _check_names(field: str, values, known) -> None:
    """A non-empty tuple of distinct names, each one of `known`."""
    unknown = [v for v in values if v not in known]
    require(
        len(values) > 0 and not unknown and len(set(values)) == len(values),
        field,
        f"must name distinct ones of {list(known)}, got {list(values)}",
    )


def _check_file(field: str, path) -> None:
    """An explicitly given input file (a translator checkpoint, an MJCF) that exists."""
    if path is not None:
        require(Path(path).is_file(), field, f"names no file: {path}")


@dataclasses.dataclass(frozen=True)
class EvalConfig:
    """What to evaluate and where to write it. Every field is checked when the config is made
    (`ConfigError`), so no run fails on a setting after minutes of simulation."""

    shapes: tuple[str, ...] = tuple(programs.SHAPES)
    """Shape names (keys of `programs.SHAPES`)."""
    methods: tuple[str, ...] = METHODS
    """Methods to run; a translator whose default checkpoint is absent is skipped with a note."""
    seeds: tuple[int, ...] = (0, 1, 2)
    """Seeds (>= 0): noise draws, and translator draws where a translator is stochastic."""
    duration_s: float = 60.0
    """Length of each shape program (s)."""
    backend: str = "c"
    """Simulator backend for every rollout except the oracle's optimisation: "c" or "mjx"."""
    simulator: str = "chain"
    """What scores the table: "chain" (the fitted MuJoCo arm, on `backend`) or "rod" (the
    reference Cosserat rod, `mjx_arm.load_rod`, float64: targets, stretch k and every method's
    D_c commands run there; no oracle, no videos; `eval.rod`)."""
    hold_factors: tuple[int, ...] = (1, 5, 10, 15, 20, 25, 30)
    """Stretch factors k (control periods per source step, >= 1) tried for the stretch baseline."""
    validation_duration_s: float = 20.0
    """Length of the validation program that picks k (s)."""
    noise_stds: tuple[float, ...] = (0.1, 0.3, 0.5)
    """Std of the Gaussian noise on normalised source pressures (pressure / 3.5 bar)."""
    n_repeats: int = 5
    """Repetitions from rest in the periodicity test."""
    robustness: bool = True
    """Run the noise and periodicity tests."""
    robust_methods: tuple[str, ...] = ("ccgan",)
    """Methods of the noise and periodicity tests, where run: the paper's tests are of its
    CCGAN-GP. Each method adds up to 14 rollouts per shape (noise draws per seed, repetitions);
    with the tests of stretch only and WCGAN-GP as well (and every rollout simulated), the main
    job took 16 min from a fresh clone on 2 cores (bench/results/cpu/main_job_fresh_clone.md).
    The chain's tables ask for every method's."""
    render: bool = False
    """Write MP4 videos."""
    out_dir: str | None = None
    """Output folder. None: RESULTS_DIR for the main job's settings (`is_main_job`; it
    regenerates the committed results), else a new run folder under RUNS_DIR (`output_dir`)."""
    quick: bool = False
    """A smoke run (`quick`): marked on every plot and video and in shapes.md."""
    xml: str | None = None
    """MJCF text of the arm (None: the file model_path); tests pass a 3-segment arm."""
    model_path: str = str(constants.TRANSLATOR_MODEL_PATH)
    """MJCF file of the arm when xml is None. Default: the arm the committed translators were
    trained on (`constants.TRANSLATOR_MODEL_PATH`, models/softarm.xml)."""
    target_domain: str = "constrained"
    """The domain translated into (D_c): "constrained", or "aged" for the second pair."""
    target_domain_file: str | None = None
    """A Domain JSON file (an identify.json or ``{"domain": {...}}``) whose Domain D_c is instead
    of target_domain's; recorded in shapes.json and shapes.md. Translators must be labelled
    "identified" and taught on the same fields (`eval.methods.load_translator`), or be
    ccgan_range. Not with another target_domain, nor with simulator "rod" (`eval.target`)."""
    taught_medium_rtol: float = 0.0
    """With target_domain_file: how far (relative, per numeric field) an "identified"
    translator's taught medium may be from the file's (0: the same fields), so that one built
    from a target's data is scored in the true medium (issue 50's identification: 5%)."""
    ccgan_path: str | None = None
    """Checkpoint for ccgan.load_translator (None: the translator's default)."""
    wcgan_path: str | None = None
    """Checkpoint of the WCGAN-GP baseline (None: WCGAN_DEFAULT_PATH)."""
    ccgan_sim_path: str | None = None
    """Checkpoint of the distilled translator, labelled "distill" (None:
    CCGAN_SIM_DEFAULT_PATH)."""
    ccgan_ident_path: str | None = None
    """Checkpoint of the translator distilled on an identified arm (`ccgan.distill
    --teach-domain`), labelled "distill" for target_domain (None: IDENT_DEFAULT_PATH)."""
    ccgan_range_path: str | None = None
    """Checkpoint of the conditioned translator over a range of media (`ccgan.distill_range`),
    labelled "distill_range" for "media_range"; scored in this run's D_c at its rule's k (None:
    RANGE_DEFAULT_PATH)."""
    trust_unlabelled_translators: bool = False
    """Score translator files that do not record their method, domains and arm (the solid-disc
    arm's, results/solid/translators/); labelled files are always checked."""
    oracle: OracleConfig = OracleConfig()
    """Oracle settings."""
    video_fps: int = 12
    """Video frame rate (frames per second of video)."""
    video_speedup: float = 6.0
    """Simulated seconds per video second."""
    video_panel_hw: tuple[int, int] = (480, 480)
    """Height, width (pixels) of each of the three video panels (at most the model's offscreen
    buffer, 720 x 1280 in the committed models)."""
    plots: bool = True
    """Write PNG figures."""

    def __post_init__(self):
        """Refuses settings that would fail (or mean nothing) after minutes of work."""
        _check_names("shapes", self.shapes, programs.SHAPES)
        _check_names("methods", self.methods, METHODS)
        _check_names("robust_methods", self.robust_methods, ("stretch", *TRANSLATOR_METHODS))
        check_ints("seeds", self.seeds, 0)  # numpy seeds are >= 0
        check_duration("duration_s", self.duration_s, programs.CONTROL_HZ)
        check_duration("validation_duration_s", self.validation_duration_s, programs.CONTROL_HZ)
        require(
            self.backend in ("c", "mjx"), "backend", f"must be 'c' or 'mjx', got {self.backend!r}"
        )
        check_ints("hold_factors", self.hold_factors, 1)  # control periods per step
        check_ints("n_repeats", self.n_repeats, 1)
        check_ints("video_fps", self.video_fps, 1)
        require(len(self.video_panel_hw) == 2, "video_panel_hw", "must be (height, width)")
        for pixels in self.video_panel_hw:  # height and width may be equal
            check_ints("video_panel_hw", pixels, 1)
        check_fields(
            self, at_least={"noise_stds": 0, "taught_medium_rtol": 0}, above={"video_speedup": 0}
        )
        require(
            self.out_dir is None or not Path(self.out_dir).is_file(),
            "out_dir",
            f"names a file, not a folder: {self.out_dir}",
        )
        if self.xml is None:
            _check_file("model_path", self.model_path)
        targets = [d for d in domains.DOMAINS if d != "source"]
        require(
            self.target_domain in targets,
            "target_domain",
            f"must be one of {targets}, got {self.target_domain!r}",
        )
        paths = ("ccgan_path", "wcgan_path", "ccgan_sim_path", "ccgan_ident_path")
        for field in (*paths, "ccgan_range_path"):
            _check_file(field, getattr(self, field))
        require(isinstance(self.oracle, OracleConfig), "oracle", "must be an OracleConfig")
        rod.check_simulator(self)
        target.check_target_file(self)
        require(
            self.oracle.held or "oracle" in self.methods,
            "oracle.held",
            "(a command per control period) sets the oracle, which is not among the methods: add"
            " oracle to --methods or leave the flag out",
        )


def quick(cfg: EvalConfig) -> EvalConfig:
    """The smoke-run version of cfg (--quick): programs of at most 10 s, the first seed, a 10 s
    validation program, two repetitions, marked as quick. Not the main job: with no out_dir it
    writes a new RUNS_DIR/quick-<time> folder."""
    return dataclasses.replace(
        cfg,
        duration_s=min(cfg.duration_s, 10.0),
        seeds=cfg.seeds[:1],
        validation_duration_s=min(cfg.validation_duration_s, 10.0),
        n_repeats=min(cfg.n_repeats, 2),
        quick=True,
    )


#: Methods the CPU's default leaves out, to keep the main job under 10 min on 2 cores: the oracle
#: (500 s for 10 Adam steps of five 2 s programs at k = 10 on a 2-core CPU, results/full at
#: commit 7e006b8) and WCGAN-GP (the baseline; about 90 s; the chain's table has it).
CPU_LEFT_OUT = ("oracle", "wcgan")


def default_methods() -> tuple[str, ...]:
    """The methods run without --methods: DEFAULT_METHODS, less CPU_LEFT_OUT on a CPU."""
    import jax

    if jax.default_backend() == "cpu":
        return tuple(m for m in DEFAULT_METHODS if m not in CPU_LEFT_OUT)
    return DEFAULT_METHODS


#: The noise levels of the CPU's default noise test: the largest, which the findings report. With
#: the translators at k = 15 each level costs the robust method 15 rollouts of 15 simulated
#: minutes (about 2 min on 2 cores), and the three levels put the main job over 10 minutes
#: (`bench/results/cpu/main_job_fresh_clone.md`).
CPU_NOISE_STDS = (0.5,)


def default_noise_stds() -> tuple[float, ...]:
    """The noise levels run without --noise-stds: EvalConfig's, or CPU_NOISE_STDS on a CPU."""
    import jax

    return CPU_NOISE_STDS if jax.default_backend() == "cpu" else EvalConfig.noise_stds


def main_job_config() -> EvalConfig:
    """The main job's settings (`python -m eval.shapes --render`), whose outputs are committed in
    results/: every default, with this machine's default methods and noise levels."""
    return EvalConfig(
        methods=default_methods(),
        noise_stds=default_noise_stds(),
        render=True,
        out_dir=RESULTS_DIR,
    )


def is_main_job(cfg: EvalConfig) -> bool:
    """Whether cfg computes what the main job computes: every setting but out_dir and render
    (videos only add files) equal to `main_job_config`'s, the same arm file, and no translator
    checkpoint asked for. Only such a run may write results/ without being told to."""
    main = main_job_config()
    same_model = Path(cfg.model_path).resolve() == Path(main.model_path).resolve()
    fixed = {"out_dir": None, "render": False, "model_path": main.model_path}
    return (
        dataclasses.replace(cfg, **fixed) == dataclasses.replace(main, **fixed)
        and same_model
        and not any(translator_source(m, cfg)[1] for m in TRANSLATOR_METHODS)
    )


def output_dir(cfg: EvalConfig) -> Path:
    """The folder a run writes, created: cfg.out_dir when given; RESULTS_DIR for the main job;
    else a new folder RUNS_DIR/<quick|custom>-<YYYYmmdd-HHMMSS>[-n], never one that exists, so
    a smoke run never replaces the committed results or another run's files."""
    if cfg.out_dir is not None:
        out = Path(cfg.out_dir)
        out.mkdir(parents=True, exist_ok=True)
        return out
    if is_main_job(cfg):
        out = Path(RESULTS_DIR)
        out.mkdir(parents=True, exist_ok=True)
        return out
    stem = f"{'quick' if cfg.quick else 'custom'}-{time.strftime('%Y%m%d-%H%M%S')}"
    Path(RUNS_DIR).mkdir(parents=True, exist_ok=True)
    for n in range(1000):
        out = Path(RUNS_DIR) / (stem if n == 0 else f"{stem}-{n}")
        try:
            out.mkdir()
            return out
        except FileExistsError:
            continue
    raise FileExistsError(f"no free run folder {stem}-<n> under {RUNS_DIR}")


def _shown_path(path: Path) -> str:
    """`path` relative to the repository when inside it, else absolute."""
    path = Path(path).resolve()
    try:
        return str(path.relative_to(constants.ROOT))
    except ValueError:
        return str(path)


def translators_note(
    translators: dict[str, TranslatorMethod], trained: dict[str, str] | None = None
) -> str:
    """Which translator files were scored, read from the files loaded: each method's checkpoint
    (and its per-seed files beside it), and whether their labels record the arm they were
    trained on; with `trained` ({method: the arm its files record}, `eval.rod.trained_on`)
    that arm per method. Empty without translators."""
    parts = []
    for method, tr in translators.items():
        files = [_shown_path(f) for f in tr.files]
        shown = files[0] if len(files) == 1 else f"{files[0]} and {', '.join(files[1:])}"
        arm = f" ({trained[method]})" if trained and method in trained else ""
        parts.append(f"{METHOD_NAMES.get(method, method)} from {shown}{arm}")
    if not parts:
        return ""
    labelled = all(tr.model_hashes for tr in translators.values())
    trained_on = "trained on this arm, as their labels record" if labelled else "not all labelled"
    if trained:
        trained_on = "the arm each was trained on, as its labels record"
    return f"translators scored ({trained_on}): " + "; ".join(parts)


def model_description(
    cfg: EvalConfig, translators: dict | None = None, trained: dict[str, str] | None = None
) -> dict:
    """{"file": the arm's MJCF (relative to the repository when inside it), "note": what it is,
    and which translator files were scored on it (`translators_note`; `trained`: the arm each
    was trained on, in rod mode)} for shapes.json and shapes.md."""
    scored = translators_note(translators or {}, trained)
    if cfg.xml is not None:
        return {
            "file": "MJCF text (EvalConfig.xml)",
            "note": "; ".join(filter(None, ["a custom arm", scored])),
        }
    path = Path(cfg.model_path).resolve()
    name = _shown_path(path)
    notes = {
        constants.TRANSLATOR_MODEL_PATH.resolve(): ARM_NOTE,
        constants.LINEAR_LAW_MODEL_PATH.resolve(): LINEAR_ARM_NOTE,
        constants.SOLID_MODEL_PATH.resolve(): SOLID_ARM_NOTE,
    }
    translators_arm = constants.TRANSLATOR_MODEL_PATH.relative_to(constants.ROOT)
    other = f"not the arm the committed translators were trained on ({translators_arm})"
    return {"file": name, "note": "; ".join(filter(None, [notes.get(path, other), scored]))}


def machine_description() -> str:
    """The CPU model (from /proc/cpuinfo), core count, and the JAX device kind."""
    import jax

    from mjx_arm.machine import cpu_model

    cpu = cpu_model()
    dev = jax.devices()[0]
    return f"{cpu}, {os.cpu_count()} cores; JAX device: {dev.platform} ({dev.device_kind})"


def load_arms(cfg: EvalConfig, target_file=None):
    """(D_s arm, D_c arm in cfg.target_domain, or in the Domain of cfg.target_domain_file) from
    cfg.xml, else the file cfg.model_path (by default the I-Support arm the committed
    translators were trained on). `target_file`: that file as already read
    (`read_target_file`), so that one reading serves the run; None reads it here."""
    target = cfg.target_domain
    if cfg.target_domain_file is not None:
        target = (target_file or read_target_file(cfg)).domain
    arm = {"xml": cfg.xml} if cfg.xml is not None else {"path": cfg.model_path}
    return mjx_arm.load(domain="source", **arm), mjx_arm.load(domain=target, **arm)


def evaluate(cfg: EvalConfig, command: str = "", log=print) -> dict:
    """Runs the evaluation and writes shapes.{md,json}, PNGs and (optionally) MP4s into
    `output_dir(cfg)`: results/ for the main job, a new run folder for other settings unless
    cfg.out_dir names one.

    Returns:
      The results dictionary written to shapes.json (trajectories are kept in memory only).

    Raises:
      TranslatorError: a translator checkpoint that was asked for is absent, one does not load,
        or one records another arm (`check_translator_arms`); raised before any simulation and
        before the output folder is made.
    """
    t_start = time.perf_counter()
    run = RunLog(log)
    cfg, arm_s, arm_c, translators, model, rods, target_file = _load(cfg, run)
    plan = _plan(cfg, arm_s, arm_c, translators, run, rods)
    oracle_future = start_oracle(plan, run)
    mpc_commands = run_mpc(plan, run)
    commands_of, poses_of = command_and_roll_out(plan, mpc_commands, run)
    oracle_out = finish_oracle(plan, oracle_future, run)
    table, trajectories = score(plan, commands_of, poses_of, oracle_out, log)
    noise, periodicity = robustness(plan, trajectories, poses_of)
    taught = taught_domains(translators, arm_s, arm_c)
    results = {
        "command": command,
        "machine": machine_description(),
        "simulator": cfg.simulator,
        "backend": plan.backend,
        "model_hash": plan.arm_s.model_hash,
        **({"rod": rod.rod_description(plan)} if rods is not None else {}),
        "model": model,
        **target_file_record(target_file, arm_s, arm_c),
        "config": dataclasses.asdict(cfg)
        | {"xml": None if cfg.xml is None else "custom", "model_path": model["file"]},
        "methods_run": plan.methods,
        "notes": run.notes,
        **({"taught_domains": taught} if taught else {}),
        "translator_labels": {method: list(tr.labels) for method, tr in translators.items()},
        "stretch_k": plan.k_stretch,
        "stretch_validation_x_err_cm": {str(k): v for k, v in plan.k_errors.items()},
        "table": table,
        "noise": noise,
        "periodicity": periodicity,
        "timings": run.timings,
    }
    _write(plan, results, trajectories, run, t_start)
    return results


def _load(cfg: EvalConfig, run: RunLog) -> tuple:
    """Step 1: the translators (a checkpoint asked for that does not load stops the run here,
    a missing default one is skipped with a note, never imitated), the arms, and the output
    folder, made only once every translator has loaded and matches the D_c arm.

    With cfg.simulator "rod" the rods are loaded too, and a translator is accepted when its
    files record the chain's D_c arm or the rod (`eval.rod`); the arm description then says
    which each was trained on. With cfg.target_domain_file the file is read once, here: its
    Domain is the D_c arm's, and the translators are checked against it.

    Returns:
      (cfg with out_dir set to the folder made, the chain's D_s arm, its D_c arm,
      {method: TranslatorMethod}, `model_description(cfg)`, (D_s rod, D_c rod) or None,
      the `mjx_arm.domains.DomainFile` of cfg.target_domain_file or None).
    """
    t0 = time.perf_counter()
    target_file = read_target_file(cfg)
    translators: dict[str, TranslatorMethod] = {}
    for method in (m for m in TRANSLATOR_METHODS if m in cfg.methods):
        tr, why = load_translator(method, cfg, target_file)
        if tr is None:
            run.note(f"{method.upper()} skipped: {why}.")
            continue
        translators[method] = tr
        if tr.trained_seeds:
            run.note(
                f"{method.upper()}: one separately trained model per seed "
                f"{sorted(tr.trained_seeds)}; its ± spans training seeds."
            )
        medium = tr.labels[0].get("medium") if tr.labels else None
        if medium:
            run.note(medium_note(method, medium))
    run.timings["translators_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    arm_s, arm_c = load_arms(cfg, target_file)
    rods = rod.load_rod_arms(cfg.target_domain) if cfg.simulator == "rod" else None
    run.timings["load_s"] = time.perf_counter() - t0
    check_translator_arms(translators, arm_c, *(rods[1:] if rods else ()))
    trained = rod.trained_on(translators, arm_c.model_hash, rods[1].model_hash) if rods else None
    model = model_description(cfg, translators, trained)
    default_arm = Path(cfg.model_path).resolve() == constants.TRANSLATOR_MODEL_PATH.resolve()
    if translators and not default_arm and cfg.xml is None:
        run.note(f"the arm {model['file']} is {model_description(cfg)['note']}.")
    note = rod.rod_note(cfg, default_arm and cfg.xml is None) if rods else None
    if note:
        run.note(note)
    out_dir = output_dir(cfg)
    cfg = dataclasses.replace(cfg, out_dir=str(out_dir))
    run.log(f"writing into {out_dir}" + (" (the committed results)" if is_main_job(cfg) else ""))
    return cfg, arm_s, arm_c, translators, model, rods, target_file


def _plan(cfg: EvalConfig, arm_s, arm_c, translators: dict, run: RunLog, rods=None) -> Plan:
    """Step 2: the methods that run, the stretch k (chosen on the validation program when
    stretch, mpc or the oracle needs it), every shape's D_s program and target poses (all
    shapes first: the oracle optimises them together), and the oracle's window.

    With `rods` ((D_s rod, D_c rod): cfg.simulator "rod") k and the targets come from the rods,
    which then score the table; the chain's D_c arm `arm_c` is kept for the tracker."""
    import jax

    run_oracle = "oracle" in cfg.methods
    if run_oracle and jax.default_backend() == "cpu" and cfg.xml is None and cfg.oracle.steps > 0:
        if cfg.oracle.horizon_s is None or cfg.oracle.horizon_s > 5.0:
            run.note(
                "oracle on CPU with a horizon over 5 s: expect hours (measured on a 2-core CPU:"
                " 500 s for 10 Adam steps of five 2 s programs at k = 10)."
            )
    methods = [m for m in cfg.methods if m not in TRANSLATOR_METHODS or m in translators]
    scorer_s, scorer_c, backend = (arm_s, arm_c, cfg.backend) if rods is None else (*rods, "rod")
    k_stretch, k_errors = 1, {}
    if "stretch" in methods or "oracle" in methods or "mpc" in methods:
        t0 = time.perf_counter()
        p_val = programs.validation_program(cfg.validation_duration_s)
        k_stretch, k_errors = choose_stretch_k(scorer_s, scorer_c, p_val, cfg.hold_factors, backend)
        run.timings["choose_k_s"] = time.perf_counter() - t0
        run.log(f"stretch k = {k_stretch} (validation X_err cm by k: {k_errors})")
    t0 = time.perf_counter()
    sources = {shape: programs.SHAPES[shape](cfg.duration_s) for shape in cfg.shapes}
    label = "D_s targets" + (" (rod)" if rods else "")
    target_list = rollout_grouped(scorer_s, [(sources[s], 1) for s in cfg.shapes], backend, label)
    targets = dict(zip(cfg.shapes, target_list, strict=True))
    run.timings["targets_s"] = time.perf_counter() - t0
    horizon = None
    if "oracle" in methods:
        horizon = min(t.shape[0] for t in targets.values())
        if cfg.oracle.horizon_s is not None:
            steps = int(round(cfg.oracle.horizon_s * programs.CONTROL_HZ))
            horizon = max(1, min(horizon, steps))
    return Plan(
        cfg,
        scorer_s,
        scorer_c,
        translators,
        methods,
        k_stretch,
        k_errors,
        sources,
        targets,
        horizon,
        rollout_backend=backend,
        tracker_arm=arm_c if rods is not None else None,
    )


def _write(plan: Plan, results: dict, trajectories: dict, run: RunLog, t_start: float) -> None:
    """Step 9: plots and videos (their files listed in results), then shapes.json and
    shapes.md into cfg.out_dir; results gains "figures", "videos" and "wall_time_s"."""
    cfg, timings = plan.cfg, run.timings
    out_dir = Path(cfg.out_dir)
    mark = run_mark(results["config"])
    if cfg.plots:
        from eval import plots

        t0 = time.perf_counter()
        results["figures"] = plots.write_all(trajectories, results, out_dir, mark)
        timings["plots_s"] = time.perf_counter() - t0
    if cfg.render:
        from eval import render

        t0 = time.perf_counter()
        results["videos"] = render.write_all(
            plan.arm_s, plan.arm_c, trajectories, cfg, out_dir, mark
        )
        timings["render_s"] = time.perf_counter() - t0
    timings["total_s"] = time.perf_counter() - t_start
    results["wall_time_s"] = timings["total_s"]
    (out_dir / "shapes.json").write_text(json.dumps(results, indent=2, default=_json_default))
    (out_dir / "shapes.md").write_text(markdown_report(results))
    run.log(f"wrote {out_dir / 'shapes.md'} and shapes.json; wall time {timings['total_s']:.1f} s")


def _json_default(obj):
    """numpy scalars and arrays as JSON numbers and lists; anything else as its str."""
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)
