"""Identify a target arm's medium and stiffness from its babbling data.

Given programs [N, T, 3] (bar, 10 Hz) and the tip poses [N, T, 6] a target arm traced under them
from rest, `identify` finds the `Domain` whose chain reproduces the tip positions: its
`viscosity_scale` (the medium's drag, a factor on the source medium's) and `stiffness_scale`,
as natural logs `theta` [P] (`mjx_arm.identify_family`). The loss is the mean squared tip
position error (m^2) over programs and periods; the last `n_val` programs are held out.

Two methods:

* "search" (the default): a log-grid over the parameters (each within `span` of the base's
  value), then Nelder-Mead from the best point, every evaluation a MuJoCo C rollout of all
  training programs in the arm's own timestep. No compile, exact model, about 50-70 rollouts.
* "gradient": Adam (optax) on `theta` with forward-mode derivatives of MJX rollouts
  (`identify_family.tangent_chunks`) in a planning copy (5 physics steps per period). The
  windows are prefixes of every program from rest (the target's state mid-program is not
  observed, so a window cannot start there), growing in stages: a short window fixes the drag
  (the early response of an overdamped arm is force over drag), the whole program the stiffness
  (the springs pull back on the drag's time scale, 35 s in D_c).

`docs/identification.md` compares them on the same data and says why "search" is the default.
Either way the uncertainty is a bootstrap over the training programs of the linearised fit
(each program's residuals and their Jacobian at the fit, Gauss-Newton: theta_b = theta -
H_b^-1 g_b with H_b, g_b the resample's sums of J^T J and J^T r), and `seeds` > 1 restarts the
fit from other points (their spread is reported beside it).
"""

from __future__ import annotations

import dataclasses
import math
import operator
import time
from collections.abc import Callable

import jax.numpy as jnp
import mujoco
import numpy as np
import optax
import scipy.optimize
from tqdm import tqdm

from mjx_arm import arm as arm_lib
from mjx_arm import checks, constants, domains, identify_cli
from mjx_arm.identify_family import FITTABLE, DomainFamily, Windows, check_fit

#: The identification methods; the first is the default.
METHODS = ("search", "gradient")


@dataclasses.dataclass(frozen=True)
class SearchConfig:
    """Settings of the "search" method (MuJoCo C rollouts)."""

    substeps: int = 0
    """Physics steps per 0.1 s period of the scoring arm; 0: the arm's own (25 for the committed
    arm: its planning copy at 5 moves the tip 0.2 mm RMS in D_c babbling, enough to bias a fit)."""
    grid_points: int = 4
    """Grid points per parameter, log-spaced over [base / span, base x span] (an even number
    leaves the base itself out, so a base that is the truth is not found by the grid)."""
    span: float = 3.0
    """How far (a factor) from the base arm's values the grid and the refinement may go."""
    xatol_log: float = 3e-3
    """Nelder-Mead stops when the simplex is this small in log-parameters (0.3%)."""
    max_evaluations: int = 40
    """Most Nelder-Mead evaluations per start (each a rollout of every training program)."""
    fd_step_log: float = 0.01
    """Step in log-parameters of the central differences (Gauss-Newton and bootstrap)."""
    polish_steps: int = 2
    """Gauss-Newton steps after Nelder-Mead (`_polish`), each 1 + 2P rollouts."""


@dataclasses.dataclass(frozen=True)
class GradientConfig:
    """Settings of the "gradient" method (Adam through MJX rollouts)."""

    substeps: int = 5
    """Physics steps per 0.1 s period of the MJX copy (0: the arm's own)."""
    chunk_periods: int = 50
    """Periods per compiled chunk (5 s); windows are whole chunks."""
    windows_s: tuple[float, ...] = (10.0, math.inf)
    """Stage windows (s): prefixes of every program from rest; inf: the whole program."""
    steps_per_stage: int = 12
    """Adam steps per stage."""
    learning_rate: float = 0.1
    """Adam's first step size in log-parameters (10% per step)."""
    final_learning_rate: float = 0.005
    """Step size at the last step (exponential decay over all stages)."""
    span: float = 3.0
    """Bound: parameters stay within a factor `span` of the base arm's values."""
    start_spread_log: float = 0.3
    """Seeds after the first start at the base's values times exp(N(0, this))."""
    polish_steps: int = 2
    """Gauss-Newton steps after Adam (`_polish`), each one pass over the whole programs."""


