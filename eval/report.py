"""The evaluation's report: shapes.md from the results dictionary (shapes.json's content).

`markdown_report` is a pure function of that dictionary, so every committed results/**/shapes.md
can be regenerated from its shapes.json; older files lack some keys (the arm, the quick-run mark,
the oracle's settings) and render as they did. Errors are X_err (cm) and phi_err (rad), see
`tracking.metrics`; k is control periods per source step.
"""

from __future__ import annotations

from eval.methods import METHOD_NAMES
from eval.rod import scored_in

#: The paper's Table I: {shape: {method: (X_err cm, phi_err rad)}}, scored through its F_c.
PAPER_TABLE_I = {
    "circle": {"ccgan": (2.98, 0.276), "wcgan": (7.14, 0.636)},
    "rectangle": {"ccgan": (1.56, 0.126), "wcgan": (6.82, 0.631)},
    "damped_circle": {"ccgan": (1.19, 0.101), "wcgan": (8.78, 0.83)},
    "ellipse": {"ccgan": (1.56, 0.126), "wcgan": (7.22, 0.717)},
    "kite": {"ccgan": (2.37, 0.19), "wcgan": (9.02, 0.81)},
}


def _paper_ccgan_line() -> str:
    return ", ".join(
        f"{shape.replace('_', ' ')} {row['ccgan'][0]:.2f}/{row['ccgan'][1]:g}"
        for shape, row in PAPER_TABLE_I.items()
    )


def target_name(results: dict) -> str:
    """The D_c the table was scored in, as a name: "identified (Domain file)" where a file gave it
    (shapes.json's "target_domain_file"), else the config's target_domain ("constrained" in
    older files, which do not record it)."""
    record = results.get("target_domain_file")
    if record:
        return f"{(record.get('domain') or {}).get('name', 'identified')} (Domain file)"
    return results["config"].get("target_domain", "constrained")


def target_file_line(results: dict) -> str | None:
    """The header's line on the Domain file D_c was read from (`eval.target.
    target_file_record`): its path, sha256, the identification method where it has one, the
    Domain fields it sets and the D_c arm's physical values; None without one."""
    record = results.get("target_domain_file")
    if not record:
        return None
    how = f", fitted by {record['method']}" if record.get("method") else ""
    fields = ", ".join(f"{k} {v}" for k, v in (record.get("domain") or {}).items() if k != "name")
    values = record.get("values") or {}
    physical = ", ".join(f"{k} {v:.5g}" for k, v in values.items() if isinstance(v, int | float))
    return (
        f"- D_c read from the Domain file `{record['path']}` (sha256"
        f" {str(record['sha256'])[:16]}{how}): {fields}; the D_c arm's physical values:"
        f" {physical} (viscosity over the source medium's)"
    )


def run_mark(config: dict) -> str | None:
    """The words marking a quick run's plots, videos and report (None for other runs).

    Args:
      config: `dataclasses.asdict` of the EvalConfig (shapes.json's "config"); older files
        have no "quick" and are not marked.
    """
    if not config.get("quick"):
        return None
    return (
        f"QUICK RUN: {config['duration_s']:g} s programs, seeds {list(config['seeds'])}"
        " - not the main job's results"
    )


def _k_errors(results: dict) -> str:
    errors = results["stretch_validation_x_err_cm"]
    return ", ".join(f"k={k}: {v:.3f}" for k, v in errors.items())


def _pair_table(caption: str, table: dict, methods: list, keys: tuple[str, str], digits: int):
    """Markdown lines of a shape x method table whose cells are two row fields, 'a / b'."""
    lines = ["", caption, "", "| shape | " + " | ".join(methods) + " |"]
    lines.append("|---|" + "---|" * len(methods))
    for shape, rows in table.items():
        cells = [
            f"{rows[m][keys[0]]:.{digits}f} / {rows[m][keys[1]]:.{digits}f}"
            if keys[0] in rows.get(m, {})
            else "-"
            for m in methods
        ]
        lines.append(f"| {shape} | " + " | ".join(cells) + " |")
    return lines


#: Each learned translator and the methods its findings compare it with: the baseline WCGAN-GP
#: only against the simple methods, CCGAN-GP against its distilled version once (from that side).
FINDINGS_BASES = {
    "ccgan": ("none", "stretch", "wcgan", "mpc"),
    "ccgan_sim": ("none", "stretch", "ccgan", "wcgan", "mpc"),
    "wcgan": ("none", "stretch"),
    "ccgan_ident": ("none", "stretch", "ccgan_sim", "mpc"),
    "ccgan_range": ("none", "stretch", "ccgan_sim", "mpc"),
}


