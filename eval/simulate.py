"""The simulator work of one evaluation, step by step: the oracle, mpc, every method's D_c
commands and their batched D_c rollouts, the table's scores and the robustness tests.

`eval.pipeline.evaluate` runs these steps in order on one `Plan` (the arms, methods, stretch k
and the programs: D_s pressures [T, 3] in bar, target poses [T, 6] in m and rad) and keeps their
timings (s) and notes in one `RunLog`. Errors are X_err (cm) and phi_err (rad), see
`tracking.metrics`; k is control periods per source step.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

import mjx_arm  # (before jax: sets the XLA CPU flag)
from eval.methods import (
    METHOD_NAMES,
    TranslatorMethod,
    forward_model,
    method_commands,
    method_seeds,
)
from mjx_arm import compile_notice, programs
from tracking import metrics, mpc
from tracking import oracle as oracle_lib
from tracking.held import every_kth, rollout_grouped

#: The oracle's state in the output folder, kept after every Adam step.
ORACLE_PROGRESS = "oracle_progress.npz"
#: The receding-horizon tracker's commands, kept in the output folder (`tracking.mpc.track`'s
#: result_path): the oracle's start over its window, and the mpc method's over whole shapes.
ORACLE_START = "oracle_start.npz"
MPC_RESULT = "mpc_commands.npz"


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
    """`tracking.metrics.tracking_errors` of poses [S, T, 6] against target [T, 6], and with an
    oracle (oracle_summary: its mean X_err "x" in cm and phi_err "phi" in rad over its window)
    the errors over the first `horizon` steps and their ratios to the oracle's."""
    out = metrics.tracking_errors(poses, target)
    if oracle_summary is not None:
        head = metrics.tracking_errors(poses[..., :horizon, :], target[:horizon])
        out["x_err_cm_mean_oracle_window"] = head["x_err_cm_mean"]
        out["phi_err_rad_mean_oracle_window"] = head["phi_err_rad_mean"]
        out["x_ratio_to_oracle"] = head["x_err_cm_mean"] / max(oracle_summary["x"], 1e-12)
        out["phi_ratio_to_oracle"] = head["phi_err_rad_mean"] / max(oracle_summary["phi"], 1e-12)
    return out


@dataclasses.dataclass
class RunLog:
    """A run's notes (stated in shapes.md), its timings (s, in the order the steps ran) and where
    its progress lines go."""

    log: object
    notes: list[str] = dataclasses.field(default_factory=list)
    timings: dict[str, float] = dataclasses.field(default_factory=dict)

    def note(self, text: str) -> None:
        """Keeps `text` for shapes.md and logs it as a NOTE."""
        self.notes.append(text)
        self.log("NOTE: " + text)


@dataclasses.dataclass(frozen=True)
class Plan:
    """What every step after loading reads: the arms, the methods run, the stretch k and the
    programs, so the steps share one argument instead of a dozen."""

    cfg: Any
    """The `eval.pipeline.EvalConfig` run (not imported: the pipeline imports this module)."""
    arm_s: mjx_arm.Arm | mjx_arm.RodArm
    """The D_s arm of the targets: the chain's, or with cfg.simulator "rod" the rod's."""
    arm_c: mjx_arm.Arm | mjx_arm.RodArm
    """The D_c arm every method's commands run in (the chain's, or the rod's)."""
    translators: dict[str, TranslatorMethod]
    methods: list[str]
    """cfg.methods less the translators that were skipped."""
    k_stretch: int
    """Control periods per source step of stretch, mpc and the oracle (1 when none runs)."""
    k_errors: dict[int, float]
    """Validation X_err (cm) by candidate k."""
    sources: dict[str, np.ndarray]
    """Shape -> D_s program [T, 3] (bar)."""
    targets: dict[str, np.ndarray]
    """Shape -> D_s poses [T, 6], the target of every method."""
    horizon: int | None
    """Source steps the oracle optimises (None when it does not run)."""
    rollout_backend: str | None = None
    """Backend of arm_s's and arm_c's rollouts: "rod" for the rod (None: cfg.backend)."""
    tracker_arm: mjx_arm.Arm | None = None
    """The D_c arm the tracker plans in: the chain's, in MuJoCo C, even when the rod scores the
    table (None: arm_c)."""

    @property
    def backend(self) -> str:
        """Backend of every rollout of arm_s and arm_c: "c", "mjx" or "rod"."""
        return self.rollout_backend or self.cfg.backend

    @property
    def planner(self) -> mjx_arm.Arm:
        """The D_c arm the tracker (and the oracle's mpc start) plans in."""
        return self.tracker_arm if self.tracker_arm is not None else self.arm_c

    @property
    def translated(self) -> list[str]:
        """Methods whose commands are made per shape (all but the oracle)."""
        return [m for m in self.methods if m != "oracle"]

    @property
    def robust_methods(self) -> list[str]:
        """Methods of the noise and periodicity tests (none when cfg.robustness is off)."""
        chosen = self.cfg.robust_methods
        return [m for m in chosen if m in self.methods and self.cfg.robustness]


