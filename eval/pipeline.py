"""Trajectory-tracking evaluation of domain translation (paper Sec. "Evaluation Criteria").

For each shape: the D_s program [T, 3] (bar) runs in the D_s simulator and gives the target poses
[T, 6]. A method turns (D_s pressures, target poses) into D_c commands [T * k, 3] (each source
step spread over k control periods); the D_c simulator runs them from rest, and every k-th pose
(the pose at the end of each source step's k periods) is compared with the target:
X_err (cm) and phi_err (rad), see `tracking.metrics`. Unlike the paper, which scored through the
learned forward model F_c, the errors here come from the simulator itself.

Methods:
  none     D_s pressures straight into D_c (k = 1).
  stretch  D_s pressures, each held k periods; k minimises the tracking error on a separate
           validation program (`mjx_arm.programs.validation_program`), searched over
           EvalConfig.stretch_candidates = {1, 5, 10, ..., 30}: the GAN's set {5, ..., 30} plus 1.
  ccgan    the trained CCGAN-GP translator `ccgan.load_translator(path)`. Every translator
           method is skipped with a note when its default checkpoint is absent; one that was
           asked for (--ccgan-path etc.) must load, or the run stops before any work.
  ccgan_sim  the CCGAN-GP translator fine-tuned in the simulator: through the MJX rollout
           (`ccgan.finetune`: results/ccgan_sim, ccgan_sim2, ccgan_sim3 on babbling programs,
           ccgan_sim4, ccgan_sim5 on shape-like ones), then by imitation of `tracking.mpc`
           (`ccgan.distill`: ccgan_sim6, ccgan_sim7, ccgan_sim8): the last stage's
           results/ccgan_sim8/translator.ckpt or --ccgan-sim-path; not in the default methods.
  wcgan    the WCGAN-GP baseline translator: a translator checkpoint given by --wcgan-path or
           found at results/wcgan/translator.ckpt.
  mpc      receding-horizon tracking in the D_c simulator itself (`tracking.mpc.track`, MuJoCo C,
           k = the stretch k): at every source step the next command is planned by Gauss-Newton
           on the simulated tracking error and applied. Not a translator (it needs the D_c
           simulator at translation time); a model-based reference. Not in the default methods.
  oracle   D_c commands optimised directly through the differentiable MJX rollout with
           optax Adam (`tracking.oracle`; k = the stretch k), commands kept in the valve range by
           a sigmoid, starting from the mpc commands (OracleConfig.init; "stretch" starts from
           the stretch program); a lower reference for the other methods. Like every
           translator's output, one command per source step held k periods (OracleConfig.held;
           --oracle-per-period frees every control period). All shapes are
           optimised together (one vmapped rollout). Gradients through thousands of MJX steps
           are slow, so the oracle optimises (and every method's ratio to it is computed over)
           the first `OracleConfig.horizon_s` seconds only, and the CLI leaves it out on CPU
           unless asked: five 2 s programs at k = 10 (5,000 physics steps each), 10 Adam steps,
           took 500 s on a 2-core CPU, compile included (results/full at commit 7e006b8); on an H200
           the first step took 98 s and each further one 11.6 s (bench/results/h200/oracle.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import json
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

import mjx_arm  # (before jax: sets the XLA CPU flag)
from ccgan.train import HelpFormatter
from mjx_arm import constants, programs
from tracking import metrics, mpc
from tracking import oracle as oracle_lib
from tracking.config import ConfigError, check_duration, check_fields, check_ints, require
from tracking.held import choose_stretch_k, every_kth, rollout_grouped, stretch
from tracking.oracle import OracleConfig

METHODS = ("none", "stretch", "ccgan", "ccgan_sim", "wcgan", "mpc", "oracle")
#: What runs without --methods (the oracle is left out on CPU).
DEFAULT_METHODS = ("none", "stretch", "ccgan", "wcgan", "oracle")
TRANSLATOR_METHODS = ("ccgan", "ccgan_sim", "wcgan")
#: Where the simulator-fine-tuned CCGAN-GP (`ccgan.finetune`) is looked for when no path is given.
CCGAN_SIM_DEFAULT_PATH = (
    Path(__file__).resolve().parent.parent / "results" / "ccgan_sim8" / "translator.ckpt"
)
#: Where the WCGAN-GP baseline's translator checkpoint is looked for when no path is given.
WCGAN_DEFAULT_PATH = (
    Path(__file__).resolve().parent.parent / "results" / "wcgan" / "translator.ckpt"
)
#: The main job's output folder, relative to the working directory (the README runs it from the
#: repository root): the committed results, which the main job regenerates.
RESULTS_DIR = "results"
#: Parent of the run folders that runs with other settings write when no output folder is given:
#: RUNS_DIR/quick-<time> for --quick, RUNS_DIR/custom-<time> otherwise, never results/.
RUNS_DIR = "runs"
#: What the report says of the arm at constants.SOLID_MODEL_PATH.
SOLID_ARM_NOTE = (
    "the old solid-disc arm, on which the committed translators (results/ccgan, results/wcgan,"
    " results/ccgan_sim8) were trained"
)


class TranslatorError(ValueError):
    """A translator checkpoint that was asked for (a path, or $CCGAN_TRANSLATOR) is missing or
    does not load; the run stops before any work instead of skipping the method."""


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
    stretch_candidates: tuple[int, ...] = (1, 5, 10, 15, 20, 25, 30)
    """Stretch factors k (control periods per source step, >= 1) tried for the stretch baseline."""
    validation_duration_s: float = 20.0
    """Length of the validation program that picks k (s)."""
    noise_stds: tuple[float, ...] = (0.1, 0.3, 0.5)
    """Std of the Gaussian noise on normalised source pressures (pressure / 3.5 bar)."""
    n_repeats: int = 5
    """Repetitions from rest in the periodicity test."""
    robustness: bool = True
    """Run the noise and periodicity tests."""
    render: bool = False
    """Write MP4 videos."""
    out_dir: str | None = None
    """Output folder. None: RESULTS_DIR for the main job's settings (`is_main_job`; it
    regenerates the committed results), else a new run folder under RUNS_DIR (`output_dir`)."""
    quick: bool = False
    """A smoke run (`quick`): marked on every plot and video and in shapes.md."""
    xml: str | None = None
    """MJCF text of the arm (None: the file model_path); tests pass a 3-segment arm."""
    model_path: str = str(constants.SOLID_MODEL_PATH)
    """MJCF file of the arm when xml is None. Default: the old solid-disc arm
    (`constants.SOLID_MODEL_PATH`), the one the committed translators were trained on."""
    target_domain: str = "constrained"
    """The domain translated into (D_c): "constrained", or "aged" for the second pair."""
    ccgan_path: str | None = None
    """Checkpoint for ccgan.load_translator (None: the translator's default)."""
    wcgan_path: str | None = None
    """Checkpoint of the WCGAN-GP baseline (None: WCGAN_DEFAULT_PATH)."""
    ccgan_sim_path: str | None = None
    """Checkpoint of the simulator-fine-tuned CCGAN-GP (None: CCGAN_SIM_DEFAULT_PATH)."""
    oracle: OracleConfig = OracleConfig()
    """Oracle settings."""
    video_fps: int = 15
    """Video frame rate (frames per second of video)."""
    video_speedup: float = 4.0
    """Simulated seconds per video second."""
    video_panel_hw: tuple[int, int] = (240, 320)
    """Height, width (pixels) of each of the three video panels."""
    plots: bool = True
    """Write PNG figures."""

    def __post_init__(self):
        """Refuses settings that would fail (or mean nothing) after minutes of work."""
        from mjx_arm import domains

        _check_names("shapes", self.shapes, programs.SHAPES)
        _check_names("methods", self.methods, METHODS)
        check_ints("seeds", self.seeds, 0)  # numpy seeds are >= 0
        check_duration("duration_s", self.duration_s, programs.CONTROL_HZ)
        check_duration("validation_duration_s", self.validation_duration_s, programs.CONTROL_HZ)
        require(
            self.backend in ("c", "mjx"), "backend", f"must be 'c' or 'mjx', got {self.backend!r}"
        )
        check_ints("stretch_candidates", self.stretch_candidates, 1)  # control periods per step
        check_ints("n_repeats", self.n_repeats, 1)
        check_ints("video_fps", self.video_fps, 1)
        require(len(self.video_panel_hw) == 2, "video_panel_hw", "must be (height, width)")
        check_ints("video_panel_hw", tuple(self.video_panel_hw), 1)
        check_fields(self, at_least={"noise_stds": 0}, above={"video_speedup": 0})
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
        for field in ("ccgan_path", "wcgan_path", "ccgan_sim_path"):
            _check_file(field, getattr(self, field))
        require(isinstance(self.oracle, OracleConfig), "oracle", "must be an OracleConfig")


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


def default_methods() -> tuple[str, ...]:
    """The methods run without --methods: DEFAULT_METHODS, less the oracle on a CPU.

    Measured on a 2-core CPU: 500 s for 10 Adam steps of five 2 s programs at k = 10
    (results/full at commit 7e006b8), which would take the main job past 15 min.
    """
    import jax

    if jax.default_backend() == "cpu":
        return tuple(m for m in DEFAULT_METHODS if m != "oracle")
    return DEFAULT_METHODS


def main_job_config() -> EvalConfig:
    """The main job's settings (`python -m eval.shapes --render`), whose outputs are committed in
    results/: every default, with this machine's default methods."""
    return EvalConfig(methods=default_methods(), render=True, out_dir=RESULTS_DIR)


def translator_source(method: str, cfg: EvalConfig) -> tuple[Path, bool]:
    """(checkpoint file, whether it was asked for) of a translator method.

    Asked for: a path in cfg, or for ccgan also $CCGAN_TRANSLATOR (`ccgan.translator_path`);
    otherwise the method's default file, which may be absent.
    """
    if method == "ccgan":
        from ccgan.translator import translator_path

        asked = cfg.ccgan_path is not None or bool(os.environ.get("CCGAN_TRANSLATOR"))
        return translator_path(cfg.ccgan_path), asked
    given, default = {
        "ccgan_sim": (cfg.ccgan_sim_path, CCGAN_SIM_DEFAULT_PATH),
        "wcgan": (cfg.wcgan_path, WCGAN_DEFAULT_PATH),
    }[method]
    return Path(given or default), given is not None


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


def run_mark(config: dict) -> str | None:
    """The words marking a quick run's plots, videos and report (None for other runs).

    Args:
      config: `dataclasses.asdict` of the EvalConfig (shapes.json's "config"); older files
        have no "quick" and are not marked.
    """
    if not config.get("quick"):
        return None
    return (
        f"QUICK RUN: {config['duration_s']:g} s programs, seeds {list(config['seeds'])}"
        " - not the main job's results"
    )


def model_description(cfg: EvalConfig) -> dict:
    """{"file": the arm's MJCF (relative to the repository when inside it), "note": what it is}
    for shapes.json and shapes.md."""
    if cfg.xml is not None:
        return {"file": "MJCF text (EvalConfig.xml)", "note": "a custom arm"}
    path = Path(cfg.model_path).resolve()
    try:
        name = str(path.relative_to(constants.ROOT))
    except ValueError:
        name = str(path)
    solid = path == constants.SOLID_MODEL_PATH.resolve()
    other = "not the arm the committed translators were trained on (models/softarm_solid.xml)"
    return {"file": name, "note": SOLID_ARM_NOTE if solid else other}


# --------------------------------------------------------------------------------- environment


def machine_description() -> str:
    """The CPU model (from /proc/cpuinfo), core count, and the JAX device kind."""
    import jax

    from mjx_arm.machine import cpu_model

    cpu = cpu_model()
    dev = jax.devices()[0]
    return f"{cpu}, {os.cpu_count()} cores; JAX device: {dev.platform} ({dev.device_kind})"


def load_arms(cfg: EvalConfig):
    """(D_s arm, D_c arm in cfg.target_domain) from cfg.xml, else the file cfg.model_path (by
    default the solid-disc arm the committed translators were trained on)."""
    if cfg.xml is not None:
        return (
            mjx_arm.load(xml=cfg.xml, domain="source"),
            mjx_arm.load(xml=cfg.xml, domain=cfg.target_domain),
        )
    return (
        mjx_arm.load(cfg.model_path, domain="source"),
        mjx_arm.load(cfg.model_path, domain=cfg.target_domain),
    )


# ------------------------------------------------------------------------------------ methods


class Translator:
    """A loaded translator method: `translate(p_s [T, 3], poses_s [T, 6], seed)`.

    With `trained_seeds` ({seed: translator}, several independently trained models) the seed
    picks the model, so a method's mean ± std spans training seeds. `model_hashes` holds the
    `Arm.model_hash`es its files record as the arm they were trained on (files written before
    that was recorded add none).
    """

    def __init__(
        self,
        name: str,
        obj,
        trained_seeds: dict | None = None,
        model_hashes: frozenset = frozenset(),
    ):
        self.name = name
        self._obj = obj
        self.trained_seeds = trained_seeds or {}
        self.model_hashes = frozenset(model_hashes)
        try:
            params = inspect.signature(obj.translate).parameters
        except (TypeError, ValueError):
            params = {}
        self.takes_seed = "seed" in params or bool(self.trained_seeds)

    def translate(self, pressures_s: np.ndarray, poses_s: np.ndarray, seed: int):
        """Returns (D_c commands [T * k, 3] bar, k)."""
        if self.trained_seeds:
            out = self.trained_seeds[seed].translate(pressures_s, poses_s)
        elif self.takes_seed:
            out = self._obj.translate(pressures_s, poses_s, seed=seed)
        else:
            out = self._obj.translate(pressures_s, poses_s)
        commands, k = out
        commands = np.asarray(commands, dtype=np.float64)
        k = int(k)
        if commands.shape != (pressures_s.shape[0] * k, 3):
            raise ValueError(
                f"{self.name}.translate returned {commands.shape}, expected"
                f" ({pressures_s.shape[0] * k}, 3) for k = {k}"
            )
        return commands, k


def load_translator(method: str, cfg: EvalConfig) -> tuple[Translator | None, str]:
    """Loads a translator method's checkpoint (`translator_source`) with `ccgan.load_translator`.

    Only a default checkpoint may be absent: then (None, a note naming the file and the flag that
    gives another). One that was asked for (`translator_source`) and is absent, or any that does
    not load, raises, so a run never reports a table without the method it was asked to score.
    The arms the files record (`ccgan.finetune.trained_model_hash`) go into
    `Translator.model_hashes`, for `check_translator_arms`.

    Returns:
      (translator, "loaded" or what was loaded) or (None, why).

    Raises:
      TranslatorError: an asked-for checkpoint is absent, or a checkpoint does not load.
    """
    path, asked = translator_source(method, cfg)
    flag = FLAGS[f"{method}_path"] + (" or $CCGAN_TRANSLATOR" if method == "ccgan" else "")
    if not path.is_file():
        if asked:
            raise TranslatorError(f"{method}: no translator checkpoint at {path} ({flag})")
        return None, f"no translator at its default {path} (give one with {flag})"
    from ccgan import checkpoint
    from ccgan.finetune import trained_model_hash
    from ccgan.translator import translator_from_checkpoint

    hashes = set()

    def checked(file: Path):
        """The translator in `file` (as `ccgan.load_translator` reads it); notes its arm."""
        try:
            source = checkpoint.load(file)
            translator = translator_from_checkpoint(source, file)
        except Exception as err:  # noqa: BLE001  (any failure to load is this error)
            raise TranslatorError(
                f"{method}: {file} does not load ({type(err).__name__}: {err})"
            ) from err
        hashes.add(trained_model_hash(source[1]))
        return translator

    obj = checked(path)
    # Separately trained seeds beside the checkpoint (`ccgan.train --seeds 0 1 2` writes
    # translator_seed{s}.ckpt): used when there is one for every evaluation seed.
    seeds, why = {}, "loaded"
    if len(cfg.seeds) > 1:
        files = {s: path.parent / f"translator_seed{s}.ckpt" for s in cfg.seeds}
        if all(f.exists() for f in files.values()):
            seeds = {s: checked(f) for s, f in files.items()}
            why = f"loaded, trained seeds {list(cfg.seeds)}"
    return Translator(method, obj, seeds, frozenset(hashes - {None})), why


def check_translator_arms(translators: dict, arm) -> None:
    """Refuses translators whose files record training on another arm than `arm`.

    Raises:
      TranslatorError: a file records another `Arm.model_hash` (another MJCF: e.g. the soft arm
        for translators of the solid-disc one), which would score them on an arm they never saw.
    """
    for method, tr in translators.items():
        other = sorted(tr.model_hashes - {arm.model_hash})
        if other:
            raise TranslatorError(
                f"{method}: trained on the arm with model hash {', '.join(other)}, but the arm"
                f" evaluated has {arm.model_hash} (choose the arm with --model)"
            )


# --------------------------------------------------------------------------------- evaluation


def add_noise(pressures_bar: np.ndarray, std: float, seed: int) -> np.ndarray:
    """Source pressures [T, 3] (bar) plus N(0, std) on the normalised scale (p / 3.5), clipped.

    The noisy normalised pressures are clipped to [0, 1] (0 .. 3.5 bar; the valve then floors
    them at 0.2 bar).
    """
    rng = np.random.default_rng(seed)
    scale = programs.P_HIGH_BAR
    noisy = np.asarray(pressures_bar) / scale + rng.normal(0.0, std, np.shape(pressures_bar))
    return np.clip(noisy, 0.0, 1.0) * scale


class _InThread:
    """Runs fn(*args) in a daemon thread (an error elsewhere does not wait for it to finish).

    With `background=False` fn runs at once, in the caller's thread.
    """

    def __init__(self, fn, *args, background: bool = True):
        self._out, self._err, self._thread = None, None, None
        if background:
            self._thread = threading.Thread(target=self._run, args=(fn, args), daemon=True)
            self._thread.start()
        else:
            self._run(fn, args)

    def _run(self, fn, args):
        try:
            self._out = fn(*args)
        except BaseException as err:  # noqa: BLE001  (re-raised in result())
            self._err = err

    def result(self):
        """fn's return value; re-raises fn's exception."""
        if self._thread is not None:
            self._thread.join()
        if self._err is not None:
            raise self._err
        return self._out


def _errors_with_ratio(poses, target, oracle_summary, horizon):
    out = metrics.tracking_errors(poses, target)
    if oracle_summary is not None:
        head = metrics.tracking_errors(poses[..., :horizon, :], target[:horizon])
        out["x_err_cm_mean_oracle_window"] = head["x_err_cm_mean"]
        out["phi_err_rad_mean_oracle_window"] = head["phi_err_rad_mean"]
        out["x_ratio_to_oracle"] = head["x_err_cm_mean"] / max(oracle_summary["x"], 1e-12)
        out["phi_ratio_to_oracle"] = head["phi_err_rad_mean"] / max(oracle_summary["phi"], 1e-12)
    return out


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
    import jax

    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    notes: list[str] = []

    # Translators first: a checkpoint that was asked for and does not load stops the run here.
    # A missing default one is skipped with a note, never imitated.
    t0 = time.perf_counter()
    translators: dict[str, Translator] = {}
    for method in TRANSLATOR_METHODS:
        if method in cfg.methods:
            tr, why = load_translator(method, cfg)
            if tr is None:
                note = f"{method.upper()} skipped: {why}."
                notes.append(note)
                log("NOTE: " + note)
            else:
                translators[method] = tr
                if tr.trained_seeds:
                    note = (
                        f"{method.upper()}: one separately trained model per seed "
                        f"{sorted(tr.trained_seeds)}; its ± spans training seeds."
                    )
                    notes.append(note)
                    log("NOTE: " + note)
    timings["translators_s"] = time.perf_counter() - t0
    model = model_description(cfg)
    if translators and model["note"] != SOLID_ARM_NOTE and cfg.xml is None:
        note = f"the arm {model['file']} is {model['note']}."
        notes.append(note)
        log("NOTE: " + note)
    t0 = time.perf_counter()
    arm_s, arm_c = load_arms(cfg)
    timings["load_s"] = time.perf_counter() - t0
    check_translator_arms(translators, arm_c)
    out_dir = output_dir(cfg)
    cfg = dataclasses.replace(cfg, out_dir=str(out_dir))
    log(f"writing into {out_dir}" + (" (the committed results)" if is_main_job(cfg) else ""))

    run_oracle = "oracle" in cfg.methods
    if run_oracle and jax.default_backend() == "cpu" and cfg.xml is None and cfg.oracle.steps > 0:
        if cfg.oracle.horizon_s is None or cfg.oracle.horizon_s > 5.0:
            note = (
                "oracle on CPU with a horizon over 5 s: expect hours (measured on a 2-core CPU:"
                " 500 s for 10 Adam steps of five 2 s programs at k = 10)."
            )
            notes.append(note)
            log("NOTE: " + note)
    methods = [m for m in cfg.methods if m not in TRANSLATOR_METHODS or m in translators]

    # The paper scored translations through its learned F_c; the CCGAN-GP checkpoint carries
    # one, so every method's D_c commands are scored through it too, beside the simulator.
    fc_model = getattr(translators.get("ccgan"), "_obj", None)
    if fc_model is not None and getattr(fc_model, "f_c_params", None) is None:
        fc_model = None
    rest_c = arm_c.rest_pose()

    def fc_errors(cmd: np.ndarray, k: int, target: np.ndarray) -> dict:
        if fc_model is None:
            return {}
        poses = every_kth(fc_model.predict_poses(cmd, rest_c), k)
        err = metrics.tracking_errors(poses, target[: poses.shape[0]])
        return {
            "fc_x_err_cm_mean": err["x_err_cm_mean"],
            "fc_phi_err_rad_mean": err["phi_err_rad_mean"],
        }

    # Stretch factor from the validation program.
    k_stretch, k_errors = 1, {}
    if "stretch" in methods or "oracle" in methods or "mpc" in methods:
        t0 = time.perf_counter()
        p_val = programs.validation_program(cfg.validation_duration_s)
        k_stretch, k_errors = choose_stretch_k(
            arm_s, arm_c, p_val, cfg.stretch_candidates, cfg.backend
        )
        timings["choose_k_s"] = time.perf_counter() - t0
        log(f"stretch k = {k_stretch} (validation X_err cm by k: {k_errors})")

    mpc_commands: dict[str, np.ndarray] = {}

    def commands_for(method, shape, p_s, poses_s, seed):
        if method == "none":
            return np.asarray(p_s), 1
        if method == "stretch":
            return stretch(p_s, k_stretch), k_stretch
        if method == "mpc":
            return mpc_commands[shape], k_stretch
        return translators[method].translate(p_s, poses_s, seed)

    def seeds_for(method):
        stochastic = method in translators and translators[method].takes_seed
        return list(cfg.seeds) if stochastic else list(cfg.seeds[:1])

    # Targets first: the oracle optimises every shape at once (one vmapped MJX rollout).
    t0 = time.perf_counter()
    sources = {shape: programs.SHAPES[shape](cfg.duration_s) for shape in cfg.shapes}
    target_list = rollout_grouped(
        arm_s, [(sources[s], 1) for s in cfg.shapes], cfg.backend, "D_s targets"
    )
    targets = dict(zip(cfg.shapes, target_list, strict=True))
    timings["targets_s"] = time.perf_counter() - t0

    # On an accelerator the oracle runs in a worker thread (JAX releases the GIL) while the
    # translators and the MuJoCo C rollouts below keep the CPU cores busy. On a CPU the two
    # would fight for the same cores (2-core EPYC, the full table: 1048 s overlapped, in
    # results/full; 915 s one after the other at commit 7e006b8), so there it runs first.
    oracle_future, horizon = None, None
    if "oracle" in methods:
        n_steps = min(t.shape[0] for t in targets.values())
        horizon = n_steps
        if cfg.oracle.horizon_s is not None:
            horizon = max(1, min(n_steps, int(round(cfg.oracle.horizon_s * programs.CONTROL_HZ))))
        oracle_targets = np.stack([targets[s][:horizon] for s in cfg.shapes])
        oracle_sources = np.stack([sources[s][:horizon] for s in cfg.shapes])
        t0 = time.perf_counter()
        oracle_init = oracle_lib.start_commands(
            arm_c, oracle_targets, oracle_sources, k_stretch, cfg.oracle, progress=True
        )
        if cfg.oracle.init == "mpc":
            timings["oracle_init_s"] = time.perf_counter() - t0
        oracle_future = _InThread(
            oracle_lib.oracle_commands,
            arm_c,
            oracle_targets,
            oracle_init,
            k_stretch,
            cfg.oracle,
            cfg.oracle.held,
            True,
            background=jax.default_backend() != "cpu",
        )

    if "mpc" in methods:
        t0 = time.perf_counter()
        every, _ = mpc.track(
            arm_c,
            np.stack([targets[s] for s in cfg.shapes]),
            k_stretch,
            np.stack([sources[s] for s in cfg.shapes]),
            progress=True,
        )
        mpc_commands.update(zip(cfg.shapes, every, strict=True))
        timings["mpc_s"] = time.perf_counter() - t0
        log(f"mpc: {len(cfg.shapes)} shapes tracked in the D_c simulator, {timings['mpc_s']:.1f} s")

    # Every method, seed, noise level and repetition of every shape: commands first, then
    # batched D_c rollouts per command length (one thread per trajectory on MuJoCo C).
    t0 = time.perf_counter()
    specs = []  # (key, method, source program [T, 3] bar, target [T, 6], seed)
    translated = [m for m in methods if m != "oracle"]
    robust_methods = [
        m for m in ("stretch", *TRANSLATOR_METHODS) if m in methods and cfg.robustness
    ]
    for shape in cfg.shapes:
        p_s, target = sources[shape], targets[shape]
        for method in translated:
            for seed in seeds_for(method):
                specs.append((("table", shape, method, seed), method, p_s, target, seed))
        for method in robust_methods:
            for std in cfg.noise_stds:
                for seed in cfg.seeds:
                    key = ("noise", shape, method, std, seed)
                    specs.append((key, method, add_noise(p_s, std, seed), target, seed))
            # Repetitions of one translator: a sampling translator draws seeds 0..R-1; one
            # with a model per training seed repeats the first seed's model.
            trained = method in translators and translators[method].trained_seeds
            rep_seeds = [cfg.seeds[0]] * cfg.n_repeats if trained else range(cfg.n_repeats)
            for rep, seed in enumerate(rep_seeds):
                specs.append((("repeat", shape, method, rep), method, p_s, target, seed))
    keys = [spec[0] for spec in specs]
    jobs = [
        commands_for(method, key[1], p_s, target, seed)
        for key, method, p_s, target, seed in tqdm(specs, desc="D_c commands", unit="program")
    ]
    timings["commands_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    n_table = sum(key[0] == "table" for key in keys)
    label = f"D_c rollouts ({n_table} shape x method, {len(keys) - n_table} noise + periodicity)"
    poses_of = dict(zip(keys, rollout_grouped(arm_c, jobs, cfg.backend, label), strict=True))
    commands_of = dict(zip(keys, jobs, strict=True))
    timings["dc_rollouts_s"] = time.perf_counter() - t0
    log(
        f"{len(jobs)} D_c rollouts ({cfg.backend}): commands {timings['commands_s']:.1f} s,"
        f" rollouts {timings['dc_rollouts_s']:.1f} s"
    )

    oracle_out: dict[str, tuple] = {}
    if oracle_future is not None:
        t0 = time.perf_counter()
        cmds, info = oracle_future.result()
        timings["oracle_s"] = info["wall_s"]
        timings["oracle_wait_s"] = time.perf_counter() - t0
        timings["oracle_first_step_s"] = info["step_wall_s"][0] if info["step_wall_s"] else 0.0
        timings["oracle_step_s_median"] = float(np.median(info["step_wall_s"][1:] or [0.0]))
        history = np.asarray(info["loss_history"]).reshape(cfg.oracle.steps, len(cfg.shapes))
        oracle_poses = rollout_grouped(arm_c, [(c, k_stretch) for c in cmds], cfg.backend)
        for i, shape in enumerate(cfg.shapes):
            losses = [float(v) for v in history[:, i]]
            oracle_out[shape] = (cmds[i], oracle_poses[i], losses, info["best_loss"][i])
        log(
            f"oracle: {len(cfg.shapes)} shapes x {horizon} steps optimised together,"
            f" {cfg.oracle.steps} Adam steps, {timings['oracle_s']:.1f} s"
            f" (first step incl. compiling {timings['oracle_first_step_s']:.1f} s, then"
            f" {timings['oracle_step_s_median']:.1f} s per step;"
            f" waited {timings['oracle_wait_s']:.1f} s for it after the rollouts)"
        )

    table: dict[str, dict] = {}
    trajectories: dict[str, dict] = {}
    for shape in cfg.shapes:
        p_s, target = sources[shape], targets[shape]
        traj = {"pressures_s": p_s, "target": target, "poses": {}, "commands": {}, "k": {}}
        rows = {}
        oracle_summary = None
        if shape in oracle_out:
            cmd, poses_o, loss_history, loss_best = oracle_out[shape]
            row = metrics.tracking_errors(poses_o, target[:horizon])
            oracle_summary = {"x": row["x_err_cm_mean"], "phi": row["phi_err_rad_mean"]}
            row.update(
                k=k_stretch,
                window_steps=horizon,
                oracle_loss_first=loss_history[0] if loss_history else None,
                oracle_loss_best=loss_best,
                oracle_loss_history=loss_history,
            )
            row["x_err_cm_mean_oracle_window"] = row["x_err_cm_mean"]
            row["phi_err_rad_mean_oracle_window"] = row["phi_err_rad_mean"]
            row["x_ratio_to_oracle"] = row["phi_ratio_to_oracle"] = 1.0
            row.update(fc_errors(cmd, k_stretch, target))
            rows["oracle"] = row
            traj["poses"]["oracle"], traj["commands"]["oracle"] = poses_o, cmd
            traj["k"]["oracle"] = k_stretch
        for method in translated:
            seeds = seeds_for(method)
            first = ("table", shape, method, seeds[0])
            cmd, k = commands_of[first]
            traj["poses"][method], traj["commands"][method] = poses_of[first], cmd
            traj["k"][method] = k
            poses_all = np.stack([poses_of["table", shape, method, s] for s in seeds])
            row = _errors_with_ratio(poses_all, target, oracle_summary, horizon)
            row.update(k=k, n_seeds=len(poses_all))
            row.update(fc_errors(cmd, k, target))
            rows[method] = row
        table[shape] = rows
        trajectories[shape] = traj
        log(
            f"{shape}: "
            + ", ".join(
                f"{m} {r['x_err_cm_mean']:.3f} cm / {r['phi_err_rad_mean']:.3f} rad"
                for m, r in rows.items()
            )
        )

    noise, periodicity = {}, {}
    for shape in cfg.shapes if robust_methods else ():
        traj, target = trajectories[shape], targets[shape]
        noise[shape], periodicity[shape] = {}, {}
        for method in robust_methods:
            res, keep = {}, {}
            for std in cfg.noise_stds:
                poses_std = np.stack(
                    [poses_of["noise", shape, method, std, seed] for seed in cfg.seeds]
                )
                res[str(std)] = metrics.tracking_errors(poses_std, target)
                keep[std] = poses_std[0]
            noise[shape][method] = res
            traj.setdefault("noise", {})[method] = keep
            reps = np.stack([poses_of["repeat", shape, method, r] for r in range(cfg.n_repeats)])
            spread = metrics.repetition_spread_cm(reps)
            spread.update(metrics.tracking_errors(reps, target))
            periodicity[shape][method] = spread
            traj.setdefault("repeats", {})[method] = reps

    results = {
        "command": command,
        "machine": machine_description(),
        "backend": cfg.backend,
        "model_hash": arm_s.model_hash,
        "model": model,
        "config": dataclasses.asdict(cfg)
        | {"xml": None if cfg.xml is None else "custom", "model_path": model["file"]},
        "methods_run": methods,
        "notes": notes,
        "stretch_k": k_stretch,
        "stretch_validation_x_err_cm": {str(k): v for k, v in k_errors.items()},
        "table": table,
        "noise": noise,
        "periodicity": periodicity,
        "timings": timings,
    }
    mark = run_mark(results["config"])
    if cfg.plots:
        from eval import plots

        t0 = time.perf_counter()
        results["figures"] = plots.write_all(trajectories, results, out_dir, mark)
        timings["plots_s"] = time.perf_counter() - t0
    if cfg.render:
        from eval import render

        t0 = time.perf_counter()
        results["videos"] = render.write_all(arm_s, arm_c, trajectories, cfg, out_dir, mark)
        timings["render_s"] = time.perf_counter() - t0
    timings["total_s"] = time.perf_counter() - t_start
    results["wall_time_s"] = timings["total_s"]
    (out_dir / "shapes.json").write_text(json.dumps(results, indent=2, default=_json_default))
    (out_dir / "shapes.md").write_text(markdown_report(results))
    log(f"wrote {out_dir / 'shapes.md'} and shapes.json; wall time {timings['total_s']:.1f} s")
    return results


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)


def _k_errors(results: dict) -> str:
    errors = results["stretch_validation_x_err_cm"]
    return ", ".join(f"k={k}: {v:.3f}" for k, v in errors.items())


def _pair_table(caption: str, table: dict, methods: list, keys: tuple[str, str], digits: int):
    """Markdown lines of a shape x method table whose cells are two row fields, 'a / b'."""
    lines = ["", caption, "", "| shape | " + " | ".join(methods) + " |"]
    lines.append("|---|" + "---|" * len(methods))
    for shape, rows in table.items():
        cells = [
            f"{rows[m][keys[0]]:.{digits}f} / {rows[m][keys[1]]:.{digits}f}"
            if keys[0] in rows.get(m, {})
            else "-"
            for m in methods
        ]
        lines.append(f"| {shape} | " + " | ".join(cells) + " |")
    return lines


METHOD_NAMES = {
    "none": "untranslated",
    "stretch": "stretch only",
    "ccgan": "CCGAN-GP",
    "ccgan_sim": "CCGAN-GP + sim fine-tune",
    "wcgan": "WCGAN-GP",
    "mpc": "MPC in the D_c simulator",
    "oracle": "the oracle",
}


#: Each learned translator and the methods its findings compare it with: the baseline WCGAN-GP
#: only against the simple methods, CCGAN-GP against its fine-tuned version once (from that side).
FINDINGS_BASES = {
    "ccgan": ("none", "stretch", "wcgan", "mpc"),
    "ccgan_sim": ("none", "stretch", "ccgan", "wcgan", "mpc"),
    "wcgan": ("none", "stretch"),
}


def _span(values) -> str:
    lo, hi = min(values), max(values)
    return f"{lo:.2f}" if f"{lo:.2f}" == f"{hi:.2f}" else f"{lo:.2f}-{hi:.2f}"


def findings(results: dict) -> list[str]:
    """Plain statements computed from the results: each learned translator against each other
    method (on how many shapes its mean X_err is lower, and the X_err ratio), how many shapes it
    tracks within 1.5x the oracle, and what the largest noise level does to each method.

    Returns:
      Markdown bullet lines (empty when there is nothing to compare).
    """
    table, methods = results["table"], results["methods_run"]
    names = list(table)
    out = []
    for m, bases in FINDINGS_BASES.items():
        if m not in methods:
            continue
        for base in (b for b in bases if b in methods):
            ratios = [table[s][m]["x_err_cm_mean"] / table[s][base]["x_err_cm_mean"] for s in names]
            lower = [s for s, r in zip(names, ratios, strict=True) if r < 1.0]
            out.append(
                f"- {METHOD_NAMES[m]} against {METHOD_NAMES[base]}: lower mean X_err on"
                f" {len(lower)} of {len(names)} shapes ({', '.join(lower) or 'no shape'});"
                f" X_err ratio {METHOD_NAMES[m]} / {METHOD_NAMES[base]} {_span(ratios)}."
            )
        if "oracle" in methods:
            ratios = [table[s][m]["x_ratio_to_oracle"] for s in names]
            within = [s for s, r in zip(names, ratios, strict=True) if r <= 1.5]
            out.append(
                f"- {METHOD_NAMES[m]} within 1.5x the oracle's X_err (over the oracle's window) on"
                f" {len(within)} of {len(names)} shapes ({', '.join(within) or 'no shape'});"
                f" ratio {_span(ratios)}."
            )
    noise = results.get("noise") or {}
    if noise:
        first = next(iter(noise.values()))
        top = max(next(iter(first.values())), key=float)
        for m in first:
            clean = [table[s][m]["x_err_cm_mean"] for s in noise]
            noisy = [noise[s][m][top]["x_err_cm_mean"] for s in noise]
            out.append(
                f"- Largest noise (std {top}), {METHOD_NAMES[m]}: mean X_err {min(clean):.3f}-"
                f"{max(clean):.3f} cm clean -> {min(noisy):.3f}-{max(noisy):.3f} cm"
                f" ({_span([n / c for n, c in zip(noisy, clean, strict=True)])}x)."
            )
    return out


def markdown_report(results: dict) -> str:
    """The results as markdown: a Table-I-like table, then the robustness tests.

    Every length in it comes from results["config"]; the arm's file and the quick-run mark are
    stated when results has them (older shapes.json files have neither and render as before).
    """
    table = results["table"]
    methods = results["methods_run"]
    config = results["config"]
    mark = run_mark(config)
    lines = ["# Trajectory tracking in D_c (simulator-scored)", ""]
    if mark:
        lines += [f"**{mark}** (`--quick`: a smoke test of the pipeline).", ""]
    lines += [
        f"- command: `{results['command']}`",
        f"- machine: {results['machine']}",
        f"- simulator backend: {results['backend']}; model hash {results['model_hash']};"
        f" domains: source -> {config.get('target_domain', 'constrained')}",
    ]
    if "model" in results:
        lines.append(
            f"- arm: `{results['model']['file']}`, {results['model']['note']}; programs"
            f" {config['duration_s']:g} s per shape, seeds {list(config['seeds'])}"
        )
    lines += [
        f"- wall time: {results['wall_time_s']:.1f} s",
        f"- stretch k = {results['stretch_k']}, chosen by lowest mean X_err on a"
        f" {config['validation_duration_s']:g} s validation"
        f" program over k in {list(results['stretch_validation_x_err_cm'])}"
        f" (X_err cm: {_k_errors(results)})",
    ]
    lines += [f"- NOTE: {n}" for n in results["notes"]]
    lines += [
        "",
        "X_err (cm) / phi_err (rad), mean ± std over all samples (and seeds, where a method is"
        " stochastic or has one trained model per seed). k = control periods per source step."
        " Paper Table I (CCGAN-GP, through F_c):"
        " circle 2.98/0.276, rectangle 1.56/0.126, damped circle 1.19/0.101, ellipse 1.56/0.126,"
        " kite 2.37/0.19.",
        "",
        "| shape | " + " | ".join(methods) + " |",
        "|---|" + "---|" * len(methods),
    ]
    for shape, rows in table.items():
        cells = []
        for m in methods:
            r = rows.get(m)
            if r is None:
                cells.append("-")
                continue
            cell = (
                f"{r['x_err_cm_mean']:.3f} ± {r['x_err_cm_std']:.3f} /"
                f" {r['phi_err_rad_mean']:.3f} ± {r['phi_err_rad_std']:.3f} (k={r['k']})"
            )
            cells.append(cell)
        lines.append(f"| {shape} | " + " | ".join(cells) + " |")
    scored = [
        m for m in methods if any("fc_x_err_cm_mean" in rows.get(m, {}) for rows in table.values())
    ]
    if scored:
        lines += _pair_table(
            "The same D_c commands scored through the CCGAN-GP checkpoint's forward model F_c"
            " (open loop from rest, every k-th pose), as the paper scored its Table I:"
            " X_err (cm) / phi_err (rad), means.",
            table,
            scored,
            ("fc_x_err_cm_mean", "fc_phi_err_rad_mean"),
            digits=3,
        )
    if "oracle" in methods:
        oracle_cfg = config.get("oracle", {})
        held = oracle_cfg.get("held", False)
        loss_first = [row["oracle"].get("oracle_loss_first") for row in table.values()]
        loss_best = [row["oracle"].get("oracle_loss_best") for row in table.values()]
        effort = ""
        if "steps" in oracle_cfg and None not in loss_first + loss_best:
            effort = (
                f" It started from the {oracle_cfg.get('init', 'stretch')} commands and ran"
                f" {oracle_cfg['steps']} Adam steps (lr {oracle_cfg['learning_rate']});"
                f" its loss fell from {min(loss_first):.4f}-{max(loss_first):.4f} to"
                f" {min(loss_best):.4f}-{max(loss_best):.4f} (cm^2), so a longer optimisation"
                " may lower it further and raise every ratio."
            )
        lines += _pair_table(
            "Ratio to the oracle (mean X_err / oracle mean X_err; mean phi_err / oracle's),"
            " over the window the oracle optimised; the oracle's commands were "
            + (
                "held k periods per source step, like every translator's."
                if held
                else "free in every control period."
            )
            + effort,
            table,
            methods,
            ("x_ratio_to_oracle", "phi_ratio_to_oracle"),
            digits=2,
        )
    found = findings(results)
    if found:
        lines += ["", "## Findings", "", *found]
    if results["noise"]:
        lines += [
            "",
            "## Noise test",
            "",
            "Gaussian noise (std on pressure / 3.5 bar, clipped to [0, 1]) on the source pressures"
            " before the method; X_err (cm) / phi_err (rad) against the clean target.",
            "",
        ]
        stds = list(next(iter(next(iter(results["noise"].values())).values())))
        lines += ["| shape | method | " + " | ".join(f"std {s}" for s in stds) + " |"]
        lines += ["|---|---|" + "---|" * len(stds)]
        for shape, per_method in results["noise"].items():
            for m, res in per_method.items():
                cells = [
                    f"{res[s]['x_err_cm_mean']:.3f} / {res[s]['phi_err_rad_mean']:.3f}"
                    for s in stds
                ]
                lines.append(f"| {shape} | {m} | " + " | ".join(cells) + " |")
    if results["periodicity"]:
        lines += [
            "",
            "## Periodicity test",
            "",
            "Each shape run repeatedly from rest (translators re-sampled with seeds 0..R-1);"
            " spread = RMS distance of the repetitions' tips from their mean (cm).",
            "",
            "| shape | method | spread mean (cm) | spread max (cm) | X_err (cm) |",
            "|---|---|---|---|---|",
        ]
        for shape, per_method in results["periodicity"].items():
            for m, r in per_method.items():
                lines.append(
                    f"| {shape} | {m} | {r['spread_cm_mean']:.2e} | {r['spread_cm_max']:.2e} |"
                    f" {r['x_err_cm_mean']:.3f} |"
                )
    if results.get("figures"):
        lines += ["", "## Figures", ""] + [f"- `{f}`" for f in results["figures"]]
    if results.get("videos"):
        lines += [
            "",
            "## Videos",
            "",
            "Panels left to right: D_s arm (source program), D_c arm under the translation, D_c arm"
            " untranslated. Green: the D_s target tip path; red: the panel's own tip path.",
            "",
        ] + [f"- `{v}`" for v in results["videos"]]
    lines += ["", "## Timings (s)", ""] + [f"- {k}: {v:.1f}" for k, v in results["timings"].items()]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------- CLI

#: EvalConfig fields (OracleConfig's as "oracle.<field>") -> the flag that sets them, so a
#: ConfigError becomes a usage error that names the flag.
FLAGS = {
    "shapes": "--shapes",
    "methods": "--methods",
    "seeds": "--seeds",
    "out_dir": "--out",
    "backend": "--backend",
    "duration_s": "--duration",
    "stretch_candidates": "--stretch-choices",
    "model_path": "--model",
    "target_domain": "--target-domain",
    "ccgan_path": "--ccgan-path",
    "wcgan_path": "--wcgan-path",
    "ccgan_sim_path": "--ccgan-sim-path",
    "oracle.steps": "--oracle-steps",
    "oracle.learning_rate": "--oracle-lr",
    "oracle.init": "--oracle-init",
    "oracle.horizon_s": "--oracle-horizon",
}


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
        choices=list(METHODS),
        metavar="METHOD",
        help=f"methods to score, of {', '.join(METHODS)} (default: "
        + " ".join(DEFAULT_METHODS)
        + ", less the oracle on"
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
        "--backend",
        "--device",
        dest="backend",
        choices=["c", "mjx"],
        default="c",
        help="simulator of every rollout but the oracle's: MuJoCo C or MJX",
    )
    p.add_argument(
        "--duration",
        metavar="SECONDS",
        type=float,
        default=EvalConfig.duration_s,
        help="length of each shape program (s)",
    )
    p.add_argument(
        "--stretch-choices",
        metavar="K",
        nargs="+",
        type=int,
        default=list(EvalConfig.stretch_candidates),
        help="stretch factors k >= 1 (control periods per source step) tried",
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
        "--model",
        metavar="MJCF",
        default=EvalConfig.model_path,
        help="MJCF file of the arm; by default the old solid-disc arm, on which the committed"
        " translators were trained",
    )
    p.add_argument(
        "--target-domain",
        default=EvalConfig.target_domain,
        choices=["constrained", "aged"],
        help="D_c: the paper's viscous medium, or the aged arm (stiffness x0.7, same medium)",
    )
    p.add_argument(
        "--ccgan-path",
        metavar="CKPT",
        default=None,
        help="CCGAN-GP translator checkpoint (default:"
        " $CCGAN_TRANSLATOR, else results/ccgan/translator.ckpt, skipped if absent)",
    )
    p.add_argument(
        "--wcgan-path",
        metavar="CKPT",
        default=None,
        help="WCGAN-GP translator checkpoint (default:"
        " results/wcgan/translator.ckpt, skipped if absent)",
    )
    p.add_argument(
        "--ccgan-sim-path",
        metavar="CKPT",
        default=None,
        help="fine-tuned CCGAN-GP checkpoint"
        " (default: results/ccgan_sim8/translator.ckpt, skipped if absent)",
    )
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
    return p


