"""The package's shape: one-way layers (import-linter's contract in pyproject.toml), no import cycle at
all, modules of a readable size, and docs generated from the code still in step with it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import grimp

from koopguide.bus import status

REPO = Path(__file__).resolve().parents[2]
MAX_MODULE_LINES = 400


def test_layer_contract_is_kept():
    lint = Path(sys.executable).with_name("lint-imports")
    result = subprocess.run([str(lint)], cwd=REPO, capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stdout[-3000:]
    assert "1 kept, 0 broken" in result.stdout


def test_no_import_cycle_anywhere():
    graph = grimp.build_graph("koopguide", "sitl")
    modules = sorted(graph.modules)
    edges = {m: set(graph.find_modules_directly_imported_by(m)) for m in modules}
    # Tarjan's strongly connected components: any component of two or more modules is a cycle.
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges.get(v, ()):
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
                cycles.append(sorted(component))

    sys.setrecursionlimit(10_000)
    for v in modules:
        if v not in index:
            visit(v)
    # A package's __init__ that re-exports its own submodule is not a cycle of logic.
    cycles = [c for c in cycles if not (len(c) == 2 and c[1].startswith(c[0] + "."))]
    assert cycles == []


def test_modules_stay_readable():
    sizes = {p: len(p.read_text().splitlines()) for d in ("koopguide", "sitl") for p in (REPO / d).rglob("*.py")}
    too_long = {str(p.relative_to(REPO)): n for p, n in sizes.items() if n > MAX_MODULE_LINES}
    assert too_long == {}


def test_status_table_in_the_docs_is_generated_from_the_schema():
    text = (REPO / "docs" / "zenoh.md").read_text()
    assert status.markdown_table() in text
