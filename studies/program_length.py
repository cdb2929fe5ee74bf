"""Does a simulator-distilled translator keep its accuracy over programs longer than those it
was distilled on? On held-out programs only (never a test shape).

`ccgan.distill` imitates receding-horizon tracking (`tracking.mpc`, its teacher) on shape-like
programs of a few seconds and picks its iterate on held-out programs of the same length; the
five shapes run 60 s. This study draws held-out shape-like programs of the long length (their
own split "length_study", full scale), plans the teacher's commands for them with the settings
the translator was distilled with, and scores in the D_c simulator (MuJoCo C) the translator of
every seed, its teacher and stretch only. X_err is split into the first `--window-s` (the
length the translator was distilled on) and the rest: a student whose ratio to its teacher grows
after the window drifts on long programs; one whose ratio stays the same does not.

    python -m studies.program_length --out studies/results/cpu/program_length

The default translators are the k = 15 ones distilled over whole programs on models/softarm.xml
(`docs/distillation.md`), whose teacher planned one step with one iteration; a translator of
another arm is refused.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import mjx_arm  # noqa: E402
from bench import run_header, write_results  # noqa: E402
from ccgan.checkpoint import CheckpointError  # noqa: E402
from ccgan.cli import cli_parser  # noqa: E402
from ccgan.translator import load_translator  # noqa: E402
from mjx_arm.programs import shape_like_programs  # noqa: E402
from studies.checks import parse_checked_args
from tracking import held, metrics, mpc  # noqa: E402

#: The chain's distilled translators, one per seed.
DEFAULT_TRANSLATORS = [
    f"studies/results/h200/issue30/distill_k15/translator_seed{seed}.ckpt" for seed in (0, 1, 2)
]
#: Source steps per second (the programs' 10 Hz).
STEPS_PER_S = 10


def split_errors(x_err_cm: np.ndarray, window: int) -> dict[str, float]:
    """Mean X_err (cm) of [..., T] over the first `window` steps, after them, and over all."""
    x_err_cm = np.asarray(x_err_cm)
    if not 0 < window < x_err_cm.shape[-1]:
        raise ValueError(f"window {window} must split programs of {x_err_cm.shape[-1]} steps")
    return {
        "window": float(x_err_cm[..., :window].mean()),
        "after": float(x_err_cm[..., window:].mean()),
        "whole": float(x_err_cm.mean()),
    }


def main(argv=None) -> None:
    p = cli_parser("studies.program_length", __doc__)
    p.add_argument("--model", default="models/softarm.xml", help="the arm's MJCF")
    p.add_argument("--translators", nargs="+", default=DEFAULT_TRANSLATORS, help="one per seed")
    p.add_argument("--n", type=int, default=5, help="held-out programs")
    p.add_argument("--duration", type=float, default=60.0, help="seconds per program")
    p.add_argument(
        "--window-s", type=float, default=4.0, help="the programs' length in the distillation"
    )
    p.add_argument(
        "--horizon-steps", type=int, default=1, help="the teacher's horizon in the distillation"
    )
    p.add_argument(
        "--iterations", type=int, default=1, help="the teacher's Gauss-Newton iterations per step"
    )
    p.add_argument("--out", required=True, help="output prefix (writes .json, .md and .png)")
    a = parse_checked_args(p, argv)
    window = int(round(a.window_s * STEPS_PER_S))
    if not 0 < window < int(round(a.duration * STEPS_PER_S)):
        p.error(f"--window-s {a.window_s} must be shorter than --duration {a.duration}")
    arm_s, arm_c = mjx_arm.load(a.model, "source"), mjx_arm.load(a.model, "constrained")
    try:  # a translator of another arm is refused, not scored on this one
        translators = [load_translator(path, model_hash=arm_c.model_hash) for path in a.translators]
    except (ValueError, CheckpointError) as err:
        p.error(f"--translators: {err}")
    ks = {tr.k for tr in translators}
    if len(ks) != 1:
        p.error(f"the translators hold their commands for different k: {sorted(ks)}")
    (k,) = ks
    programs = shape_like_programs(a.n, a.duration, seed=0, split="length_study", full_scale=True)
    targets = arm_s.rollout(programs.astype(np.float64), backend="c")

    commands = {"stretch": held.stretch(programs, k)}
    for seed, tr in enumerate(translators):
        commands[f"translator seed {seed}"] = np.stack(
            [tr.translate(prog, target)[0] for prog, target in zip(programs, targets, strict=True)]
        )
    cfg = mpc.MpcConfig(horizon_steps=a.horizon_steps, iterations=a.iterations)
    commands["teacher (mpc)"], info = mpc.track(arm_c, targets, k, programs, cfg, progress=True)
    x_err = {
        name: metrics.position_error_cm(held.run_dc(arm_c, cmd, k, "c"), targets)
        for name, cmd in commands.items()
    }
    errors = {name: split_errors(err, window) for name, err in x_err.items()}
    teacher = errors["teacher (mpc)"]

    header = run_header("studies.program_length", argv)
    rest = arm_s.rest_pose()
    excursion = [metrics.tip_excursion_cm(target, rest) for target in targets]
    result = {
        "model": a.model,
        "translators": a.translators,
        "k": k,
        "n": a.n,
        "duration_s": a.duration,
        "window_s": a.window_s,
        "teacher": {
            "horizon_steps": a.horizon_steps,
            "iterations": a.iterations,
            "wall_s": info.get("wall_s"),
        },
        "tip_excursion_cm": excursion,
        "x_err_cm": errors,
        "x_err_cm_per_program": {name: err.mean(-1).tolist() for name, err in x_err.items()},
    }
    body = [
        f"- {a.n} held-out shape-like programs of {a.duration:g} s (split length_study, full"
        f" scale); tip excursion of the targets {np.mean(excursion):.2f} cm (mean); k = {k};"
        f" teacher: receding-horizon tracking over {a.horizon_steps} source step(s),"
        f" {a.iterations} Gauss-Newton iteration(s) per step (MuJoCo C)",
        "",
        f"X_err (cm) in the D_c simulator (MuJoCo C), mean over programs and time: over the first"
        f" {a.window_s:g} s (the length distilled on), after it, and over the whole program;"
        " in brackets the ratio to the teacher.",
        "",
        f"| method | first {a.window_s:g} s | after | whole |",
        "|---|---|---|---|",
    ]
    for name, e in errors.items():
        cells = [
            f"{e[part]:.3f} ({e[part] / teacher[part]:.2f})"
            for part in ("window", "after", "whole")
        ]
        body.append(f"| {name} | " + " | ".join(cells) + " |")
    title = f"A distilled translator over long programs, on {a.model}"
    md = write_results(a.out, header, result, title, body)

    fig, ax = plt.subplots(figsize=(9, 4))
    t = np.arange(targets.shape[1]) / STEPS_PER_S
    for name, err in x_err.items():
        ax.plot(t, err.mean(0), label=name, lw=1.2)
    ax.axvline(a.window_s, color="grey", ls=":", label=f"distilled on {a.window_s:g} s")
    ax.set(xlabel="time (s)", ylabel="X_err (cm), mean over programs", yscale="log")
    ax.set_title(f"{a.n} held-out programs of {a.duration:g} s in D_c")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(md.with_suffix(".png"), dpi=110)
    print(md.read_text())


if __name__ == "__main__":
    main()
