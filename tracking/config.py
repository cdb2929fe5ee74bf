"""Settings checks shared by every layer: one error type for a bad field, and its checks.

The settings dataclasses (`tracking.oracle.OracleConfig`, `ccgan.train.TrainConfig`,
`ccgan.distill.DistillConfig`, `eval.pipeline.EvalConfig`, ...) check their fields in
`__post_init__` and raise `ConfigError`, so the Python API and every command line refuse the
same values, with messages "<field> <problem>". It lives here, at the lowest layer that has a
settings class, so that every layer above raises and catches the same type.
"""

from __future__ import annotations

import math
import numbers
import operator

import jax
import numpy as np


class ConfigError(ValueError):
    """A settings field holds a value the code cannot use.

    Raised by the config dataclasses' `__post_init__`, so the Python API and the command line
    refuse the same values; `ccgan.train.config_from_args` and `eval.shapes.parse_args` turn it
    into a usage error naming the flag.

    Attributes:
      field: the offending field.
      problem: what is wrong, a phrase that follows the field's name ("must be >= 1, got 0").
    """

    def __init__(self, field: str, problem: str):
        super().__init__(f"{field} {problem}")
        self.field, self.problem = field, problem


_BOUND_CHECKS = ((">=", operator.ge), (">", operator.gt), ("<", operator.lt))


def check_fields(
    config,
    at_least: dict[str, float] | None = None,
    above: dict[str, float] | None = None,
    below: dict[str, float] | None = None,
) -> None:
    """Refuses fields of `config` that are not finite numbers within their bounds.

    A tuple field is checked element by element and must not be empty. Values traced by JAX
    (`ccgan.tune` passes hyperparameters into a jitted `dataclasses.replace`) are skipped: they
    were checked when concrete.

    Args:
      config: a dataclass instance.
      at_least: {field: lowest allowed value}.
      above: {field: a bound the value must exceed}.
      below: {field: a bound the value must stay under}.

    Raises:
      ConfigError: the first field out of range, with its value.
    """
    for (word, ok), rules in zip(_BOUND_CHECKS, (at_least, above, below), strict=True):
        for name, bound in (rules or {}).items():
            value = getattr(config, name)
            many = isinstance(value, tuple | list)
            if many and not value:
                raise ConfigError(name, "must not be empty")
            for v in value if many else (value,):
                if isinstance(v, jax.core.Tracer):
                    continue
                if (
                    isinstance(v, bool)
                    or not isinstance(v, numbers.Real | np.ndarray | jax.Array)
                    or not math.isfinite(float(v))
                    or not ok(float(v), bound)
                ):
                    each = "each " if many else ""
                    raise ConfigError(
                        name, f"must be {each}a finite number {word} {bound}, got {value!r}"
                    )


def require(ok: bool, field: str, problem: str) -> None:
    """ConfigError(field, problem) unless ok; `problem` follows the field's name."""
    if not ok:
        raise ConfigError(field, problem)


def check_ints(field: str, values, lowest: int) -> None:
    """A tuple of distinct integers >= lowest, or one integer >= lowest."""
    many = isinstance(values, tuple | list)
    items = values if many else (values,)
    require(
        len(items) > 0
        and all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in items)
        and all(v >= lowest for v in items)
        and len(set(items)) == len(items),
        field,
        f"must be {'distinct integers' if many else 'an integer'} >= {lowest}, got {values!r}",
    )


def check_duration(field: str, value, control_hz: float) -> None:
    """A program length (s) that gives at least one command at control_hz (Hz)."""
    require(
        isinstance(value, int | float) and math.isfinite(value) and round(value * control_hz) >= 1,
        field,
        f"must be a length (s) of at least one {1 / control_hz:g} s command, got {value!r}",
    )