@dataclasses.dataclass(frozen=True)
class IdentifyResult:
    """What `identify` found. Values are Domain fields (factors); errors are tip positions."""

    domain: domains.Domain
    """The fitted domain: the base's, with the fitted fields replaced."""
    method: str
    fit: tuple[str, ...]
    values: dict
    """Fitted value of each field in `fit`."""
    uncertainty: dict
    """One standard deviation of each value, bootstrap over the training programs."""
    seed_values: dict
    """Each field's value from every start (`seeds`), best first."""
    base_values: dict
    """The base arm's value of each field (where the fit started)."""
    train_rms_cm: float
    """Tip RMS error (cm) of the fitted arm on the training programs, in the fit's model."""
    val_rms_cm: float
    """Tip RMS error (cm) of the fitted arm (MuJoCo C, its own timestep) on held-out programs."""
    base_val_rms_cm: float
    """The same for the base arm, before identification."""
    length_m: float
    """The arm's length (m), base to tip at its reference pose."""
    history: list
    """Loss history: one dict per evaluation or step ("rms_mm" and each field's value)."""
    n_train: int
    n_val: int
    duration_s: float
    """Length of each program (s)."""
    wall_s: float
    """Wall time of `identify`, loading, compiling and held-out scoring included (s)."""
    cpu_s: float
    """This process's CPU time over the same span, every thread (s): on a machine shared with
    other work, with the process pinned to one core (`taskset -c 0`), it is the wall time the
    fit would take there alone."""
    settings: dict

    @property
    def val_rms_pct_length(self) -> float:
        """Held-out tip RMS error as % of the arm's length."""
        return 100.0 * self.val_rms_cm / (100.0 * self.length_m)

    def to_dict(self) -> dict:
        """A JSON-ready dict of every field."""
        out = dataclasses.asdict(self)
        out["domain"] = dataclasses.asdict(self.domain)
        out["val_rms_pct_length"] = self.val_rms_pct_length
        return out


def check_data(programs_bar, poses) -> tuple[np.ndarray, np.ndarray]:
    """Checks programs [N, T, 3] (bar) and poses [N, T, 6] (m, unit d3) of N >= 2 programs.

    Returns:
      (programs float64, poses float64).

    Raises:
      TypeError, ValueError: as `checks.check_pressures`; poses of another shape, non-real or
      non-finite; N < 2.
    """
    if np.ndim(programs_bar) != 3:
        raise ValueError(f"programs_bar must be [N, T, 3], got shape {np.shape(programs_bar)}")
    programs = checks.check_pressures(programs_bar)
    raw = np.asarray(poses)
    if raw.dtype.kind not in "iuf":
        raise TypeError(f"poses must be real numbers (m, unit d3), got dtype {raw.dtype}")
    if raw.shape != programs.shape[:2] + (constants.POSE_DIM,):
        raise ValueError(
            f"poses must be [N, T, 6] matching programs {programs.shape}, got {raw.shape}"
        )
    if not np.isfinite(raw).all():
        raise ValueError(f"poses hold {int((~np.isfinite(raw)).sum())} non-finite value(s)")
    if programs.shape[0] < 2:
        raise ValueError(f"need >= 2 programs (some to fit, some held out), got {len(programs)}")
    return programs, raw.astype(np.float64)


def _check_int(name: str, value, low: int, high: int | None = None) -> int:
    if isinstance(value, bool | np.bool_):
        raise TypeError(f"{name} must be an int, got {value!r}")
    try:
        value = operator.index(value)
    except TypeError:
        raise TypeError(f"{name} must be an int, got {value!r}") from None
    if value < low or (high is not None and value > high):
        bound = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise ValueError(f"{name} must be {bound}, got {value}")
    return value


