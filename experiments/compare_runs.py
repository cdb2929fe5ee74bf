"""Two runs of a chain side by side: which outputs came out the same, and their held-out numbers.

    python -m experiments.compare_runs results/paper/run results/paper/rerun_2026-11-24/run

Reads only what each stage folder keeps: `stage.json` (the sha256 of every output file), a
training's `metrics.csv` (the held-out `val_error_cm` of each seed at its last epoch) and a
distillation's `distill.json` (each seed's best held-out X_err). Either folder may be a committed
copy without the large files, since the hashes are in the manifests. Why: whether a second run
of the same command reproduces the first is a question of the files, not of the test shapes.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

from mjx_arm.atomic import write_atomically
from mjx_arm.run_folder import check_writable_folder


def _held_out(folder: Path) -> tuple[str, list[float]] | None:
    """(what the number is, one per seed) from a stage folder, or None when it has none."""
    metrics, distill = folder / "metrics.csv", folder / "distill.json"
    if metrics.exists():
        last: dict[str, dict] = {}
        with metrics.open() as f:
            for row in csv.DictReader(f):
                last[row["seed"]] = row
        rows = [last[s] for s in sorted(last, key=int)]
        epoch = rows[0]["epoch"] if rows else "?"
        return f"val_error_cm at epoch {epoch}", [float(r["val_error_cm"]) for r in rows]
    if distill.exists():
        history = json.loads(distill.read_text())["history"]
        return "best_val_x_err_cm", [float(v) for v in history["best_val_x_err_cm"]]
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
    except ManifestError as err:
        parser.error(str(err))
    print(text, end="")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(args.out, lambda f: f.write(text.encode()))


if __name__ == "__main__":
    main()
