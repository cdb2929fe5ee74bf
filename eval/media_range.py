"""Error against the medium: a conditioned translator and stretch only over a range of media.

`python -m eval.media_range` scores a conditioned translator (`ccgan.distill_range`, one file
per seed) in the true simulator of each medium: the chain of --model in medium (r, s)
(`mjx_arm.media`), MuJoCo C, as `eval.shapes` scores its table. Per medium:

- k: the translator's rule (k = 0.526 t63, t63 from the step-time model its file records) and,
  beside it, the k the medium's own step time, measured here in MuJoCo C, gives (the rule's
  k on a real arm, from one step test);
- X_err (cm, mean over the programs and their steps) of each seed's commands, held its k;
- stretch only: the D_s program held the same k (the rule's k is stretch only's best on the 14
  media `studies.k_by_medium` measured, to its grid of 5);
- optionally per-medium translators (`--reference R S FILE`: a translator of one pair, e.g. the
  chain's distilled D_c one at 10 1), each at its own k, the mean of its seeds' files
  (translator_seed<s>.ckpt beside FILE) where there are.

The programs are `--programs shape_like` (default: `--n-programs` shape-like programs of a
stream no translator is taught on, "media_range/test") or `shapes` (the paper's five test shapes,
to be scored once, at the end). Each medium's role (training, held out, or neither) is read
from the translator's file. Writes PREFIX.json, PREFIX.md (the table) and PREFIX.png (X_err and
k against r). `--merge A.json B.json --out PREFIX` writes one table of runs that scored
different media (e.g. in two processes, each pinned to a core).

    python -m eval.media_range --translators DIR/translator_seed{0,1,2}.ckpt --out PREFIX \\
        [--media 10 1 10 0.7 ...] [--programs shapes --duration 60] \\
        [--reference 10 1 results/paper/rerun_2026-11-27/run/ccgan_sim/translator.ckpt]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

import mjx_arm
from ccgan.checkpoint import CheckpointError
from ccgan.cli import HelpFormatter
from ccgan.distill_range.media import medium_arm
from ccgan.media_range import MEDIA_RANGE, k_from_step_time
from ccgan.translator import Translator, load_translator
from mjx_arm import constants, media, programs
from mjx_arm.atomic import write_atomically
from mjx_arm.machine import cpu_model
from tracking.held import run_dc, stretch
from tracking.metrics import position_error_cm

#: The random stream of the scored shape-like programs: no teacher draws from it.
TEST_SPLIT = "media_range/test"
#: Drag ratios labelled on the plots' axes (those inside the scored media's span).
RATIO_TICKS = (1, 2, 3, 4, 5, 7, 10, 15, 20, 30, 50)
#: Relative distance at which a scored medium is the file's training or held-out medium.
SAME_MEDIUM = 1e-6


def role(translator: Translator, drag_ratio: float, stiffness_scale: float) -> str:
    """ "training", "held out" or "other": what the translator's file says of medium (r, s)."""

    def among(listed) -> bool:
        return any(
            math.isclose(r, drag_ratio, rel_tol=SAME_MEDIUM)
            and math.isclose(s, stiffness_scale, rel_tol=SAME_MEDIUM)
            for r, s in listed
        )

    if among(translator.media.training_media):
        return "training"
    return "held out" if among(translator.media.held_out_media) else "other"


def scored_programs(kind: str, n: int, duration_s: float) -> tuple[list[str], np.ndarray]:
    """(names, programs [P, T, 3] bar): `n` shape-like programs of `TEST_SPLIT`, or the five
    test shapes ("shapes")."""
    if kind == "shapes":
        names = list(programs.SHAPES)
        return names, np.stack([programs.SHAPES[name](duration_s) for name in names])
    chosen = programs.shape_like_programs(n, duration_s, seed=0, split=TEST_SPLIT)
    return [f"shape_like_{i}" for i in range(n)], chosen.astype(np.float64)


def x_err_cm(arm, commands_c: np.ndarray, k: int, targets: np.ndarray) -> np.ndarray:
    """X_err (cm) [P] of held commands [P, T k, 3] (bar) in `arm` (MuJoCo C) against the D_s
    targets [P, T, 6], each the mean over its steps."""
    return position_error_cm(run_dc(arm, commands_c, k, "c"), targets).mean(-1)