def _span(values) -> str:
    lo, hi = min(values), max(values)
    return f"{lo:.2f}" if f"{lo:.2f}" == f"{hi:.2f}" else f"{lo:.2f}-{hi:.2f}"


def findings(results: dict) -> list[str]:
    """Plain statements computed from the results: each learned translator against each other
    method (on how many shapes its mean X_err is lower, and the X_err ratio), how many shapes it
    tracks within 1.5x the oracle, and what the largest noise level does to each method.

    Returns:
      Markdown bullet lines (empty when there is nothing to compare).
    """
    table, methods = results["table"], results["methods_run"]
    names = list(table)
    out = []
    for m, bases in FINDINGS_BASES.items():
        if m not in methods:
            continue
        for base in (b for b in bases if b in methods):
            ratios = [table[s][m]["x_err_cm_mean"] / table[s][base]["x_err_cm_mean"] for s in names]
            lower = [s for s, r in zip(names, ratios, strict=True) if r < 1.0]
            out.append(
                f"- {METHOD_NAMES[m]} against {METHOD_NAMES[base]}: lower mean X_err on"
                f" {len(lower)} of {len(names)} shapes ({', '.join(lower) or 'no shape'});"
                f" X_err ratio {METHOD_NAMES[m]} / {METHOD_NAMES[base]} {_span(ratios)}."
            )
        if "oracle" in methods:
            ratios = [table[s][m]["x_ratio_to_oracle"] for s in names]
            within = [s for s, r in zip(names, ratios, strict=True) if r <= 1.5]
            out.append(
                f"- {METHOD_NAMES[m]} within 1.5x the oracle's X_err (over the oracle's window) on"
                f" {len(within)} of {len(names)} shapes ({', '.join(within) or 'no shape'});"
                f" ratio {_span(ratios)}."
            )
    noise = results.get("noise") or {}
    if noise:
        first = next(iter(noise.values()))
        top = max(next(iter(first.values())), key=float)
        for m in first:
            clean = [table[s][m]["x_err_cm_mean"] for s in noise]
            noisy = [noise[s][m][top]["x_err_cm_mean"] for s in noise]
            out.append(
                f"- Largest noise (std {top}), {METHOD_NAMES[m]}: mean X_err {min(clean):.3f}-"
                f"{max(clean):.3f} cm clean -> {min(noisy):.3f}-{max(noisy):.3f} cm"
                f" ({_span([n / c for n, c in zip(noisy, clean, strict=True)])}x)."
            )
    return out


def markdown_report(results: dict) -> str:
    """The results as markdown: a Table-I-like table, then the robustness tests.

    Every length in it comes from results["config"]; the arm's file and the quick-run mark are
    stated when results has them (older shapes.json files have neither and render as before).
    """
    lines = _header(results) + _main_table(results) + _excursion_table(results)
    lines += taught_section(results)
    lines += _fc_table(results)
    lines += _oracle_table(results)
    found = findings(results)
    if found:
        lines += ["", "## Findings", "", *found]
    lines += _noise_section(results) + _periodicity_section(results) + _files_section(results)
    lines += ["", "## Timings (s)", ""] + [f"- {k}: {v:.1f}" for k, v in results["timings"].items()]
    return "\n".join(lines) + "\n"


def _header(results: dict) -> list[str]:
    """Title, quick-run mark, and the run's facts: command, machine, arm, wall time, stretch k,
    notes."""
    config = results["config"]
    mark = run_mark(config)
    where = (
        "scored in the reference rod" if results.get("simulator") == "rod" else "simulator-scored"
    )
    lines = [f"# Trajectory tracking in D_c ({where})", ""]
    if mark:
        lines += [f"**{mark}** (`--quick`: a smoke test of the pipeline).", ""]
    lines += [
        f"- command: `{results['command']}`",
        f"- machine: {results['machine']}",
        *filter(None, [scored_in(results)]),
        f"- simulator backend: {results['backend']}; model hash {results['model_hash']};"
        f" domains: source -> {target_name(results)}",
        *filter(None, [target_file_line(results)]),
    ]
    if "model" in results:
        lines.append(
            f"- arm: `{results['model']['file']}`, {results['model']['note']}; programs"
            f" {config['duration_s']:g} s per shape, seeds {list(config['seeds'])}"
        )
    lines += [
        f"- wall time: {results['wall_time_s']:.1f} s",
        f"- stretch k = {results['stretch_k']}, chosen by lowest mean X_err on a"
        f" {config['validation_duration_s']:g} s validation"
        f" program over k in {list(results['stretch_validation_x_err_cm'])}"
        f" (X_err cm: {_k_errors(results)})",
    ]
    lines += [f"- NOTE: {n}" for n in results["notes"]]
    return lines


