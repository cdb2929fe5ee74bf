"""The command line of ``python -m mjx_arm.identify``: a target arm's medium and stiffness from
its babbling data (`mjx_arm.identify`, whose `main` runs this module's with its `identify`).

    python -m mjx_arm.identify --data out/babble --out out/identify            # search
    python -m mjx_arm.identify --data out/babble/aged_train.npz --out DIR --method both

Reads a `python -m mjx_arm.babble` folder (``<domain>_train.npz``, and ``<domain>_val.npz`` for
the held-out programs when it is there) or one of its files, checks every option and file before
any simulation (a usage error, exit 2), and writes ``identify.json`` (every result, its loss
history and settings) and ``identify.md`` (the table). Where the data were made by the chain in
a known domain (the file's metadata), the table sets the recovered values beside the truth.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import shlex
import sys
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from mjx_arm import arm as arm_lib
from mjx_arm import atomic, dataset, domains, identify_family, machine, run_folder
from mjx_arm.identify_family import FITTABLE

#: Held-out programs taken from the end of the training file when the folder has no val file.
DEFAULT_N_VAL = 2


def build_parser(methods: tuple[str, ...]) -> argparse.ArgumentParser:
    """The options of ``python -m mjx_arm.identify`` (`methods`: `identify.METHODS`)."""
    p = argparse.ArgumentParser(
        prog="python -m mjx_arm.identify",
        description="Identify a target arm's medium (viscosity scale) and stiffness scale"
        " from its babbling data; writes identify.json and identify.md.",
        formatter_class=_HelpFormatter,
    )
    p.add_argument(
        "--data",
        required=True,
        help="a babbling folder (python -m mjx_arm.babble --out) or one of its"
        " <domain>_train.npz files",
    )
    p.add_argument("--out", required=True, help="folder for identify.json and identify.md")
    p.add_argument(
        "--method",
        choices=(*methods, "both"),
        default=methods[0],
        help="search: grid and Nelder-Mead over MuJoCo C rollouts; gradient: Adam through MJX"
        " (docs/identification.md); both: each on the same data",
    )
    p.add_argument("--domain", help="which <domain>_train.npz of a folder (default: the only one)")
    p.add_argument(
        "--n-programs",
        type=_positive_int,
        help="fit on the first N training programs (default: all of them)",
    )
    p.add_argument(
        "--n-val",
        type=_positive_int,
        help="held-out programs: the first N of the val file, or without one the last N of"
        f" the training programs (default: the whole val file, or {DEFAULT_N_VAL})",
    )
    p.add_argument(
        "--base",
        default="constrained",
        choices=sorted(domains.DOMAINS),
        help="the domain the fit starts from and keeps its other fields of",
    )
    p.add_argument(
        "--base-viscosity-scale",
        type=_positive_float,
        help="start from this viscosity scale instead of the base's (e.g. 10, the paper's)",
    )
    p.add_argument(
        "--base-stiffness-scale",
        type=_positive_float,
        help="start from this stiffness scale instead of the base's",
    )
    p.add_argument(
        "--fit", default=",".join(FITTABLE), help=f"fields to fit, a comma list of {FITTABLE}"
    )
    p.add_argument("--seeds", type=_positive_int, default=1, help="starts of each fit")
    p.add_argument("--model", help="the arm's MJCF (default: models/softarm.xml)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    return p


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows every default except None ones, whose help says what None means."""

    def _get_help_string(self, action):
        return action.help if action.default is None else super()._get_help_string(action)


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be finite and > 0, got {text}")
    return value