def start_oracle(plan: Plan, run: RunLog) -> _InThread | None:
    """Step 3: the oracle's start commands, then its optimisation of every shape at once over
    the first `plan.horizon` source steps. Its state is kept in the output folder after every
    Adam step (`ORACLE_PROGRESS`), so a run stopped part-way and run again into the same folder
    continues the optimisation.

    On an accelerator it runs in a worker thread (JAX releases the GIL) while the translators and
    the MuJoCo C rollouts keep the CPU cores busy. On a CPU the two would fight for the same cores
    (2-core EPYC, the full table: 1048 s overlapped, in results/solid/tables/full; 915 s one after
    the other at commit 7e006b8), so there it runs at once, before them.
    """
    import jax

    if "oracle" not in plan.methods:
        return None
    cfg, shapes = plan.cfg, plan.cfg.shapes
    oracle_targets = np.stack([plan.targets[s][: plan.horizon] for s in shapes])
    oracle_sources = np.stack([plan.sources[s][: plan.horizon] for s in shapes])
    t0 = time.perf_counter()
    oracle_init = oracle_lib.start_commands(
        plan.arm_c,
        oracle_targets,
        oracle_sources,
        plan.k_stretch,
        cfg.oracle,
        progress=True,
        result_path=_kept(cfg, ORACLE_START),
    )
    if cfg.oracle.init == "mpc":
        run.timings["oracle_init_s"] = time.perf_counter() - t0
    if cfg.oracle.steps > 0:  # its gradient compiles silently for minutes on a CPU
        compile_notice.announce_compile(
            ("eval.oracle", oracle_targets.shape, plan.k_stretch),
            len(shapes),
            plan.horizon * plan.k_stretch,
            what="the oracle's gradient through the MJX rollout",
        )
    return _InThread(
        oracle_lib.oracle_commands,
        plan.arm_c,
        oracle_targets,
        oracle_init,
        plan.k_stretch,
        cfg.oracle,
        cfg.oracle.held,
        True,
        _kept(cfg, ORACLE_PROGRESS),
        background=jax.default_backend() != "cpu",
    )


def run_mpc(plan: Plan, run: RunLog) -> dict[str, np.ndarray]:
    """Step 4: mpc's D_c commands, shape -> [T * k_stretch, 3] (bar), every shape tracked at once
    in the chain's D_c simulator (`Plan.planner`, MuJoCo C; with the rod scoring the table,
    towards the rod's targets at the rod's k; empty when mpc does not run). Its cache in the
    output folder is fingerprinted by arm, targets, start, k and settings (`tracking.mpc`), so
    a run towards other targets (the chain's, the rod's) never reads another's commands."""
    if "mpc" not in plan.methods:
        return {}
    shapes = plan.cfg.shapes
    t0 = time.perf_counter()
    every, info = mpc.track(
        plan.planner,
        np.stack([plan.targets[s] for s in shapes]),
        plan.k_stretch,
        np.stack([plan.sources[s] for s in shapes]),
        progress=True,
        result_path=_kept(plan.cfg, MPC_RESULT),
    )
    run.timings["mpc_s"] = time.perf_counter() - t0
    where = "the chain's D_c simulator" if plan.tracker_arm is not None else "the D_c simulator"
    how = f"read from {MPC_RESULT}" if info["reused"] else f"tracked in {where}"
    run.log(f"mpc: {len(shapes)} shapes {how}, {run.timings['mpc_s']:.1f} s")
    return dict(zip(shapes, every, strict=True))


def _kept(cfg, name: str) -> Path | None:
    """Where a stage of the run keeps its result in the output folder (None: no folder), so a
    run stopped part-way (a deadline) and run again into the same folder continues."""
    return None if cfg.out_dir is None else Path(cfg.out_dir) / name


