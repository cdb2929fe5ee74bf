"""Benchmarks whose results are committed under bench/results (see each module's docstring)."""

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
