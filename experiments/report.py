"""paper.md: what each stage of a chain made, its wall time, and the tables beside the paper's.

Read only from the finished stages' manifests and the evaluation stages' shapes.json, so the
report can be rewritten at any time without running anything.

The rod's section can also be written from loose evaluation folders (tables scored in the rod
outside a chain, e.g. with the committed chain's translators):

    python -m experiments.report --rod-table DIR --rod-aged-table DIR \
        --chain-table results/paper/rerun_2026-11-27/run/table --out rod.md

A chain's paper.md from the stages finished so far (`experiments.paper` writes it only once
every stage is done; this names the unfinished ones and leaves their tables out):

    python -m experiments.report --run DIR --config experiments/paper.json --out paper.md
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from eval.report import METHOD_NAMES, PAPER_TABLE_I, taught_section
from experiments.stages import Chain, digest, shown_command

#: The stages whose shapes.json the report reads: the D_c medium, and the aged arm.
TABLE_STAGE, AGED_TABLE_STAGE = "table", "table_aged"
#: The table of the translator distilled on the identified arm beside the privileged one.
IDENT_TABLE_STAGE = "table_ident"
ROD_IDENT_TABLE_STAGE = "rod_table_ident"
#: The same tables scored in the reference rod (`eval.shapes --simulator rod`).
ROD_TABLE_STAGE, ROD_AGED_TABLE_STAGE = "rod_table", "rod_table_aged"
#: Column names of the rod's tables: which arm each method learnt or planned on.
ROD_NAMES = {
    "ccgan": "CCGAN-GP (rod's data)",
    "wcgan": "WCGAN-GP (rod's data)",
    "ccgan_sim": "distilled (chain's)",
    "mpc": "tracker (planned in the chain)",
    "ccgan_ident": "distilled (rod's data, identified arm)",
}
#: Above this ratio of rod to chain X_err the docs must say why a translator lost it (issue text).
ROD_LOSS_FLAG = 1.5
#: Translators that need no simulator when they translate.
TRANSLATORS = ("ccgan", "ccgan_sim", "wcgan")


def _shapes(chain: Chain, name: str) -> dict | None:
    path = chain.folder(name) / "shapes.json"
    return json.loads(path.read_text()) if path.exists() else None


def _hms(seconds: float) -> str:
    minutes, s = divmod(int(round(seconds)), 60)
    return f"{minutes // 60} h {minutes % 60:02d} min {s:02d} s"


def attempts_of(chain: Chain, name: str) -> tuple[list[dict], bool]:
    """(a stage's attempts so far, whether it finished): from its stage.json when it finished,
    else from NAME.attempts.json beside its partial folder ([] when it never started)."""
    manifest = chain.manifest(name)
    if manifest is not None:
        return manifest["attempts"], True
    path = chain.attempts_path(name)
    return (json.loads(path.read_text())["attempts"] if path.exists() else []), False


def stage_lines(chain: Chain) -> list[str]:
    """The stages: what each made, where it ran, its wall time over its attempts, its command.
    A stage that has not finished is named so, with its time so far."""
    lines = [
        "| stage | what | wall time | attempts | stages at once | machine |",
        "|---|---|---|---|---|---|",
    ]
    total = 0.0
    for name, stage in chain.stages.items():
        m = chain.manifest(name)
        if m is None:
            attempts, _ = attempts_of(chain, name)
            spent = sum(a["wall_s"] or 0.0 for a in attempts)  # None: the attempt running
            total += spent
            machines = sorted({a.get("machine", "?") for a in attempts}) or ["-"]
            lines.append(
                f"| {name} | {stage.about} | not finished ({_hms(spent)} so far)"
                f" | {len(attempts)} | - | {'; '.join(machines)} |"
            )
            continue
        total += m["wall_s"]
        lines.append(
            f"| {name} | {m['about']} | {_hms(m['wall_s'])} | {len(m['attempts'])}"
            f" | up to {max(a.get('jobs', 1) for a in m['attempts'])} | {m['machine']} |"
        )
    lines += [
        "",
        f"Sum of the stages' wall times: {_hms(total)}. A stage that shared the machine with"
        " others ('stages at once' above 1) ran slower than it would alone, and the chain took"
        " less than this sum.",
        "",
        "Commands, in order (DIR is the run folder, `--out`; a stage resumed on another machine"
        " ran from another folder, which its stage.json names):",
        "",
    ]
    # From the config, not the manifests: every command then names the same run folder.
    as_run_by_hand = Chain(list(chain.stages.values()), Path("DIR"), chain.repo)
    lines += [f"- `{shown_command(as_run_by_hand, n)}`" for n in chain.stages]
    return lines


def timeline_lines(chain: Chain) -> list[str]:
    """Each stage's attempts in time: start (s after the chain's first start), wall time (s)
    and the GPU it was given; finished or not. Between calls to a lent machine the clock runs on,
    so the gaps include the packing, the return and the next call's start."""
    from datetime import datetime

    rows, starts = [], []
    for name in chain.stages:
        attempts, finished = attempts_of(chain, name)
        for a in attempts:
            if "started" not in a:  # records written before attempts kept their start
                continue
            start = datetime.fromisoformat(a["started"])
            starts.append(start)
            rows.append((start, name, a, finished))
    if not rows:
        return ["No stage has started."]
    first = min(starts)
    lines = [
        "| stage | attempt | start s | end s | wall s | GPU | finished |",
        "|---|---|---|---|---|---|---|",
    ]
    count: dict[str, int] = {}
    for start, name, a, finished in sorted(rows, key=lambda r: (r[0], r[1])):
        count[name] = count.get(name, 0) + 1
        at, wall = (start - first).total_seconds(), a["wall_s"]
        end, wall = ("running", "-") if wall is None else (f"{at + wall:.0f}", f"{wall:.0f}")
        lines.append(
            f"| {name} | {count[name]} | {at:.0f} | {end} | {wall}"
            f" | {a.get('device', '-')} | {'yes' if finished else 'not yet'} |"
        )
    return lines


