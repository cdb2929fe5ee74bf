"""The hold factor k chosen in the target-domain simulator, as the authors' code chooses it.

The authors pick k by running G_c's commands in their D_c simulator, each held k control periods,
and comparing every k-th pose with the D_s target (`scripts/train_test_utils.py`;
`shared/notes/paper-facts.md`). Choosing k through the learned F_c instead measures F_c's open-loop
drift as much as the translator (3.7 cm on held-out D_c babbling for the paper-scale F_c), so the
trainer's default (`TrainConfig.k_choice = "simulator"`) is this module: held-out D_s programs of
the training data, translated by each seed's G_c and rolled out from rest in the true target-domain
arm at every k of `TrainConfig.hold_factors`.

It runs on the host between epochs (`ccgan.train.train_and_evaluate`): before training, every
`stretch_every` epochs and after the last. The rollouts are MuJoCo C on the host's cores by
default (every k is another program length, which MJX would compile once each).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ccgan.config import TrainConfig
from ccgan.data import PRESSURE_DIM, TranslationData, denormalise_pose, denormalise_pressure
from ccgan.models import Generator
from mjx_arm.constants import CONTROL_HZ
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


class SimulatorChoice:
    """Scores G_c on held-out D_s programs in the target-domain simulator, at every hold factor.

    Args:
      arm: the target-domain arm (`mjx_arm.load(..., domain="constrained")` or "aged"), the one
        the training data's target domain was simulated on.
      data: the prepared training data; its held-out D_s trajectories (`data.source.val`, the
        babbling programs `TrainConfig.n_val` kept out of training, each run from rest) are
        translated and their recorded D_s poses are the targets.
      config: the run's settings (generator widths, `hold_factors`, `k_choice_seconds`).
      backend: "c" (MuJoCo C, one thread per trajectory) or "mjx".
      progress: label of a progress bar over the rollouts, or None for none.
    """

    def __init__(
        self,
        arm,
        data: TranslationData,
        config: TrainConfig,
        backend: str = "c",
        progress: str | None = None,
    ):
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

        Every (seed, program, k) is one rollout from rest; rollouts of one k run as one batch.
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
