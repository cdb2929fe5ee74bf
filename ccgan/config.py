"""The settings of CCGAN training: `TrainConfig`, and the check of `ccgan.forward.ForwardConfig`.

Each field's `#:` comment is its documentation and its `--help` line (`ccgan.cli.field_docs`).
"""

from __future__ import annotations

import dataclasses
import json
from typing import TYPE_CHECKING

from tracking.config import ConfigError, check_fields

if TYPE_CHECKING:
    from ccgan.forward import ForwardConfig

#: Where `TrainConfig.k_choice` scores the hold factors.
K_CHOICES = ("simulator", "forward")
#: The simulators `TrainConfig.k_choice_simulator` can name: the fitted chain (`mjx_arm.load`)
#: or the reference rod (`mjx_arm.load_rod`).
K_CHOICE_SIMULATORS = ("chain", "rod")
#: The held-out programs `TrainConfig.k_choice_programs` can name.
K_CHOICE_PROGRAMS = ("babbling", "shape_like")
#: The feedback rollouts `TrainConfig.feedback_impl` can name.
FEEDBACK_IMPLS = ("auto", "lean", "lean_reduce")
#: Rollouts that were options once and lost (docs/benchmarks.md, "Retired experiments"). A
#: config naming one is refused; a stored run naming one resumes with this run's rollout.
RETIRED_FEEDBACK_IMPLS = ("cell", "pallas")
#: `TrainConfig` fields renamed since runs were first stored, {old name: new name}. A stored
#: config (checkpoint metadata) reads through `stored_config`; the old flag stays a hidden alias.
RENAMED_FIELDS = {"stretch_choices": "hold_factors"}


