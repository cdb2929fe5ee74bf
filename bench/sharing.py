"""Do trainings that share one GPU get more done than the same trainings one after another?

`experiments.paper --jobs N` runs up to N stages at once, and on one GPU its trainings take turns
on it. For each N in --jobs this starts N copies of the same `bench.train --paper` run at once
(the paper's data size with synthetic values, --seeds seeds vmapped, --epochs epochs with the
k selection and checkpoint chunks of a real training, no files), each a process of its own with
GPU memory taken as needed (as the chain sets it), and reads their seconds per epoch after
compiling.
The throughput of N together against one alone is N x (s/epoch alone) / (mean s/epoch of the N):
above 1 sharing gains, below 1 it costs.

    python -m bench.sharing --jobs 1 2 4 --out bench/results/h200/sharing

Each training compiles first; enough epochs (--epochs) make the N trainings' epochs overlap, so
that they do take turns on the accelerator while they are timed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench import parse_checked, run_header, write_results
from ccgan.cli import cli_parser


def train_command(args, out: Path) -> list[str]:
    """One `bench.train --paper` run into folder `out` (writes out/train_paper.json)."""
    return [
        sys.executable,
        "-m",
        "bench.train",
        "--paper",
        "--paper-epochs",
        str(args.epochs),
        "--paper-seeds",
        str(args.seeds),
        "--out",
        str(out),
    ]


def run_together(args, n: int, folder: Path) -> dict:
    """Starts n timings at once and waits for all; returns their wall time and timings.

    Raises:
      RuntimeError: a timing failed (its output is in folder/job<i>.log).
    """
    env = dict(os.environ)
    if n > 1:
        env.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
    t0 = time.perf_counter()
    procs = []
    for i in range(n):
        log = open(folder / f"job{i}.log", "w")  # noqa: SIM115 (closed below)
        cmd = train_command(args, folder / f"job{i}")
        procs.append((subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env), log))
    codes = []
    for proc, log in procs:
        codes.append(proc.wait())
        log.close()
    wall_s = time.perf_counter() - t0
    failed = [i for i, code in enumerate(codes) if code != 0]
    if failed:
        tail = (folder / f"job{failed[0]}.log").read_text()[-3000:]
        raise RuntimeError(
            f"{n} at once: training(s) {failed} failed; the first's output ends:\n{tail}"
        )
    timings = [
        json.loads((folder / f"job{i}" / "train_paper.json").read_text())["paper_run"]
        for i in range(n)
    ]
    return {
        "jobs": n,
        "wall_s": wall_s,
        "epoch_s": [t["epoch_s"] for t in timings],
        "compile_s": [t["compile_s"] for t in timings],
    }


def main(argv=None) -> None:
    p = cli_parser("bench.sharing", __doc__)
    p.add_argument("--jobs", type=int, nargs="+", default=[1, 2, 4], help="trainings at once")
    p.add_argument("--epochs", type=int, default=40, help="timed epochs per training")
    p.add_argument("--seeds", type=int, default=3, help="seeds vmapped in each training")
    p.add_argument("--out", required=True, help="output prefix (writes .json and .md)")
    a = parse_checked(p, argv)
    if min(a.jobs) != 1:
        p.error("--jobs must be positive and include 1, the reference")
    header = run_header("bench.sharing", argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="sharing-") as tmp:
        for n in sorted(set(a.jobs)):
            folder = Path(tmp) / f"n{n}"
            folder.mkdir()
            rows.append(run_together(a, n, folder))
            print(json.dumps(rows[-1]), flush=True)
            md = write_report(a, header, rows)  # after every row: a stopped run keeps its rows
    print(md.read_text())


def write_report(a, header: dict, rows: list[dict]) -> Path:
    """Writes the rows so far, each with its throughput against the first (one alone)."""
    alone = rows[0]["epoch_s"][0]
    for row in rows:
        row["throughput_vs_alone"] = row["jobs"] * alone / float(np.mean(row["epoch_s"]))
    lines = [
        "",
        f"Each training: `python {' '.join(train_command(a, Path('DIR'))[1:])}` (the paper's"
        f" data size, synthetic values; seeds vmapped: {a.seeds}; {a.epochs} epochs)."
        " 'Throughput' is the epochs all N trainings finish per second, against one training"
        " alone.",
        "",
        "| trainings at once | s / epoch after compiling, each | compile (s), each |"
        " wall time of all (s) | throughput vs alone |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['jobs']} | {', '.join(f'{v:.3f}' for v in r['epoch_s'])}"
            f" | {', '.join(f'{v:.1f}' for v in r['compile_s'])} | {r['wall_s']:.0f}"
            f" | {r['throughput_vs_alone']:.2f} |"
        )
    title = "Trainings sharing one accelerator"
    result = {"epochs": a.epochs, "seeds": a.seeds, "rows": rows}
    return write_results(a.out, header, result, title, lines)


if __name__ == "__main__":
    main()