def arm_length_m(arm: arm_lib.Arm) -> float:
    """Base-to-tip distance (m) at the reference pose, as `rest.settle` measures it."""
    m = arm.mj_model
    data = mujoco.MjData(m)
    mujoco.mj_kinematics(m, data)
    site = arm.tip_site_id
    root = m.body_rootid[m.site_bodyid[site]]
    return float(np.linalg.norm(data.site_xpos[site] - data.xpos[root]))


def tip_rms_m(simulated: np.ndarray, target: np.ndarray) -> float:
    """Tip position RMS error (m) of poses [..., 6] against poses [..., 6]."""
    return float(np.sqrt(np.mean(np.sum((simulated[..., :3] - target[..., :3]) ** 2, -1))))


def gauss_newton_steps(residuals: np.ndarray, jacobian: np.ndarray, weights: np.ndarray):
    """Gauss-Newton steps of a least-squares fit over programs, one per weighting.

    Args:
      residuals: [N, K] each program's residuals at the fit (any unit).
      jacobian: [N, P, K] their derivatives by each log-parameter.
      weights: [B, N] each program's weight in each of B fits (ones: the fit itself; counts
        drawn with replacement: a bootstrap).

    Returns:
      [B, P] steps in log-parameters, -H_b^-1 g_b with H_b = sum_i w_i J_i J_i^T and
      g_b = sum_i w_i J_i r_i.
    """
    g = np.einsum("nk,npk->np", residuals, jacobian)
    h = np.einsum("npk,nqk->npq", jacobian, jacobian)
    hb = np.einsum("bn,npq->bpq", weights, h)
    gb = np.einsum("bn,np->bp", weights, g)
    ridge = 1e-12 * np.trace(h.sum(0)) * np.eye(h.shape[-1])
    return -np.linalg.solve(hb + ridge, gb[..., None])[..., 0]


def bootstrap_weights(n: int, n_boot: int, seed: int = 0) -> np.ndarray:
    """[n_boot, n] counts of each of n programs in resamples drawn with replacement."""
    return np.random.default_rng(seed).multinomial(n, np.full(n, 1.0 / n), size=n_boot)


def _polish(theta, evaluate, low, high, record, steps: int):
    """Gauss-Newton steps from the optimiser's end, each kept only if it lowers the loss.

    `evaluate(theta) -> (loss m^2, residuals [N, W, 3], jacobian [N, P, W, 3])`; returns the
    kept (theta, residuals, jacobian). Adam and Nelder-Mead stop short of the floor of the
    valley along which drag and stiffness trade; the Jacobian the bootstrap needs anyway
    reaches it in a step or two where the residuals are near-linear in theta."""
    loss, r, j = evaluate(theta)
    n = len(r)
    for _ in range(steps):
        step = gauss_newton_steps(r.reshape(n, -1), j.reshape(n, len(theta), -1), np.ones((1, n)))
        candidate = np.clip(theta + step[0], low, high)
        new_loss, new_r, new_j = evaluate(candidate)
        record(candidate, new_loss)
        if not new_loss < loss:
            break
        theta, loss, r, j = candidate, new_loss, new_r, new_j
    return theta, r, j


# ---------------------------------------------------------------------------------- search


