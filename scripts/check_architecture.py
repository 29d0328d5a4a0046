"""Check the package layering and the length of functions in ``src/hazardhunt``.

Imports flow one way, from the top of this list to the bottom: a module may import its own
package and any package below it, never one above (``docs/design.md`` explains each layer).
Imports inside functions count too. The script also lists every function longer than
``MAX_FUNCTION_LINES`` lines (its docstring not counted) whose docstring does not say why it is
long (a docstring containing "long because"), and every module over ``MAX_MODULE_LINES`` lines
whose docstring does not say why.

    python scripts/check_architecture.py           # exit 1 on a violation
    python scripts/check_architecture.py --graph   # also print the package import graph
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import defaultdict
from pathlib import Path

LAYERS = (
    "templates",  # files `hazardhunt new-sut` writes for a user to edit: nothing imports them
    "benchmark",  # the benchmarks' own systems under test, plug-ins: nothing imports them
    "cli",
    "cases",
    "analysis",
    "likelihood",
    "campaign",
    "testers",
    "env",
    "sim",
    "spec",
    "sut",
    "world",
)
"""The packages of ``hazardhunt``, top first; the package root (``hazardhunt/__init__.py``:
version, registration) is below them all."""

MAX_FUNCTION_LINES = 60
MAX_MODULE_LINES = 500
"""A longer module says why in its docstring ("long ... because")."""
SOURCE = Path(__file__).resolve().parents[1] / "src" / "hazardhunt"


def package_of(path: Path) -> str:
    """The layer a module belongs to (``""`` for the package root)."""
    parts = path.relative_to(SOURCE).with_suffix("").parts
    if len(parts) == 1 and parts[0] not in LAYERS:  # a module of the root: __init__, errors
        return ""
    return parts[0]


def imported_packages(tree: ast.AST) -> set[tuple[str, int]]:
    """The ``hazardhunt`` packages a module imports, with the line of each import."""
    found = set()
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        for name in names:
            parts = name.split(".")
            if parts[0] == "hazardhunt":
                package = parts[1] if len(parts) > 1 else ""
                found.add((package if package in LAYERS else "", node.lineno))
    return found


def rank(package: str) -> int:
    """How low a package sits: the root 0, ``world`` 1, ..., ``cli`` the highest."""
    return 0 if package == "" else len(LAYERS) - LAYERS.index(package)


def long_functions(tree: ast.AST) -> list[tuple[str, int, int]]:
    """Functions over the limit whose docstring does not explain it: name, line, length (its
    lines from the ``def`` to its end, without the docstring)."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            length = (node.end_lineno or node.lineno) - node.lineno + 1
            docstring = ast.get_docstring(node) or ""
            first = node.body[0]
            if docstring and isinstance(first, ast.Expr):
                length -= (first.end_lineno or first.lineno) - first.lineno + 1
            if length > MAX_FUNCTION_LINES and "long because" not in docstring:
                found.append((node.name, node.lineno, length))
    return found


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--graph", action="store_true", help="print the package import graph")
    args = parser.parse_args()
    problems = []
    graph: dict[str, set[str]] = defaultdict(set)
    for path in sorted(SOURCE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        package = package_of(path)
        where = path.relative_to(SOURCE.parent)
        if package not in ("", *LAYERS):
            problems.append(f"{where}: package {package!r} is not in LAYERS")
            continue
        for imported, line in sorted(imported_packages(tree)):
            if imported == package:
                continue
            graph[package or "(root)"].add(imported or "(root)")
            if imported not in ("", *LAYERS) or rank(imported) > rank(package):
                problems.append(f"{where}:{line}: {package or 'root'} imports {imported}, above it")
        lines = len(path.read_text(encoding="utf-8").splitlines())
        docstring = (ast.get_docstring(tree) or "").lower()
        if lines > MAX_MODULE_LINES and not ("long" in docstring and "because" in docstring):
            problems.append(
                f"{where}: {lines} lines (over {MAX_MODULE_LINES}; split it, or say why in its "
                "docstring: 'long because ...')"
            )
        for name, line, length in long_functions(tree):
            problems.append(
                f"{where}:{line}: {name} has {length} lines (over {MAX_FUNCTION_LINES}; "
                "say why in its docstring: 'long because ...')"
            )
    if args.graph:
        for package in (*LAYERS, "(root)"):
            if package in graph:
                print(f"{package:9} -> {', '.join(sorted(graph[package], key=rank_name))}")
    for problem in problems:
        print(problem)
    print(f"{len(problems)} problems in {SOURCE}")
    return 1 if problems else 0


def rank_name(package: str) -> int:
    return rank("" if package == "(root)" else package)


if __name__ == "__main__":
    sys.exit(main())
