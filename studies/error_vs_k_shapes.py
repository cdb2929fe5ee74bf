"""Tracking error against the hold factor k, on the held-out programs and on the five shapes:
for each k, stretch only, the teacher and the translator distilled at that k.

Nothing is simulated here. Each k brings two finished runs:
- a distillation folder (`ccgan.distill --out`), found in the results of `studies.distill_runs`
  (`--distill-runs`): the 16 held-out 60 s programs' X_err of the kept iterate per seed, of its
  teacher (the one-step tracker in MJX) and of stretch only at that k;
- an `eval.shapes` folder run with `--hold-factors K --methods stretch ccgan_sim mpc
  --ccgan-sim-path <that distillation's translator.ckpt>`: the five shapes at that k, the
  tracker (`mpc`, MuJoCo C) standing for the teacher.

Both are checked to be at that k (a table at the wrong k is refused, not mixed in).

    python -m studies.error_vs_k_shapes \\
        --distill-runs studies/results/cpu/issue30/distill_runs.json \\
        --runs 10=studies/results/h100/issue30/distill_k10:SHAPES/k10 15=...:... 20=...:... \\
        --out studies/results/cpu/issue30/error_vs_k_shapes
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bench import run_header, write_results  # noqa: E402
from ccgan.cli import cli_parser  # noqa: E402
from studies.checks import parse_checked_args

#: The methods an `eval.shapes` table must hold, by the names this study gives them.
SHAPE_METHODS = {"stretch": "stretch only", "mpc": "teacher (tracker)", "ccgan_sim": "distilled"}


def parse_runs(texts: list[str]) -> dict[int, tuple[Path, Path]]:
    """['K=DISTILL_DIR:SHAPES_DIR', ...] -> {K: (distill folder, eval.shapes folder)}."""
    runs: dict[int, tuple[Path, Path]] = {}
    for text in texts:
        k_text, _, dirs = text.partition("=")
        distill_dir, _, shapes_dir = dirs.partition(":")
        try:
            k = int(k_text)
        except ValueError:
            raise ValueError(f"a run is K=DISTILL_DIR:SHAPES_DIR, got {text!r}") from None
        if k < 1 or not distill_dir or not shapes_dir or k in runs:
            raise ValueError(f"a run is K=DISTILL_DIR:SHAPES_DIR with K >= 1, once each: {text!r}")
        runs[k] = (Path(distill_dir), Path(shapes_dir))
    return runs


def held_out_row(k: int, distill_dir: Path, distill_runs: dict) -> dict:
    """The held-out X_err (cm) of one distillation at k, as `studies.distill_runs` put it: per
    seed, its teacher, stretch only (recorded by the run, or simulated by that study for runs
    made before distill.json recorded it).

    Raises:
        ValueError: the run is not in that study, or is at another k.
    """
    rows = [r for r in distill_runs["rows"] if Path(r["run"]) == distill_dir]
    if len(rows) != 1 or rows[0]["k"] != k:
        raise ValueError(f"{distill_dir}: not a distillation at k = {k} in --distill-runs")
    row = rows[0]
    return {
        "per_seed": [float(x) for x in row["seeds_cm"]],
        "mean": float(np.mean(row["seeds_cm"])),
        "teacher": float(row["teacher_cm"]),
        "stretch": float(row["stretch_cm"]),
    }


def shapes_rows(k: int, shapes_dir: Path) -> dict:
    """{shape: {method: X_err cm}} of one eval.shapes table at k (stretch, mpc, ccgan_sim).

    Raises:
        ValueError: a method is missing, or stretch or the translator is held another k.
    """
    result = json.loads((shapes_dir / "shapes.json").read_text())
    rows = {}
    for shape, methods in result["table"].items():
        missing = [m for m in SHAPE_METHODS if m not in methods]
        if missing:
            raise ValueError(f"{shapes_dir}: {shape} has no {missing}")
        wrong_k = [m for m in SHAPE_METHODS if methods[m]["k"] != k]
        if wrong_k:
            raise ValueError(f"{shapes_dir}: {wrong_k} of {shape} not held k = {k} periods")
        rows[shape] = {m: float(methods[m]["x_err_cm_mean"]) for m in SHAPE_METHODS}
    return rows


def main(argv=None) -> None:
    p = cli_parser("studies.error_vs_k_shapes", __doc__)
    p.add_argument("--runs", nargs="+", required=True, help="K=DISTILL_DIR:SHAPES_DIR per k")
    p.add_argument(
        "--distill-runs", required=True, help="studies.distill_runs' JSON holding every run"
    )
    p.add_argument("--out", required=True, help="output prefix (writes .json, .md and .png)")
    a = parse_checked_args(p, argv)
    try:
        runs = parse_runs(a.runs)
        distill_runs = json.loads(Path(a.distill_runs).read_text())
        held = {k: held_out_row(k, d, distill_runs) for k, (d, _) in sorted(runs.items())}
        shapes = {k: shapes_rows(k, s) for k, (_, s) in sorted(runs.items())}
    except (ValueError, OSError, KeyError) as err:
        p.error(str(err))
    ks = sorted(runs)
    names = list(next(iter(shapes.values())))

    body = [
        "",
        "Held-out: the 16 programs of 60 s that picked each distillation's iterate"
        " (studies.distill_runs; teacher: one-step tracker in MJX). Shapes: the five shapes"
        " over 60 s (eval.shapes at that k; teacher: the table's tracker, MuJoCo C). X_err in"
        " cm in the D_c simulator; the translator's figure is the mean over its 3 seeds.",
        "",
        "| k | D_c s per 60 s program | held-out: stretch only | teacher | distilled (seeds)"
        " | / teacher | / stretch | shapes, mean: stretch only | tracker | distilled"
        " | / tracker | / stretch |",
        "|" + "---|" * 12,
    ]
    shape_means = {
        k: {m: float(np.mean([shapes[k][s][m] for s in names])) for m in SHAPE_METHODS} for k in ks
    }
    for k in ks:
        h, mean = held[k], shape_means[k]
        seeds = " / ".join(f"{x:.3f}" for x in h["per_seed"])
        body.append(
            f"| {k} | {60 * k} | {h['stretch']:.3f} | {h['teacher']:.4f} | {h['mean']:.3f}"
            f" ({seeds}) | {h['mean'] / h['teacher']:.2f} | {h['mean'] / h['stretch']:.2f}"
            f" | {mean['stretch']:.3f} | {mean['mpc']:.3f} | {mean['ccgan_sim']:.3f}"
            f" | {mean['ccgan_sim'] / mean['mpc']:.2f}"
            f" | {mean['ccgan_sim'] / mean['stretch']:.2f} |"
        )
    body += [
        "",
        "Per shape, X_err (cm): stretch only / tracker / distilled (distilled / stretch).",
        "",
    ]
    body += ["| shape | " + " | ".join(f"k = {k}" for k in ks) + " |", "|" + "---|" * (len(ks) + 1)]
    for shape in names:
        cells = []
        for k in ks:
            r = shapes[k][shape]
            cells.append(
                f"{r['stretch']:.3f} / {r['mpc']:.3f} / {r['ccgan_sim']:.3f}"
                f" ({r['ccgan_sim'] / r['stretch']:.2f})"
            )
        body.append(f"| {shape} | " + " | ".join(cells) + " |")
    header = run_header("studies.error_vs_k_shapes", argv)
    result = {
        "runs": {str(k): [str(d), str(s)] for k, (d, s) in runs.items()},
        "held_out": {str(k): held[k] for k in ks},
        "shapes": {str(k): shapes[k] for k in ks},
    }
    md = write_results(a.out, header, result, "Tracking error against k: held out and shapes", body)

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    left.plot(ks, [held[k]["stretch"] for k in ks], "o-", label="stretch only")
    left.plot(ks, [held[k]["teacher"] for k in ks], "s-", label="teacher (MJX tracker)")
    left.plot(ks, [held[k]["mean"] for k in ks], "*-", markersize=10, label="distilled at k")
    left.set_title("16 held-out programs of 60 s")
    for m, label in SHAPE_METHODS.items():
        means = [shape_means[k][m] for k in ks]
        right.plot(ks, means, {"stretch": "o-", "mpc": "s-", "ccgan_sim": "*-"}[m], label=label)
    right.set_title("the five shapes, mean")
    for ax in (left, right):
        ax.set(xlabel="k (control periods per command)", xticks=ks, yscale="log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    left.set_ylabel("X_err in D_c (cm)")
    fig.tight_layout()
    fig.savefig(md.with_suffix(".png"), dpi=110)
    print(md.read_text())


if __name__ == "__main__":
    main()
