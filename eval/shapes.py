"""The evaluation's command line and its five test shapes.

`python -m eval.shapes` scores every method on the paper's five shapes in the D_c simulator (this
module's `main`; `python -m eval.shapes --help` lists the options, `eval.pipeline` does the work).

The pressure programs themselves are pure functions of time and live below every layer that
draws them, in `mjx_arm.programs` (the circle, rectangle, damped circle, ellipse and kite, each
a [T, 3] array of chamber commands in bar at 10 Hz; the validation program; the random
shape-like programs of the fine-tunes). They are re-exported here under their old names, for
users of `eval.shapes`.
"""

from __future__ import annotations

from mjx_arm.programs import (
    AMPLITUDE_BAR,
    CHAMBER_ANGLES_RAD,
    CONTROL_HZ,
    P_HIGH_BAR,
    P_LOW_BAR,
    P_MID_BAR,
    PERIOD_S,
    PERIODIC_SHAPES,
    SHAPE_LIKE_KINDS,
    SHAPES,
    circle,
    damped_circle,
    ellipse,
    kite,
    pressures_from_bend,
    rectangle,
    shape_like_program,
    shape_like_programs,
    times_s,
    validation_program,
)

__all__ = [
    "AMPLITUDE_BAR",
    "CHAMBER_ANGLES_RAD",
    "CONTROL_HZ",
    "PERIODIC_SHAPES",
    "PERIOD_S",
    "P_HIGH_BAR",
    "P_LOW_BAR",
    "P_MID_BAR",
    "SHAPES",
    "SHAPE_LIKE_KINDS",
    "circle",
    "damped_circle",
    "ellipse",
    "kite",
    "main",
    "pressures_from_bend",
    "rectangle",
    "shape_like_program",
    "shape_like_programs",
    "times_s",
    "validation_program",
]


def main(argv: list[str] | None = None) -> None:
    """CLI: evaluate the methods on the shapes; see `eval.pipeline.parse_args`."""
    from eval import pipeline

    pipeline.main(argv)


if __name__ == "__main__":
    main()
