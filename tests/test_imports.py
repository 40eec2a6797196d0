"""The house's layout: stages import one way, and no module imports itself back round a circle.

io -> models -> simulate -> features -> identify -> monitor -> forecast -> diagnose -> store
-> report -> workflows -> cli: a stage may import an earlier one, never a later one
(function-level imports included; ``if TYPE_CHECKING:`` blocks are for the
type checker and left out). The package's top level (errors, the BLAS
limiter) is below every stage.
"""

from __future__ import annotations

import ast
from pathlib import Path

import condmon

SRC = Path(condmon.__file__).resolve().parent
STAGES = ("io", "models", "simulate", "features", "identify", "monitor", "forecast", "diagnose",
          "store", "report", "workflows", "cli")


def _graph() -> dict[str, set[str]]:
    """Each module's imports of condmon modules."""
    mods = {}
    for p in SRC.rglob("*.py"):
        name = ".".join(("condmon", *p.relative_to(SRC).with_suffix("").parts))
        mods[name.removesuffix(".__init__")] = p

    class Imports(ast.NodeVisitor):
        def __init__(self) -> None:
            self.found: set[str] = set()

        def visit_If(self, node: ast.If) -> None:
            if "TYPE_CHECKING" in ast.unparse(node.test):
                for child in node.orelse:
                    self.visit(child)
                return
            self.generic_visit(node)

        def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
            if node.module and node.module.startswith("condmon"):
                subs = {f"{node.module}.{a.name}" for a in node.names} & set(mods)
                self.found |= subs
                if len(subs) < len(node.names) and node.module in mods:
                    self.found.add(node.module)

        def visit_Import(self, node: ast.Import) -> None:
            self.found |= {a.name for a in node.names} & set(mods)

    graph = {}
    for name, path in mods.items():
        v = Imports()
        v.visit(ast.parse(path.read_text(encoding="utf-8")))
        graph[name] = v.found - {name}
    return graph


def _stage(module: str) -> int | None:
    parts = module.split(".")
    return STAGES.index(parts[1]) if len(parts) > 1 and parts[1] in STAGES else None


def test_stages_import_one_way() -> None:
    backwards = sorted(f"{a} imports {b}" for a, deps in _graph().items() for b in deps
                       if (sa := _stage(a)) is not None and (sb := _stage(b)) is not None
                       and sb > sa)
    assert backwards == []


def test_no_module_imports_itself_back() -> None:
    graph = _graph()
    seen: dict[str, int] = {}   # 1: on the path, 2: done
    circles: list[list[str]] = []

    def walk(node: str, path: list[str]) -> None:
        seen[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if seen.get(nxt) == 1:
                circles.append(path[path.index(nxt):] + [nxt])
            elif nxt not in seen:
                walk(nxt, path + [nxt])
        seen[node] = 2

    for start in sorted(graph):
        if start not in seen:
            walk(start, [start])
    assert circles == []
