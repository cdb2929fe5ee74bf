"""The report of a `ccgan.tune` study: `tune.md`, `tune.json` and `tune_history.png`.

`summary` turns a stored study into a JSON-able dict; `write_report` writes it as a markdown
table by trial and by structure, beside the optimisation history as a plot.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import optuna

from ccgan.sim_choice import describe_programs
from ccgan.tune_study import STRUCTURAL, TUNED


def _fmt(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def summary(study: optuna.Study, extra: dict) -> dict:
    """The study as a JSON-able dict: best trial, every trial, and `extra` (machine, command...)."""
    trials = []
    for t in study.trials:
        trials.append(
            {
                "number": t.number,
                "state": t.state.name,
                "value_cm": t.value,
                "params": t.params,
                **{
                    n: t.user_attrs.get(n)
                    for n in ("batch", "batch_wall_s", "k", "epoch", "stretch_only_cm", "errors_cm")
                },
            }
        )
    done = [t for t in study.trials if t.value is not None]
    best = None
    if done:
        b = study.best_trial
        best = {
            "number": b.number,
            "value_cm": b.value,
            "params": b.params,
            "k": b.user_attrs.get("k"),
            "stretch_only_cm": b.user_attrs.get("stretch_only_cm"),
        }
    return extra | {"study_name": study.study_name, "best": best, "trials": trials}


def _plot_history(done: list[dict], study_name: str, path: Path) -> None:
    """The trials' values and the best so far, beside stretch only at each trial's k."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    if done:
        x = [t["number"] for t in done]
        y = [t["value_cm"] for t in done]
        ax.plot(x, y, "o", label="trial (D_c simulator, its k)")
        ax.step(x, np.minimum.accumulate(y), where="post", label="best so far")
        ax.plot(
            x, [t["stretch_only_cm"] for t in done], "x", c="grey", label="stretch only, same k"
        )
    ax.set_xlabel("trial")
    ax.set_ylabel("held-out tracking error (cm)")
    ax.set_title(f"Optuna TPE: {study_name}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def structure_lines(trials: list[dict]) -> list[str]:
    """A table of the trials by structure: count, pruned, best and median value, k chosen.

    A pruned trial's value is the last one it reported (Optuna's rule)."""
    groups: dict[tuple, list[dict]] = {}
    for t in trials:
        if all(n in t["params"] for n in STRUCTURAL):
            groups.setdefault(tuple(t["params"][n] for n in STRUCTURAL), []).append(t)
    lines = [
        "| " + " | ".join(STRUCTURAL) + " | trials | pruned | best (cm) | median (cm) | k chosen |",
        "|" + "---|" * (len(STRUCTURAL) + 5),
    ]
    for key, ts in groups.items():
        values = [t["value_cm"] for t in ts if t["value_cm"] is not None]
        ks = {}
        for t in ts:
            ks[t["k"]] = ks.get(t["k"], 0) + 1
        cells = [
            str(len(ts)),
            str(sum(t["state"] == "PRUNED" for t in ts)),
            f"{min(values):.3f}" if values else "",
            f"{np.median(values):.3f}" if values else "",
            ", ".join(f"{k}: {n}" for k, n in sorted(ks.items(), key=lambda kv: str(kv[0]))),
        ]
        lines.append("| " + " | ".join(map(str, key)) + " | " + " | ".join(cells) + " |")
    return [*lines, ""]


def write_report(summ: dict, report_dir: str | Path, note: str = "") -> dict[str, Path]:
    """Writes tune.md, tune.json and tune_history.png; returns their paths."""
    out = Path(report_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        k: out / f"tune{s}" for k, s in (("md", ".md"), ("json", ".json"), ("png", "_history.png"))
    }
    paths["json"].write_text(json.dumps(summ | {"note": note}, indent=2) + "\n")

    done = [t for t in summ["trials"] if t["value_cm"] is not None]
    try:
        _plot_history(done, summ["study_name"], paths["png"])
    except ImportError:  # a GPU image without matplotlib: the tables still get written
        paths.pop("png")

    base = summ["base_config"]
    lines = [f"# CCGAN-GP study: {summ['study_name']}", ""]
    if note:
        lines += [note, ""]
    n_pruned = sum(t["state"] == "PRUNED" for t in summ["trials"])
    lines += [
        f"- Command: `{summ['command']}`",
        f"- Machine: {summ['machine']} ({summ['device_kind']})",
        f"- This run: {summ['new_trials']} trials in {summ['wall_time_s']:.0f} s wall time"
        f" ({summ['wall_time_s'] / 60:.1f} min of this machine); study:"
        f" {len(summ['trials'])} trials"
        f" ({n_pruned} pruned) in `{summ['storage']}`",
        f"- Budget per trial: {base['epochs']} epochs, seed {summ['seed']}; scored and pruned"
        f" every {base['stretch_every']} epochs",
        f"- Objective: mean X_err (cm) of {describe_programs(base)}, translated by G_c and"
        " held k periods from rest in the D_c simulator, at the k of"
        f" {tuple(base['hold_factors'])} that scores best"
        " (`ccgan.sim_choice`). Stretch only: the untranslated programs at that k.",
        f"- Sampler: TPE, seed {summ['seed']} (+ trials already stored), one structure per batch"
        " of trials; median pruner",
        "",
    ]
    lines += structure_lines(summ["trials"])
    if summ["best"]:
        b = summ["best"]
        lines += [
            f"Best: trial {b['number']}, {b['value_cm']:.3f} cm at k = {b['k']}"
            f" (stretch only at that k: {b['stretch_only_cm']:.3f} cm)",
            "",
            "| parameter | value |",
            "|---|---|",
        ]
        lines += [f"| {n} | {_fmt(b['params'][n])} |" for n in TUNED]
        lines += [""]
    head = ["trial", "state", "error (cm)", "k", "stretch only (cm)", *TUNED, "batch"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for t in summ["trials"]:
        row = [
            str(t["number"]),
            t["state"],
            "" if t["value_cm"] is None else f"{t['value_cm']:.3f}",
            str(t["k"]),
            "" if t["stretch_only_cm"] is None else f"{t['stretch_only_cm']:.3f}",
            *(_fmt(t["params"].get(n, "")) for n in TUNED),
            str(t["batch"]),
        ]
        lines.append("| " + " | ".join(row) + " |")
    if "png" in paths:
        lines += ["", f"![optimisation history]({paths['png'].name})"]
    lines += [""]
    paths["md"].write_text("\n".join(lines))
    return paths
