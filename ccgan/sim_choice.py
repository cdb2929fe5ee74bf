"""The hold factor k chosen in the target-domain simulator, as the authors' code chooses it.

The authors pick k by running G_c's commands in their D_c simulator, each held k control periods,
and comparing every k-th pose with the D_s target (`scripts/train_test_utils.py`;
`shared/notes/paper-facts.md`). Choosing k through the learned F_c instead measures F_c's open-loop
drift as much as the translator (3.7 cm on held-out D_c babbling for the paper-scale F_c), so the
trainer's default (`TrainConfig.k_choice = "simulator"`) is this module: held-out D_s programs (the
training data's held-out babbling, or shape-like programs with `TrainConfig.k_choice_programs`),
translated by each seed's G_c and rolled out from rest in the true target-domain arm at every k
of `TrainConfig.hold_factors`.

It runs on the host between epochs (`ccgan.train.train_and_evaluate`): before training, every
`stretch_every` epochs and after the last. The rollouts are MuJoCo C on the host's cores by
default (every k is another program length, which MJX would compile once each).

With `TrainConfig.k_choice_simulator` "rod" the target-domain simulator is the reference rod
(`mjx_arm.load_rod(target domain)`, float64; and with k_choice_programs "shape_like" the D_s
targets come from `load_rod("source")`), as the authors' code scores k in its own rod simulator;
the training data must then be the rod's too (`simulator_of` their model hash). The rod is
latency-bound, so all (seed, program, k) rollouts of one scoring run through
`tracking.held.rollout_grouped(rod, jobs, "rod")`: on a GPU as one padded batch (each program
held at its last command up to the longest; the rod is causal, so each keeps its own poses),
costing about the longest program, k_choice_seconds x max(hold_factors) periods (20 s x k = 30
= 600 simulated s: ~80-100 s on one H200 for up to ~64 rollouts); on a CPU group by group,
costing the sum of all rollouts at ~25-35 simulated s per wall s (3 seeds x 3 programs of 20 s
at k = 5..30: ~19,000 simulated s, ~10 min per scoring on 2 cores: use a GPU).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ccgan.config import TrainConfig
from ccgan.data import (
    PRESSURE_DIM,
    TranslationData,
    denormalise_pose,
    denormalise_pressure,
    samples,
)
from ccgan.models import Generator
from mjx_arm.constants import CONTROL_HZ
from mjx_arm.programs import shape_like_programs
from tracking import held, metrics


class Choice(NamedTuple):
    """One choice of k for every seed.

    Attributes:
      k: [S] the chosen hold factor per seed.
      error_cm: [S] mean X_err (cm) of the held-out programs at that k.
      errors_cm: [S, K] mean X_err (cm) at every k of `TrainConfig.hold_factors`.
    """

    k: np.ndarray
    error_cm: np.ndarray
    errors_cm: np.ndarray


def simulator_of(model_hash: str | None) -> str:
    """The simulator an arm or a dataset's model hash names: "rod" for the reference rod
    (`mjx_arm.RodArm.model_hash`, "rod-..."), "chain" for an MJCF's (`mjx_arm.Arm.model_hash`)."""
    return "rod" if str(model_hash or "").startswith("rod-") else "chain"


def _check_simulator(arm, config: TrainConfig, what: str) -> str:
    """The simulator of `arm` (`simulator_of`), refused (ValueError) unless it is
    `config.k_choice_simulator`."""
    found = simulator_of(getattr(arm, "model_hash", None))
    if found != config.k_choice_simulator:
        make = "mjx_arm.load_rod(domain)" if config.k_choice_simulator == "rod" else "mjx_arm.load"
        raise ValueError(
            f"k_choice_simulator is {config.k_choice_simulator!r}, but {what} is the {found}'s"
            f" (model hash {getattr(arm, 'model_hash', None)}): pass the arm of {make}"
        )
    return found


#: The split of `mjx_arm.programs.shape_like_programs` the shape-like held-out programs come
#: from (disjoint from the fine-tuning, distillation and study splits; never a test shape).
SHAPE_LIKE_SPLIT = "k_choice"


def describe_programs(config: dict) -> str:
    """What the held-out programs of a stored `TrainConfig` dict are, for reports."""
    if config.get("k_choice_programs", "babbling") == "shape_like":
        return (
            f"{config['k_choice_n_programs']} held-out shape-like D_s programs of"
            f" {config['k_choice_seconds']:g} s (`shape_like_programs` split {SHAPE_LIKE_SPLIT},"
            " full scale, never a test shape)"
        )
    seconds = config["k_choice_seconds"]
    part = f"first {seconds:g} s" if seconds else "whole length"
    return f"the {config['n_val']} held-out babbling D_s programs' {part}"


def shape_like_samples(source_arm, data: TranslationData, config: TrainConfig) -> np.ndarray:
    """Held-out shape-like D_s programs as normalised samples [N, T, 9].

    `config.k_choice_n_programs` programs of `config.k_choice_seconds` (split `SHAPE_LIKE_SPLIT`,
    seed 0, full scale as the shapes are), each run from rest in the source-domain arm (MuJoCo
    C, or the rod for a `mjx_arm.RodArm`); their poses are the targets, normalised with the
    training data's pose bounds.
    """
    programs = shape_like_programs(
        config.k_choice_n_programs,
        config.k_choice_seconds,
        seed=0,
        split=SHAPE_LIKE_SPLIT,
        full_scale=True,
    )
    backend = "rod" if simulator_of(getattr(source_arm, "model_hash", None)) == "rod" else "c"
    poses = source_arm.rollout(programs.astype(np.float64), backend=backend)
    return samples(programs, poses, data.bounds)


