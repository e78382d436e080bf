"""The package's architecture as tests: subpackages import downward only, never in a cycle, and library
code speaks Python (parameter names), not command-line flags."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "kinfu_cli"

# Bottom to top. A module may import its own subpackage and any subpackage of a lower layer; subpackages
# on one layer do not import each other. The top-level modules (cli, demo, warmup, __main__) sit above commands.
LAYERS: list[set[str]] = [
    {"core"},
    {"io"},
    {"fusion", "sim"},
    {"attention", "segmentation", "change"},
    {"nbv", "grasp", "localization"},
    {"evaluation"},
    {"api"},
    {"batch"},
    {"report"},
    {"commands"},
    {"cli"},
    {"demo", "warmup", "__main__"},
]
# Plots still called from two library pipelines; the renovation moves them into the commands.
_BEING_MOVED: set[tuple[str, str]] = set()
LAYER_OF = {name: i for i, layer in enumerate(LAYERS) for name in layer}


def _unit(module: str) -> str:
    """'kinfu_cli.fusion.volume' -> 'fusion'; 'kinfu_cli.cli' -> 'cli'; 'kinfu_cli' -> ''."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path) -> list[tuple[str, int]]:
    """(imported kinfu_cli module, line) for every import in the file, at any depth."""
    module = _module_name(path)
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names if a.name.startswith("kinfu_cli")]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target == "kinfu_cli":  # `from kinfu_cli import x`: x is the unit
                out += [(f"kinfu_cli.{a.name}", node.lineno) for a in node.names]
            elif target.startswith("kinfu_cli."):
                out.append((target, node.lineno))
    return out


def _edges() -> dict[tuple[str, str], list[str]]:
    edges: dict[tuple[str, str], list[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        src = _unit(_module_name(path))
        if not src:
            continue  # kinfu_cli/__init__.py imports nothing of the package
        for target, line in _imports(path):
            dst = _unit(target)
            if dst and dst != src and dst != "__version__":
                edges.setdefault((src, dst), []).append(f"{path.relative_to(PACKAGE.parent)}:{line}")
    return edges


def test_every_subpackage_has_a_layer():
    units = {_unit(_module_name(p)) for p in PACKAGE.rglob("*.py")} - {""}
    assert units <= set(LAYER_OF), f"add to LAYERS: {sorted(units - set(LAYER_OF))}"


def test_no_upward_or_sideways_import():
    bad = [f"{a} -> {b} ({', '.join(sites[:3])})" for (a, b), sites in sorted(_edges().items())
           if LAYER_OF[b] >= LAYER_OF[a] and (a, b) not in _BEING_MOVED]
    assert not bad, "imports against the layering:\n" + "\n".join(bad)


def test_import_graph_has_no_cycle():
    graph: dict[str, set[str]] = {}
    for a, b in _edges():
        if (a, b) not in _BEING_MOVED:
            graph.setdefault(a, set()).add(b)
    state: dict[str, int] = {}

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                pytest.fail("import cycle: " + " -> ".join(trail[trail.index(nxt):] + [node, nxt])
                            if nxt in trail else f"import cycle through {node} -> {nxt}")
            if nxt not in state:
                visit(nxt, trail + [node])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])


def test_core_imports_no_stage():
    stages = {u for u in LAYER_OF if u != "core"}
    bad = [(a, b) for a, b in _edges() if a == "core" and b in stages]
    assert not bad
# "--flag" inside a string literal of library code (outside commands/, cli.py, demo.py)
_FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9]*(?:-[a-z0-9]+)*")


def test_library_code_names_parameters_not_flags():
    hits = []
    for path in sorted(PACKAGE.rglob("*.py")):
        unit = _unit(_module_name(path))
        if LAYER_OF.get(unit, 0) >= LAYER_OF["commands"] or not unit:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                for m in _FLAG.finditer(node.value):
                    hits.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}: {m.group(0)}")
    assert not hits, "library code mentions command-line flags:\n" + "\n".join(hits)


MAX_LINES = 120


def test_long_functions_say_why_in_their_docstring():
    """A function over MAX_LINES lines is a hot-path kernel kept whole on purpose; its docstring says why
    (and contains "on purpose")."""
    long = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                doc = (ast.get_docstring(node) or "").lower()
                if n > MAX_LINES and "on purpose" not in doc:
                    long.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno} {node.name} ({n} lines)")
    assert not long, "functions over 120 lines without a reason:\n" + "\n".join(long)
