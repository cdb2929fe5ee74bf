"""PNG figures of the shape evaluation (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from eval.methods import METHOD_NAMES  # noqa: E402
from mjx_arm.constants import CONTROL_HZ  # noqa: E402

CM = 100.0
COLORS = {
    "target": "tab:blue",
    "none": "maroon",
    "stretch": "tab:orange",
    "ccgan": "tab:green",
    "ccgan_sim": "tab:purple",
    "ccgan_range": "tab:brown",
    "wcgan": "tab:red",
    "mpc": "tab:gray",
    "oracle": "black",
}
#: Legend and panel labels: each method's one name (`eval.methods.METHOD_NAMES`).
LABELS = {"target": "target (D_s)", **METHOD_NAMES}


def save(fig, path: Path, mark: str | None = None) -> None:
    """Lays out, marks and writes a figure, then closes it.

    A run that is not the main job's (`eval.report.run_mark`) carries `mark` in red across the
    figure and in the PNG's "Comment" text, so none of its figures can pass for a committed one.
    """
    fig.tight_layout()
    metadata = None
    if mark:
        fig.text(
            0.5,
            0.5,
            mark,
            ha="center",
            va="center",
            rotation=15,
            fontsize=28,
            color="red",
            alpha=0.45,
            weight="bold",
            wrap=True,
        )
        metadata = {"Comment": mark}
    fig.savefig(path, dpi=90, metadata=metadata)
    plt.close(fig)


def _xy(ax, poses, key, **kw):
    ax.plot(poses[:, 0] * CM, poses[:, 1] * CM, color=COLORS.get(key), label=LABELS.get(key), **kw)


def paths_figure(shape: str, traj: dict, path: Path, mark: str | None = None) -> None:
    """XY paths (left) and X, Y, Z against time (right) of the target and every method.

    Args:
      traj: {"target": [T, 6], "poses": {method: [T, 6]}} (m).
      mark: see `save`.
    """
    fig = plt.figure(figsize=(12, 4.5))
    ax = fig.add_subplot(1, 2, 1)
    _xy(ax, traj["target"], "target", lw=2.5)
    for m, poses in traj["poses"].items():
        _xy(ax, poses, m, lw=1.2, ls="--" if m == "oracle" else "-")
    ax.set(xlabel="x (cm)", ylabel="y (cm)", title=f"{shape}: XY path", aspect="equal")
    ax.legend(fontsize=8)
    t = np.arange(traj["target"].shape[0]) / CONTROL_HZ
    for i, name in enumerate("xyz"):
        axi = fig.add_subplot(3, 2, 2 * (i + 1))
        axi.plot(t, traj["target"][:, i] * CM, color=COLORS["target"], lw=2)
        for m, poses in traj["poses"].items():
            axi.plot(t[: poses.shape[0]], poses[:, i] * CM, color=COLORS.get(m), lw=1)
        axi.set_ylabel(f"{name} (cm)")
        if i == 2:
            axi.set_xlabel("source time (s)")
    save(fig, path, mark)


def error_bars_figure(table: dict, methods: list[str], path: Path, mark: str | None = None) -> None:
    """Grouped bars of mean X_err and phi_err (± std) per shape and method."""
    shapes = list(table)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    width = 0.8 / max(1, len(methods))
    for j, (key, unit) in enumerate((("x_err_cm", "X_err (cm)"), ("phi_err_rad", "phi_err (rad)"))):
        ax = axes[j]
        for i, m in enumerate(methods):
            mean = [table[s][m][f"{key}_mean"] if m in table[s] else np.nan for s in shapes]
            std = [table[s][m][f"{key}_std"] if m in table[s] else np.nan for s in shapes]
            x = np.arange(len(shapes)) + (i - (len(methods) - 1) / 2) * width
            label = LABELS.get(m)
            window = [table[s][m].get("window_steps") for s in shapes if m in table[s]]
            if m == "oracle" and window and window[0]:
                # The oracle optimises only the start of each program; the others span all of it.
                label = f"{label} (first {window[0] / CONTROL_HZ:g} s only)"
            ax.bar(x, mean, width, yerr=std, color=COLORS.get(m), label=label, capsize=2)
        ax.set_xticks(np.arange(len(shapes)), shapes, rotation=20)
        ax.set_ylabel(unit)
        ax.legend(fontsize=8)
    save(fig, path, mark)


def noise_figure(trajectories: dict, results: dict, path: Path, mark: str | None = None) -> None:
    """Per shape: XY paths of the first robustness method under each noise level (seed 0)."""
    shapes = [s for s in trajectories if "noise" in trajectories[s]]
    fig, axes = plt.subplots(2, max(1, len(shapes)), figsize=(3.6 * max(1, len(shapes)), 7))
    axes = np.asarray(axes).reshape(2, -1)
    markers = ["o", "+", "*", "x", "s"]
    for j, s in enumerate(shapes):
        traj = trajectories[s]
        method = next(iter(traj["noise"]))
        ax = axes[0, j]
        _xy(ax, traj["target"], "target", lw=2)
        for i, (std, poses) in enumerate(traj["noise"][method].items()):
            ax.plot(poses[:, 0] * CM, poses[:, 1] * CM, markers[i % 5], ms=2, label=f"std {std}")
        ax.set(title=f"{s} ({LABELS.get(method)})", xlabel="x (cm)", ylabel="y (cm)")
        ax.legend(fontsize=7)
        res = results["noise"][s]
        ax = axes[1, j]
        for m, per_std in res.items():
            stds = [float(k) for k in per_std]
            ax.errorbar(
                stds,
                [v["x_err_cm_mean"] for v in per_std.values()],
                yerr=[v["x_err_cm_std"] for v in per_std.values()],
                color=COLORS.get(m),
                label=LABELS.get(m),
                marker="o",
                capsize=2,
            )
        ax.set(xlabel="noise std (normalised)", ylabel="X_err (cm)")
        ax.legend(fontsize=7)
    save(fig, path, mark)


def periodicity_figure(trajectories: dict, path: Path, mark: str | None = None) -> None:
    """Per shape: XY paths of each repetition from rest (first robustness method)."""
    shapes = [s for s in trajectories if "repeats" in trajectories[s]]
    fig, axes = plt.subplots(1, max(1, len(shapes)), figsize=(3.6 * max(1, len(shapes)), 3.8))
    axes = np.atleast_1d(axes)
    for j, s in enumerate(shapes):
        traj = trajectories[s]
        method = next(iter(traj["repeats"]))
        ax = axes[j]
        _xy(ax, traj["target"], "target", lw=2)
        for r, poses in enumerate(traj["repeats"][method]):
            ax.plot(poses[:, 0] * CM, poses[:, 1] * CM, lw=0.8, label=f"run {r + 1}")
        ax.set(title=f"{s} ({LABELS.get(method)})", xlabel="x (cm)", ylabel="y (cm)")
        ax.legend(fontsize=7)
    save(fig, path, mark)


def write_all(
    trajectories: dict, results: dict, out_dir: Path, mark: str | None = None
) -> list[str]:
    """Writes every figure under out_dir, each marked with `mark` (see `save`); returns their
    file names."""
    out_dir = Path(out_dir)
    names = []
    for shape, traj in trajectories.items():
        name = f"shape_{shape}.png"
        paths_figure(shape, traj, out_dir / name, mark)
        names.append(name)
    error_bars_figure(results["table"], results["methods_run"], out_dir / "errors.png", mark)
    names.append("errors.png")
    if results["noise"]:
        noise_figure(trajectories, results, out_dir / "noise.png", mark)
        names.append("noise.png")
    if results["periodicity"]:
        periodicity_figure(trajectories, out_dir / "periodicity.png", mark)
        names.append("periodicity.png")
    return names
