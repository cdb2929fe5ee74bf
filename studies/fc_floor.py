"""Does feedback through F_c see what the simulator sees, on programs like the shapes?

CCGAN-GP's feedback loss rates G_c's commands by F_c's prediction: each 10-step window of a D_s
program, G_c's commands held k periods, run through F_c from the D_s pose before the window
(`ccgan.trainer`'s feedback rollout), against the D_s poses. This study scores the same commands
both ways on held-out shape-like programs (`shape_like_programs` split "fc_floor", full scale,
never a test shape): stretch only (the D_s commands themselves) and each given translator's G_c
(default: the chain's CCGAN-GP, one file per seed; the committed fc_floor.md also scored the
retired fine-tune through the MJX simulator, studies/results/h200/issue29/finetune, at commit
0fc38f3, whose default it was).

  - "simulator": X_err (cm) of the whole program held k periods from rest in the D_c simulator
    (MuJoCo C), every k-th pose against the D_s poses (what `eval` and the issue's target score);
  - "F_c, feedback windows": the feedback loss's view of the same commands, in cm.

Where F_c ranks the translator above stretch only and the simulator ranks it below, the feedback
loss teaches G_c to correct F_c's error, not the arm's.

    python -m studies.fc_floor --out studies/results/cpu/fc_floor
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan.cli import cli_parser
from ccgan.data import (
    PRESSURE_DIM,
    denormalise_pose,
    denormalise_pressure,
    normalise_pose,
    normalise_pressure,
    samples,
)
from ccgan.models import forward_open_loop
from ccgan.translator import load_translator
from mjx_arm.programs import shape_like_programs
from studies.checks import parse_checked_args
from tracking import held, metrics

#: The chain's CCGAN-GP (studies/results/h200/issue29/chain), one file per seed.
DEFAULT_TRANSLATORS = [
    f"studies/results/h200/issue29/chain/ccgan/translator_seed{seed}.ckpt" for seed in (0, 1, 2)
]


def feedback_view_cm(tr, commands_bar, targets, k: int, window: int) -> np.ndarray:
    """X_err (cm) F_c predicts for commands [N, T, 3] (bar) held k periods, window by window.

    Each window of `window` source steps starts F_c (zero LSTM state) at the D_s pose before it
    (the rest pose's place is taken by the first target pose for the first window), as the
    feedback loss does. Returns [N, T // window * window] per-step errors.
    """
    n, t = commands_bar.shape[:2]
    w = t // window
    cmd = commands_bar[:, : w * window].reshape(n * w, window, PRESSURE_DIM)
    tgt = targets[:, : w * window].reshape(n * w, window, -1)
    before = np.concatenate([targets[:, :1], targets[:, : w * window - 1]], axis=1)
    pose0 = before.reshape(n * w, window, -1)[:, 0]
    p = jnp.asarray(normalise_pressure(held.stretch(cmd, k)), jnp.float32)
    x0 = jnp.asarray(normalise_pose(pose0, tr.bounds), jnp.float32)
    rollout = jax.jit(lambda p, x0: forward_open_loop(tr.forward_model, tr.f_c_params, p, x0))
    pred = denormalise_pose(np.asarray(rollout(p, x0), np.float64), tr.bounds)
    err = metrics.position_error_cm(held.every_kth(pred, k), tgt)
    return err.reshape(n, w * window)


def main(argv=None) -> None:
    p = cli_parser("studies.fc_floor", __doc__)
    p.add_argument("--model", default="models/softarm.xml", help="the arm's MJCF")
    p.add_argument("--translators", nargs="+", default=DEFAULT_TRANSLATORS, help="one per seed")
    p.add_argument("--n", type=int, default=8, help="held-out programs")
    p.add_argument("--duration", type=float, default=30.0, help="seconds per program")
    p.add_argument("--hold-factors", type=int, nargs="+", default=[15, 20])
    p.add_argument("--window", type=int, default=10, help="the feedback loss's window (steps)")
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    translators = [load_translator(path) for path in a.translators]
    if any(tr.f_c_params is None for tr in translators):
        p.error("every translator must hold its F_c")
    arm_s, arm_c = mjx_arm.load(a.model, "source"), mjx_arm.load(a.model, "constrained")
    programs = shape_like_programs(a.n, a.duration, seed=0, split="fc_floor", full_scale=True)
    targets = arm_s.rollout(programs.astype(np.float64), backend="c")

    commands = {"stretch only": programs.astype(np.float64)}
    for path, tr in zip(a.translators, translators, strict=True):
        s = jnp.asarray(samples(programs, targets, tr.bounds))
        out = np.asarray(tr.generator.apply(tr.g_c_params, s), np.float64)[..., :PRESSURE_DIM]
        commands[f"{Path(path).parent.name}/{Path(path).stem}"] = denormalise_pressure(out)
    rows = {}
    for name, cmd in commands.items():
        rows[name] = {}
        for k in a.hold_factors:
            sim = metrics.position_error_cm(
                held.run_dc(arm_c, held.stretch(cmd, k), k, "c"), targets
            )
            # F_c of the first translator: the chain's translators and their fine-tunes hold
            # the same F_c.
            view = feedback_view_cm(translators[0], cmd, targets, k, a.window)
            rows[name][str(k)] = {"simulator_cm": float(sim.mean()), "f_c_cm": float(view.mean())}
            print(name, k, rows[name][str(k)], flush=True)

    header = run_header("studies.fc_floor", argv)
    result = {
        "model": a.model,
        "translators": a.translators,
        "n": a.n,
        "duration_s": a.duration,
        "window": a.window,
        "errors": rows,
    }
    body = [
        f"- {a.n} held-out shape-like programs of {a.duration:g} s (split fc_floor, full scale)",
        f"- F_c: the translators' own (`{a.translators[0]}`); feedback windows of {a.window}"
        " steps from the D_s pose before each window",
        "",
        "X_err (cm), mean over programs and time, by the D_c simulator and by F_c as the"
        " feedback loss sees it; in brackets the ratio to stretch only at the same k.",
        "",
        "| commands | "
        + " | ".join(f"k = {k}: simulator | k = {k}: F_c" for k in a.hold_factors)
        + " |",
        "|---|" + "---|---|" * len(a.hold_factors),
    ]
    base = rows["stretch only"]
    for name, by_k in rows.items():
        cells = []
        for k in a.hold_factors:
            e, b = by_k[str(k)], base[str(k)]
            cells += [
                f"{e['simulator_cm']:.3f} ({e['simulator_cm'] / b['simulator_cm']:.2f})",
                f"{e['f_c_cm']:.3f} ({e['f_c_cm'] / b['f_c_cm']:.2f})",
            ]
        body.append(f"| {name} | " + " | ".join(cells) + " |")
    md = write_results(
        a.out, header, result, f"Feedback through F_c against the simulator, on {a.model}", body
    )
    print(md.read_text())


if __name__ == "__main__":
    main()
