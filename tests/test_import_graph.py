"""Imports run one way (STYLE.md; issue 38): no import circle among the modules of repro/,
counting every import -- at the top, inside a function, and under ``TYPE_CHECKING`` (a
circle hidden there is still a circle of concerns) -- and nothing in repro/ imports
experiments/."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _modules(package: str) -> dict[str, Path]:
    out = {}
    for f in (ROOT / package).rglob("*.py"):
        parts = f.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = f
    return out


def import_graph(package: str = "repro") -> dict[str, set[str]]:
    """module -> the modules of ``package`` (and of experiments/) it imports anywhere."""
    mods = {**_modules(package), **_modules("experiments")}
    graph: dict[str, set[str]] = defaultdict(set)
    for name, path in _modules(package).items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            graph[name] |= {t for t in targets if t in mods and t != name}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_circle_in_repro() -> None:
    assert circles(import_graph()) == []


def test_repro_never_imports_experiments() -> None:
    bad = {m: sorted(t for t in ts if t.startswith("experiments"))
           for m, ts in import_graph().items() if any(t.startswith("experiments") for t in ts)}
    assert bad == {}


def test_the_circle_finder_finds_a_circle_and_only_that() -> None:
    """The two circles issue 38 found, as they were: each is one component."""
    graph = {"repro.runs.trace": {"repro.runs.validate"},
             "repro.runs.validate": {"repro.runs.trace", "repro.runs.columns"},
             "repro.sensors.camera": {"repro.sensors.camera_window"},
             "repro.sensors.camera_window": {"repro.sensors.camera"},
             "repro.runs.columns": set()}
    assert sorted(circles(graph)) == [["repro.runs.trace", "repro.runs.validate"],
                                      ["repro.sensors.camera", "repro.sensors.camera_window"]]
