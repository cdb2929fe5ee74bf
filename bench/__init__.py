"""Timings: how fast the simulator, training and the oracle run, with committed results.

Each module runs as `python -m bench.NAME` (its docstring gives the command); the committed
results are in bench/results/<machine>/. Studies of accuracy rather than speed live in `studies`;
docs/benchmarks.md lists every benchmark and study with its numbers.
"""

import json
import sys
from pathlib import Path

from mjx_arm.atomic import write_atomically
from mjx_arm.run_folder import check_out


def parse_checked(parser, argv: list[str] | None, prefix: bool = True):
    """`parser.parse_args(argv)`, then `--out` checked before any work: with `prefix`, the
    `.md` file the bench will write (`--out` names a prefix); else a folder it can write or make.
    A usage error (exit 2) names `--out` otherwise, instead of a traceback after the timings."""
    args = parser.parse_args(argv)
    if prefix:
        check_out(parser, "--out", f"{args.out}.md", file=True)
    else:
        check_out(parser, "--out", args.out)
    return args


def run_header(module: str, argv: list[str] | None) -> dict:
    """Where and how a bench ran: {"device", "cpu", "jax", "command"} for its result files."""
    import jax

    from mjx_arm.machine import cpu_model

    device = jax.devices()[0]
    args = argv if argv is not None else sys.argv[1:]
    # On a CPU the kind is the platform again ("cpu"): name it once.
    kind = device.device_kind
    return {
        "device": device.platform if kind == device.platform else f"{device.platform}: {kind}",
        "cpu": cpu_model(),
        "jax": jax.__version__,
        "command": " ".join([f"python -m {module}", *args]),
    }


def write_results(out: str | Path, header: dict, result: dict, title: str, body: list[str]) -> Path:
    """Writes a benchmark's or study's results: OUT.json (`header | result`) and OUT.md (the
    title, the header as a list, then the body lines), each file whole or not at all, so a run
    stopped while writing leaves the earlier results readable. Returns the .md file's path."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    data = json.dumps(header | result, indent=2).encode()
    write_atomically(out.with_suffix(".json"), lambda f: f.write(data))
    lines = [f"# {title}", "", *(f"- {key}: {value}" for key, value in header.items()), *body]
    text = ("\n".join(lines) + "\n").encode()
    return write_atomically(out.with_suffix(".md"), lambda f: f.write(text))