def score_media(
    translators: list[Translator],
    arm_c,
    media_list: list[tuple[float, float]],
    pressures_s: np.ndarray,
    targets: np.ndarray,
    references: list[tuple[float, float, str, Translator]] = (),
    log=print,
) -> list[dict]:
    """The table's rows: each medium of `media_list` scored in its own arm (MuJoCo C).

    Args:
      translators: a conditioned translator per seed (the same range and rule).
      arm_c: the D_c arm of the chain they were taught on (its MJCF; `medium_arm`).
      media_list: (r, s) pairs inside the translators' range.
      pressures_s: [P, T, 3] D_s programs (bar); targets: [P, T, 6] their D_s poses.
      references: (r, s, label, translator of one pair, or a list of its seeds' translators)
        scored at that medium at its own k (a list: the mean over its seeds, per program).

    Returns:
      per medium {"r", "s", "role", "t63_fit_s", "t63_measured_s", "k", "k_measured",
      "x_err_cm": {"conditioned" [seeds] (mean over programs), "conditioned_mean",
      "stretch", references' labels...}, "per_program_cm": {the same, [P] or [seeds, P]}}.
    """
    rule = translators[0].media
    rows = []
    for r, s in media_list:
        t0 = time.perf_counter()
        arm = medium_arm(arm_c, r, s)
        t63_measured = media.step_t63_s(arm, media.step_hold_s(r, s))
        k = rule.hold_factor(r, s)
        conditioned = []
        for translator in translators:
            commands = [
                translator.translate(p, x, target=(r, s))
                for p, x in zip(pressures_s, targets, strict=True)
            ]
            if any(c_k != k for _, c_k in commands):
                raise ValueError("the seeds' files disagree on the rule's k")
            conditioned.append(x_err_cm(arm, np.stack([c for c, _ in commands]), k, targets))
        per_program = {
            "conditioned": np.stack(conditioned),
            "stretch": x_err_cm(arm, stretch(pressures_s, k), k, targets),
        }
        for r_ref, s_ref, label, reference in references:
            if math.isclose(r_ref, r) and math.isclose(s_ref, s):
                members = list(reference) if isinstance(reference, (list, tuple)) else [reference]
                errors = []
                for member in members:  # its seeds' files, or one file
                    held = [
                        member.translate(p, x) for p, x in zip(pressures_s, targets, strict=True)
                    ]
                    commands = np.stack([c for c, _ in held])
                    errors.append(x_err_cm(arm, commands, member.k, targets))
                per_program[label] = np.mean(errors, axis=0)
        means = {name: float(v.mean()) for name, v in per_program.items()}
        means["conditioned"] = per_program["conditioned"].mean(-1).tolist()
        means["conditioned_mean"] = float(per_program["conditioned"].mean())
        rows.append(
            {
                "r": float(r),
                "s": float(s),
                "role": role(translators[0], r, s),
                "t63_fit_s": rule.step_time.t63_s(r, s),
                "t63_measured_s": t63_measured,
                "k": k,
                "k_measured": k_from_step_time(t63_measured, rule.k_grid),
                "x_err_cm": means,
                "per_program_cm": {name: v.tolist() for name, v in per_program.items()},
            }
        )
        log(
            f"r={r:g} s={s:g} ({rows[-1]['role']}): k {k}, X_err conditioned"
            f" {means['conditioned_mean']:.3f} cm, stretch {means['stretch']:.3f} cm"
            f" ({time.perf_counter() - t0:.0f} s)"
        )
    return rows


def table_lines(rows: list[dict], reference_labels: list[str]) -> list[str]:
    """The markdown table of `score_media`'s rows."""
    refs = "".join(f" {label} |" for label in reference_labels)
    ratio = " conditioned / per-medium |" if reference_labels else ""
    lines = [
        "| r | s | role | t63 s (fit / measured) | k (rule / from measured t63) |"
        " conditioned X_err cm (seeds) | stretch only X_err cm | conditioned / stretch |"
        + refs
        + ratio,
        "|---|---|---|---|---|---|---|---|" + "---|" * (len(reference_labels) + bool(ratio)),
    ]
    for row in rows:
        e = row["x_err_cm"]
        seeds = ", ".join(f"{v:.3f}" for v in e["conditioned"])
        ref_cells = "".join(
            f" {e[label]:.3f} |" if label in e else " - |" for label in reference_labels
        )
        if ratio:
            here = [e[label] for label in reference_labels if label in e]
            ref_cells += f" {e['conditioned_mean'] / min(here):.2f} |" if here else " - |"
        lines.append(
            f"| {row['r']:.3g} | {row['s']:.3g} | {row['role']} |"
            f" {row['t63_fit_s']:.1f} / {row['t63_measured_s']:.1f} |"
            f" {row['k']} / {row['k_measured']} | {e['conditioned_mean']:.3f} ({seeds}) |"
            f" {e['stretch']:.3f} | {e['conditioned_mean'] / e['stretch']:.2f} |{ref_cells}"
        )
    return lines


#: The X_err entries of a row that are not per-medium translators.
OWN_ENTRIES = ("conditioned", "conditioned_mean", "stretch")


def reference_labels(row: dict) -> list[str]:
    """The per-medium translators scored at a row's medium (its X_err entries beyond
    `OWN_ENTRIES`)."""
    return [label for label in row["x_err_cm"] if label not in OWN_ENTRIES]


