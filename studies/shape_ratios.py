"""The five shapes' X_err of methods from several `eval.shapes` folders, side by side, with
each one's ratio to a baseline column (issue 50: the data-only translator against stretch only
and against the privileged one, scored in separate runs of the same medium).

    python -m studies.shape_ratios --out studies/results/cpu/offpair_shapes/half_drag/ratios \\
        --column "stretch only=DIR_A:stretch" "data-only=DIR_A:ccgan_ident" \\
        "privileged=DIR_B:ccgan_ident" --baseline "stretch only" "privileged"

Each DIR is a folder with shapes.json; every column must be of the same medium (the folders'
`target_domain_file` and `stretch_k` agree, or the run refuses).
"""

from __future__ import annotations

import json
from pathlib import Path

from bench import run_header, write_results
from ccgan.cli import cli_parser
from studies.checks import parse_checked_args

SHAPES = ("circle", "rectangle", "damped_circle", "ellipse", "kite")


def read_column(p, spec: str) -> tuple[str, dict, dict]:
    """NAME=DIR:METHOD -> (name, {shape: X_err cm}, the folder's shapes.json)."""
    name, sep, rest = spec.partition("=")
    folder, sep2, method = rest.rpartition(":")
    if not (sep and sep2 and name and folder and method):
        p.error(f"--column: expected NAME=DIR:METHOD, got {spec!r}")
    path = Path(folder) / "shapes.json"
    if not path.is_file():
        p.error(f"--column {name}: no {path}")
    run = json.loads(path.read_text())
    missing = [s for s in SHAPES if method not in run["table"].get(s, {})]
    if missing:
        p.error(f"--column {name}: {path} has no {method} for {', '.join(missing)}")
    return name, {s: run["table"][s][method]["x_err_cm_mean"] for s in SHAPES}, run


def main(argv=None) -> None:
    p = cli_parser("studies.shape_ratios", __doc__)
    p.add_argument("--column", nargs="+", required=True, metavar="NAME=DIR:METHOD")
    p.add_argument("--baseline", nargs="+", required=True, metavar="NAME")
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked_args(p, argv)
    columns = [read_column(p, spec) for spec in a.column]
    names = [name for name, _, _ in columns]
    if len(set(names)) != len(names):
        p.error(f"--column: names must differ, got {names}")
    for base in a.baseline:
        if base not in names:
            p.error(f"--baseline {base}: not a column ({', '.join(names)})")
    media = {json.dumps(run.get("target_domain_file")) for _, _, run in columns}
    if len(media) != 1:
        p.error(f"--column: the folders score different media ({', '.join(sorted(media))})")
    errors = {name: err for name, err, _ in columns}
    header = [f"X_err (cm), mean over seeds, and ratios: {', '.join(a.column)}.", ""]

    def compared(n: str, b: str) -> bool:  # not a baseline against itself or an earlier one
        return n != b and not (n in a.baseline and a.baseline.index(n) < a.baseline.index(b))

    cols = names + [f"{n} / {b}" for b in a.baseline for n in names if compared(n, b)]
    lines = [*header, "| shape | " + " | ".join(cols) + " |", "|---|" + "---|" * len(cols)]
    ratios = {}
    for shape in SHAPES:
        row = [f"{errors[n][shape]:.3f}" for n in names]
        for b in a.baseline:
            for n in names:
                if compared(n, b):
                    r = errors[n][shape] / errors[b][shape]
                    ratios.setdefault(f"{n} / {b}", {})[shape] = r
                    row.append(f"{r:.2f}x")
        lines.append(f"| {shape} | " + " | ".join(row) + " |")
    spans = [f"{key}: {min(v.values()):.2f}-{max(v.values()):.2f}x" for key, v in ratios.items()]
    lines += ["", "Over the five shapes: " + "; ".join(spans) + "."]
    print("\n".join(lines))
    result = {"columns": a.column, "x_err_cm": errors, "ratios": ratios}
    write_results(a.out, run_header("studies.shape_ratios", argv), result, "The five shapes", lines)


if __name__ == "__main__":
    main()
