"""The settings of an imitation fine-tune (`DistillConfig`), checked when made."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import mjx_arm  # noqa: F401  (before jax: sets the XLA CPU flag)
from mjx_arm import arm as mjx_arm_arm
from mjx_arm.dataset import sha256_file
from tracking.config import ConfigError, check_fields, check_ints

__all__ = ["ConfigError", "DistillConfig", "SOURCE_SIMULATORS"]

#: What can give the D_s poses a teacher tracks (`DistillConfig.source_simulator`).
SOURCE_SIMULATORS = ("chain", "rod")


@dataclasses.dataclass(frozen=True)
class DistillConfig:
    """Settings of an imitation fine-tune."""

    n_train: int = 128
    """Teacher programs to imitate."""
    n_val: int = 16
    """Held-out programs that pick the best iterate."""
    n_train_full: int = 0
    """More teacher programs, scaled to the full valve amplitude as the test shapes are
    (`shape_like_program(full_scale=True)`, their own random stream)."""
    n_val_full: int = 0
    """More held-out programs at the full amplitude."""
    n_train_babble: int = 0
    """More teacher programs from the babbling family (`mjx_arm.babble`'s, the paper's holds of
    0.5-3 s between 0 and 3.5 bar, a stream of their own): programs unlike any shape, for a
    translator that meets programs it was not written for."""
    n_val_babble: int = 0
    """More held-out babbling programs."""
    duration_s: float = 20.0
    """Length of every program, from rest (s of source time)."""
    window_s: float = 2.0
    """The held-out score averages the X_err over the first window_s seconds and the whole."""
    head_weight: float = 1.0
    """Weight of the first window_s seconds in the imitation loss (the rest weighs 1): the
    start from rest is where the oracle is compared and where the teacher's commands change
    fastest."""
    horizon_steps: int = 1
    """The teacher's planning horizon (`tracking.mpc.MpcConfig.horizon_steps`)."""
    iterations: int = 2
    """The teacher's Gauss-Newton iterations per step."""
    epochs: int = 300
    """Passes over the teacher programs."""
    batch_size: int = 16
    """Programs per Adam step."""
    learning_rate: float = 1e-3
    """Adam step size."""
    final_lr_factor: float = 1.0
    """The step size falls along a cosine from learning_rate to learning_rate x this over the
    run's epochs (1: constant). At k = 20 the held-out score of the constant rate moved by up to
    1.8x between validations (docs/distillation.md)."""
    eval_every: int = 50
    """Epochs between held-out scores (and the last epoch)."""
    seed: int = 0
    """Seed of the programs and of the batch order."""
    max_wall_s: float = 0.0
    """Stop training after this many seconds (0: no limit); the best iterate so far is kept."""
    teacher_backend: str = "c"
    """Where the teacher plans: "c" (`tracking.mpc`, MuJoCo C on the host's cores, any horizon)
    or "mjx" (`tracking.mpc_mjx`, every program at once on the accelerator, horizon 1); its
    commands are scored in MuJoCo C either way. `bench.teacher` measures which is faster."""
    generator_unroll: int = 1
    """LSTM time steps per loop iteration of G_c's scans while it trains and is scored (the
    numerics are unchanged; `bench.distill_step` measures the speed). A whole 60 s program is
    600 sequential steps per layer, forward and backward."""
    teacher_substeps: int = 0
    """Physics steps per control period of the arm the teacher plans in (0: the arm's own, 25 of
    4 ms). A planning copy (`mjx_arm.Arm.planning_copy`) with 5 runs five times fewer sequential
    steps; its commands are still scored in the arm itself (`studies.planning_arm` measures what
    the coarser arm costs the teacher)."""
    score_substeps: int = 0
    """Physics steps per control period of the arm the held-out programs are scored in, which
    picks the kept iterate (0: the arm's own, 25 of 4 ms). A planning copy of 5 scores five
    times faster (MuJoCo C): the chain's scorings of 48 programs of 900-1,500 simulated s took
    about 40 s each in the arm, four per run (`docs/chain.md`)."""
    teacher_shard: int = 0
    """Programs the teacher plans per call, across splits, the cache written after each (0: a
    split per call), so that a run stopped at a deadline keeps the shards it finished; with
    the MJX teacher one call's wall time barely grows with its programs."""
    hold_factor: int = 0
    """k, the control periods each command is held, for the teacher and the distilled
    translators (0: the translators' own, which must agree). G_c gives one command per source
    step whatever k is; a k at which the D_c arm keeps up with the targets keeps the teacher
    off the valve limits (`studies.mpc_saturation`)."""
    k_candidates: tuple[int, ...] = ()
    """Hold factors k to choose k among, in the arm the teacher plans in (with --teach-domain,
    the identified arm): stretch only's best on `mjx_arm.programs.validation_program` (never a
    test shape), as `eval.shapes` picks stretch only's k (empty: hold_factor, or the
    translators' own). The chosen k and the X_err by k go into distill.json."""
    k_choice_seconds: float = 20.0
    """Length of the validation program that chooses k among k_candidates (s; eval.shapes's is
    20 s)."""
    source_simulator: str = "chain"
    """What gives the D_s poses the teacher tracks and G_c reads: "chain" (the chain's D_s arm,
    MuJoCo C) or "rod" (the reference rod in D_s, float64: `mjx_arm.load_rod("source")`), for a
    translator meant for an arm whose D_s paths are the rod's. The translator is asked to make
    the target trace its own arm's D_s path; taught on the chain's, it inherits the chain's D_s
    model error (1.3-6.4% of L on the five shapes, `results/fidelity.md`)."""
    train_sets: int = 1
    """How many sets of the training splits the run trains on: 1 for a pair; one per training
    medium in `ccgan.distill_range` (set there from --n-media: no flag). batch_size may be at
    most their programs in all."""
    correction_translator: str = ""
    """A translator file whose commands, run on the target (the reference rod in
    `correction_domain`) and in the arm the teacher plans in, correct the teacher's targets: one
    step of iterative learning control. With d = rod(u0) - arm(u0) the pose difference along its
    commands u0 (every k-th pose, k the teacher's), the teacher tracks x_s - d, so that the rod,
    which is the arm plus d, traces x_s; G_c still reads x_s, and the held-out programs are
    scored in the arm against x_s - d. The target's own rollouts of training programs (never a
    test shape) are what a user of a real arm can record. Empty: no correction."""
    correction_domain: str = "constrained"
    """The reference rod's domain the correction's target rollouts run in (`mjx_arm.load_rod`)."""
    correction_dtype: str = "float32"
    """The rod's dtype for the correction's rollouts: float32 is 9x faster on a GPU and 1e-4 of
    L from float64 (`bench/results/h100/rod_throughput_8192`), far below the 1% of L it corrects."""

    def __post_init__(self):
        """Refuses settings that would fail late, after the teacher's commands are computed and
        cached (ConfigError names the field)."""
        period = 1.0 / mjx_arm.CONTROL_HZ
        check_fields(
            self,
            at_least={
                "n_train": 0,
                "n_val": 0,
                "n_train_full": 0,
                "n_val_full": 0,
                "n_train_babble": 0,
                "n_val_babble": 0,
                "duration_s": period,
                "window_s": period,
                "horizon_steps": 1,
                "iterations": 1,
                "epochs": 1,
                "batch_size": 1,
                "eval_every": 1,
                "seed": 0,
                "max_wall_s": 0,
                "hold_factor": 0,
                "teacher_shard": 0,
                "teacher_substeps": 0,
                "score_substeps": 0,
                "generator_unroll": 1,
                "final_lr_factor": 0,
                "k_choice_seconds": period,
                "train_sets": 1,
            },
            above={"head_weight": 0, "learning_rate": 0},
        )
        if self.teacher_backend not in ("c", "mjx"):
            raise ConfigError(
                "teacher_backend", f"must be 'c' or 'mjx', got {self.teacher_backend!r}"
            )
        if self.source_simulator not in SOURCE_SIMULATORS:
            raise ConfigError(
                "source_simulator",
                f"must be one of {SOURCE_SIMULATORS}, got {self.source_simulator!r}",
            )
        if self.correction_translator and not Path(self.correction_translator).is_file():
            raise ConfigError(
                "correction_translator", f"{self.correction_translator}: no such file"
            )
        if self.correction_dtype not in ("float32", "float64"):
            raise ConfigError(
                "correction_dtype", f"must be float32 or float64, got {self.correction_dtype!r}"
            )
        if self.teacher_backend == "mjx" and self.horizon_steps != 1:
            raise ConfigError(
                "horizon_steps", f"must be 1 with teacher_backend 'mjx', got {self.horizon_steps}"
            )
        if self.batch_size > self.n_train_programs * self.train_sets:
            per_set = "" if self.train_sets == 1 else f" per medium x {self.train_sets} media"
            raise ConfigError(
                "batch_size",
                f"must be <= n_train + n_train_full + n_train_babble{per_set} ="
                f" {self.n_train_programs * self.train_sets} training programs, got"
                f" {self.batch_size}",
            )
        if self.k_candidates:
            check_ints("k_candidates", self.k_candidates, 1)
            if self.hold_factor:
                raise ConfigError(
                    "k_candidates",
                    f"choose k or set it (hold_factor {self.hold_factor}), not both",
                )
        if self.n_val + self.n_val_full + self.n_val_babble < 1:
            raise ConfigError(
                "n_val", "plus n_val_full and n_val_babble must be >= 1 (held-out programs)"
            )

    @property
    def n_train_programs(self) -> int:
        """Training programs of every family."""
        return self.n_train + self.n_train_full + self.n_train_babble

    def teacher_key(self) -> dict:
        """The settings the cached teacher commands depend on (not the program counts);
        `ccgan.distill.teacher.teacher_cache_key` adds k, the arm, its domain, the program
        families and the planner's other settings."""
        keys = ("duration_s", "horizon_steps", "iterations", "seed")
        key = {name: getattr(self, name) for name in keys}
        if self.teacher_backend != "c":  # caches of the C teacher keep their key
            key["teacher_backend"] = self.teacher_backend
            # TensorFloat32 plans (before MJX_MATMUL_PRECISION) are not reused
            key["mjx_matmul_precision"] = mjx_arm_arm.MJX_MATMUL_PRECISION
        if self.teacher_substeps:  # caches planned in the arm itself keep their key
            key["teacher_substeps"] = self.teacher_substeps
        if self.source_simulator != "chain":  # caches of the chain's D_s paths keep their key
            key["source_simulator"] = self.source_simulator
        if self.correction_translator:  # uncorrected caches keep their key
            key["correction"] = {
                "translator_sha256": sha256_file(Path(self.correction_translator)),
                "domain": self.correction_domain,
                "dtype": self.correction_dtype,
            }
        return key