def _search(family, source, programs, targets, config: SearchConfig, seeds: int, bar):
    """Grid, then Nelder-Mead from the `seeds` best grid points; every evaluation is one
    MuJoCo C rollout of the training programs. Returns (theta, seed thetas, history, J, r)."""
    substeps = config.substeps or None
    cache: dict[tuple, np.ndarray] = {}
    history: list[dict] = []

    def tips(theta) -> np.ndarray:
        key = tuple(np.round(np.asarray(theta, np.float64), 12))
        if key not in cache:
            try:
                arm = arm_lib.load(domain=family.domain(theta), substeps=substeps, **source)
                cache[key] = arm.rollout(programs, backend="c")[..., :3]
            except arm_lib.SimulationDivergedError:
                cache[key] = np.full(programs.shape[:2] + (3,), np.inf)
            bar.update()
        return cache[key]

    def loss(theta) -> float:
        err = tips(theta) - targets[..., :3]
        value = float(np.mean(np.sum(err**2, -1))) if np.isfinite(err).all() else math.inf
        history.append(_record(family, theta, value))
        return value

    center = family.base_theta()
    half = math.log(config.span)
    axes = [np.linspace(c - half, c + half, config.grid_points) for c in center]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(center))
    scores = np.array([loss(theta) for theta in grid])
    bounds = [(c - half, c + half) for c in center]
    step = half / max(1, config.grid_points - 1)
    ends = []
    for start in grid[np.argsort(scores)[:seeds]]:
        simplex = np.vstack([start, start + step * np.eye(len(start))])
        simplex = np.clip(simplex, [b[0] for b in bounds], [b[1] for b in bounds])
        res = scipy.optimize.minimize(
            loss,
            start,
            method="Nelder-Mead",
            bounds=bounds,
            options={
                "initial_simplex": simplex,
                "xatol": config.xatol_log,
                "fatol": 0.0,
                "maxfev": config.max_evaluations,
            },
        )
        ends.append((float(res.fun), np.asarray(res.x)))
    ends.sort(key=lambda e: e[0])

    def evaluate(theta):
        residuals = tips(theta) - targets[..., :3]
        h = config.fd_step_log
        steps = h * np.eye(len(theta))
        jacobian = np.stack([(tips(theta + e) - tips(theta - e)) / (2 * h) for e in steps], 1)
        return float(np.mean(np.sum(residuals**2, -1))), residuals, jacobian

    def record(theta, value):
        history.append(_record(family, theta, value) | {"polish": True})

    low, high = [b[0] for b in bounds], [b[1] for b in bounds]
    theta, residuals, jacobian = _polish(
        ends[0][1], evaluate, low, high, record, config.polish_steps
    )
    return theta, [e[1] for e in ends], history, jacobian, residuals


# ---------------------------------------------------------------------------------- gradient


def stage_periods(config: GradientConfig, periods: int) -> list[int]:
    """The stages' windows (periods, whole chunks, at most `periods`), shortest first."""
    chunk = config.chunk_periods
    out = set()
    for w in config.windows_s:
        wanted = periods if not math.isfinite(w) else math.ceil(w * constants.CONTROL_HZ / chunk)
        out.add(min(periods, max(1, wanted) * chunk if math.isfinite(w) else periods))
    return sorted(out)


def _gradient(family, windows: Windows, config: GradientConfig, seeds: int, bar):
    """Adam from `seeds` starts over the staged windows. Returns (theta, seed thetas, history,
    J, r) as `_search`."""
    stages = stage_periods(config, windows.periods)
    total = len(stages) * config.steps_per_stage
    decay = (config.final_learning_rate / config.learning_rate) ** (1.0 / max(1, total - 1))
    schedule = optax.exponential_decay(config.learning_rate, 1, decay)
    center = family.base_theta()
    low, high = center - math.log(config.span), center + math.log(config.span)
    rng = np.random.default_rng(0)
    history, ends = [], []
    for seed in range(seeds):
        theta = center.copy()
        if seed:
            theta = np.clip(
                center + rng.normal(0.0, config.start_spread_log, center.shape), low, high
            )
        optimizer = optax.adam(schedule)
        state = optimizer.init(jnp.asarray(theta))
        for periods in stages:
            for _ in range(config.steps_per_stage):
                loss, grad, _, _ = windows(theta, periods)
                record = _record(family, theta, loss) | {
                    "seed": seed,
                    "window_s": periods / constants.CONTROL_HZ,
                }
                history.append(record)
                bar.update()
                if not math.isfinite(loss):
                    raise arm_lib.SimulationDivergedError(
                        f"the MJX copy diverged at {record}; lower GradientConfig.span or"
                        " learning_rate",
                        np.array([0]),
                        np.array([0]),
                    )
                updates, state = optimizer.update(jnp.asarray(grad), state)
                theta = np.clip(theta + np.asarray(updates, np.float64), low, high)
        loss, _, r, j = windows(theta, windows.periods)
        history.append(
            _record(family, theta, loss)
            | {"seed": seed, "window_s": windows.periods / constants.CONTROL_HZ}
        )
        ends.append((loss, theta, r, j))
    ends.sort(key=lambda e: e[0])
    known = {ends[0][1].tobytes(): ends[0]}

    def evaluate(theta):
        if theta.tobytes() in known:  # the best start's end, evaluated above
            loss, _, r, j = known[theta.tobytes()]
        else:
            loss, _, r, j = windows(theta, windows.periods)
        return loss, r, j

    def record(theta, value):
        history.append(_record(family, theta, value) | {"polish": True})
        bar.update()

    theta, r, j = _polish(ends[0][1], evaluate, low, high, record, config.polish_steps)
    return theta, [e[1] for e in ends], history, j, r


