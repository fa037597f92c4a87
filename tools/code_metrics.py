"""Size and import-cycle figures of the package, measured from outside.

Prints every function over ``--function`` lines, class over ``--class`` lines
and module over ``--module`` lines (defaults: the project's targets, 100, 400
and 600), then every import cycle between the package's modules (function-level
and ``if TYPE_CHECKING:`` imports included), then the import statements inside
function bodies: at most ``--late-imports``, each with a comment saying why it
is late. Exit status 1 when anything is over a limit, a cycle exists or a late
import has no comment, so a check can call it; ``--report`` always exits 0.

    python tools/code_metrics.py [--function 100] [--class 400] [--module 600] [--late-imports 150] [--report]
"""
from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: Repository folder -> the package it is installed as (pyproject.toml's package-dir).
PACKAGES = {"cli": "nbrdf.cli", "neural": "nbrdf.neural", "training": "nbrdf.training", "imaging": "nbrdf.imaging",
            "viewer": "nbrdf.viewer", "mitsuba_plugin": "nbrdf.mitsuba"}


def modules() -> dict[str, Path]:
    """Installed module name -> source file, for every module of the package."""
    out = {}
    for folder, package in PACKAGES.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            parts = list(path.relative_to(ROOT / folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([package, *parts])] = path
    return out


def _span(node: ast.AST) -> int:
    return node.end_lineno - node.lineno + 1  # type: ignore[attr-defined,operator]


def sizes(mods: dict[str, Path]) -> tuple[list, list, list]:
    """(lines, name) of every function, class and module."""
    functions, classes, files = [], [], []
    for name, path in mods.items():
        text = path.read_text(encoding="utf-8")
        files.append((len(text.splitlines()), name))
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                functions.append((_span(node), f"{name}.{node.name}"))
            elif isinstance(node, ast.ClassDef):
                classes.append((_span(node), f"{name}.{node.name}"))
    return functions, classes, files


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """ids of the import nodes inside ``if TYPE_CHECKING:`` blocks."""
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for inner in node.body:
                skip.update(id(n) for n in ast.walk(inner))
    return skip


def imports(mods: dict[str, Path], type_checking: bool = True) -> dict[str, set[str]]:
    """Module -> the package modules it imports anywhere in its source; with ``type_checking`` the imports under
    ``if TYPE_CHECKING:`` count too (a circle they hold is still a circle a reader must follow)."""
    graph: dict[str, set[str]] = {}
    for name, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip = set() if type_checking else _type_checking_nodes(tree)
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found = set()
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            if isinstance(node, ast.Import):
                found.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                found.add(base)
                found.update(f"{base}.{a.name}" for a in node.names)
        graph[name] = {m for m in found if m in mods and m != name}
    return graph


def function_imports(mods: dict[str, Path]) -> list[tuple[str, int, str]]:
    """(module, line, the line's comment or "") of every import statement inside a function body."""
    out = []
    for name, path in mods.items():
        text = path.read_text(encoding="utf-8")
        lines = text.splitlines()
        seen: set[int] = set()
        for fn in ast.walk(ast.parse(text)):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in seen:
                    seen.add(id(node))
                    span = lines[node.lineno - 1: node.end_lineno]  # type: ignore[misc]
                    comment = next((s.split("#", 1)[1].strip() for s in span if "#" in s), "")
                    out.append((name, node.lineno, comment))
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
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
        for w in sorted(graph[v]):
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

    sys.setrecursionlimit(10_000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--function", type=int, default=100, help="largest function, lines")
    ap.add_argument("--class", dest="klass", type=int, default=400, help="largest class, lines")
    ap.add_argument("--module", type=int, default=600, help="largest module, lines")
    ap.add_argument("--late-imports", type=int, default=150, help="most import statements inside function bodies")
    ap.add_argument("--report", action="store_true", help="print only; exit 0 whatever is found")
    args = ap.parse_args(argv)
    mods = modules()
    functions, classes, files = sizes(mods)
    over = 0
    for label, items, limit in (("functions", functions, args.function), ("classes", classes, args.klass),
                                ("modules", files, args.module)):
        big = sorted((x for x in items if x[0] > limit), reverse=True)
        top = max(items)
        print(f"{label} over {limit} lines: {len(big)} (largest: {top[1]}, {top[0]} lines)")
        for n, name in big:
            print(f"  {n:5d}  {name}")
        over += len(big)
    found = cycles(imports(mods))
    print(f"import cycles (function-level and TYPE_CHECKING imports included): {len(found)}")
    for comp in found:
        print("  " + " <-> ".join(comp))
    late = function_imports(mods)
    bare = [(m, line) for m, line, comment in late if not comment]
    print(f"imports inside function bodies: {len(late)} (limit {args.late_imports}), without a comment: {len(bare)}")
    for m, line in bare:
        print(f"  {m}:{line}")
    bad = over or found or bare or len(late) > args.late_imports
    return 0 if args.report or not bad else 1


if __name__ == "__main__":
    sys.exit(main())