def _rollout_specs(plan: Plan) -> list[tuple]:
    """Every D_c rollout of the table and the robustness tests, as (key, method, source program
    [T, 3] bar, target [T, 6], seed). Keys: ("table", shape, method, seed), ("noise", shape,
    method, std, seed), ("repeat", shape, method, repetition)."""
    cfg, specs = plan.cfg, []
    for shape in cfg.shapes:
        p_s, target = plan.sources[shape], plan.targets[shape]
        for method in plan.translated:
            for seed in method_seeds(method, plan.translators, cfg.seeds):
                specs.append((("table", shape, method, seed), method, p_s, target, seed))
        for method in plan.robust_methods:
            for std in cfg.noise_stds:
                for seed in cfg.seeds:
                    key = ("noise", shape, method, std, seed)
                    specs.append((key, method, add_noise(p_s, std, seed), target, seed))
            # Repetitions of one translator: a sampling translator draws seeds 0..R-1; one
            # with a model per training seed repeats the first seed's model.
            trained = method in plan.translators and plan.translators[method].trained_seeds
            rep_seeds = [cfg.seeds[0]] * cfg.n_repeats if trained else range(cfg.n_repeats)
            for rep, seed in enumerate(rep_seeds):
                specs.append((("repeat", shape, method, rep), method, p_s, target, seed))
    return specs