def _plain(config: dict) -> dict:
    """A config dict for JSON: an infinite window (the whole program) as None."""
    return {
        k: [None if w == math.inf else w for w in v] if k == "windows_s" else v
        for k, v in config.items()
    }


def _record(family: DomainFamily, theta, loss: float) -> dict:
    values = {
        name: float(math.exp(t)) for name, t in zip(family.fit, np.asarray(theta), strict=True)
    }
    return {"rms_mm": 1000.0 * math.sqrt(loss) if math.isfinite(loss) else None} | values


# ---------------------------------------------------------------------------------- identify


def identify(
    programs_bar,
    poses,
    *,
    base: str | domains.Domain = "constrained",
    fit=FITTABLE,
    method: str = "search",
    n_val: int = 1,
    seeds: int = 1,
    model=None,
    xml: str | None = None,
    config: SearchConfig | GradientConfig | None = None,
    n_boot: int = 1000,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
) -> IdentifyResult:
    """Fits the Domain fields `fit` of the base arm to a target arm's babbling data.

    Args:
      programs_bar: [N, T, 3] chamber commands (bar) at 10 Hz, each run from rest.
      poses: [N, T, 6] the target's tip poses under them (m, then unit d3).
      base: the domain the fit starts from and whose other fields it keeps ("constrained",
        "aged", "source" or a `Domain`).
      fit: Domain fields to fit, from `FITTABLE`.
      method: "search" or "gradient" (module doc).
      n_val: the last n_val programs are held out (1 <= n_val < N).
      seeds: starts of the fit (>= 1): Nelder-Mead from the best `seeds` grid points; Adam
        from the base's values, then from points about them (`GradientConfig.start_spread_log`).
      model, xml: the arm's MJCF (path or text, as `mjx_arm.load`; default the committed arm).
      config: the method's settings (`SearchConfig` or `GradientConfig`; None: defaults).
      n_boot: bootstrap resamples of the training programs.
      progress: show a progress bar.
      log: where to write progress lines (None: nowhere).

    Returns:
      An `IdentifyResult`.

    Raises:
      TypeError, ValueError: bad data (`check_data`), method, fit, n_val, seeds, config or
        base; all checked before any simulation. SimulationDivergedError: the MJX copy diverged.
    """
    started, cpu_started = time.perf_counter(), time.process_time()
    programs, targets = check_data(programs_bar, poses)
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    fit = check_fit(fit)
    n = programs.shape[0]
    n_val = _check_int("n_val", n_val, 1, n - 1)
    seeds = _check_int("seeds", seeds, 1)
    n_boot = _check_int("n_boot", n_boot, 2)
    config = _check_config(method, config)
    log = log or (lambda _: None)
    base_arm = arm_lib.load(model, domain=domains.resolve(base), xml=xml)
    source = {"path": base_arm.path} if base_arm.path is not None else {"xml": base_arm.mjcf_text}
    train_p, train_y = programs[: n - n_val], targets[: n - n_val]
    val_p, val_y = programs[n - n_val :], targets[n - n_val :]
    log(f"identify ({method}): {fit} from {len(train_p)} programs of {programs.shape[1] / 10:g} s")
    if method == "search":
        family = DomainFamily.of(base_arm, fit)
        total = config.grid_points ** len(fit) + seeds * config.max_evaluations + 2 * len(fit)
        with tqdm(
            total=total, desc="identify: search", unit="rollout", disable=not progress
        ) as bar:
            theta, starts, history, jac, res = _search(
                family, source, train_p, train_y, config, seeds, bar
            )
    else:
        family = DomainFamily.of(base_arm.planning_copy(config.substeps), fit)
        family.check_rest()
        windows = Windows(family, train_p, train_y, config.chunk_periods)
        n_stages = len(stage_periods(config, windows.periods))
        total = seeds * (n_stages * config.steps_per_stage + 1) + config.polish_steps
        with tqdm(total=total, desc="identify: gradient", unit="step", disable=not progress) as bar:
            theta, starts, history, jac, res = _gradient(family, windows, config, seeds, bar)
    # Each program's residuals and Jacobian, flattened over periods and axes.
    k = res.shape[1] * 3
    weights = bootstrap_weights(len(res), n_boot)
    steps = gauss_newton_steps(
        res.reshape(len(res), k), jac.reshape(len(jac), len(fit), k), weights
    )
    values = np.exp(theta)
    # RMS of the resamples' optima about the fit: their spread, plus any step the fit left.
    spread = np.sqrt(np.mean((np.exp(theta + steps) - values) ** 2, 0))
    fitted = family.domain(theta, name=f"identified ({method})")
    fitted_arm = arm_lib.load(domain=fitted, **source)
    val_rms = tip_rms_m(fitted_arm.rollout(val_p, backend="c"), val_y)
    base_rms = tip_rms_m(base_arm.rollout(val_p, backend="c"), val_y)
    result = IdentifyResult(
        domain=fitted,
        method=method,
        fit=fit,
        values={name: float(v) for name, v in zip(fit, values, strict=True)},
        uncertainty={name: float(s) for name, s in zip(fit, spread, strict=True)},
        seed_values={name: [float(math.exp(t[i])) for t in starts] for i, name in enumerate(fit)},
        base_values={name: family.base[name] for name in fit},
        train_rms_cm=100.0 * float(np.sqrt(np.mean(np.sum(res**2, -1)))),
        val_rms_cm=100.0 * val_rms,
        base_val_rms_cm=100.0 * base_rms,
        length_m=arm_length_m(base_arm),
        history=history,
        n_train=len(train_p),
        n_val=n_val,
        duration_s=programs.shape[1] / constants.CONTROL_HZ,
        wall_s=time.perf_counter() - started,
        cpu_s=time.process_time() - cpu_started,
        settings={"config": _plain(dataclasses.asdict(config)), "seeds": seeds, "n_boot": n_boot}
        | {"base_domain": dataclasses.asdict(base_arm.domain), "model_hash": base_arm.model_hash},
    )
    log(
        f"identify ({method}): {result.values} +- {result.uncertainty}; held-out tip RMS"
        f" {result.val_rms_cm:.3f} cm ({result.val_rms_pct_length:.2f}% of L), base"
        f" {result.base_val_rms_cm:.3f} cm; {result.wall_s:.1f} s ({result.cpu_s:.1f} s CPU)"
    )
    return result


