"""Many CCGAN-GP settings trained as one vmapped run, each scored in the target-domain simulator.

A study (`ccgan.tune`) or an ablation (`studies.ccgan_ablation`) trains dozens of settings that
differ only in numbers: loss weights and learning rates. Those enter training as traced values,
so one compiled program trains all of them side by side, seeds included, the way purejaxrl vmaps
whole training runs: `BatchTrainer.train(configs, seeds)` stacks the settings' `CONTINUOUS`
fields and the seeds on one leading axis of C * S members. Settings that differ in a shape or a
structure (window length, critic steps, generator kind) cannot share a program: `static_part`
says which group a setting belongs to, and a batch must be one group.

Every `stretch_every` epochs and after the last, each member's hold factor k is chosen in the
simulator on held-out programs (`ccgan.sim_choice`), as `ccgan.train` chooses it; the error at
that k is the member's score. `on_choice` sees the scores as they come, so a study can report
them to Optuna and prune: a pruned setting is no longer scored (its simulator rollouts are the
costly part) and the batch stops once every setting is pruned.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ccgan.config import TrainConfig
from ccgan.data import TranslationData
from ccgan.models import ForwardModel
from ccgan.sim_choice import SimulatorChoice
from ccgan.trainer import init_each, make_trainer

#: The TrainConfig fields that enter training only as numbers: traced, so settings differing
#: only in them train in one compiled, vmapped program.
CONTINUOUS = (
    "lambda_adversarial",
    "lambda_cycle",
    "lambda_identity",
    "lambda_feedback",
    "lr_generator",
    "lr_critic",
)


def static_part(config: TrainConfig) -> TrainConfig:
    """`config` with its `CONTINUOUS` fields at their defaults: equal for settings that can
    train in one batch."""
    defaults = TrainConfig()
    return dataclasses.replace(config, **{n: getattr(defaults, n) for n in CONTINUOUS})


class BatchResult(NamedTuple):
    """The scores of one batch, per setting c and seed s.

    Attributes:
      k: [C, S] hold factor chosen at the setting's last scored epoch.
      error_cm: [C, S] mean held-out X_err (cm) at that k.
      errors_cm: [C, S, K] mean held-out X_err (cm) at every k of `hold_factors`.
      epoch: [C] the last epoch at which each setting was scored (below `epochs` if pruned).
      g_c: G_c variables of every member, stacked [C * S, ...] (setting-major).
      history: one dict per scoring, {"epoch", "index" [C'] (the settings still live), "k"
        [C', S], "error_cm" [C', S]}: what a stop on held-out error picks from.
    """

    k: np.ndarray
    error_cm: np.ndarray
    errors_cm: np.ndarray
    epoch: np.ndarray
    g_c: dict
    history: tuple = ()


class BatchTrainer:
    """Trains groups of settings vmapped and scores them in the simulator.

    Args:
      data: prepared training data (its window length must be the settings').
      forward_c_params, forward_model: the frozen F_c of the feedback loss.
      judge: the `SimulatorChoice` that scores G_c (built with any setting of the group: it
        reads the generator's shape and the hold factors from it).
    """

    def __init__(
        self,
        data: TranslationData,
        forward_c_params,
        judge: SimulatorChoice,
        forward_model: ForwardModel | None = None,
    ):
        self.data = data
        self.forward_c_params = forward_c_params
        self.forward_model = forward_model
        self.judge = judge
        self._programs: dict[TrainConfig, tuple] = {}

    def _compiled(self, static: TrainConfig):
        """(init(key, hparams) for one member, run(state, key, start, hparams, n) jitted and
        vmapped over members) for one group; `init_each` initialises the members."""
        if static not in self._programs:

            def trainer(hparams):
                config = dataclasses.replace(static, **hparams)
                return make_trainer(config, self.data, self.forward_c_params, self.forward_model)

            def init(key, hparams):
                return trainer(hparams).init(key)

            def run(state, key, start, hparams, n_epochs):
                return trainer(hparams).run_epochs(state, key, start, n_epochs)

            self._programs[static] = (
                init,
                jax.jit(jax.vmap(run, in_axes=(0, 0, None, 0, None)), static_argnums=4),
            )
        return self._programs[static]

    def train(
        self,
        configs: Sequence[TrainConfig],
        seeds: Sequence[int] = (0,),
        on_choice: Callable[..., np.ndarray] | None = None,
    ) -> BatchResult:
        """Trains every setting with every seed, vmapped; scores them in the simulator.

        Args:
          configs: settings of one group (`static_part` equal), epochs and stretch_every from
            the first.
          seeds: PRNG seeds; member (c, s) starts from `PRNGKey(seed)` as `ccgan.train` does.
          on_choice: `(epoch, index [C'], k [C', S], error_cm [C', S], errors_cm [C', S, K])
            -> keep [C'] bool`, called after each scoring before the last with the live settings
            only (their indices into `configs`); False prunes a setting.

        Returns:
          `BatchResult`.

        Raises:
          ValueError: no settings, or settings of several groups.
        """
        if not configs:
            raise ValueError("no settings to train")
        static = static_part(configs[0])
        for c in configs[1:]:
            if static_part(c) != static:
                raise ValueError(
                    "settings of one batch may differ only in "
                    f"{', '.join(CONTINUOUS)}; {c} differs from {configs[0]} elsewhere"
                )
        n_cfg, n_seeds = len(configs), len(seeds)
        hparams = {
            n: jnp.asarray([getattr(c, n) for c in configs for _ in seeds], jnp.float32)
            for n in CONTINUOUS
        }
        keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(list(seeds) * n_cfg))
        init_keys, run_keys = jnp.swapaxes(jax.vmap(jax.random.split)(keys), 0, 1)
        init, run = self._compiled(static)
        state = init_each(init, init_keys, hparams)

        n_k = len(static.hold_factors)
        k = np.full((n_cfg, n_seeds), static.hold_factors[0])
        error = np.full((n_cfg, n_seeds), np.nan)
        errors = np.full((n_cfg, n_seeds, n_k), np.nan)
        scored_epoch = np.zeros(n_cfg, int)
        live = np.ones(n_cfg, bool)
        history = []
        ends = list(range(static.stretch_every, static.epochs, static.stretch_every))
        start = 0
        for end in [*ends, static.epochs]:
            state, _ = run(state, run_keys, jnp.int32(start), hparams, end - start)
            start = end
            index = np.flatnonzero(live)
            members = (index[:, None] * n_seeds + np.arange(n_seeds)).ravel()
            g_c = jax.tree.map(lambda x, m=members: x[m, 0], state.params["gen"])
            choice = self.judge.choose(g_c)
            k[index] = choice.k.reshape(-1, n_seeds)
            error[index] = choice.error_cm.reshape(-1, n_seeds)
            errors[index] = choice.errors_cm.reshape(-1, n_seeds, n_k)
            scored_epoch[index] = end
            history.append(
                {
                    "epoch": end,
                    "index": index,
                    "k": k[index].copy(),
                    "error_cm": error[index].copy(),
                }
            )
            new_k = np.asarray(state.k).copy()
            new_k[members] = choice.k
            state = state.replace(k=jnp.asarray(new_k, state.k.dtype))
            if on_choice is not None and end < static.epochs:
                keep = np.asarray(
                    on_choice(end, index, k[index], error[index], errors[index]), bool
                )
                live[index[~keep]] = False
                if not live.any():
                    break
        g_c = jax.tree.map(lambda x: np.asarray(x[:, 0]), state.params["gen"])
        return BatchResult(
            k=k, error_cm=error, errors_cm=errors, epoch=scored_epoch, g_c=g_c,
            history=tuple(history),
        )  # fmt: skip
