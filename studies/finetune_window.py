"""Tracking error of translator folders on the five shapes: first 2 s from rest and whole 60 s.

Shows what simulator fine-tuning (`ccgan.finetune`) changes where its gradient reaches (the
first `window` seconds from rest) and after it. For each folder, each trained seed's translator
(translator_seed{s}.ckpt) runs every shape in the MuJoCo C simulator of D_c; X_err (cm) is
averaged over seeds.

    python -m studies.finetune_window results/solid/translators/ccgan \\
        results/solid/translators/ccgan_sim --out runs/finetune_window

(The committed table also read the fine-tune stage folders of commit a2573cb.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import mjx_arm
from bench import run_header, write_results
from ccgan import load_translator
from ccgan.cli import cli_parser
from mjx_arm.programs import CONTROL_HZ, SHAPES
from tracking import held, metrics


def main(argv=None) -> None:
    p = cli_parser("studies.finetune_window", __doc__)
    p.add_argument("folders", nargs="+", help="folders with translator_seed{s}.ckpt")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--window", type=float, default=2.0, help="seconds from rest")
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = p.parse_args(argv)
    arm_s, arm_c = mjx_arm.load(domain="source"), mjx_arm.load(domain="constrained")
    head = int(round(a.window * CONTROL_HZ))
    translators = {
        folder: [load_translator(Path(folder) / f"translator_seed{s}.ckpt") for s in a.seeds]
        for folder in a.folders
    }
    rows = {}
    for name, fn in SHAPES.items():
        program = fn(60.0)
        target = arm_s.rollout(program, backend="c")
        rows[name] = {}
        for folder in a.folders:
            jobs = [tr.translate(program, target) for tr in translators[folder]]
            poses = held.rollout_grouped(arm_c, jobs, "c")
            err = np.stack([metrics.position_error_cm(x, target) for x in poses])
            rows[name][folder] = {
                "x_err_cm_window": float(err[:, :head].mean()),
                "x_err_cm_60s": float(err.mean()),
            }
    header = run_header("studies.finetune_window", argv)
    result = {"window_s": a.window, "seeds": a.seeds, "rows": rows}
    lines = ["", "| shape | " + " | ".join(a.folders) + " |", "|---" * (len(a.folders) + 1) + "|"]
    for name, r in rows.items():
        cells = [f"{r[f]['x_err_cm_window']:.4f} / {r[f]['x_err_cm_60s']:.4f}" for f in a.folders]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    title = f"Translators: X_err (cm), first {a.window:g} s from rest / whole 60 s"
    write_results(a.out, header, result, title, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
