"""Quality studies: what a setting or a method changes in accuracy, with committed results.

Each module runs as `python -m studies.NAME` (its docstring gives the command that wrote its
results) and writes its tables to studies/results/<machine>/. Timings live in `bench`, whose
run header the studies share; docs/benchmarks.md lists every study and benchmark with its
numbers.
"""

from __future__ import annotations

import json
from pathlib import Path

from mjx_arm.atomic import write_atomically


def write_study(out: str | Path, header: dict, result: dict, title: str, body: list[str]) -> Path:
    """Writes a study's results: OUT.json (`header | result`) and OUT.md (the title, the header
    as a list, then the body lines), each file whole or not at all, so a study stopped while
    writing leaves its earlier results readable. Returns the .md file's path."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    data = json.dumps(header | result, indent=2).encode()
    write_atomically(out.with_suffix(".json"), lambda f: f.write(data))
    lines = [f"# {title}", "", *(f"- {key}: {value}" for key, value in header.items()), *body]
    text = ("\n".join(lines) + "\n").encode()
    return write_atomically(out.with_suffix(".md"), lambda f: f.write(text))