class SimulatorChoice:
    """Scores G_c on held-out D_s programs in the target-domain simulator, at every hold factor.

    Args:
      arm: the target-domain arm (`mjx_arm.load(..., domain="constrained")` or "aged"), the one
        the training data's target domain was simulated on; with `config.k_choice_simulator`
        "rod", the rod (`mjx_arm.load_rod(domain)`). Another simulator than the config names is
        refused.
      data: the prepared training data. With `TrainConfig.k_choice_programs` "babbling" its
        held-out D_s trajectories (`data.source.val`, the babbling programs `TrainConfig.n_val`
        kept out of training, each run from rest) are translated and their recorded D_s poses
        are the targets; with "shape_like", `shape_like_samples` (its pose bounds normalise).
      config: the run's settings (generator widths, `hold_factors`, `k_choice_seconds`).
      backend: the chain's "c" (MuJoCo C, one thread per trajectory) or "mjx"; for the rod
        "rod". None: "c", or "rod" for the rod.
      progress: label of a progress bar over the rollouts, or None for none.
      source_arm: the source-domain arm (of the same simulator), needed with
        k_choice_programs "shape_like" (it simulates the programs' targets).

    Raises:
      ValueError: `arm` or `source_arm` is not of `config.k_choice_simulator`, a chain backend
        for the rod, or no `source_arm` with k_choice_programs "shape_like".
    """

    def __init__(
        self,
        arm,
        data: TranslationData,
        config: TrainConfig,
        backend: str | None = None,
        progress: str | None = None,
        source_arm=None,
    ):
        simulator = _check_simulator(arm, config, "the target-domain arm")
        if backend is None:
            backend = "rod" if simulator == "rod" else "c"
        if (backend == "rod") != (simulator == "rod"):
            raise ValueError(f"backend {backend!r} is not the {simulator}'s")
        if config.k_choice_programs == "shape_like":
            if source_arm is None:
                make = (
                    'load_rod("source")' if simulator == "rod" else 'load(model, domain="source")'
                )
                raise ValueError(
                    'k_choice_programs "shape_like" simulates the programs\' D_s targets: pass'
                    f" source_arm=mjx_arm.{make}"
                )
            _check_simulator(source_arm, config, "source_arm")
            val = shape_like_samples(source_arm, data, config)
        else:
            val = np.asarray(data.source.val)
        n_steps = val.shape[1]
        if config.k_choice_seconds:
            n_steps = min(n_steps, max(1, round(config.k_choice_seconds * CONTROL_HZ)))
        self.arm = arm
        self.backend = backend
        self.progress = progress
        self.hold_factors = tuple(int(k) for k in config.hold_factors)
        self.n_steps = n_steps
        # G_c is causal (unidirectional LSTMs), so translating the prefix equals translating the
        # whole program and keeping its prefix.
        self._samples = jnp.asarray(val[:, :n_steps])
        self.target = denormalise_pose(val[:, :n_steps, PRESSURE_DIM:], data.bounds)
        generator = Generator(**config.generator_args, unroll=config.gen_unroll)
        self._commands = jax.jit(
            jax.vmap(lambda params: generator.apply(params, self._samples)[..., :PRESSURE_DIM])
        )

    def commands_bar(self, g_c_params) -> np.ndarray:
        """G_c's commands on the held-out programs, [S, n_val, T, 3] bar, for G_c variables
        stacked on a leading seed axis [S, ...]."""
        return denormalise_pressure(np.asarray(self._commands(g_c_params), np.float64))

    def errors_of_commands(self, commands_bar: np.ndarray) -> np.ndarray:
        """Mean X_err (cm) of commands [S, n_val, T, 3] (bar) held k periods, [S, K].

        Every (seed, program, k) is one rollout from rest; rollouts of one k run as one batch
        (the rod on a GPU: all of them as one padded batch, `tracking.held.rollout_grouped`).
        """
        n_seeds, n_prog = commands_bar.shape[:2]
        flat = commands_bar.reshape(n_seeds * n_prog, *commands_bar.shape[2:])
        jobs = [(held.stretch(c, k), k) for k in self.hold_factors for c in flat]
        poses = held.rollout_grouped(self.arm, jobs, self.backend, progress=self.progress)
        poses = np.stack(poses).reshape(len(self.hold_factors), n_seeds, n_prog, self.n_steps, -1)
        err = metrics.position_error_cm(poses, self.target[None, None]).mean(axis=(-1, -2))
        return np.moveaxis(err, 0, -1)

    def choose(self, g_c_params) -> Choice:
        """The hold factor with the lowest held-out error for each seed ([S, ...] variables)."""
        errors = self.errors_of_commands(self.commands_bar(g_c_params))
        best = errors.argmin(-1)
        return Choice(
            k=np.asarray(self.hold_factors)[best],
            error_cm=np.take_along_axis(errors, best[:, None], -1)[:, 0],
            errors_cm=errors,
        )

    def stretch_only_errors(self) -> np.ndarray:
        """The untranslated held-out D_s commands held k periods: mean X_err (cm), [K].

        The baseline a translator must beat at its own k (`eval`'s "stretch only").
        """
        p_bar = denormalise_pressure(np.asarray(self._samples[..., :PRESSURE_DIM], np.float64))
        return self.errors_of_commands(p_bar[None])[0]
