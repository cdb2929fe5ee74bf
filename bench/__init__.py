"""Timings: how fast the simulator, training and the oracle run, with committed results.

Each module runs as `python -m bench.NAME` (its docstring gives the command); the committed
results are in bench/results/<machine>/. Studies of accuracy rather than speed live in `studies`;
docs/benchmarks.md lists every benchmark and study with its numbers.
"""

import sys


def run_header(module: str, argv: list[str] | None) -> dict:
    """Where and how a bench ran: {"device", "cpu", "jax", "command"} for its result files."""
    import jax

    from mjx_arm.machine import cpu_model

    device = jax.devices()[0]
    args = argv if argv is not None else sys.argv[1:]
    return {
        "device": f"{device.platform}: {device.device_kind}",
        "cpu": cpu_model(),
        "jax": jax.__version__,
        "command": " ".join([f"python -m {module}", *args]),
    }