def find_files(data: str | Path, domain: str | None) -> tuple[Path, Path | None]:
    """(training file, val file or None) of `--data` and `--domain`.

    Raises:
      ValueError: no such file or folder, a folder with no (or several, without `domain`)
        ``*_train.npz``, or a file whose name is not ``<domain>_train.npz`` with a `domain`.
    """
    data = Path(data)
    if data.is_file():
        name = data.name
        if domain is not None and name != f"{domain}_train.npz":
            raise ValueError(f"--domain {domain} does not name the file {data}")
        val = data.with_name(name.replace("_train.npz", "_val.npz"))
        return data, (val if name.endswith("_train.npz") and val.is_file() else None)
    if not data.is_dir():
        raise ValueError(f"--data {data}: no such file or folder")
    if domain is not None:
        train = data / f"{domain}_train.npz"
        if not train.is_file():
            raise ValueError(f"--data {data} holds no {train.name}")
    else:
        found = sorted(data.glob("*_train.npz"))
        if len(found) != 1:
            names = [f.name for f in found] or "none"
            raise ValueError(f"--data {data}: need one *_train.npz or --domain, found {names}")
        train = found[0]
    val = train.with_name(train.name.replace("_train.npz", "_val.npz"))
    return train, (val if val.is_file() else None)


def truth_values(ds: dataset.Dataset, model, fit) -> dict | None:
    """The fitted fields' true values where the chain made the data in a known domain: the
    viscosity as a factor on the MJCF's, the stiffness scale; None for the rod's data or a
    domain with another mass scale. Read from the Domain fields in the data's metadata, so a
    medium that is not built in (a `Domain` of its own values, as `studies.identify_targets`
    babbles) has its truth too."""
    if ds.model_hash.startswith("rod-") or ds.config.get("backend") == "rod":
        return None
    fields = {k: v for k, v in ds.domain_fields.items() if k != "name"}
    try:
        truth = domains.Domain(name=ds.domain, **fields)
    except (TypeError, ValueError):
        return None
    if truth.mass_scale != 1.0:
        return None
    viscosity = arm_lib.load(model, domain=truth).mj_model.opt.viscosity
    unit = arm_lib.load(model, domain=domains.Domain(viscosity_scale=1.0)).mj_model.opt.viscosity
    values = {"viscosity_scale": viscosity / unit, "stiffness_scale": truth.stiffness_scale}
    return {name: float(values[name]) for name in fit}


def run(
    args: argparse.Namespace,
    parser: argparse.ArgumentParser,
    argv: list[str],
    identify: Callable,
    methods: tuple[str, ...],
) -> dict:
    """Checks `args` (parsed from `argv`), fits with `identify` (`mjx_arm.identify.identify`)
    by each method asked for, writes the report; returns the JSON written. Every check is an
    argparse usage error (exit 2) before any simulation."""
    out = run_folder.check_out(parser, "--out", args.out)
    try:
        fit = identify_family.check_fit([f.strip() for f in args.fit.split(",") if f.strip()])
        train_path, val_path = find_files(args.data, args.domain)
        model_hash = arm_lib.load(args.model).model_hash
        train = dataset.load_dataset(train_path)
        val = dataset.load_dataset(val_path) if val_path is not None else None
    except (ValueError, OSError) as err:
        parser.error(str(err))
    for path, ds in ((train_path, train), (val_path, val)):
        if ds is not None and not ds.model_hash.startswith("rod-") and ds.model_hash != model_hash:
            parser.error(f"{path}: made with model {ds.model_hash}, --model is {model_hash}")
    programs, poses = train.pressures_bar, train.poses
    if args.n_programs is not None:
        if args.n_programs > len(programs):
            parser.error(f"--n-programs {args.n_programs}: {train_path} holds {len(programs)}")
        programs, poses = programs[: args.n_programs], poses[: args.n_programs]
    if val is not None:
        n_val = len(val.pressures_bar) if args.n_val is None else args.n_val
        if n_val > len(val.pressures_bar) or val.n_steps != train.n_steps:
            parser.error(
                f"--n-val {n_val}: {val_path} holds {len(val.pressures_bar)} programs"
                f" of {val.n_steps} periods (training: {train.n_steps})"
            )
        programs = np.concatenate([programs, val.pressures_bar[:n_val]])
        poses = np.concatenate([poses, val.poses[:n_val]])
    else:
        n_val = DEFAULT_N_VAL if args.n_val is None else args.n_val
        if n_val >= len(programs):
            parser.error(f"--n-val {n_val} leaves no training program of {len(programs)}")
    base = domains.resolve(args.base)
    overrides = {
        "viscosity_scale": args.base_viscosity_scale,
        "stiffness_scale": args.base_stiffness_scale,
    }
    overrides = {k: v for k, v in overrides.items() if v is not None}
    if overrides:
        name = base.name + ", " + ", ".join(f"{k}={v:g}" for k, v in overrides.items())
        base = dataclasses.replace(base, name=name, **overrides)
    truth = truth_values(train, args.model, fit)
    methods = methods if args.method == "both" else (args.method,)
    results = {}
    for method in methods:
        result = identify(
            programs,
            poses,
            base=base,
            fit=fit,
            method=method,
            n_val=n_val,
            seeds=args.seeds,
            model=args.model,
            progress=not args.no_progress,
            log=lambda line: print(line, file=sys.stderr, flush=True),
        )
        results[method] = result.to_dict()
        if truth is not None:
            results[method]["error_pct"] = {
                k: 100.0 * (result.values[k] / truth[k] - 1.0) for k in fit
            }
    report = {
        "command": "python -m mjx_arm.identify " + shlex.join(argv),
        "data": {
            "train": str(train_path),
            "val": None if val_path is None else str(val_path),
            "domain": train.domain,
            "domain_fields": train.domain_fields,
            "model_hash": train.model_hash,
            "n_train": len(programs) - n_val,
            "n_val": n_val,
            "duration_s": train.duration_s,
        },
        "truth": truth,
        "results": results,
        "machine": {
            "cpu": machine.cpu_model(),
            "cores": machine.usable_cores(),
            "jax_backend": jax.default_backend(),
        },
    }
    out.mkdir(parents=True, exist_ok=True)
    text = json.dumps(report, indent=1, default=_json_default, allow_nan=False)
    _write(out / "identify.json", text + "\n")
    _write(out / "identify.md", markdown(report))
    return report


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON: {type(value).__name__}")


