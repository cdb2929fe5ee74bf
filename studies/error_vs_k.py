"""Tracking error against the hold factor k: distilled translators, their teacher and stretch
only on held-out programs (split "error_vs_k", full scale; never a test shape).

A larger k lets the slow D_c arm keep up, and makes a program k times longer in D_c: a 60 s
D_s program takes 60 k / 10 s. For every k of `--ks`, this study plans the teacher
(`tracking.mpc.track`, MuJoCo C, one-step horizon) and scores in the D_c simulator:
- stretch only at k;
- each translator set of `--translators` with its commands held k periods.

A set is named by the k it was distilled at (`--translators 15=a.ckpt,b.ckpt,c.ckpt`). A set
held at another k than its own is marked so in the table: it shows how a translator taught at
one k carries to another, not what distilling at that k gives.

    python -m studies.error_vs_k --ks 10 15 20 \\
        --translators 10=studies/results/h100/issue30/distill_k10/translator_seed0.ckpt,... \\
        15=studies/results/h200/issue30/distill_k15/translator_seed0.ckpt,... 20=... \\
        --out studies/results/cpu/issue30/error_vs_k
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


def parse_sets(texts: list[str]) -> dict[int, list[str]]:
    """['K=a,b', ...] -> {K: [a, b]}: translator files by the k they were distilled at."""
    sets: dict[int, list[str]] = {}
    for text in texts:
        k_text, _, paths = text.partition("=")
        try:
            k = int(k_text)
        except ValueError:
            raise ValueError(f"a translator set is K=FILE[,FILE...], got {text!r}") from None
        files = [path for path in paths.split(",") if path]
        if k < 1 or not files or k in sets:
            raise ValueError(
                f"a translator set is K=FILE[,FILE...] with K >= 1, once each: {text!r}"
            )
        sets[k] = files
    return sets


def main(argv=None) -> None:
    p = cli_parser("studies.error_vs_k", __doc__)
    p.add_argument("--model", default="models/softarm.xml", help="the arm's MJCF")
    p.add_argument("--ks", type=int, nargs="+", default=[10, 15, 20], help="hold factors")
    p.add_argument(
        "--translators", nargs="*", default=[], help="K=FILE[,FILE...]: a set per distilled k"
    )
    p.add_argument("--n", type=int, default=8, help="held-out programs")
    p.add_argument("--duration", type=float, default=60.0, help="seconds per program")
    p.add_argument("--out", required=True, help="output prefix (writes .json, .md and .png)")
    a = parse_checked_args(p, argv)
    try:
        sets = parse_sets(a.translators)
    except ValueError as err:
        p.error(str(err))
    if min(a.ks) < 1 or a.n < 1:
        p.error("--ks and --n must be >= 1")
    arm_s = mjx_arm.load(a.model, "source")
    arm_c = mjx_arm.load(a.model, "constrained")
    try:  # a translator of another arm is refused, not scored on this one
        translators = {
            k: [load_translator(path, model_hash=arm_c.model_hash) for path in files]
            for k, files in sets.items()
        }
    except (ValueError, CheckpointError) as err:
        p.error(f"--translators: {err}")
    programs = shape_like_programs(a.n, a.duration, seed=0, split="error_vs_k", full_scale=True)
    targets = arm_s.rollout(programs, backend="c")
    # Each translator's commands, one per source step [n, T, 3] (bar).
    step_commands = {
        k_set: [
            np.stack(
                [
                    tr.translate(prog, x)[0][:: tr.k]
                    for prog, x in zip(programs, targets, strict=True)
                ]
            )
            for tr in trs
        ]
        for k_set, trs in translators.items()
    }

    def x_err(commands, k: int) -> float:
        poses = held.run_dc(arm_c, held.stretch(commands, k), k, "c")
        return float(metrics.position_error_cm(poses, targets).mean())

    rows = []
    cfg = mpc.MpcConfig(horizon_steps=1, iterations=1)
    for k in a.ks:
        teacher, _ = mpc.track(arm_c, targets, k, programs, cfg, progress=True)
        row = {
            "k": k,
            "d_c_seconds_per_program": a.duration * k,
            "stretch": x_err(programs, k),
            "teacher": x_err(teacher[:, k - 1 :: k], k),
            "translators": {},
        }
        for k_set, per_seed in step_commands.items():
            errors = [x_err(commands, k) for commands in per_seed]
            row["translators"][str(k_set)] = {"per_seed": errors, "mean": float(np.mean(errors))}
        rows.append(row)

    body = [
        f"- {a.n} held-out shape-like programs of {a.duration:g} s (split error_vs_k, full"
        " scale); X_err (cm) in the D_c simulator (MuJoCo C), mean over programs and time;"
        " teacher: one-step receding-horizon tracking, one Gauss-Newton iteration (MuJoCo C)",
        "- a translator set 'distilled at k = K' held at another k is marked (held at k):"
        " it shows how the set carries, not what distilling at that k gives",
        "",
    ]
    head = ["k", "D_c s per program", "stretch only", "teacher"]
    head += [f"distilled at k = {k_set}, mean over seeds (/ teacher, / stretch)" for k_set in sets]
    body += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        cells = [str(row["k"]), f"{row['d_c_seconds_per_program']:g}"]
        cells += [f"{row['stretch']:.3f}", f"{row['teacher']:.3f}"]
        for k_set, err in row["translators"].items():
            held_note = "" if int(k_set) == row["k"] else " (held at k)"
            cells.append(
                f"{err['mean']:.3f} ({err['mean'] / row['teacher']:.2f},"
                f" {err['mean'] / row['stretch']:.2f}){held_note}"
            )
        body.append("| " + " | ".join(cells) + " |")
    result = {"model": a.model, "n": a.n, "duration_s": a.duration, "sets": sets, "rows": rows}
    header = run_header("studies.error_vs_k", argv)
    md = write_results(a.out, header, result, "Tracking error against k", body)

    fig, ax = plt.subplots(figsize=(6, 4))
    ks = [row["k"] for row in rows]
    ax.plot(ks, [row["stretch"] for row in rows], "o-", label="stretch only")
    ax.plot(ks, [row["teacher"] for row in rows], "s-", label="teacher (tracker)")
    for k_set in sets:
        means = [row["translators"][str(k_set)]["mean"] for row in rows]
        ax.plot(ks, means, "^:", alpha=0.6, label=f"distilled at k = {k_set}, held at k")
    own = [row for row in rows if str(row["k"]) in row["translators"]]
    if own:  # each k's own translators: what distilling at that k gives
        ax.plot(
            [row["k"] for row in own],
            [row["translators"][str(row["k"])]["mean"] for row in own],
            "*-", color="black", markersize=10, label="distilled at its own k",
        )  # fmt: skip
    ax.set(xlabel="k (control periods per command)", ylabel="X_err (cm)", xticks=ks)
    ax.set_title(f"{a.n} held-out programs of {a.duration:g} s in D_c")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(md.with_suffix(".png"), dpi=110)
    print(md.read_text())


if __name__ == "__main__":
    main()