def command_and_roll_out(plan: Plan, mpc_commands: dict, run: RunLog) -> tuple[dict, dict]:
    """Step 5: every method's commands for every shape, seed, noise level and repetition
    (`_rollout_specs`), then batched D_c rollouts per command length (one thread per trajectory
    on MuJoCo C).

    Returns:
      ({key: (commands [T * k, 3] bar, k)}, {key: D_c poses [T, 6] at every k-th period}).
    """
    t0 = time.perf_counter()
    specs = _rollout_specs(plan)
    keys = [spec[0] for spec in specs]
    jobs = [
        method_commands(
            method, p_s, target, seed, plan.translators, plan.k_stretch, mpc_commands.get(key[1])
        )
        for key, method, p_s, target, seed in tqdm(specs, desc="D_c commands", unit="program")
    ]
    run.timings["commands_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    n_table = sum(key[0] == "table" for key in keys)
    label = f"D_c rollouts ({n_table} shape x method, {len(keys) - n_table} noise + periodicity)"
    poses_of = dict(zip(keys, rollout_grouped(plan.arm_c, jobs, plan.backend, label), strict=True))
    run.timings["dc_rollouts_s"] = time.perf_counter() - t0
    run.log(
        f"{len(jobs)} D_c rollouts ({plan.backend}): commands {run.timings['commands_s']:.1f} s,"
        f" rollouts {run.timings['dc_rollouts_s']:.1f} s"
    )
    return dict(zip(keys, jobs, strict=True)), poses_of


def finish_oracle(plan: Plan, future: _InThread | None, run: RunLog) -> dict[str, tuple]:
    """Step 6: waits for the oracle and rolls its commands out in the D_c simulator.

    Returns:
      {shape: (commands [horizon * k, 3] bar, poses [horizon, 6], loss per Adam step (cm^2),
      best loss)}; empty when the oracle does not run.
    """
    if future is None:
        return {}
    cfg, timings = plan.cfg, run.timings
    t0 = time.perf_counter()
    cmds, info = future.result()
    timings["oracle_s"] = info["wall_s"]
    timings["oracle_wait_s"] = time.perf_counter() - t0
    timings["oracle_first_step_s"] = info["step_wall_s"][0] if info["step_wall_s"] else 0.0
    timings["oracle_step_s_median"] = float(np.median(info["step_wall_s"][1:] or [0.0]))
    history = np.asarray(info["loss_history"]).reshape(cfg.oracle.steps, len(cfg.shapes))
    oracle_poses = rollout_grouped(plan.arm_c, [(c, plan.k_stretch) for c in cmds], plan.backend)
    out = {}
    for i, shape in enumerate(cfg.shapes):
        losses = [float(v) for v in history[:, i]]
        out[shape] = (cmds[i], oracle_poses[i], losses, info["best_loss"][i])
    run.log(
        f"oracle: {len(cfg.shapes)} shapes x {plan.horizon} steps optimised together,"
        f" {cfg.oracle.steps} Adam steps, {timings['oracle_s']:.1f} s in this run,"
        f" {sum(info['step_wall_s']):.1f} s over every run that kept its progress"
        f" (first step incl. compiling {timings['oracle_first_step_s']:.1f} s, then"
        f" {timings['oracle_step_s_median']:.1f} s per step;"
        f" waited {timings['oracle_wait_s']:.1f} s for it after the rollouts)"
    )
    return out


def _fc_errors(fc_model, rest_c: np.ndarray, cmd: np.ndarray, k: int, target: np.ndarray) -> dict:
    """Means of X_err (cm) and phi_err (rad) of D_c commands [N, 3] (bar) run open loop from the
    rest pose [6] through the learned F_c, every k-th pose against target [T, 6]; {} without
    F_c."""
    if fc_model is None:
        return {}
    poses = every_kth(fc_model.predict_poses(cmd, rest_c), k)
    err = metrics.tracking_errors(poses, target[: poses.shape[0]])
    return {
        "fc_x_err_cm_mean": err["x_err_cm_mean"],
        "fc_phi_err_rad_mean": err["phi_err_rad_mean"],
    }


def _oracle_row(plan: Plan, shape: str, oracle_out: dict, fc) -> dict:
    """The oracle's table row over its window: its errors, its losses (cm^2), ratios of 1."""
    cmd, poses_o, loss_history, loss_best = oracle_out[shape]
    row = metrics.tracking_errors(poses_o, plan.targets[shape][: plan.horizon])
    row.update(
        k=plan.k_stretch,
        window_steps=plan.horizon,
        oracle_loss_first=loss_history[0] if loss_history else None,
        oracle_loss_best=loss_best,
        oracle_loss_history=loss_history,
    )
    row["x_err_cm_mean_oracle_window"] = row["x_err_cm_mean"]
    row["phi_err_rad_mean_oracle_window"] = row["phi_err_rad_mean"]
    row["x_ratio_to_oracle"] = row["phi_ratio_to_oracle"] = 1.0
    row.update(fc(cmd, plan.k_stretch, plan.targets[shape]))
    return row


def score(plan: Plan, commands_of: dict, poses_of: dict, oracle_out: dict, log) -> tuple:
    """Step 7: the table, {shape: {method: errors (cm, rad), k, ratios to the oracle, F_c
    errors}}, and the trajectories the plots and videos draw, {shape: {"pressures_s",
    "target", "poses", "commands", "k"}} (the first seed's of each method)."""
    fc_model, rest_c = forward_model(plan.translators), plan.arm_c.rest_pose()
    rest_s = plan.arm_s.rest_pose()

    def fc(cmd, k, target):
        return _fc_errors(fc_model, rest_c, cmd, k, target)

    table, trajectories = {}, {}
    for shape in plan.cfg.shapes:
        p_s, target = plan.sources[shape], plan.targets[shape]
        excursion_cm = metrics.tip_excursion_cm(target, rest_s)
        traj = {"pressures_s": p_s, "target": target, "poses": {}, "commands": {}, "k": {}}
        rows, oracle_summary = {}, None
        if shape in oracle_out:
            rows["oracle"] = row = _oracle_row(plan, shape, oracle_out, fc)
            oracle_summary = {"x": row["x_err_cm_mean"], "phi": row["phi_err_rad_mean"]}
            cmd, poses_o = oracle_out[shape][:2]
            traj["poses"]["oracle"], traj["commands"]["oracle"] = poses_o, cmd
            traj["k"]["oracle"] = plan.k_stretch
        for method in plan.translated:
            seeds = method_seeds(method, plan.translators, plan.cfg.seeds)
            first = ("table", shape, method, seeds[0])
            cmd, k = commands_of[first]
            traj["poses"][method], traj["commands"][method] = poses_of[first], cmd
            traj["k"][method] = k
            poses_all = np.stack([poses_of["table", shape, method, s] for s in seeds])
            row = _errors_with_ratio(poses_all, target, oracle_summary, plan.horizon)
            row.update(k=k, n_seeds=len(poses_all))
            row.update(fc(cmd, k, target))
            rows[method] = row
        for row in rows.values():
            row["target_excursion_cm"] = excursion_cm
            row["x_err_pct_of_excursion"] = 100.0 * row["x_err_cm_mean"] / excursion_cm
        table[shape], trajectories[shape] = rows, traj
        errors = (
            f"{METHOD_NAMES.get(m, m)} {r['x_err_cm_mean']:.3f} cm"
            f" / {r['phi_err_rad_mean']:.3f} rad"
            for m, r in rows.items()
        )
        log(f"{shape}: " + ", ".join(errors))
    return table, trajectories


def robustness(plan: Plan, trajectories: dict, poses_of: dict) -> tuple[dict, dict]:
    """Step 8: the noise test, {shape: {method: {std: errors against the clean target}}}, and
    the periodicity test, {shape: {method: repetitions' tip spread (cm) and errors}}; the first
    seed's noisy poses and every repetition go into the trajectories for the plots."""
    cfg, noise, periodicity = plan.cfg, {}, {}
    for shape in cfg.shapes if plan.robust_methods else ():
        traj, target = trajectories[shape], plan.targets[shape]
        noise[shape], periodicity[shape] = {}, {}
        for method in plan.robust_methods:
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
    return noise, periodicity
