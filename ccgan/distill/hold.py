"""The distillation's hold factor k: set, the start translators' own, or chosen in the arm the
teacher plans in.

Chosen (`DistillConfig.k_candidates`), k is stretch only's best among the candidates on
`mjx_arm.programs.validation_program`, the program `eval.shapes` picks stretch only's k on
(never a test shape), in the teaching arm: taught on an identified arm (`ccgan.distill
--teach-domain`), k is then chosen from the target's data alone, not in the true target.
"""

from __future__ import annotations

import dataclasses

import mjx_arm  # noqa: F401  (before jax: sets the XLA CPU flag)
from ccgan.distill.config import DistillConfig
from ccgan.stage import common_k
from mjx_arm.programs import validation_program
from tracking.held import choose_stretch_k


def choose_hold_factor(
    config: DistillConfig, translators: list, arm_s, arm_c, log=print
) -> tuple[int, dict | None]:
    """(k, how it was chosen) of a distillation.

    Args:
      config: its settings: `k_candidates` (chosen among them), else `hold_factor` (> 0: set),
        else the translators' common k.
      translators: the start translators (`ccgan.translator.Translator`; only their k is read).
      arm_s, arm_c: the D_s arm and the arm the teacher plans in (the identified arm when taught
        on one), both in their own timestep; the candidates run in MuJoCo C.

    Returns:
      (k, None) when set or the translators', else (k, {"k", "candidates", "x_err_cm_by_k"
      {str(k): mean X_err cm of the validation program held k periods}, "program" (what it
      was), "domain" (every field of the arm's Domain)}).

    Raises:
      ValueError: no candidates, no hold factor, and translators that disagree on k (or none).
    """
    if not config.k_candidates:
        return config.hold_factor or common_k(translators), None
    program = validation_program(config.k_choice_seconds)
    k, errors = choose_stretch_k(
        arm_s, arm_c, program, config.k_candidates, backend="c", progress=False
    )
    shown = ", ".join(f"{c}: {e:.4f}" for c, e in errors.items())
    log(f"k = {k}: stretch only's best in the {arm_c.domain.name} arm (X_err cm by k: {shown})")
    return k, {
        "k": k,
        "candidates": list(config.k_candidates),
        "x_err_cm_by_k": {str(c): e for c, e in errors.items()},
        "program": f"mjx_arm.programs.validation_program({config.k_choice_seconds:g})",
        "domain": dataclasses.asdict(arm_c.domain),
    }
