"""What the persistent JAX compilation cache saves: a command's second run against its first.

For each job, four fresh processes run back to back: two with the cache in an empty folder of its
own (`SOFTARM_JAX_CACHE=DIR`: the first run compiles and writes, the second reads), then two with
the cache off (`SOFTARM_JAX_CACHE=0`: both compile). Each row gives the wall time, the 1-minute
load average just before the run (the machine may be shared) and the cache's files after it.
Every run writes into a fresh temporary folder. Writes OUT.{md,json}.

Jobs:
- `shapes`: the main job's smoke run, `python -m eval.shapes --quick --out TMP`;
- `forward`: the chain's forward stage (`ccgan.train --forward-only`) with the arguments of
  experiments/quick.json, on babbling data made once beforehand (MuJoCo C, not timed);
- `babble_mjx`: `python -m mjx_arm.babble --backend mjx` on a few short programs.

    python -m bench.compile_cache --jobs babble_mjx forward shapes \
        --out bench/results/cpu/compile_cache
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ccgan.cli import cli_parser

ROOT = Path(__file__).resolve().parents[1]
JOBS = ("shapes", "forward", "babble_mjx")
MODES = (("cache", "first"), ("cache", "second"), ("off", "first"), ("off", "second"))


def _forward_args(data: Path, workdir: Path) -> list[str]:
    """experiments/quick.json's forward stage, its placeholders filled in."""
    stages = json.loads((ROOT / "experiments" / "quick.json").read_text())["stages"]
    args = next(s["args"] for s in stages if s["name"] == "forward")
    args = args.replace("{stage:data_paper}", str(data)).replace("{dir}", str(workdir))
    args = args.replace("{file:models/softarm.xml}", str(ROOT / "models" / "softarm.xml"))
    return ["-m", "ccgan.train", *args.split()]


def _babble(out: Path, backend: str, n: int, duration_s: float, domain: str) -> list[str]:
    return [
        "-m", "mjx_arm.babble", "--n", str(n), "--n-val", "1", "--duration", str(duration_s),
        "--domain", domain, "--seed", "0", "--backend", backend, "--no-progress", "--out", str(out),
    ]  # fmt: skip


def _command(job: str, work: Path, data: Path) -> list[str]:
    """The job's arguments to the Python interpreter, writing under `work`."""
    if job == "shapes":
        return ["-m", "eval.shapes", "--quick", "--out", str(work / "out")]
    if job == "forward":
        return _forward_args(data, work / "forward")
    return _babble(work / "babble", "mjx", n=2, duration_s=4.0, domain="source")


def _cache_files(path: Path) -> tuple[int, int]:
    """(entries, bytes) of a JAX cache folder."""
    files = [p for p in path.glob("*-cache")] if path.exists() else []
    return len(files), sum(p.stat().st_size for p in files)


def run_once(
    job: str, mode: str, cache_dir: Path, data: Path, log: Path, min_compile_s: float | None
) -> dict:
    """One fresh process; returns its row (wall time, load, cache files)."""
    env = dict(os.environ, SOFTARM_JAX_CACHE=str(cache_dir) if mode == "cache" else "0")
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    env.pop("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", None)
    if min_compile_s is not None:
        env["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = str(min_compile_s)
    with tempfile.TemporaryDirectory(prefix=f"cc_{job}_") as tmp:
        cmd = [sys.executable, *_command(job, Path(tmp), data)]
        load_before = os.getloadavg()
        start = time.perf_counter()
        with log.open("ab") as f:
            f.write(f"\n$ {' '.join(cmd)}  [{mode}]\n".encode())
            f.flush()
            rc = subprocess.run(cmd, env=env, cwd=ROOT, stdout=f, stderr=f).returncode
        wall_s = time.perf_counter() - start
        command = " ".join(["python", *cmd[1:]]).replace(tmp, "TMP")
    entries, size = _cache_files(cache_dir) if mode == "cache" else (0, 0)
    return {
        "job": job,
        "cache": mode,
        "returncode": rc,
        "wall_s": wall_s,
        "load_1m_before": load_before[0],
        "load_1m_after": os.getloadavg()[0],
        "cache_entries": entries,
        "cache_mb": size / 1e6,
        "command": command,
    }


def main(argv=None) -> None:
    """CLI: run every --jobs job four times and write the table."""
    from bench import parse_checked, run_header, write_results

    p = cli_parser("bench.compile_cache", __doc__)
    p.add_argument("--jobs", nargs="+", choices=JOBS, default=list(JOBS), help="jobs to time")
    p.add_argument(
        "--min-compile-time-s",
        type=float,
        default=None,
        help="write programs that compile at least this long (default: the package's, 1 s)",
    )
    p.add_argument("--out", required=True, help="output prefix (writes .md and .json)")
    a = parse_checked(p, argv)
    header = run_header("bench.compile_cache", argv)
    header["cores"] = os.cpu_count()
    header["min_compile_time_s"] = (
        "the package's (1 s)" if a.min_compile_time_s is None else a.min_compile_time_s
    )
    scratch = Path(tempfile.mkdtemp(prefix="bench_compile_cache_"))
    log = Path(tempfile.gettempdir()) / "bench_compile_cache_log.txt"
    log.write_text("")
    print(f"the runs' output: {log}", flush=True)
    rows = []
    try:
        stage = scratch / "data_paper"  # quick.json's {stage:data_paper}: babbling in babble/
        if "forward" in a.jobs:  # its input, made once with MuJoCo C (no JAX compile to speak of)
            cmd = [
                sys.executable,
                *_babble(stage / "babble", "c", n=3, duration_s=8.0, domain="both"),
            ]
            env = dict(os.environ, SOFTARM_JAX_CACHE="0")
            subprocess.run(cmd, env=env, cwd=ROOT, check=True, capture_output=True)
        for job in a.jobs:
            cache_dir = scratch / f"cache_{job}"
            for mode, which in MODES:
                row = run_once(job, mode, cache_dir, stage, log, a.min_compile_time_s)
                row["run"] = which
                row["command"] = row["command"].replace(str(scratch), "SCRATCH")
                rows.append(row)
                print(json.dumps(row), flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    md = write_results(
        a.out,
        header,
        {"rows": rows},
        "JAX compilation cache: second run against first",
        _body(rows),
    )
    print(md.read_text())


def _body(rows: list[dict]) -> list[str]:
    lines = [
        "",
        "Each row a fresh process, run back to back in the order shown. cache: SOFTARM_JAX_CACHE"
        " set to a folder that was empty before the job's first row; off: SOFTARM_JAX_CACHE=0."
        " load: the 1-minute load average just before and after the run.",
        "",
        "| job | cache | run | wall (s) | load before / after | cache entries | cache (MB) | rc |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['job']} | {r['cache']} | {r['run']} | {r['wall_s']:.1f} |"
            f" {r['load_1m_before']:.2f} / {r['load_1m_after']:.2f} |"
            f" {r['cache_entries'] if r['cache'] == 'cache' else '-'} |"
            f" {r['cache_mb']:.1f} | {r['returncode']} |"
        )
    lines += ["", "Commands:"] + sorted({f"- `{r['command']}`" for r in rows})
    return lines


if __name__ == "__main__":
    main()