def _write(path: Path, text: str) -> None:
    atomic.write_atomically(path, lambda f: f.write(text.encode()))


def markdown(report: dict) -> str:
    """identify.md: the data, then one row per method and fitted field."""
    d, truth = report["data"], report["truth"]
    lines = [
        "# Identification",
        "",
        f"`{report['command']}`",
        "",
        f"Data: `{d['train']}` (domain {d['domain']}, model {d['model_hash']}): {d['n_train']}"
        f" programs of {d['duration_s']:g} s fitted, {d['n_val']} held out"
        + (f" (`{d['val']}`)" if d["val"] else "")
        + ". Truth: "
        + (
            f"the data's domain, {d['domain']} ("
            + ", ".join(f"{k} {v:.5g}" for k, v in truth.items())
            + ")."
            if truth
            else "unknown (not the chain in a Domain)."
        )
        + f" Machine: {report['machine']['cpu']}, usable cores: {report['machine']['cores']}"
        f" (JAX on {report['machine']['jax_backend']}).",
        "",
        "| method | field | base | fitted | +- (1 sd, bootstrap) | truth | error | held-out tip"
        " RMS | base's held-out | wall time (CPU) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for method, r in report["results"].items():
        for name, value in r["values"].items():
            t = truth[name] if truth else None
            err = f"{r['error_pct'][name]:+.2f}%" if truth else "-"
            lines.append(
                f"| {method} | {name} | {r['base_values'][name]:.5g} | {value:.5g} |"
                f" {r['uncertainty'][name]:.2g} | {'-' if t is None else f'{t:.5g}'} | {err} |"
                f" {10 * r['val_rms_cm']:.2g} mm ({r['val_rms_pct_length']:.2g}% of L) |"
                f" {10 * r['base_val_rms_cm']:.3g} mm | {r['wall_s']:.0f} s ({r['cpu_s']:.0f} s) |"
            )
    lines += [
        "",
        "Held-out tip RMS: the fitted domain's arm (MuJoCo C, its own timestep) on the held-out"
        " programs. Wall time: the whole fit, loading, compiling and held-out scoring included;"
        " CPU: the process's CPU time over it (all threads).",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None, identify: Callable, methods: tuple[str, ...]) -> int:
    """Runs the command line with `identify` and its `methods` (`mjx_arm.identify.main` passes
    its own: the library imports this module, not the other way round); returns the exit
    status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(methods)
    run(parser.parse_args(argv), parser, argv, identify, methods)
    return 0
