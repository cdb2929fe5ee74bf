"""Identification beyond the paper's pair of domains (issue 50, 3(c) and 3(d)): can
`mjx_arm.identify` find a medium off the paper's pair, and how much of the chain's error against
the reference rod does it remove?

Cases (each run by ``--case``; every run rewrites the table from all the case folders in --out):

- ``half_drag`` and ``double_drag``: the chain in a medium of half and twice D_c's drag. D_c is
  ``Domain(viscosity_scale=None)``, the model's fitted scale (20.117 on models/softarm.xml, the
  source medium's drag times the scale that maps the rod's 10x damping), so the two media are
  ``viscosity_scale`` = 0.5 and 2 times that number, stiffness 1. Their babbling is made here in
  MuJoCo C (own program streams, not D_c's) and written with the Domain's values in its metadata,
  so identify.md sets the truth beside the fit. The fit starts from D_c itself (20.117, 1): the
  truth is then half and twice the start, inside the search grid [start / 3, start x 3].
- ``aged``: the aged arm (D_c's medium, stiffness x0.7) the same way, from the same start.
- ``rod``: the reference rod in D_c (`--rod-data`, a ``python -m mjx_arm.babble --backend rod``
  folder) as the truth. The chain's family does not contain it, so there is no truth column;
  instead the held-out tip RMS against the rod of three chain arms on the same held-out
  programs: the nominal start (viscosity x10 the source's, stiffness 1, the paper's), the chain's
  committed D_c (20.117, 1) and the fitted arm.
- ``rod_k``: stretch only's k on eval's validation program (`mjx_arm.programs.validation_program`,
  20 s; `tracking.held.choose_stretch_k`, as `eval.shapes` picks it) in the rod (float64), in the
  committed D_c and in each identified arm of the rod cases already in --out (MuJoCo C): whether
  an arm identified from the rod's babbling chooses the rod's k. Writes OUT/rod_k/rod_k.json.

    python -m studies.identify_targets --out studies/results/cpu/identify --case half_drag
    python -m studies.identify_targets --out studies/results/cpu/identify_50 --case aged --n 50 \\
        --duration 60
    python -m studies.identify_targets --out studies/results/cpu/identify --case rod \\
        --rod-data /work/rod_data_gpu/babble --rod-n-programs 10

Writes OUT/<case>/ (the rod's as OUT/rod_<N>/, N its training programs): babble/ for the
media, and `mjx_arm.identify`'s report identify.json and identify.md; then OUT/targets.{md,json}:
one row per case and method. Never a test shape.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from bench import run_header, write_results
from mjx_arm import arm as arm_lib
from mjx_arm import babble, dataset, domains, identify, identify_cli, identify_family
from studies.checks import parse_checked_args

#: Each custom medium: (its viscosity as a factor on D_c's, its stiffness scale). "aged" is the
#: built-in aged arm (D_c's medium, stiffness x0.7), babbled here in its own program stream.
MEDIA = {"half_drag": (0.5, 1.0), "double_drag": (2.0, 1.0), "aged": (1.0, 0.7)}
CASES = (*MEDIA, "rod", "rod_k")
#: Hold factors the rod_k case compares: eval's stretch only candidates around D_c's best.
K_CANDIDATES = (10, 15, 20, 25)
#: The rod case starts from the paper's nominal medium: ten times the source's viscosity.
NOMINAL_VISCOSITY_SCALE = 10.0
#: The babbling seed of the custom media (their streams are named after the case).
SEED = 0


def dc_viscosity_scale(model: str | None = None) -> float:
    """D_c's viscosity as a factor on the source medium's (the model's fitted scale; 20.117 on
    the committed MJCF): what ``Domain(viscosity_scale=None)`` resolves to."""
    constrained = arm_lib.load(model, domain="constrained").mj_model
    source = arm_lib.load(model, domain="source").mj_model
    return domains.physical_values(constrained, source, domains.CONSTRAINED)["viscosity_scale"]


def medium_domain(case: str, model: str | None = None) -> domains.Domain:
    """The Domain of a custom medium case: `MEDIA`[case]'s factor times D_c's viscosity, and its
    stiffness scale."""
    viscosity_factor, stiffness = MEDIA[case]
    return domains.Domain(
        name=case,
        viscosity_scale=viscosity_factor * dc_viscosity_scale(model),
        stiffness_scale=stiffness,
    )


def babble_medium(
    domain: domains.Domain, n_train: int, n_val: int, duration_s: float, model: str | None = None
) -> dict[str, dataset.Dataset]:
    """Babbling of the chain in `domain` (MuJoCo C): {"<name>_train.npz", "<name>_val.npz"}
    datasets of [n, duration_s x 10 Hz] programs, whose metadata carry every Domain field (the
    truth identify.md prints). Programs come from the stream ``babble/<domain.name>/<split>``
    of the paper's babbling family, so they are not D_c's."""
    config = dataclasses.replace(
        babble.PAPER,
        seed=SEED,
        n_train=n_train,
        n_val=n_val,
        duration_s=duration_s,
        domains=("constrained",),  # validated names only; the streams below use domain.name
        backend="c",
    )
    arm = arm_lib.load(model, domain=domain)
    made = {}
    for split, n in config.splits().items():
        programs = babble.family_programs(config, n, domain.name, split)
        poses = babble.simulate(arm, programs, backend="c")
        made[f"{domain.name}_{split}.npz"] = dataset.Dataset(
            pressures_bar=programs,
            poses=poses,
            pose_low=np.zeros(6, np.float32),
            pose_high=np.ones(6, np.float32),
            domain=domain.name,
            domain_fields=dataclasses.asdict(domain),
            model_hash=arm.model_hash,
            seed=config.seed,
            split=split,
            config=dataclasses.asdict(config)
            | {"domains": [domain.name], "study": "studies.identify_targets"},
        )
    low, high = dataset.workspace_bounds(*(d.poses for d in made.values()))
    return {name: d.with_bounds(low, high) for name, d in made.items()}


def held_out_rms_mm(domain: domains.Domain, val_path: Path, n_val: int, model=None) -> float:
    """Tip RMS (mm) of the chain in `domain` (MuJoCo C, its own timestep) against the first
    `n_val` programs of `val_path`, the held-out programs `mjx_arm.identify` scores on."""
    val = dataset.load_dataset(val_path)
    arm = arm_lib.load(model, domain=domain)
    simulated = arm.rollout(val.pressures_bar[:n_val], backend="c")
    return 1000.0 * identify.tip_rms_m(simulated, val.poses[:n_val])


def run_identify(argv: list[str]) -> dict:
    """`python -m mjx_arm.identify` with `argv`, in this process; returns its report."""
    parser = identify_cli.build_parser(identify.METHODS)
    args = parser.parse_args(argv)
    return identify_cli.run(args, parser, argv, identify.identify, identify.METHODS)


def case_folder(case: str, args: argparse.Namespace) -> str:
    """The folder name of a case: the rod's carries its number of training programs
    (``rod_10``; ``rod_all`` for the whole file), so fits on more programs sit beside it."""
    if case != "rod":
        return case
    return f"rod_{args.rod_n_programs or 'all'}"


def run_case(case: str, args: argparse.Namespace, out: Path, study_command: str) -> dict:
    """Runs one case into out/`case_folder`/ and returns its summary (also its case.json)."""
    folder = out / case_folder(case, args)
    started = time.perf_counter()
    common = ["--method", args.method, "--out", str(folder), "--no-progress"]
    if case in MEDIA:
        domain = medium_domain(case, args.model)
        data = folder / "babble"
        dataset.save_folder(
            data, babble_medium(domain, args.n, args.n_val, args.duration, args.model)
        )
        report = run_identify(["--data", str(data), *common])
        summary = {"truth_domain": dataclasses.asdict(domain)}
    else:
        argv = ["--data", str(args.rod_data), "--domain", "constrained", "--n-val", str(args.n_val)]
        argv += ["--base-viscosity-scale", f"{NOMINAL_VISCOSITY_SCALE:g}"]
        if args.rod_n_programs is not None:
            argv += ["--n-programs", str(args.rod_n_programs)]
        report = run_identify(argv + common)
        val_path = Path(report["data"]["val"])
        summary = {
            "committed_dc_val_rms_mm": held_out_rms_mm(
                domains.CONSTRAINED, val_path, args.n_val, args.model
            )
        }
    summary |= {
        "case": folder.name,
        "kind": case,
        "study_command": study_command,
        "command": report["command"],
        "data": report["data"],
        "truth": report["truth"],
        "results": {
            method: {
                k: r[k]
                for k in ("values", "base_values", "uncertainty", "error_pct", "wall_s", "cpu_s")
                if k in r
            }
            | {"val_rms_mm": 10 * r["val_rms_cm"], "base_val_rms_mm": 10 * r["base_val_rms_cm"]}
            for method, r in report["results"].items()
        },
        "case_wall_s": time.perf_counter() - started,
    }
    text = json.dumps(summary, indent=1, default=float) + "\n"
    (folder / "case.json").write_text(text)
    return summary


def run_rod_k(out: Path, study_command: str, model=None) -> dict:
    """The rod_k case: stretch only's validation X_err by k in the rod, the committed D_c and the
    identified arms of out/rod_<N>/case.json; written to out/rod_k/rod_k.json and returned."""
    from mjx_arm import load, load_rod, programs
    from tracking.held import choose_stretch_k

    program = programs.validation_program(20.0)
    arms = {"the rod (D_c, float64)": (load_rod("source"), load_rod("constrained"), "rod")}
    arm_s = load(model, domain="source")
    arms["committed D_c"] = (arm_s, load(model, domain=domains.CONSTRAINED), "c")
    for path in sorted(out.glob("rod_*/case.json")):
        case = json.loads(path.read_text())
        for method, r in case["results"].items():
            v = r["values"]
            domain = domains.Domain(name=f"identified ({method}, {case['case']})", **v)
            arms[domain.name] = (arm_s, load(model, domain=domain), "c")
    rows = []
    for name, (source, target, backend) in arms.items():
        k, errors = choose_stretch_k(source, target, program, K_CANDIDATES, backend, False)
        values = {} if backend == "rod" else identify_family.base_values(target)
        errors = {str(hold): float(err) for hold, err in errors.items()}  # as JSON keeps them
        rows.append({"arm": name, "k": k, "x_err_cm_by_k": errors, "values": values})
    result = {"study_command": study_command, "candidates": list(K_CANDIDATES), "rows": rows}
    (out / "rod_k").mkdir(parents=True, exist_ok=True)
    (out / "rod_k" / "rod_k.json").write_text(json.dumps(result, indent=1, default=float) + "\n")
    return result


def rod_k_lines(result: dict) -> list[str]:
    """The rod_k case's table: stretch only's k and its validation X_err by k, per arm."""
    ks = result["candidates"]
    lines = [
        "",
        "Stretch only's k on eval's validation program (20 s), chosen in each arm (rod_k):",
        "",
        "| arm | viscosity_scale, stiffness_scale | chosen k | "
        + " | ".join(f"X_err k = {k}" for k in ks)
        + " |",
        "|---|---|---|" + "---|" * len(ks),
    ]
    for r in result["rows"]:
        v = r["values"]
        shown = f"{v['viscosity_scale']:.5g}, {v['stiffness_scale']:.4g}" if v else "-"
        errors = r["x_err_cm_by_k"]
        cells = " | ".join(
            f"{errors[str(k)] if str(k) in errors else errors[k]:.3f} cm" for k in ks
        )
        lines.append(f"| {r['arm']} | {shown} | {r['k']} | {cells} |")
    lines += ["", f"Command: `{result['study_command']}`"]
    return lines


def table(summaries: list[dict]) -> list[str]:
    """The body of targets.md: one row per case and method, then the rod's comparison."""
    lines = [
        "",
        "| case | truth (viscosity, stiffness) | data | method | start | viscosity_scale |"
        " stiffness_scale | held-out tip RMS | start's held-out | wall (CPU) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in summaries:
        t, d = s["truth"], s["data"]
        truth = f"{t['viscosity_scale']:.4g}, {t['stiffness_scale']:.4g}" if t else "the rod"
        for method, r in s["results"].items():
            v, b, err = r["values"], r["base_values"], r.get("error_pct")
            cells = [
                f"{v[k]:.5g}" + (f" ({err[k]:+.3f}%)" if err else f" +- {r['uncertainty'][k]:.2g}")
                for k in ("viscosity_scale", "stiffness_scale")
            ]
            lines.append(
                f"| {s['case']} | {truth} | {d['n_train']} + {d['n_val']} x {d['duration_s']:g} s |"
                f" {method} | {b['viscosity_scale']:.4g}, {b['stiffness_scale']:.4g} |"
                f" {cells[0]} | {cells[1]} | {r['val_rms_mm']:.3g} mm | {r['base_val_rms_mm']:.3g}"
                f" mm | {r['wall_s']:.0f} s ({r['cpu_s']:.0f} s) |"
            )
    for s in summaries:
        if "committed_dc_val_rms_mm" not in s:
            continue
        committed = s["committed_dc_val_rms_mm"]
        lines += [
            "",
            f"The rod ({s['case']}), held-out tip RMS of chain arms against the rod on its"
            f" {s['data']['n_val']} held-out programs:",
            "",
            "| chain arm | viscosity_scale, stiffness_scale | held-out tip RMS | removed of the"
            " committed D_c's |",
            "|---|---|---|---|",
        ]
        base = next(iter(s["results"].values()))
        lines.append(
            f"| nominal start (the paper's medium) | {NOMINAL_VISCOSITY_SCALE:g}, 1 |"
            f" {base['base_val_rms_mm']:.3g} mm | - |"
        )
        lines.append(f"| committed D_c | {dc_viscosity_scale():.5g}, 1 | {committed:.3g} mm | - |")
        for method, r in s["results"].items():
            v = r["values"]
            removed = 100 * (1 - r["val_rms_mm"] / committed)
            lines.append(
                f"| identified ({method}) | {v['viscosity_scale']:.5g},"
                f" {v['stiffness_scale']:.4g} | {r['val_rms_mm']:.3g} mm | {removed:.0f}% |"
            )
    lines += ["", "Commands (each case's study run, then the identification it ran):", ""]
    for s in summaries:
        lines += [f"- {s['case']}: `{s['study_command']}`; `{s['command']}`"]
    lines += [
        "",
        "Held-out tip RMS: the chain arm (MuJoCo C, its own timestep) against the target's"
        " held-out programs. Wall (CPU): the identification's, CPU time being the process's.",
    ]
    return lines


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m studies.identify_targets",
        description="Identify media off the paper's pair and the reference rod; writes"
        " OUT/<case>/ and OUT/targets.{md,json}.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("--out", required=True, help="folder of the case folders and the table")
    p.add_argument(
        "--case",
        nargs="*",
        choices=CASES,
        default=["half_drag", "double_drag"],
        help="cases to run (none: only write the table again from the case folders)",
    )
    p.add_argument("--method", choices=(*identify.METHODS, "both"), default="search")
    p.add_argument("--n", type=identify_cli._positive_int, default=10, help="media: programs")
    p.add_argument(
        "--n-val", type=identify_cli._positive_int, default=3, help="held-out programs (all cases)"
    )
    p.add_argument(
        "--duration", type=identify_cli._positive_float, default=20.0, help="media: seconds"
    )
    p.add_argument("--rod-data", help="rod: a python -m mjx_arm.babble --backend rod folder")
    p.add_argument(
        "--rod-n-programs", type=identify_cli._positive_int, help="rod: fit on the first N"
    )
    p.add_argument("--model", help="the arm's MJCF (default: models/softarm.xml)")
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parse_checked_args(parser, argv)
    if "rod" in args.case:
        if args.rod_data is None:
            parser.error("--case rod needs --rod-data")
        try:
            identify_cli.find_files(args.rod_data, "constrained")
        except ValueError as err:
            parser.error(str(err))
    out = Path(args.out)
    header = run_header("studies.identify_targets", argv)
    for case in args.case:
        if case == "rod_k":
            run_rod_k(out, header["command"], args.model)
        else:
            run_case(case, args, out, header["command"])
    summaries = [json.loads(path.read_text()) for path in out.glob("*/case.json")]
    # Summaries written before "kind" was recorded are the media's, named after their case.
    summaries.sort(key=lambda s: (CASES.index(s.get("kind", s["case"])), s["data"]["n_train"]))
    body = table(summaries)
    rod_k = out / "rod_k" / "rod_k.json"
    if rod_k.exists():
        body += rod_k_lines(json.loads(rod_k.read_text()))
    write_results(
        out / "targets",
        header,
        {"cases": summaries},
        "Identification beyond the paper's pair: custom media and the reference rod",
        body,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