def parse_args(argv: list[str] | None = None) -> EvalConfig:
    """EvalConfig from command-line flags (see --help); a setting EvalConfig refuses exits with
    a usage error naming its flag, before any work."""
    p = build_parser()
    a = p.parse_args(argv)
    methods = default_methods() if a.methods is None else a.methods
    horizon = None if a.oracle_horizon is not None and a.oracle_horizon <= 0 else a.oracle_horizon
    try:
        cfg = EvalConfig(
            shapes=tuple(a.shapes),
            methods=tuple(methods),
            seeds=tuple(a.seeds),
            duration_s=a.duration,
            backend=a.backend,
            stretch_candidates=tuple(a.stretch_choices),
            render=a.render,
            robustness=not a.no_robustness,
            out_dir=a.out,
            model_path=a.model,
            ccgan_path=a.ccgan_path,
            wcgan_path=a.wcgan_path,
            ccgan_sim_path=a.ccgan_sim_path,
            target_domain=a.target_domain,
            oracle=OracleConfig(
                steps=a.oracle_steps,
                learning_rate=a.oracle_lr,
                horizon_s=horizon,
                held=not a.oracle_per_period,
                init=a.oracle_init,
            ),
        )
        cfg = quick(cfg) if a.quick else cfg
    except ConfigError as err:
        p.error(f"{FLAGS.get(err.field, err.field)} {err.problem}")
    if a.methods is None and "oracle" not in methods:
        print(
            "NOTE: oracle left out by default on CPU (MJX gradients: ~8 min more on 2 cores"
            " with --oracle-steps 10); add it with --methods ... oracle."
        )
    return cfg


def main(argv: list[str] | None = None) -> dict:
    """Thin entry point: parse flags, evaluate, print the wall time. A translator checkpoint
    that does not load ends the run with an error (exit status 1) before any work."""
    from mjx_arm.machine import enable_compilation_cache

    cfg = parse_args(argv)
    enable_compilation_cache()
    command = "python -m eval.shapes " + " ".join(sys.argv[1:] if argv is None else argv)
    t0 = time.perf_counter()
    try:
        results = evaluate(cfg, command=command.strip())
    except TranslatorError as err:
        raise SystemExit(f"python -m eval.shapes: error: {err}") from None
    print(f"total wall time: {time.perf_counter() - t0:.1f} s")
    return results
