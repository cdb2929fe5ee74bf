"""F_s and F_c in open loop over whole held-out programs, at the hold factors a translator uses.

The feedback loss and the old choice of k run F_c open loop on held commands. How far F_c drifts
from the simulator there is F_c's own error. It is not the translator's, and it belongs in F_c's
report, not in the translator tables (issue 29). For each hold factor k, the held-out D_s
programs (60 s) are held k periods:
  - in the D_c simulator from rest (MuJoCo C): the truth;
  - through F_c open loop from the rest pose (`ccgan.models.forward_open_loop`).
The report gives the X_err at every k-th pose (what a translator is scored on) and over every
period. F_s on the same programs at k = 1, against the D_s simulator, is the reference.

    python -m studies.forward_open_loop --study-dir studies/results/h100/ccgan_study \\
        --hold-factors 1 10 15 20 --out studies/results/cpu

Held-out programs only; the five shapes are never used.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import mjx_arm
from ccgan import checkpoint
from ccgan import data as data_lib
from ccgan.forward import ForwardConfig
from ccgan.models import forward_open_loop
from mjx_arm.machine import cpu_model
from studies.checks import parse_checked_args
from studies.study_folder import load_study_folder
from tracking import held, metrics


def open_loop_cm(model, params, commands_bar, bounds, pose0) -> np.ndarray:
    """F's open-loop poses (m, unit d3) for commands [N, T, 3] (bar) from pose0 [6] (m)."""
    p = jnp.asarray(data_lib.normalise_pressure(commands_bar), jnp.float32)
    x0 = jnp.asarray(data_lib.normalise_pose(pose0, bounds), jnp.float32)
    x0 = jnp.broadcast_to(x0, (p.shape[0], x0.shape[-1]))
    pred = jax.jit(lambda p, x0: forward_open_loop(model, params, p, x0))(p, x0)
    return data_lib.denormalise_pose(np.asarray(pred, np.float64), bounds)


def row(model: str, k: int, kept_cm: np.ndarray, every_cm: np.ndarray) -> dict:
    """One line of the report: X_err (cm) at the kept poses and over every period."""
    return {
        "model": model,
        "k": k,
        "kept_cm": float(kept_cm.mean()),
        "every_period_cm": float(every_cm.mean()),
        "max_cm": float(every_cm.max()),
    }


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m studies.forward_open_loop", description=__doc__)
    p.add_argument("--study-dir", required=True, help="babble/ and forward/ (ccgan_study.sh)")
    p.add_argument("--hold-factors", type=int, nargs="+", default=[1, 10, 15, 20])
    p.add_argument("--model", default="models/softarm.xml")
    p.add_argument("--out", required=True)
    a = parse_checked_args(p, argv)
    study = load_study_folder(a.study_dir, a.model)
    folder, arm_s, arm_c, bounds, n_val = (
        study.folder,
        study.arm_s,
        study.arm_c,
        study.bounds,
        study.n_val,
    )
    programs, target_s = study.heldout_programs_bar, study.heldout_poses_s
    params = {}
    for name in ("forward_s", "forward_c"):
        params[name], meta = checkpoint.load(folder / "forward" / f"{name}.ckpt")
    fconf = ForwardConfig(**meta["config"])
    model = fconf.model

    start = time.perf_counter()
    rows = []
    pred_s = open_loop_cm(model, params["forward_s"], programs, bounds, arm_s.rest_pose())
    err_s = metrics.position_error_cm(pred_s, target_s)
    rows.append(row("F_s", 1, err_s, err_s))
    for k in a.hold_factors:
        commands = held.stretch(programs, k)
        truth = arm_c.rollout(commands, backend="c")
        pred = open_loop_cm(model, params["forward_c"], commands, bounds, arm_c.rest_pose())
        every = metrics.position_error_cm(pred, truth)
        kept = metrics.position_error_cm(held.every_kth(pred, k), held.every_kth(truth, k))
        rows.append(row("F_c", k, kept, every))
        print(rows[-1], flush=True)
    wall = time.perf_counter() - start
    forward_metrics = json.loads((folder / "forward" / "forward_metrics.json").read_text())
    summary = {
        "command": "python -m studies.forward_open_loop "
        + shlex.join(sys.argv[1:] if argv is None else argv),
        "machine": f"{cpu_model()} ({jax.devices()[0].device_kind})",
        "wall_time_s": wall,
        "forward_config": dataclasses.asdict(fconf),
        "n_programs": n_val,
        "seconds_per_program": programs.shape[1] / mjx_arm.CONTROL_HZ,
        "rows": rows,
        "forward_metrics": forward_metrics,
    }
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "forward_open_loop.json").write_text(json.dumps(summary, indent=2) + "\n")
    lines = [
        "# F_s and F_c in open loop over held-out programs",
        "",
        f"Command: `{summary['command']}`. Machine: {summary['machine']}; {wall:.0f} s.",
        f"Forward models and data: `{folder}` (the paper-scale babbling, 50 + 3 programs of 60 s"
        f" per domain). Programs: the {n_val} held-out D_s programs of"
        f" {summary['seconds_per_program']:g} s, each command held k periods from rest; truth:"
        " the simulator (MuJoCo C).",
        "",
        "| model | k | X_err at every k-th pose (cm) | over every period (cm) | largest (cm) |",
        "|---|---|---|---|---|",
    ]
    lines += [
        f"| {r['model']} | {r['k']} | {r['kept_cm']:.2f} | {r['every_period_cm']:.2f} |"
        f" {r['max_cm']:.2f} |"
        for r in rows
    ]
    lines += [
        "",
        "F_c's own metric at training (`forward_metrics.json`, held-out D_c babbling at k = 1):"
        f" open loop {forward_metrics['forward_c']['open_loop_cm']:.2f} cm, one step"
        f" {forward_metrics['forward_c']['one_step_cm']:.3f} cm.",
        "",
    ]
    (out / "forward_open_loop.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