def _main_table(results: dict) -> list[str]:
    """The simulator-scored table: shape x method cells "X_err ± std / phi_err ± std (k=k)"."""
    table, methods = results["table"], results["methods_run"]
    lines = [
        "",
        "X_err (cm) / phi_err (rad), mean ± std over all samples (and seeds, where a method is"
        " stochastic or has one trained model per seed). k = control periods per source step."
        f" Paper Table I (CCGAN-GP, through F_c): {_paper_ccgan_line()}.",
        "",
        "| shape | " + " | ".join(methods) + " |",
        "|---|" + "---|" * len(methods),
    ]
    for shape, rows in table.items():
        cells = []
        for m in methods:
            r = rows.get(m)
            if r is None:
                cells.append("-")
                continue
            cell = (
                f"{r['x_err_cm_mean']:.3f} ± {r['x_err_cm_std']:.3f} /"
                f" {r['phi_err_rad_mean']:.3f} ± {r['phi_err_rad_std']:.3f} (k={r['k']})"
            )
            cells.append(cell)
        lines.append(f"| {shape} | " + " | ".join(cells) + " |")
    return lines


#: The physical values an identified arm is set beside the truth by (`mjx_arm.domains.
#: physical_values`), with what each is.
TAUGHT_FIELDS = {
    "viscosity_scale": "medium viscosity / the source medium's",
    "stiffness_scale": "joint stiffness factor",
    "mass_scale": "mass factor",
}


def taught_section(results: dict, heading: bool = True) -> list[str]:
    """The translators taught on an identified arm (shapes.json's "taught_domains", written by
    `eval.methods.taught_domains`): what each was taught on, the identified values beside the
    truth of the target the table was scored in, and which distilled translator is privileged;
    under its own heading unless `heading` is False (a report that has one). Empty for runs
    without one."""
    taught = results.get("taught_domains") or {}
    if not taught:
        return []
    target = target_name(results)
    rod = results.get("simulator") == "rod"
    lines = ["", "## Taught on the identified arm (data-only)"] if heading else []
    lines.append("")
    for method, record in taught.items():
        how = f" by {record['method']}" if record.get("method") else ""
        lines += [
            f'{method} ("{METHOD_NAMES.get(method, method)}") was distilled on an arm'
            f" identified from the target's data{how} (`{record['path']}`, sha256"
            f" {str(record['sha256'])[:16]}): its teacher planned and its iterate was picked in"
            " that arm, at the k it holds (chosen there, or set by its stage's --hold-factor), and"
            " it is scored here in the true target like every method."
            + (
                f' ccgan_sim ("{METHOD_NAMES["ccgan_sim"]}") was taught in the true target'
                " itself: the privileged upper bound."
                if "ccgan_sim" in results["methods_run"]
                else ""
            ),
            "",
            (
                f"| value | identified | the chain's {target} arm (the rod holds no such value)"
                " | difference |"
                if rod
                else f"| value | identified | truth ({target}) | error |"
            ),
            "|---|---|---|---|",
        ]
        for name, what in TAUGHT_FIELDS.items():
            value, truth = record["values"].get(name), record["truth"].get(name)
            if value is None or truth is None:
                continue
            error = record.get("error_pct", {}).get(name)
            shown = "-" if error is None else f"{error:+.3f}%"
            lines.append(f"| {name} ({what}) | {value:.5g} | {truth:.5g} | {shown} |")
        lines.append("")
    return lines[:-1]


def _excursion_table(results: dict) -> list[str]:
    """Mean X_err as a percentage of each shape's tip excursion (older files: none)."""
    table, methods = results["table"], results["methods_run"]
    first = next(iter(table.values()), {})
    if not any("target_excursion_cm" in row for row in first.values()):
        return []
    lines = [
        "",
        "Mean X_err as % of the shape's tip excursion (the RMS distance of the target tip from"
        " rest, cm, in the second column).",
        "",
        "| shape | excursion cm | " + " | ".join(methods) + " |",
        "|---|---|" + "---|" * len(methods),
    ]
    for shape, rows in table.items():
        excursion = next(iter(rows.values()))["target_excursion_cm"]
        cells = [f"{rows[m]['x_err_pct_of_excursion']:.1f}" if m in rows else "-" for m in methods]
        lines.append(f"| {shape} | {excursion:.2f} | " + " | ".join(cells) + " |")
    return lines