def stored_config(config: dict) -> dict:
    """A stored `TrainConfig` dict (checkpoint metadata), renamed fields under their new names."""
    return {RENAMED_FIELDS.get(name, name): value for name, value in config.items()}


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """CCGAN-GP settings; defaults are the paper's where it gives one."""

    #: Passes over the training windows (paper: 550).
    epochs: int = 550
    #: Windows per step and domain (paper: 10), split over local devices.
    batch_size: int = 10
    #: Control steps per training window (not in the paper; >= 2 for the instance-norm critic).
    window_length: int = 10
    #: Step between window starts (0 = window_length, non-overlapping).
    window_stride: int = 0
    #: Trajectories per domain held out for validation (paper: 3).
    n_val: int = 3
    #: Generator learning rate (paper: 1e-4).
    lr_generator: float = 1e-4
    #: Critic learning rate (paper: 2e-4).
    lr_critic: float = 2e-4
    #: AdamW first-moment decay beta1 (paper: 0.5).
    beta1: float = 0.5
    #: AdamW second-moment decay beta2 (paper: 0.999).
    beta2: float = 0.999
    #: AdamW decoupled weight decay (paper: unstated; PyTorch's AdamW default 1e-2).
    weight_decay: float = 1e-2
    #: Cycle-loss weight lambda_c (paper code: 10).
    lambda_cycle: float = 10.0
    #: Identity-loss weight (paper: 1).
    lambda_identity: float = 1.0
    #: Feedback-loss weight lambda_f (paper code: 5).
    lambda_feedback: float = 5.0
    #: Gradient-penalty weight (paper code: 10).
    lambda_gp: float = 10.0
    #: Hold factors k (control periods each translated command is held) to choose from
    #: (paper: 5..30). Formerly `stretch_choices` (`RENAMED_FIELDS`).
    hold_factors: tuple[int, ...] = (5, 10, 15, 20, 25, 30)
    #: Epochs between choices of k (the paper's N; also chosen once before training and, with
    #: k_choice "simulator", after the last epoch).
    stretch_every: int = 100
    #: Where k is chosen: "simulator" runs G_c's commands on the held-out D_s programs in the
    #: target-domain arm, as the authors' code does (`ccgan.sim_choice`); "forward" runs them
    #: through the learned F_c inside the jitted epoch (fast, but F_c's open-loop drift enters).
    k_choice: str = "simulator"
    #: With k_choice "simulator": write each seed's G_c (and its k) from the scored epoch with
    #: the lowest held-out error, not the last epoch's (a stop on held-out error; untrained G_c
    #: never counts). Training oscillates: the best scored epochs were 20-40 of 80
    #: (docs/ccgan_study.md).
    keep_best: bool = True
    #: With keep_best: stop training once this many scorings in a row (every `stretch_every`
    #: epochs) gave no seed a lower held-out error, and write the best iterates; `epochs` is
    #: then the most it trains. 0 trains every epoch. The chain's CCGAN-GP seeds kept epochs
    #: 20-40 of 80 (docs/ccgan_study.md): the epochs after them cost GPU time for nothing.
    patience: int = 0
    #: Seconds of each held-out program simulated when k_choice is "simulator" (0 = whole
    #: programs; the authors' code uses one 30 s program).
    k_choice_seconds: float = 20.0
    #: The held-out D_s programs k is chosen (and keep_best scores) on with k_choice
    #: "simulator": "babbling" (the training data's held-out babbling, `n_val` of them) or
    #: "shape_like" (`k_choice_n_programs` programs of the shapes' signal types,
    #: `mjx_arm.programs.shape_like_programs` split "k_choice", full scale, never a test shape;
    #: their D_s targets simulated from rest). Babbling at these holds does not stand for the
    #: shapes: a translator can beat stretch only there and lose on the shapes
    #: (docs/ccgan_study.md).
    k_choice_programs: str = "babbling"
    #: The simulator k_choice "simulator" scores in: "chain" (the fitted chain of `--model`,
    #: MuJoCo C) or "rod" (the reference Cosserat rod of the paper's law, `mjx_arm.load_rod`,
    #: float64), which must be the simulator the training data came from (`ccgan.train` refuses
    #: a mix). The rod is latency-bound: one scoring's rollouts go as one padded batch on a GPU
    #: and cost about the longest program, k_choice_seconds x max(hold_factors) simulated s at
    #: ~7 simulated s per wall s on one H200 (20 s x k = 30: ~90 s), so a run costs that once per
    #: scoring (epochs / stretch_every + 2); on a CPU, the sum of every rollout at ~25-35
    #: simulated s per wall s (`ccgan.sim_choice`).
    k_choice_simulator: str = "chain"
    #: Shape-like programs drawn when k_choice_programs is "shape_like".
    k_choice_n_programs: int = 12
    #: Physics steps per control period of the arm k_choice "simulator" scores in (0: the arm's
    #: own, 25 of 4 ms; 5: a planning copy, `mjx_arm.Arm.planning_copy`, five times fewer steps
    #: and 0.01 mm from the arm on average over held programs, `studies.planning_arm`). The
    #: scores only choose k and the kept epoch; every reported error is the arm's own.
    k_choice_substeps: int = 0
    #: Control steps per held-out window when k_choice is "forward" (0 = whole trajectories).
    #: Each window starts F_c from the recorded pose, so the windows run in parallel: the
    #: choice costs val_window_length * k_max sequential F_c periods instead of T_val * k_max.
    val_window_length: int = 100
    #: LSTM time steps per loop iteration in the generators (numerics unchanged).
    gen_unroll: int = 10
    #: F_c periods per loop iteration in the feedback rollout and the choice of k.
    feedback_unroll: int = 25
    #: The feedback rollout, one of `models.forward_stretched`'s ("lean", "lean_reduce"), or
    #: "auto": "lean_reduce" on a GPU, where XLA fuses its multiply-and-sum products into fewer
    #: kernels, "lean" elsewhere, where those products are slower than a matrix product
    #: (docs/benchmarks.md).
    feedback_impl: str = "auto"
    #: WCGAN-GP baseline: one generator and one critic on D_c only, no cycle/identity loss.
    baseline: bool = False
    #: Epochs between checkpoints (also the driver's jitted chunk and tqdm tick).
    checkpoint_every: int = 10
    #: Generator LSTM width (paper: 32).
    gen_hidden: int = 32
    #: Generator FC width (paper: 128).
    gen_fc: int = 128
    #: Generator on each time step alone, as the authors' code trains it (sequence length 1).
    gen_per_sample: bool = False
    #: Generator as the identity plus a learnt correction (`ccgan.models.Generator`).
    gen_residual: bool = False
    #: Critic updates per generator update, each on the step's batch with a fresh gradient
    #: penalty sample (the authors' code: 1; WGAN-GP's authors: 5).
    critic_steps: int = 1
    #: Adversarial-loss weight (paper: 1; 0 ablates the critics' influence on the generators).
    lambda_adversarial: float = 1.0
    #: Critic Conv1D widths (five layers).
    critic_features: tuple[int, ...] = (32, 64, 64, 128, 128)

    #: Old field names (not a field: no annotation); `add_config_flags` keeps their flags hidden.
    RENAMED_FIELDS = RENAMED_FIELDS

    def __post_init__(self):
        """Refuses settings that would fail late or train nothing (ConfigError names the field).

        A window of one step makes the instance-norm critic's output constant, so the critic
        and adversarial losses are exactly 0: window_length must be >= 2.
        """
        check_fields(
            self,
            at_least={
                "epochs": 1,
                "batch_size": 1,
                "window_length": 2,
                "window_stride": 0,
                "n_val": 1,
                "beta1": 0,
                "beta2": 0,
                "weight_decay": 0,
                "lambda_cycle": 0,
                "lambda_adversarial": 0,
                "critic_steps": 1,
                "lambda_identity": 0,
                "lambda_feedback": 0,
                "lambda_gp": 0,
                "hold_factors": 1,
                "stretch_every": 1,
                "patience": 0,
                "val_window_length": 0,
                "k_choice_seconds": 0,
                "k_choice_n_programs": 1,
                "k_choice_substeps": 0,
                "gen_unroll": 1,
                "feedback_unroll": 1,
                "checkpoint_every": 1,
                "gen_hidden": 1,
                "gen_fc": 1,
                "critic_features": 1,
            },
            above={"lr_generator": 0, "lr_critic": 0},
            below={"beta1": 1, "beta2": 1},
        )
        if self.k_choice not in K_CHOICES:
            raise ConfigError("k_choice", f"must be one of {K_CHOICES}, got {self.k_choice!r}")
        if self.k_choice_programs not in K_CHOICE_PROGRAMS:
            raise ConfigError(
                "k_choice_programs",
                f"must be one of {K_CHOICE_PROGRAMS}, got {self.k_choice_programs!r}",
            )
        if self.k_choice_simulator not in K_CHOICE_SIMULATORS:
            raise ConfigError(
                "k_choice_simulator",
                f"must be one of {K_CHOICE_SIMULATORS}, got {self.k_choice_simulator!r}",
            )
        if self.k_choice_simulator == "rod" and self.k_choice_substeps:
            raise ConfigError(
                "k_choice_substeps",
                "is the chain's planning copy; the rod (k_choice_simulator 'rod') has none:"
                f" give 0, got {self.k_choice_substeps}",
            )
        if self.k_choice_programs == "shape_like" and not self.k_choice_seconds:
            raise ConfigError(
                "k_choice_seconds", "must be > 0 with k_choice_programs shape_like (their length)"
            )
        if self.patience and not (self.keep_best and self.k_choice == "simulator"):
            raise ConfigError(
                "patience",
                "needs keep_best and k_choice 'simulator' (it stops on their held-out scores),"
                f" got keep_best={self.keep_best}, k_choice={self.k_choice!r}",
            )
        if self.feedback_impl not in FEEDBACK_IMPLS:
            retired = (
                ", a retired rollout (docs/benchmarks.md)"
                if self.feedback_impl in RETIRED_FEEDBACK_IMPLS
                else ""
            )
            raise ConfigError(
                "feedback_impl",
                f"must be one of {FEEDBACK_IMPLS}, got {self.feedback_impl!r}{retired}",
            )

    @property
    def generator_args(self) -> dict:
        """The `ccgan.models.Generator` fields these settings give (the translator files'
        "generator" metadata)."""
        return {
            "hidden": self.gen_hidden,
            "fc": self.gen_fc,
            "per_sample": self.gen_per_sample,
            "residual": self.gen_residual,
        }

    @property
    def stride(self) -> int:
        return self.window_stride or self.window_length

    @property
    def k_max(self) -> int:
        return max(self.hold_factors)

    def to_dict(self) -> dict:
        """The settings as JSON values. `k_choice_simulator` is left out when it is "chain",
        the only simulator before the field existed: so every stored run, forward model and
        translator file (checkpoint metadata compares these dicts) still matches and resumes;
        `from_dict` gives it back."""
        d = json.loads(json.dumps(dataclasses.asdict(self)))
        if d["k_choice_simulator"] == "chain":
            del d["k_choice_simulator"]
        return d

    @classmethod
    def from_dict(cls, config: dict) -> TrainConfig:
        """The config of a `to_dict` dict, old field names (`RENAMED_FIELDS`) included."""
        return cls(
            **{k: tuple(v) if isinstance(v, list) else v for k, v in stored_config(config).items()}
        )


def check_forward_config(config: ForwardConfig) -> None:
    """Refuses forward-model settings that cannot train (`ForwardConfig` has no checks).

    Raises:
      ConfigError: epochs, batch_size, hidden or fc < 1; lr <= 0; weight_decay < 0.
    """
    check_fields(
        config,
        at_least={"epochs": 1, "batch_size": 1, "hidden": 1, "fc": 1, "weight_decay": 0},
        above={"lr": 0},
    )