#: The commands that score the five test shapes (`mjx_arm.programs.SHAPES`); no other command of
#: a chain reads them (training picks its iterates and k on babbling or shape-like programs).
SHAPE_SCORERS = ("eval.shapes",)
#: Methods that need no translator: a stage may score them on the shapes early (the table reads
#: its caches) without any translator having seen the shapes.
NO_TRANSLATOR_METHODS = ("none", "stretch", "mpc", "oracle")


def _methods_of(args: list[str]) -> list[str] | None:
    """The --methods of an eval.shapes command line (None: its default methods)."""
    if "--methods" not in args:
        return None
    rest = args[args.index("--methods") + 1 :]
    end = next((i for i, a in enumerate(rest) if a.startswith("-")), len(rest))
    return rest[:end]


def shape_use(chain: Chain) -> list[str]:
    """How the finished stages' records (their stage.json keys: module, args, inputs) used the
    five shapes; empty when they were used only for the tables and the references that need no
    translator.

    Returns one line per finding: a stage that read the outputs of a stage that scored the
    shapes without scoring them itself (a training, say), or an early stage whose outputs others
    read and which scored a translator on the shapes. A stage without a manifest is a finding
    too: its record cannot show what it read.
    """
    keys = {}
    for name in chain.stages:
        manifest = chain.manifest(name)
        if manifest is None:
            return [f"stage {name} has not finished, so its record cannot show what it read"]
        keys[name] = manifest["key"]
    scorers = {n for n, k in keys.items() if k.get("module") in SHAPE_SCORERS}
    findings = []
    for name, key in keys.items():
        read = sorted(set(key.get("inputs", {})) & scorers)
        if read and name not in scorers:
            findings.append(
                f"stage {name} ({key.get('module')}) read the outputs of {', '.join(read)},"
                " which scored the five shapes"
            )
    for name in sorted(scorers):
        readers = [n for n, k in keys.items() if name in k.get("inputs", {})]
        methods = _methods_of(list(keys[name].get("args", [])))
        translators = (
            ["its default methods"]
            if methods is None
            else [m for m in methods if m not in NO_TRANSLATOR_METHODS]
        )
        if readers and translators:
            findings.append(
                f"stage {name} scored {', '.join(translators)} on the five shapes and"
                f" {', '.join(readers)} read its outputs"
            )
    return findings