def _fc_table(results: dict) -> list[str]:
    """The same commands scored through the CCGAN-GP checkpoint's F_c (none when no method was)."""
    table, methods = results["table"], results["methods_run"]
    scored = [
        m for m in methods if any("fc_x_err_cm_mean" in rows.get(m, {}) for rows in table.values())
    ]
    if not scored:
        return []
    return _pair_table(
        "The same D_c commands scored through the CCGAN-GP checkpoint's forward model F_c"
        " (open loop from rest, every k-th pose), as the paper scored its Table I:"
        " X_err (cm) / phi_err (rad), means.",
        table,
        scored,
        ("fc_x_err_cm_mean", "fc_phi_err_rad_mean"),
        digits=3,
    )


def _oracle_table(results: dict) -> list[str]:
    """Each method's error ratios to the oracle's over the oracle's window, with how the oracle
    was run (held or free commands, its start, Adam steps and loss in cm^2) where recorded."""
    table, methods, config = results["table"], results["methods_run"], results["config"]
    if "oracle" not in methods:
        return []
    oracle_cfg = config.get("oracle", {})
    held = oracle_cfg.get("held", False)
    loss_first = [row["oracle"].get("oracle_loss_first") for row in table.values()]
    loss_best = [row["oracle"].get("oracle_loss_best") for row in table.values()]
    effort = ""
    if "steps" in oracle_cfg and None not in loss_first + loss_best:
        effort = (
            f" It started from the {oracle_cfg.get('init', 'stretch')} commands and ran"
            f" {oracle_cfg['steps']} Adam steps (lr {oracle_cfg['learning_rate']});"
            f" its loss fell from {min(loss_first):.4f}-{max(loss_first):.4f} to"
            f" {min(loss_best):.4f}-{max(loss_best):.4f} (cm^2), so a longer optimisation"
            " may lower it further and raise every ratio."
        )
    if oracle_cfg.get("substeps"):
        effort += (
            f" Adam differentiated through a copy of the arm with {oracle_cfg['substeps']}"
            " physics steps per control period (its loss picked the iterate); the errors"
            " above are those of its commands in the arm itself."
        )
    return _pair_table(
        "Ratio to the oracle (mean X_err / oracle mean X_err; mean phi_err / oracle's),"
        " over the window the oracle optimised; the oracle's commands were "
        + (
            "held k periods per source step, like every translator's."
            if held
            else "free in every control period."
        )
        + effort,
        table,
        methods,
        ("x_ratio_to_oracle", "phi_ratio_to_oracle"),
        digits=2,
    )


def _noise_section(results: dict) -> list[str]:
    """The noise test: shape x method rows, one "X_err / phi_err" cell per noise std."""
    if not results["noise"]:
        return []
    lines = [
        "",
        "## Noise test",
        "",
        "Gaussian noise (std on pressure / 3.5 bar, clipped to [0, 1]) on the source pressures"
        " before the method; X_err (cm) / phi_err (rad) against the clean target.",
        "",
    ]
    stds = list(next(iter(next(iter(results["noise"].values())).values())))
    lines += ["| shape | method | " + " | ".join(f"std {s}" for s in stds) + " |"]
    lines += ["|---|---|" + "---|" * len(stds)]
    for shape, per_method in results["noise"].items():
        for m, res in per_method.items():
            cells = [
                f"{res[s]['x_err_cm_mean']:.3f} / {res[s]['phi_err_rad_mean']:.3f}" for s in stds
            ]
            lines.append(f"| {shape} | {m} | " + " | ".join(cells) + " |")
    return lines


def _periodicity_section(results: dict) -> list[str]:
    """The periodicity test: the repetitions' tip spread (cm) and X_err per shape and method."""
    if not results["periodicity"]:
        return []
    lines = [
        "",
        "## Periodicity test",
        "",
        "Each shape run repeatedly from rest (translators re-sampled with seeds 0..R-1);"
        " spread = RMS distance of the repetitions' tips from their mean (cm).",
        "",
        "| shape | method | spread mean (cm) | spread max (cm) | X_err (cm) |",
        "|---|---|---|---|---|",
    ]
    for shape, per_method in results["periodicity"].items():
        for m, r in per_method.items():
            lines.append(
                f"| {shape} | {m} | {r['spread_cm_mean']:.2e} | {r['spread_cm_max']:.2e} |"
                f" {r['x_err_cm_mean']:.3f} |"
            )
    return lines


def _files_section(results: dict) -> list[str]:
    """The figures and videos written, with what the video panels show."""
    lines = []
    if results.get("figures"):
        lines += ["", "## Figures", ""] + [f"- `{f}`" for f in results["figures"]]
    if results.get("videos"):
        lines += [
            "",
            "## Videos",
            "",
            "Panels left to right: D_s arm (source program), D_c arm under the translation, D_c arm"
            " untranslated. Green: the D_s target tip path; red: the panel's own tip path.",
            "",
        ] + [f"- `{v}`" for v in results["videos"]]
    return lines
