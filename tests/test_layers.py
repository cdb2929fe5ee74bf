"""The package layers point only down, and no package's modules import each other in a circle.

Floors, lowest first: mjx_arm (the simulator) < tracking (non-learned tracking: metrics, held
commands, mpc, oracle) < ccgan (learned translators) < eval (the shape evaluation) < bench
(timings) and studies (quality studies, which share bench's run header), side by side, <
experiments (the whole chain, run as stages of the commands below it). A module may import its
own floor and the ones below. Every import counts, also one inside a function (a deferred import
still makes the lower layer depend on the higher one), so the modules are read with `ast`, never
imported.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FLOORS = {
    "mjx_arm": 0,
    "tracking": 1,
    "ccgan": 2,
    "eval": 3,
    "bench": 4,
    "studies": 4,
    "experiments": 5,
}


def module_files() -> dict[str, Path]:
    """{dotted module name: file} of every module of the layered packages."""
    out = {}
    for package in FLOORS:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = module_files()


def imported_modules(name: str, path: Path) -> list[tuple[str, int]]:
    """(module imported, line) for every import in a module's file, at any depth.

    `from P import x` names the submodule P.x when there is one (else P itself); `import a.b.c`
    names a.b.c. Relative imports are resolved against the module's package.
    """
    tree = ast.parse(path.read_text(), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                found.append((sub if sub in MODULES else base, node.lineno))
    return sorted(set(found), key=lambda item: (item[1], item[0]))


def floor(module: str) -> int | None:
    return FLOORS.get(module.split(".")[0])


def test_every_layered_package_is_found():
    assert {m.split(".")[0] for m in MODULES} == set(FLOORS)
    assert {"tracking.metrics", "tracking.mpc", "tracking.oracle", "mjx_arm.programs"} <= set(
        MODULES
    )


@pytest.mark.parametrize("package", list(FLOORS))
def test_imports_point_only_down(package):
    wrong = []
    for name, path in MODULES.items():
        if name.split(".")[0] != package:
            continue
        for target, line in imported_modules(name, path):
            if floor(target) is not None and floor(target) > FLOORS[package]:
                rel = path.relative_to(ROOT)
                wrong.append(f"{name} ({rel}:{line}) imports {target}, a higher floor")
    assert not wrong, "\n".join(wrong)


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every strongly connected component of more than one module (Tarjan), as sorted lists."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_cycles_finds_a_circle():
    graph = {"p.a": {"p.b"}, "p.b": {"p.c"}, "p.c": {"p.a"}, "p.d": {"p.a"}}
    assert cycles(graph) == [["p.a", "p.b", "p.c"]]
    assert cycles({"p.a": {"p.b"}, "p.b": set()}) == []


@pytest.mark.parametrize("package", list(FLOORS))
def test_no_import_cycle_inside_a_package(package):
    graph = {}
    for name, path in MODULES.items():
        if name.split(".")[0] == package:
            graph[name] = {
                target
                for target, _ in imported_modules(name, path)
                if target in MODULES and target.split(".")[0] == package and target != name
            }
    found = cycles(graph)
    detail = [
        " <-> ".join(c) + ": " + "; ".join(f"{a} imports {sorted(graph[a] & set(c))}" for a in c)
        for c in found
    ]
    assert not found, "import cycles in " + package + ":\n" + "\n".join(detail)