def shape_use_line(chain: Chain) -> str:
    """The report's sentence on where the five shapes were used, as the stages' records show."""
    findings = shape_use(chain)
    if not findings:
        return (
            "As the stages' records show, the five shapes were used only for the tables below"
            " (and for their references that need no translator, the tracker and the oracle,"
            " where a stage plans them early): no other stage read a stage that scored them,"
            " and every iterate was picked inside its command on other programs."
        )
    return (
        "The stages' records do not show that the five shapes were kept for the tables alone: "
        + "; ".join(findings)
        + "."
    )


def paper_lines(results: dict) -> list[str]:
    """The paper's Table I beside ours: through F_c as the paper scored, and in the simulator."""
    table = results["table"]
    ours = [m for m in ("ccgan", "wcgan", "ccgan_sim") if m in results["methods_run"]]
    head = ["shape", "paper CCGAN-GP", "paper WCGAN-GP"]
    head += [f"{METHOD_NAMES[m]}, through F_c" for m in ours if m != "ccgan_sim"]
    head += [f"{METHOD_NAMES[m]}, simulator" for m in ours]
    lines = [
        "X_err (cm) / phi_err (rad), means. The paper scored its Table I through its forward"
        " model F_c; 'through F_c' scores our commands the same way with our F_c, 'simulator'"
        " in the true D_c simulator (what every target below is judged on).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for shape, rows in table.items():
        paper = PAPER_TABLE_I.get(shape, {})
        cells = [
            f"{paper[m][0]:.2f} / {paper[m][1]:.3f}" if m in paper else "-"
            for m in ("ccgan", "wcgan")
        ]
        for m in ours:
            if m != "ccgan_sim":
                r = rows[m]
                cells.append(f"{r['fc_x_err_cm_mean']:.2f} / {r['fc_phi_err_rad_mean']:.3f}")
        for m in ours:
            r = rows[m]
            cells.append(f"{r['x_err_cm_mean']:.2f} / {r['phi_err_rad_mean']:.3f}")
        lines.append(f"| {shape} | " + " | ".join(cells) + " |")
    return lines


def _count(shapes: list[str], ok) -> str:
    passed = [s for s in shapes if ok(s)]
    missed = [s for s in shapes if s not in passed]
    verdict = f"not met (missed on {', '.join(missed)})" if missed else "met"
    return f"{len(passed)} of {len(shapes)} shapes: {verdict}"


def target_lines(results: dict, aged: dict | None) -> list[str]:
    """Each target of the chain, checked shape by shape in the simulator."""
    table, methods = results["table"], results["methods_run"]
    shapes = list(table)

    def x(m, s, t=table):
        return t[s][m]["x_err_cm_mean"]

    lines = []
    if {"ccgan", "wcgan", "none"} <= set(methods):
        lines.append(
            "- CCGAN-GP at most the paper's CCGAN-GP error: "
            + _count(shapes, lambda s: x("ccgan", s) <= PAPER_TABLE_I[s]["ccgan"][0])
        )
        lines.append(
            "- CCGAN-GP below WCGAN-GP and below untranslated: "
            + _count(shapes, lambda s: x("ccgan", s) < min(x("wcgan", s), x("none", s)))
        )
    best = min(
        (m for m in TRANSLATORS if m in methods),
        key=lambda m: sum(x(m, s) for s in shapes),
        default=None,
    )
    if best is not None:
        lines.append(
            f"- Best translator ({METHOD_NAMES[best]}, lowest X_err summed over the shapes) at"
            " most a third of the paper's error: "
            + _count(shapes, lambda s: x(best, s) <= PAPER_TABLE_I[s]["ccgan"][0] / 3)
        )
        if "oracle" in methods:
            lines.append(
                f"- {METHOD_NAMES[best]} within 1.5x the oracle over its window: "
                + _count(shapes, lambda s: table[s][best]["x_ratio_to_oracle"] <= 1.5)
            )
        if "stretch" in methods:
            ratios = [x(best, s) / x("stretch", s) for s in shapes]
            lines.append(
                f"- {METHOD_NAMES[best]} at most 0.5x stretch only: "
                + _count(shapes, lambda s: x(best, s) <= 0.5 * x("stretch", s))
                + f"; X_err ratio translator / stretch {min(ratios):.2f}-{max(ratios):.2f}"
            )
        if "mpc" in methods:
            lines.append(
                f"- {METHOD_NAMES[best]} at most 1.5x the receding-horizon tracker over the whole"
                " program (mpc: the one-step planner with 2 Gauss-Newton iterations in MuJoCo C;"
                " the distillation's teacher takes 1): "
                + _count(shapes, lambda s: x(best, s) <= 1.5 * x("mpc", s))
            )
    if aged is not None:
        aged_methods = [m for m in TRANSLATORS if m in aged["methods_run"]]
        if aged_methods and "stretch" in aged["methods_run"]:
            t = aged["table"]
            best_aged = min(aged_methods, key=lambda m: sum(x(m, s, t) for s in t))
            lines.append(
                f"- Aged arm: {METHOD_NAMES[best_aged]} at most 0.5x stretch only: "
                + _count(list(t), lambda s: x(best_aged, s, t) <= 0.5 * x("stretch", s, t))
            )
    return lines


#: The README's columns for the chain's tables: (method in shapes.json, header).
README_METHODS = (
    ("none", "untranslated"),
    ("stretch", "stretch only"),
    ("ccgan", "CCGAN-GP"),
    ("wcgan", "WCGAN-GP"),
    ("ccgan_sim", METHOD_NAMES["ccgan_sim"]),
    ("ccgan_ident", METHOD_NAMES["ccgan_ident"]),
    ("mpc", METHOD_NAMES["mpc"]),
    ("oracle", "oracle, first 2 s"),
)


def readme_tables(results: dict, names: dict[str, str] | None = None) -> list[str]:
    """The README's tables of a chain's evaluation stage (`results`: its shapes.json content).

    The first gives each method's X_err (cm) / phi_err (rad) means with its k, beside the
    paper's Table I (CCGAN-GP, cm / rad) where the arm is D_c's; the second, each error as a
    percentage of the shape's tip excursion. Methods the stage did not run are left out, so the
    aged arm's table has its three columns. `tests/test_readme.py` checks that the README holds
    these lines for the committed run. `names` overrides column headers by method (the rod's
    tables: `ROD_NAMES`).
    """
    table = results["table"]
    shapes = list(table)
    methods = [(m, (names or {}).get(m, h)) for m, h in README_METHODS if m in table[shapes[0]]]
    k = {m: table[shapes[0]][m]["k"] for m, _ in methods}
    paper = results["config"].get("target_domain", "constrained") == "constrained"
    paper = paper and not results.get("target_domain_file")  # a medium from a Domain file
    head = [f"{h} (k = {k[m]})" if m != "none" else h for m, h in methods]
    head += ["paper Table I CCGAN-GP"] if paper else []
    lines = ["| shape | " + " | ".join(head) + " |", "|---" * (len(head) + 1) + "|"]
    for shape in shapes:
        cells = [
            f"{table[shape][m]['x_err_cm_mean']:.2f} / {table[shape][m]['phi_err_rad_mean']:.3f}"
            for m, _ in methods
        ]
        if paper:
            cm, rad = PAPER_TABLE_I[shape]["ccgan"]
            cells.append(f"{cm:.2f} / {rad:.3f}")
        lines.append(f"| {shape.replace('_', ' ')} | " + " | ".join(cells) + " |")
    lines.append("")
    over_window = [m for m, _ in methods if table[shapes[0]][m].get("window_steps") is None]
    lines += [
        "| shape | tip excursion cm | " + " | ".join(h for m, h in methods if m in over_window)
        + " |",
        "|---" * (len(over_window) + 2) + "|",
    ]  # fmt: skip
    for shape in shapes:
        rows = table[shape]
        excursion = rows[over_window[0]]["target_excursion_cm"]
        cells = [f"{rows[m]['x_err_pct_of_excursion']:.1f}%" for m in over_window]
        lines.append(f"| {shape.replace('_', ' ')} | {excursion:.2f} | " + " | ".join(cells) + " |")
    return lines


def rod_lines(rod: dict, chain_results: dict | None, rod_aged: dict | None = None) -> list[str]:
    """The targets of the tables scored in the rod, shape by shape, and what going from the
    chain to the rod costs each method scored in both (X_err in the rod / in the chain)."""
    table, methods = rod["table"], rod["methods_run"]
    shapes = list(table)

    def x(m, s, t=table):
        return t[s][m]["x_err_cm_mean"]

    lines = []
    if {"ccgan", "wcgan", "none"} <= set(methods):
        lines.append(
            "- CCGAN-GP (rod's data) below WCGAN-GP (rod's data) and below untranslated: "
            + _count(shapes, lambda s: x("ccgan", s) < min(x("wcgan", s), x("none", s)))
        )
        lines.append(
            "- CCGAN-GP (rod's data) at most the paper's CCGAN-GP error: "
            + _count(shapes, lambda s: x("ccgan", s) <= PAPER_TABLE_I[s]["ccgan"][0])
        )
    if "stretch" in methods:
        for m in (m for m in ("ccgan", "ccgan_sim", "mpc") if m in methods):
            ratios = [x(m, s) / x("stretch", s) for s in shapes]
            lines.append(
                f"- {ROD_NAMES[m]} / stretch only in the rod: {min(ratios):.2f}-{max(ratios):.2f}"
            )
    if chain_results is not None:
        both = [m for m in ("none", "stretch", "ccgan_sim", "mpc") if m in methods]
        both = [m for m in both if m in chain_results["methods_run"]]
        for m in both:
            ratios = {s: x(m, s) / x(m, s, chain_results["table"]) for s in shapes}
            over = [s for s, r in ratios.items() if r > ROD_LOSS_FLAG]
            lines.append(
                f"- {METHOD_NAMES[m]}, X_err in the rod / in the chain:"
                f" {min(ratios.values()):.2f}-{max(ratios.values()):.2f}"
                + (f" (over {ROD_LOSS_FLAG}x on {', '.join(over)})" if over else "")
            )
    if rod_aged is not None and {"stretch", "ccgan_sim"} <= set(rod_aged["methods_run"]):
        t = rod_aged["table"]
        ratios = [x("ccgan_sim", s, t) / x("stretch", s, t) for s in t]
        lines.append(
            f"- Aged arm in the rod: {ROD_NAMES['ccgan_sim']} / stretch only"
            f" {min(ratios):.2f}-{max(ratios):.2f}"
        )
    return lines


def ident_lines(results: dict, intro: str | None = None, names: dict | None = None) -> list[str]:
    """The table of the translator distilled on the identified arm (ccgan_ident) beside the one
    taught in the true target (ccgan_sim, the privileged upper bound), its ratios to that one, to
    stretch only and to CCGAN-GP where they ran, and the identified values beside the truth
    (`eval.report.taught_section`). `intro` replaces the opening sentence, `names` the methods'
    names (the rod's tables)."""
    table, methods = results["table"], results["methods_run"]
    headers = dict(README_METHODS) | (names or {})
    lines = [
        intro
        or "The distilled translator taught on the arm identified from the D_c babbling alone"
        " (its teacher, iterate and k all in that arm), scored in the true D_c simulator beside"
        " the one taught in the true D_c arm. X_err (cm) / phi_err (rad), then % of the shape's"
        " excursion:",
        "",
        *readme_tables(results, names),
        "",
    ]
    if "ccgan_ident" in methods:
        for base in (b for b in ("ccgan_sim", "stretch", "ccgan") if b in methods):
            ratios = [
                rows["ccgan_ident"]["x_err_cm_mean"] / rows[base]["x_err_cm_mean"]
                for rows in table.values()
            ]
            lines.append(
                f"- {headers['ccgan_ident']} / {headers[base]}: {min(ratios):.2f}-{max(ratios):.2f}"
            )
    return lines + taught_section(results, heading=False)


#: The opening sentence of the rod's data-only table (`ROD_IDENT_TABLE_STAGE`).
ROD_IDENT_INTRO = (
    "The distilled translator built from the rod's data alone (the rod-trained CCGAN-GP, taught"
    " in the arm identified from the rod's D_c babbling, at k from the rod's step time), scored"
    " in the reference rod beside the translator taught in the chain's true D_c arm (privileged"
    " information, and the chain's model error), CCGAN-GP trained on the rod's data and stretch"
    " only at the rod's k. X_err (cm) / phi_err (rad), then % of the shape's excursion:"
)


def write(chain: Chain, config: dict, config_path: Path, out: Path | None = None) -> Path:
    """Writes `out` (default chain.out/paper.md) from the finished stages; returns its path."""
    results = _shapes(chain, TABLE_STAGE)
    aged = _shapes(chain, AGED_TABLE_STAGE)
    lines = [
        "# The chain on the soft arm, beside the paper's Table I",
        "",
        f"Config: `{config_path.name}` (digest {digest(config)}); {config.get('about', '')}",
        "",
        shape_use_line(chain),
        "",
        "## Stages",
        "",
        *stage_lines(chain),
        "",
        "## Timeline",
        "",
        *timeline_lines(chain),
    ]
    unfinished = [n for n in chain.stages if chain.manifest(n) is None]
    if unfinished:
        lines[4:4] = [
            f"**Not finished:** {', '.join(unfinished)}: their tables are not below.",
            "",
        ]
    if results is not None:
        lines += ["", "## Beside the paper", "", *paper_lines(results)]
        lines += ["", "## Targets (true D_c simulator)", "", *target_lines(results, aged)]
        lines += ["", f"Full tables: `{TABLE_STAGE}/shapes.md`"]
        if aged is not None:
            lines[-1] += f", the aged arm's `{AGED_TABLE_STAGE}/shapes.md`."
    ident, rod_ident = _shapes(chain, IDENT_TABLE_STAGE), _shapes(chain, ROD_IDENT_TABLE_STAGE)
    taught = []
    if ident is not None:
        taught += ["", "## Taught on the identified arm (data-only)", "", *ident_lines(ident)]
    if rod_ident is not None:
        heading = "## Taught on the arm identified from the rod's data (data-only, in the rod)"
        taught += ["", heading, "", *ident_lines(rod_ident, ROD_IDENT_INTRO, ROD_NAMES)]
    # Paths as the commands above name them: DIR for the run folder, wherever it ran.
    for folder in {str(chain.out.resolve()), str(chain.out.absolute())}:
        taught = [line.replace(folder, "DIR") for line in taught]
    lines += taught
    rod, rod_aged = _shapes(chain, ROD_TABLE_STAGE), _shapes(chain, ROD_AGED_TABLE_STAGE)
    if rod is not None:
        lines += ["", "## In the reference rod (the paper's simulator)", ""]
        lines += rod_section(rod, results, rod_aged)
    path = out or chain.out / "paper.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def rod_section(rod: dict, chain_results: dict | None, rod_aged: dict | None) -> list[str]:
    """The rod's tables (shapes.json contents of `eval.shapes --simulator rod`), their targets,
    and what going from the chain (`chain_results`, its table scored in the chain) costs."""
    methods = rod["methods_run"]
    gans = [n for m, n in (("ccgan", "CCGAN-GP"), ("wcgan", "WCGAN-GP")) if m in methods]
    learnt = (
        f"{' and '.join(gans)} learnt from the rod's babbling with k chosen in the rod"
        if gans
        else "no GAN trained on the rod's data is in this table"
    )
    lines = [
        "The five shapes scored in the reference Cosserat rod (`eval.shapes --simulator rod`,"
        f" float64): the rod's own D_s path is the target, stretch only's k is chosen in the"
        f" rod; {learnt}; the distilled translator and the tracker were taught or planned in the"
        " chain and run in the rod. X_err (cm) / phi_err (rad), then % of the shape's excursion:",
        "",
        *readme_tables(rod, ROD_NAMES),
        "",
        *rod_lines(rod, chain_results, rod_aged),
    ]
    if rod_aged is not None:
        lines += ["", "The aged arm in the rod:", "", *readme_tables(rod_aged, ROD_NAMES)]
    return lines


def main(argv: list[str] | None = None) -> int:
    """Writes the rod's section from loose evaluation folders (see the module docstring)."""
    parser = argparse.ArgumentParser(
        prog="python -m experiments.report",
        description="the rod's tables, targets and chain-to-rod costs, from eval.shapes folders",
    )
    parser.add_argument(
        "--run", type=Path, help="a chain's run folder: its paper.md from the finished stages"
    )
    parser.add_argument(
        "--config", type=Path, default=Path("experiments/paper.json"), help="--run's config"
    )
    parser.add_argument("--rod-table", type=Path, help="eval.shapes --simulator rod")
    parser.add_argument("--rod-aged-table", type=Path, help="the same with --target-domain aged")
    parser.add_argument("--chain-table", type=Path, help="the same shapes scored in the chain")
    parser.add_argument("--out", required=True, type=Path, help="the markdown file to write")
    args = parser.parse_args(argv)
    if args.run is not None:
        return _write_run(parser, args)
    if args.rod_table is None:
        parser.error("give --rod-table (the rod's section) or --run (a chain's paper.md)")
    loaded = {}
    for flag in ("rod_table", "rod_aged_table", "chain_table"):
        folder = getattr(args, flag)
        if folder is None:
            loaded[flag] = None
            continue
        path = folder / "shapes.json"
        if not path.is_file():
            parser.error(f"--{flag.replace('_', '-')} {folder}: no shapes.json there")
        loaded[flag] = json.loads(path.read_text())
    if loaded["rod_table"].get("simulator") != "rod":
        parser.error(f"--rod-table {args.rod_table}: not scored in the rod (--simulator rod)")
    text = "\n".join(
        ["# The five shapes in the reference rod", ""]
        + rod_section(loaded["rod_table"], loaded["chain_table"], loaded["rod_aged_table"])
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n")
    print(f"wrote {args.out}")
    return 0


def _write_run(parser: argparse.ArgumentParser, args) -> int:
    """paper.md of the run folder `args.run` from its finished stages, written to `args.out`."""
    from experiments.stages import StageError, load_config

    if not args.run.is_dir():
        parser.error(f"--run {args.run}: not a folder")
    try:
        config, stages = load_config(args.config)
    except (OSError, StageError) as err:
        parser.error(f"--config {args.config}: {err}")
    chain = Chain(stages, args.run, Path(__file__).resolve().parents[1])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    print(f"wrote {write(chain, config, args.config, args.out)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
