"""What every study's command line checks before any work: that its --out can be written.

A study writes OUT.json and OUT.md (`bench.write_results`) or a folder OUT; both need OUT's
nearest existing parent to be a writable folder and OUT not to be a file. Checking it after
parsing, before the minutes of simulation, turns an OSError at the end into a usage error at the
start (`mjx_arm.run_folder.check_writable_folder`).
"""

from __future__ import annotations

import argparse

from mjx_arm.run_folder import check_writable_folder


def parse_checked_args(
    parser: argparse.ArgumentParser, argv: list[str] | None = None
) -> argparse.Namespace:
    """`parser.parse_args(argv)`, then a usage error (exit status 2) naming --out when the
    output cannot be written there.

    Returns:
      The parsed arguments.
    """
    args = parser.parse_args(argv)
    out = getattr(args, "out", None)
    if out is not None:
        try:
            check_writable_folder(out)
        except OSError as err:
            parser.error(f"--out: {err}")
    return args
