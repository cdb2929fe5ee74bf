"""Peak memory of one chunk of MuJoCo C rollouts (`mjx_arm.arm.C_CHUNK` trajectories per call).

`Arm.rollout(..., backend="c")` runs its batch `chunk` trajectories at a time, each call holding
every substep's state of a 5 s slice. For each chunk size a fresh process loads the arm, runs one
trajectory (so the model, the thread pool and the imports are paid), reads its peak resident set
(`resource.getrusage`, ru_maxrss), then rolls out one chunk of `--seconds`-long programs from rest
and reads the peak again; the difference is the chunk's cost. Writes c_chunk_memory.{md,json}.

    python -m bench.c_chunk_memory --out bench/results/cpu/c_chunk_memory
"""

from __future__ import annotations

import json
import subprocess
import sys

from ccgan.cli import cli_parser

#: What one measuring process runs: load, warm up on one trajectory, then one chunk.
_CHILD = """
import json, resource, sys
import numpy as np
import mjx_arm
from mjx_arm.programs import random_held_programs
model, chunk, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
arm = mjx_arm.load(None if model == "default" else model)
rng = np.random.default_rng(0)
arm.rollout(random_held_programs(rng, 1, steps), backend="c", chunk=chunk)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
arm.rollout(random_held_programs(rng, chunk, steps), backend="c", chunk=chunk)
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"chunk": chunk, "model_hash": arm.model_hash, "nq": arm.mj_model.nq,
                  "nu": arm.mj_model.nu,
                  "peak_before_mb": before / 1024, "peak_after_mb": after / 1024}))
"""


def measure(model: str, chunk: int, seconds: float) -> dict:
    """One fresh process's peak RSS (MB, ru_maxrss in KiB on Linux) before and after a chunk."""
    steps = int(round(seconds * 10))
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, model, str(chunk), str(steps)],
        capture_output=True,
        text=True,
        check=True,
    )
    row = json.loads(out.stdout.strip().splitlines()[-1])
    row["chunk_mb"] = row["peak_after_mb"] - row["peak_before_mb"]
    row["per_trajectory_mb"] = row["chunk_mb"] / chunk
    return row


def main(argv=None) -> None:
    """CLI: measure each --chunks size and write the table."""
    from bench import parse_checked, run_header, write_results
    from mjx_arm.arm import C_CHUNK

    p = cli_parser("bench.c_chunk_memory", __doc__)
    p.add_argument("--model", default="default", help="MJCF (default: models/softarm.xml)")
    p.add_argument("--chunks", type=int, nargs="+", default=[64, C_CHUNK], help="chunk sizes")
    p.add_argument("--seconds", type=float, default=10.0, help="program length (s), >= 5")
    p.add_argument("--out", required=True, help="output prefix (writes .md and .json)")
    a = parse_checked(p, argv)
    if min(a.chunks) < 1 or a.seconds < 5:
        p.error("--chunks must be >= 1 and --seconds >= 5 (one whole 5 s slice)")
    header = run_header("bench.c_chunk_memory", argv)
    rows = []
    for chunk in a.chunks:
        rows.append(measure(a.model, chunk, a.seconds))
        print(json.dumps(rows[-1]), flush=True)
    header["model"] = f"{a.model} (model hash {rows[0]['model_hash']}, nq {rows[0]['nq']})"
    body = [
        "",
        f"Programs of {a.seconds:g} s from rest; each row a fresh process; peak resident set"
        " (ru_maxrss) after one warm-up trajectory, then after one chunk.",
        "",
        "| chunk | peak before (MB) | peak after (MB) | chunk (MB) | per trajectory (MB) |",
        "|---|---|---|---|---|",
    ]
    body += [
        f"| {r['chunk']} | {r['peak_before_mb']:.0f} | {r['peak_after_mb']:.0f} |"
        f" {r['chunk_mb']:.0f} | {r['per_trajectory_mb']:.2f} |"
        for r in rows
    ]
    md = write_results(a.out, header, {"rows": rows}, "MuJoCo C: memory of one rollout chunk", body)
    print(md.read_text())


if __name__ == "__main__":
    main()