def _check_config(method: str, config):
    """The method's config (defaults for None), checked."""
    kind = SearchConfig if method == "search" else GradientConfig
    if config is None:
        return kind()
    if not isinstance(config, kind):
        raise TypeError(f"method {method!r} takes a {kind.__name__}, got {type(config).__name__}")
    _check_int("config.substeps", config.substeps, 0)
    if not (math.isfinite(config.span) and config.span > 1.0):
        raise ValueError(f"config.span must be a finite factor > 1, got {config.span}")
    if isinstance(config, SearchConfig):
        _check_int("config.grid_points", config.grid_points, 2)
        _check_int("config.max_evaluations", config.max_evaluations, 1)
    else:
        _check_int("config.chunk_periods", config.chunk_periods, 1)
        _check_int("config.steps_per_stage", config.steps_per_stage, 1)
        if not config.windows_s or not all(w > 0 for w in config.windows_s):
            raise ValueError(f"config.windows_s must be seconds > 0, got {config.windows_s}")
    return config


def build_parser():
    """``python -m mjx_arm.identify``'s parser (`identify_cli.build_parser` with METHODS), which
    the chain's config checks read like every command's."""
    return identify_cli.build_parser(METHODS)


def main(argv: list[str] | None = None) -> int:
    """``python -m mjx_arm.identify``: `identify_cli.main` with this module's `identify`."""
    return identify_cli.main(argv, identify, METHODS)


if __name__ == "__main__":
    raise SystemExit(main())
