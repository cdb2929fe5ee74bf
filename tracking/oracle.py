"""The oracle: D_c commands optimised directly through the differentiable MJX rollout.

A lower reference for every translator: for known D_s target poses [T, 6] it searches the D_c
commands [T * k, 3] (bar) that track them best, by Adam on `tracking.metrics.tracking_loss`
through `mjx_arm`'s MJX rollout, with the commands kept in the valve range by a sigmoid. Like
every translator's output, the commands are by default one per source step held k periods
(`OracleConfig.held`). It starts from the receding-horizon tracker's commands (`tracking.mpc`)
or the stretch program (`start_commands`). Gradients through thousands of MJX steps are slow,
so the evaluation (`eval.pipeline`) optimises the first `OracleConfig.horizon_s` seconds only.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from mjx_arm import constants
from mjx_arm.atomic import write_atomically
from mjx_arm.domains import DOMAINS
from tracking import held as held_lib
from tracking import metrics, mpc
from tracking.config import ConfigError, check_duration, check_fields, check_ints, require


@dataclasses.dataclass(frozen=True)
class OracleConfig:
    """Direct optimisation of D_c commands through MJX (the achievable-error reference)."""

    steps: int = 30
    """Adam steps (a few hundred on a GPU; the CPU default is small)."""
    learning_rate: float = 0.03
    """Adam step size on the sigmoid logits (dimensionless). From the mpc start 0.3 overshoots
    (bench/oracle_start.py); the stretch-started tables of earlier commits used 0.3."""
    horizon_s: float | None = 2.0
    """Seconds of the source program optimised (None: all of it)."""
    orientation_weight_cm_per_rad: float = 10.0
    """How many cm of position error one rad of orientation error is worth in the loss."""
    held: bool = True
    """One command per source step held k periods, the output space of every translator
    (False: a free command per control period)."""
    init: str = "mpc"
    """Where Adam starts: "mpc" (the receding-horizon tracker's commands, `tracking.mpc`) or
    "stretch" (the stretch program)."""
    substeps: int = 0
    """Physics steps per control period of the arm Adam differentiates through (0: the arm's
    own, 25 of 4 ms): a planning copy (`mjx_arm.Arm.planning_copy`) with 5 takes five times
    fewer sequential steps. The best iterate is picked by its loss in that copy; the caller
    scores the commands in the arm itself (`eval.pipeline` does)."""

    def __post_init__(self):
        """Refuses settings that would fail (or mean nothing) after minutes of work; fields are
        named "oracle.<field>" in the ConfigError."""
        require(
            self.init in ("mpc", "stretch"),
            "oracle.init",
            f"must be 'mpc' or 'stretch', got {self.init!r}",
        )
        check_ints("oracle.steps", self.steps, 1)
        check_ints("oracle.substeps", self.substeps, 0)
        if self.horizon_s is not None:
            check_duration("oracle.horizon_s", self.horizon_s, constants.CONTROL_HZ)
        try:
            check_fields(
                self, above={"learning_rate": 0}, at_least={"orientation_weight_cm_per_rad": 0}
            )
        except ConfigError as err:
            raise ConfigError(f"oracle.{err.field}", err.problem) from None


def start_commands(
    arm_c,
    target_poses: np.ndarray,
    source_programs: np.ndarray,
    k: int,
    cfg: OracleConfig,
    progress: bool = False,
    result_path: str | os.PathLike | None = None,
) -> np.ndarray:
    """Where the oracle starts (`OracleConfig.init`): the receding-horizon tracker's commands
    ("mpc", `tracking.mpc.track` in MuJoCo C, kept in result_path when given) or the stretch
    program ("stretch").

    Args:
      arm_c: the D_c arm.
      target_poses: [T, 6] or [S, T, 6] target poses (m, unit d3).
      source_programs: [T, 3] or [S, T, 3] the D_s programs (bar) of the targets.
      k: control periods per source step.
      cfg: the oracle's settings.
      progress: show the tracker's progress bar.

    Returns:
      [T * k, 3] or [S, T * k, 3] commands (bar), each held k periods.
    """
    if cfg.init == "mpc":
        commands, _ = mpc.track(
            arm_c, target_poses, k, source_programs, progress=progress, result_path=result_path
        )
        return commands
    return held_lib.stretch(source_programs, k)


def _batched(
    target_poses: np.ndarray, init_commands: np.ndarray, k: int, held
) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray]:
    """Checks the oracle's inputs and gives them a program axis.

    Returns:
      (single: whether one program [T, ...] was given, targets [S, T, 6] (m, unit d3), inits
      [S, T * k, 3] (bar), held [S] bools).

    Raises:
      ValueError: the shapes do not match for k, or a held program's init is not constant over
        each source step's k periods.
    """
    single = np.ndim(target_poses) == 2
    targets = np.asarray(target_poses)[None] if single else np.asarray(target_poses)
    inits = np.asarray(init_commands)[None] if single else np.asarray(init_commands)
    if targets.shape[0] != inits.shape[0] or inits.shape[1] != targets.shape[1] * k:
        raise ValueError(
            f"targets {targets.shape} and init commands {inits.shape} do not match for k = {k}"
        )
    held = np.broadcast_to(np.asarray(held, bool), inits.shape[:1])
    blocks = inits[held].reshape(-1, targets.shape[1], k, inits.shape[-1])
    if not np.allclose(blocks, blocks[:, :, :1]):
        raise ValueError(
            "a held program's init commands must be constant over each step's k periods"
        )
    return single, targets, inits, held


def _adam_step(arm_c, targets: np.ndarray, held: np.ndarray, k: int, cfg: OracleConfig):
    """The oracle's jitted Adam step and the map from logits to commands.

    Commands are p_min + (p_max - p_min) * sigmoid(z), so every iterate stays in the valve
    range; a program's loss is inf once its rollout diverges.

    Args:
      arm_c: the D_c arm.
      targets: [S, T, 6] target poses (m, unit d3).
      held: [S] bools: programs whose gradient is summed over each source step's k periods.
      k: control periods per source step.
      cfg: oracle settings (learning rate, orientation weight).

    Returns:
      (update: jitted (z [S, T * k, 3], opt_state) -> (new z, new opt_state, [S] loss of z),
      opt: the optax transformation, commands_of: z -> [S, T * k, 3] commands (bar)).
    """
    import jax
    import jax.numpy as jnp
    import optax

    lo, hi = arm_c.valve.p_min_bar, arm_c.valve.p_max_bar
    target = jnp.asarray(targets, dtype=jnp.float32)
    rollout = jax.vmap(arm_c.rollout_fn(), in_axes=(None, 0))
    mjx_model = arm_c.mjx_model
    w = cfg.orientation_weight_cm_per_rad
    held_mask = jnp.asarray(held)[:, None, None]

    def project(grad):
        """Held programs' gradients [S, T * k, 3] summed over each step's k periods."""
        per_step = grad.reshape(grad.shape[0], -1, k, grad.shape[-1]).sum(2)
        return jnp.where(held_mask, jnp.repeat(per_step, k, axis=1), grad)

    def commands_of(z):
        return lo + (hi - lo) * jax.nn.sigmoid(z)

    def losses_of(z):
        """[S] loss of each program."""
        poses, ok = rollout(mjx_model, commands_of(z))
        loss = metrics.tracking_loss(poses[:, k - 1 :: k], target, w)
        return jnp.where(ok[:, -1], loss, jnp.inf)

    # The step size is state, not a constant of the compiled step: one compilation (and the
    # persistent cache) serves every learning rate.
    opt = optax.inject_hyperparams(optax.adam)(learning_rate=cfg.learning_rate)

    @jax.jit
    def update(z, opt_state):
        # The programs are independent: pulling back ones gives each its own gradient.
        loss, pullback = jax.vjp(losses_of, z)
        (grad,) = pullback(jnp.ones_like(loss))
        grad = project(grad)
        updates, opt_state = opt.update(grad, opt_state, z)
        return optax.apply_updates(z, updates), opt_state, loss

    return update, opt, commands_of


def _save_progress(path: Path, fingerprint: str, z, opt_state, best_z, best_loss, history, walls):
    """Writes the optimisation's state after a step, atomically (a stopped run keeps the last
    whole file)."""
    import jax

    leaves = jax.tree.leaves(opt_state)
    arrays = {f"opt_{i}": np.asarray(leaf) for i, leaf in enumerate(leaves)}
    arrays |= {
        "fingerprint": np.asarray(fingerprint),
        "z": np.asarray(z),
        "best_z": np.asarray(best_z),
        "best_loss": best_loss,
        "history": np.asarray(history),
        "step_wall_s": np.asarray(walls),
    }
    write_atomically(path, lambda f: np.savez(f, **arrays))


def _load_progress(path: Path | None, fingerprint: str, opt_state):
    """(z, opt_state, best_z, best_loss, history, step_wall_s) stored by an earlier run of the
    same optimisation, or None: no file, or one of another optimisation (its fingerprint)."""
    import jax
    import jax.numpy as jnp

    if path is None or not path.exists():
        return None
    try:
        with np.load(path) as f:
            if str(f["fingerprint"]) != fingerprint:
                return None
            treedef = jax.tree.structure(opt_state)
            leaves = [jnp.asarray(f[f"opt_{i}"]) for i in range(treedef.num_leaves)]
            return (
                jnp.asarray(f["z"]),
                jax.tree.unflatten(treedef, leaves),
                jnp.asarray(f["best_z"]),
                np.asarray(f["best_loss"]),
                list(np.asarray(f["history"])),
                list(np.asarray(f["step_wall_s"])),
            )
    except (OSError, ValueError, KeyError) as err:
        raise ValueError(f"{path}: unreadable oracle progress ({err}); remove it") from err


def _best_iterates(update, opt, z0, steps: int, progress: bool, progress_path=None, fingerprint=""):
    """Runs `steps` Adam steps from logits z0 [S, T * k, 3] and keeps each program's best.

    With `progress_path`, the state is written there after every step and a run that finds a
    file of the same optimisation (`fingerprint`) continues from it, with the same iterates.

    Returns:
      (best_z [S, T * k, 3], best_loss [S] (the lowest loss of any iterate; inf if none was
      finite), history: list of [S] losses of each iterate before its update, step_wall_s: list
      of seconds per step, the first of each run including compilation).
    """
    import jax.numpy as jnp

    z, opt_state = z0, opt.init(z0)
    best_z, best_loss, history, step_wall_s = z0, np.full(z0.shape[0], np.inf), [], []
    stored = _load_progress(progress_path, fingerprint, opt_state)
    if stored is not None:
        z, opt_state, best_z, best_loss, history, step_wall_s = stored
    bar = tqdm(
        range(len(history), steps),
        initial=len(history),
        total=steps,
        desc="oracle Adam steps (the 1st compiles)",
        unit="step",
        disable=not progress,
    )
    for _ in bar:
        t_step = time.perf_counter()
        new_z, opt_state, loss = update(z, opt_state)
        loss = np.asarray(loss)  # the loss of z, before this update
        step_wall_s.append(time.perf_counter() - t_step)
        history.append(loss)
        better = loss < best_loss
        best_z = jnp.where(jnp.asarray(better)[:, None, None], z, best_z)
        best_loss = np.where(better, loss, best_loss)
        z = new_z
        if progress_path is not None:
            _save_progress(
                progress_path, fingerprint, z, opt_state, best_z, best_loss, history, step_wall_s
            )
        bar.set_postfix(best_loss_max=f"{best_loss.max():.4g}", refresh=False)
    return best_z, best_loss, history, step_wall_s


def _fingerprint(arm_c, targets, inits, held, k: int, cfg: OracleConfig) -> str:
    """What the optimisation's iterates depend on: the arm, targets, start, k and settings
    (not the number of steps: a longer run's first iterates are the shorter run's), and the
    arm's Domain where it is none of the built-in ones (one read from a file: two such media
    share the MJCF's hash; the built-in media are left out, so progress kept before stays
    valid)."""
    digest = hashlib.sha256()
    for array in (targets, inits, held):
        digest.update(np.ascontiguousarray(array).tobytes())
    settings = dataclasses.asdict(cfg) | {"steps": None}
    if not cfg.substeps:  # progress kept before the field existed stays valid
        settings.pop("substeps")
    key = (arm_c.model_hash, k, settings)
    domain = getattr(arm_c, "domain", None)
    if domain is not None and domain not in DOMAINS.values():
        key += (domain,)
    digest.update(repr(key).encode())
    return digest.hexdigest()[:16]


def oracle_commands(
    arm_c,
    target_poses: np.ndarray,
    init_commands: np.ndarray,
    k: int,
    cfg: OracleConfig,
    held=False,
    progress: bool = False,
    progress_path: str | os.PathLike | None = None,
) -> tuple[np.ndarray, dict]:
    """D_c commands that track the targets, optimised through the MJX rollout.

    The commands are p_min + (p_max - p_min) * sigmoid(z); z starts at the init commands (clipped
    0.01% inside the range) and Adam minimises mean(X_err_cm^2) + w^2 mean(phi_err^2), with
    phi_err^2 ~ 2 (1 - cos). Several programs are optimised at once (one vmapped rollout; Adam
    acts elementwise, so each program's iterates are those of its own optimisation), and each
    program's best iterate is returned.

    A held program keeps one command per source step, held k control periods, as every
    translator's output is: its gradient is summed over each step's k periods, so from a held
    start (the stretch program) Adam's iterates are exactly those of Adam on the [T, 3] held
    commands. A free program has a command per control period.

    Args:
      arm_c: the D_c arm (its planning copy when `cfg.substeps` is set).
      target_poses: [T, 6] or [S, T, 6] target poses (m, unit d3).
      init_commands: [T * k, 3] or [S, T * k, 3] starting commands (bar), e.g. the stretch
        program.
      k: control periods per source step.
      cfg: oracle settings.
      held: bool, or [S] bools: which programs are held (each init program must then be
        constant over each source step's k periods).
      progress: show a progress bar over Adam steps (the first compiles: minutes).
      progress_path: a file the optimisation's state is kept in after every step; a stopped
        run (a device call's time limit) continues from it when called again with the same
        arm, targets, start and settings. None: nothing kept.

    Returns:
      (commands [T * k, 3] or [S, T * k, 3] bar, info: "loss_history" [steps] or [steps, S]
      (the loss of each iterate), "best_loss" (float or [S]), "wall_s", "step_wall_s" (per
      Adam step; the first includes compiling)).
    """
    import jax.numpy as jnp

    single, targets, inits, held = _batched(target_poses, init_commands, k, held)
    lo, hi = arm_c.valve.p_min_bar, arm_c.valve.p_max_bar
    # Inits at a valve limit start just inside it (the sigmoid never reaches its ends); Adam's
    # normalised steps move them out again however flat the sigmoid is there.
    frac = np.clip((inits - lo) / (hi - lo), 1e-4, 1 - 1e-4)
    z0 = jnp.asarray(np.log(frac / (1 - frac)), dtype=jnp.float32)
    plan_arm = arm_c.planning_copy(cfg.substeps)
    update, opt, commands_of = _adam_step(plan_arm, targets, held, k, cfg)
    t0 = time.perf_counter()
    path = None if progress_path is None else Path(progress_path)
    fingerprint = _fingerprint(plan_arm, targets, inits, held, k, cfg)
    best_z, best_loss, history, step_wall_s = _best_iterates(
        update, opt, z0, cfg.steps, progress, path, fingerprint
    )
    commands = np.asarray(commands_of(best_z), dtype=np.float64)
    history = np.asarray(history).reshape(len(history), z0.shape[0])
    info = {
        "loss_history": history[:, 0].tolist() if single else history.tolist(),
        "best_loss": float(best_loss[0]) if single else best_loss.tolist(),
        "wall_s": time.perf_counter() - t0,
        "step_wall_s": step_wall_s,
    }
    return (commands[0] if single else commands), info