def plot(rows: list[dict], path: Path) -> None:
    """X_err (conditioned: filled, stretch only: open, per-medium translators: crosses) and k
    against r, coloured by s, squares for training media and circles for the others (PNG at
    `path`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    fig, (ax_e, ax_k) = plt.subplots(1, 2, figsize=(10, 3.8))
    stiffness = [row["s"] for row in rows]
    low, high = min(stiffness), max(stiffness)
    colour = plt.get_cmap("viridis")
    ratios = [row["r"] for row in rows]
    ticks = [t for t in RATIO_TICKS if min(ratios) / 1.2 <= t <= max(ratios) * 1.2]
    for row in rows:
        c = colour(0.5 if high == low else (row["s"] - low) / (high - low))
        marker = "s" if row["role"] == "training" else "o"
        ax_e.plot(row["r"], row["x_err_cm"]["conditioned_mean"], marker, color=c)
        ax_e.plot(row["r"], row["x_err_cm"]["stretch"], marker, mfc="none", color=c)
        for label in reference_labels(row):
            ax_e.plot(row["r"], row["x_err_cm"][label], "x", color=c, markersize=8)
        ax_k.plot(row["r"], row["k"], marker, color=c)
    ax_e.set_title("X_err (cm), MuJoCo C")
    ax_k.set_title("k (the rule, 0.526 t63)")
    for ax in (ax_e, ax_k):
        ax.set_xscale("log")
        ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
        ax.minorticks_off()
        ax.set_xlabel("drag ratio r (source = 1, paper's D_c = 10)")
        ax.grid(alpha=0.3)
    grey = dict(color="grey", linestyle="none")
    ax_e.legend(
        handles=[
            Line2D([], [], marker="o", label="conditioned", **grey),
            Line2D([], [], marker="o", mfc="none", label="stretch only", **grey),
            Line2D([], [], marker="s", label="training medium", **grey),
            *(
                [Line2D([], [], marker="x", label="per-medium translator", **grey)]
                if any(reference_labels(row) for row in rows)
                else []
            ),
        ],
        fontsize=8,
    )
    sm = plt.cm.ScalarMappable(cmap=colour, norm=plt.Normalize(low, high))
    fig.colorbar(sm, ax=ax_k, label="stiffness scale s")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m eval.media_range",
        description=__doc__.strip().splitlines()[0],
        formatter_class=HelpFormatter,
    )
    p.add_argument("--translators", nargs="+", help="conditioned translator files, one per seed")
    p.add_argument(
        "--merge",
        nargs="+",
        metavar="JSON",
        help="instead of scoring: one table, plot and json of these runs' PREFIX.json (media"
        " scored in separate processes), which must share translators, programs and range",
    )
    p.add_argument("--out", required=True, help="output prefix (writes .json, .md and .png)")
    p.add_argument("--model", default=str(constants.TRANSLATOR_MODEL_PATH), help="the chain's MJCF")
    p.add_argument(
        "--media",
        type=float,
        nargs="+",
        help="media to score as r s pairs, flat (default: the file's held-out and training media)",
    )
    p.add_argument(
        "--programs",
        choices=("shape_like", "shapes"),
        default="shape_like",
        help="held-out shape-like programs, or the five test shapes (once, at the end)",
    )
    p.add_argument("--n-programs", type=int, default=8, help="shape-like programs per medium")
    p.add_argument("--duration", type=float, default=60.0, help="program length (s)")
    p.add_argument(
        "--reference",
        nargs=3,
        action="append",
        default=[],
        metavar=("R", "S", "FILE"),
        help="a per-medium translator (of one pair) scored at medium (R, S); repeat for more",
    )
    return p


def main(argv: list[str] | None = None) -> None:
    """CLI (the module doc)."""
    p = build_parser()
    a = p.parse_args(argv)
    if a.merge:
        if a.translators:
            p.error("--merge writes a table of earlier runs: give no --translators")
        try:
            parts = [json.loads(Path(path).read_text()) for path in a.merge]
            merged = merge_results(parts, a.merge)
        except (OSError, ValueError, KeyError) as err:
            p.error(f"--merge: {err}")
        write_outputs(Path(a.out), merged)
        return
    if not a.translators:
        p.error("--translators is required (or --merge)")
    if a.n_programs < 1 or not a.duration > 0:
        p.error(f"--n-programs >= 1 and --duration > 0, got {a.n_programs}, {a.duration}")
    try:
        translators = [
            load_translator(path, method="distill_range", target_domain=MEDIA_RANGE)
            for path in a.translators
        ]
        references = []
        for r, s, f in a.reference:
            # Its seeds' files beside it (translator_seed<s>.ckpt), as eval.shapes reads them.
            files = sorted(Path(f).parent.glob("translator_seed*.ckpt")) or [Path(f)]
            seeds = [load_translator(file, source_domain="source") for file in files]
            name = Path(f).parent.name or f
            label = f"per-medium {name} (k {seeds[0].k}, {len(seeds)} seed{'s' * (len(seeds) > 1)})"
            references.append((float(r), float(s), label, seeds))
    except (CheckpointError, ValueError) as err:
        p.error(str(err))
    if any(t.media != translators[0].media for t in translators):
        p.error("--translators record different ranges: give the seeds of one run")
    if any(t.conditioned for *_, seeds in references for t in seeds):
        p.error("--reference takes translators of one pair, not conditioned ones")
    rule = translators[0].media
    if a.media is None:
        media_list = list(rule.held_out_media) + list(rule.training_media)
    elif len(a.media) % 2:
        p.error("--media takes r s pairs")
    else:
        media_list = list(zip(a.media[::2], a.media[1::2], strict=True))
    for r, s in media_list:
        try:
            rule.check(r, s)
        except ValueError as err:
            p.error(f"--media: {err}")
    arm_s, arm_c = (mjx_arm.load(a.model, domain=d) for d in ("source", "constrained"))
    names, pressures_s = scored_programs(a.programs, a.n_programs, a.duration)
    targets = arm_s.rollout(pressures_s, backend="c")
    t0 = time.perf_counter()
    rows = score_media(translators, arm_c, media_list, pressures_s, targets, references)
    import jax

    header = {
        "machine": f"{cpu_model()}; JAX device: {jax.devices()[0].platform}",
        "command": "python -m eval.media_range " + " ".join(sys.argv[1:] if argv is None else argv),
    }
    result = header | {
        "translators": a.translators,
        "model": a.model,
        "programs": names,
        "programs_kind": a.programs,
        "duration_s": a.duration,
        "media_range": rule.to_dict(),
        "rows": rows,
        "wall_s": time.perf_counter() - t0,
    }
    write_outputs(Path(a.out), result)


#: What every part of a merge must share (`merge_results`).
SHARED_KEYS = ("translators", "model", "programs", "duration_s", "media_range")


def write_outputs(out: Path, result: dict) -> None:
    """PREFIX.json (`result`), PREFIX.md (the table) and PREFIX.png (`plot`) at prefix `out`."""
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = result["rows"]
    labels = list(dict.fromkeys(label for row in rows for label in reference_labels(row)))
    header = {key: result[key] for key in ("machine", "command", "merged_from") if key in result}
    lines = [
        f"# Error against the medium: {len(result['translators'])} seeds of a conditioned"
        " translator",
        "",
        *(f"- {key}: {value}" for key, value in header.items()),
        "",
        f"X_err (cm, MuJoCo C, the chain of {result['model']} in each medium) over"
        f" {len(result['programs'])} {result.get('programs_kind', 'shape_like')} programs of"
        f" {result['duration_s']:g} s; every method holds the rule's k (stretch only's too;"
        " references their own k).",
        "",
        *table_lines(rows, labels),
        "",
        f"Wall time {result['wall_s']:.0f} s.",
    ]
    data = json.dumps(result, indent=2).encode()
    write_atomically(out.with_suffix(".json"), lambda f: f.write(data))
    text = ("\n".join(lines) + "\n").encode()
    write_atomically(out.with_suffix(".md"), lambda f: f.write(text))
    plot(rows, out.with_suffix(".png"))
    print("\n".join(lines))


def merge_results(parts: list[dict], paths: list[str]) -> dict:
    """One result of several runs' (`--merge`: media scored in separate processes or machines),
    their rows in the order given; the wall time is the sum of theirs.

    Raises:
      ValueError: the parts differ in translators, model, programs, length or range, or score
        a medium twice.
    """
    first = parts[0]
    for path, part in zip(paths[1:], parts[1:], strict=True):
        differ = [key for key in SHARED_KEYS if part.get(key) != first.get(key)]
        if differ:
            raise ValueError(f"{path} differs from {paths[0]} in {', '.join(differ)}")
    rows = [row for part in parts for row in part["rows"]]
    media_seen = [(row["r"], row["s"]) for row in rows]
    twice = sorted({m for m in media_seen if media_seen.count(m) > 1})
    if twice:
        raise ValueError(f"media scored in more than one part: {twice}")
    machines = sorted({part["machine"] for part in parts})
    return {key: first[key] for key in SHARED_KEYS} | {
        "machine": "; ".join(machines),
        "command": " ; ".join(part["command"] for part in parts),
        "merged_from": ", ".join(paths),
        "programs_kind": first.get("programs_kind", "shape_like"),
        "rows": rows,
        "wall_s": float(sum(part["wall_s"] for part in parts)),
    }


if __name__ == "__main__":
    main()
