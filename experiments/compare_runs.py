"""Two runs of a chain side by side: which outputs came out the same, and their held-out numbers.

    python -m experiments.compare_runs results/paper/run results/paper/rerun_2026-11-24/run

Reads only what each stage folder keeps: `stage.json` (the sha256 of every output file), a
training's `metrics.csv` (the held-out `val_error_cm` of each seed at its last epoch) and a
distillation's `distill.json` (each seed's best held-out X_err). Either folder may be a committed
copy without the large files, since the hashes are in the manifests. Why: whether a second run
of the same command reproduces the first is a question of the files, not of the test shapes.

When the two runs' stages were run with other commands (a quick run beside a paper-scale one),
a note under the table names each differing setting (`ccgan.checkpoint.differences` on the
commands their manifests record), since their numbers then answer different questions.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

from ccgan.checkpoint import differences
from mjx_arm.atomic import write_atomically
from mjx_arm.run_folder import check_writable_folder


class MetricError(ValueError):
    """A stage's metrics.csv or distill.json without the held-out number this table shows, or
    with one that is not a number."""


def _number(value, where: str) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise MetricError(f"{where}: {value!r} is not a number") from None


def _held_out(folder: Path) -> tuple[str, list[float]] | None:
    """(what the number is, one per seed) from a stage folder, or None when it has none.

    Raises:
      MetricError: the file lacks the columns or keys read here, or a value is not a number.
    """
    metrics, distill = folder / "metrics.csv", folder / "distill.json"
    if metrics.exists():
        last: dict[str, dict] = {}
        with metrics.open() as f:
            reader = csv.DictReader(f)
            missing = {"seed", "epoch", "val_error_cm"} - set(reader.fieldnames or ())
            if missing:
                raise MetricError(f"{metrics} has no column {', '.join(sorted(missing))}")
            for row in reader:
                last[row["seed"]] = row
        rows = [last[s] for s in sorted(last, key=lambda s: _number(s, f"{metrics} seed"))]
        epoch = rows[0]["epoch"] if rows else "?"
        where = f"{metrics} val_error_cm"
        return f"val_error_cm at epoch {epoch}", [_number(r["val_error_cm"], where) for r in rows]
    if distill.exists():
        try:
            record = json.loads(distill.read_text())
        except (OSError, UnicodeDecodeError, ValueError) as err:
            raise MetricError(f"{distill} is not readable JSON: {err}") from err
        history = record.get("history") if isinstance(record, dict) else None
        values = history.get("best_val_x_err_cm") if isinstance(history, dict) else None
        if not isinstance(values, list):
            raise MetricError(
                f'{distill} has no "history" with "best_val_x_err_cm" (one per seed): not the'
                " record of a finished ccgan.distill"
            )
        return "best_val_x_err_cm", [_number(v, f"{distill} best_val_x_err_cm") for v in values]
    return None


class ManifestError(ValueError):
    """A stage.json that is not a stage's manifest (no "files" of output hashes)."""


def _files(path: Path) -> dict:
    """{output file: sha256} of a stage's manifest; a missing or unreadable one raises
    ManifestError naming the file."""
    try:
        files = json.loads(path.read_text()).get("files")
    except (OSError, UnicodeDecodeError, ValueError, AttributeError) as err:
        raise ManifestError(f"{path} is not a stage manifest: {err}") from err
    if not isinstance(files, dict):
        raise ManifestError(f'{path} has no "files" (the sha256 of each output): not a manifest')
    return files


def stage_settings(manifest_path: Path) -> dict:
    """{"module": ..., "--flag": its value(s) joined by spaces, "args": leading positionals} of
    the command a stage's manifest records (its key); empty when it records none."""
    try:
        key = json.loads(manifest_path.read_text()).get("key")
    except (OSError, UnicodeDecodeError, ValueError, AttributeError):
        return {}
    if not isinstance(key, dict):
        return {}
    settings, flag = {"module": key.get("module")}, "args"
    for token in key.get("args", []):
        token = str(token)
        if token.startswith("--"):
            flag = token
            settings.setdefault(flag, "")
        else:
            settings[flag] = f"{settings.get(flag, '')} {token}".strip()
    return settings


def config_differences(first: Path, second: Path, names: list[str]) -> list[str]:
    """ "stage.--flag: first X, second Y" for every setting the two runs' stages ran with
    differently."""
    out = []
    for name in names:
        settings = [stage_settings(run / name / "stage.json") for run in (first, second)]
        for line in differences(*settings, prefix=name):
            for old, new in (
                (": not stored, this run ", ": not in first, second "),
                (", not in this run", ", not in second"),
                (": stored ", ": first "),
                (", this run ", ", second "),
            ):
                line = line.replace(old, new)
            out.append(line)
    return out


def compare(first: Path, second: Path) -> list[str]:
    """Markdown lines: per stage present in both, the outputs with equal and differing hashes,
    and the held-out numbers of each run."""
    lines = [
        f"# {first} against {second}",
        "",
        "| stage | same sha256 | different sha256 | held-out number | first, per seed"
        " | second, per seed |",
        "|---|---|---|---|---|---|",
    ]
    names = sorted(
        p.parent.name for p in second.glob("*/stage.json") if (first / p.parent.name).is_dir()
    )
    for name in names:
        files = [_files(run / name / "stage.json") for run in (first, second)]
        shared = sorted(set(files[0]) & set(files[1]) - {"stage.log"})
        same = [f for f in shared if files[0][f] == files[1][f]]
        differ = [f for f in shared if files[0][f] != files[1][f]]
        numbers = [_held_out(run / name) for run in (first, second)]
        what = numbers[0][0] if numbers[0] else ""
        shown = [" / ".join(f"{v:.3f}" for v in n[1]) if n else "" for n in numbers]
        lines.append(
            f"| {name} | {', '.join(same) or '-'} | {', '.join(differ) or '-'} | {what} |"
            f" {shown[0]} | {shown[1]} |"
        )
    differing = config_differences(first, second, names)
    if differing:
        lines += [
            "",
            f"Note: the two runs' configs differ in {len(differing)} settings of their stages'"
            " commands, so their numbers are not of the same settings:",
            "",
            *[f"- {line}" for line in differing],
        ]
    return lines


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m experiments.compare_runs",
        description=__doc__.split("\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument("first", type=Path, help="a run folder (experiments.paper --out)")
    parser.add_argument("second", type=Path, help="another run folder of the same config")
    parser.add_argument("--out", type=Path, help="also write the table to this file")
    args = parser.parse_args(argv)
    for folder in (args.first, args.second):
        if not any(folder.glob("*/stage.json")):
            parser.error(f"{folder}: no stage folder with a stage.json")
    if args.out is not None:
        if args.out.is_dir():
            parser.error(f"--out {args.out} is a folder; name a file")
        try:
            check_writable_folder(args.out.parent)
        except OSError as err:
            parser.error(f"--out: {err}")
    try:
        text = "\n".join(compare(args.first, args.second)) + "\n"
    except (ManifestError, MetricError) as err:
        parser.error(str(err))
    print(text, end="")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(args.out, lambda f: f.write(text.encode()))


if __name__ == "__main__":
    main()
