"""The package plan of docs/ARCHITECTURE.md, held from outside the code: its "may import" table, the names it
gives, no import cycle (``TYPE_CHECKING`` imports counted), late imports few and each explained, and no
definition the tree never uses (vulture, with the Python-protocol and library-callback names it cannot see
listed in tools/vulture_whitelist.py)."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))
import code_metrics  # noqa: E402  (tools/ is not a package)

ARCH = (ROOT / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
MODS = code_metrics.modules()
GRAPH = code_metrics.imports(MODS, type_checking=True)
#: The installed package a repository folder is (pyproject.toml's package-dir).
FOLDERS = {"neural": "nbrdf.neural", "training": "nbrdf.training", "imaging": "nbrdf.imaging",
           "mitsuba_plugin": "nbrdf.mitsuba", "cli": "nbrdf.cli", "viewer": "nbrdf.viewer"}


def _table() -> dict[str, list[str]]:
    """Folder (dotted package) -> the packages its "may import" cell names, from ARCHITECTURE's table."""
    rows = {}
    for line in ARCH.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or not cells[0].startswith("`") or "/" not in cells[0]:
            continue
        folder = cells[0].strip("`").rstrip("/")
        top, _, sub = folder.partition("/")
        if top not in FOLDERS:
            continue
        package = FOLDERS[top] + ("." + sub.replace("/", ".") if sub else "")
        rows[package] = re.findall(r"`([\w.]+)`", cells[2])
    return rows


TABLE = _table()


def _package_of(module: str) -> str:
    """The table row a module belongs to: its deepest package that has a row."""
    parts = module.split(".")
    for n in range(len(parts), 1, -1):
        if ".".join(parts[:n]) in TABLE:
            return ".".join(parts[:n])
    raise AssertionError(f"{module}: no row of docs/ARCHITECTURE.md's table holds it")


def _allowed(row: str, target: str) -> bool:
    names = TABLE[row]
    if "all" in names:
        return True
    home = _package_of(target)
    if home == row:
        return True
    return any(home == "nbrdf." + n.replace("mitsuba_plugin", "mitsuba") for n in names)


def test_the_table_has_a_row_for_every_package():
    for folder in ("neural", "training", "imaging", "viewer", "viewer.gpu", "viewer.scene", "viewer.reference",
                   "viewer.jobs", "viewer.session", "viewer.ui", "mitsuba", "cli"):
        assert "nbrdf." + folder in TABLE, folder


def test_every_module_imports_only_what_its_row_allows():
    wrong = [f"{m} -> {t}" for m, targets in GRAPH.items() for t in targets
             if not _allowed(_package_of(m), t)]
    assert not wrong, "imports against docs/ARCHITECTURE.md's table:\n" + "\n".join(sorted(wrong))


def test_the_plugin_never_imports_the_previewer():
    for path in (ROOT / "mitsuba_plugin").rglob("*.py"):
        assert "nbrdf.viewer" not in path.read_text(encoding="utf-8"), path


def test_only_the_window_imports_the_panels():
    """viewer/ui (the window and its panels) is the top of the previewer: no library module imports it; the
    command line opens the window through it."""
    wrong = [f"{m} -> {t}" for m, targets in GRAPH.items() for t in targets
             if t.startswith("nbrdf.viewer.ui") and not m.startswith(("nbrdf.viewer.ui", "nbrdf.cli"))]
    assert not wrong, wrong


def test_no_import_cycles_counting_type_checking_imports():
    assert code_metrics.cycles(GRAPH) == []


def test_late_imports_are_few_and_each_says_why():
    late = code_metrics.function_imports(MODS)
    bare = [f"{m}:{line}" for m, line, comment in late if not comment]
    assert not bare, "imports inside functions without a comment saying why:\n" + "\n".join(bare)
    assert len(late) <= 150, len(late)


def test_every_class_the_architecture_names_exists():
    source = "\n".join(p.read_text(encoding="utf-8") for p in MODS.values())
    defined = set(re.findall(r"^\s*class (\w+)", source, flags=re.M))
    named = {n for n in re.findall(r"`([A-Z][A-Za-z]+)(?:[.`(])", ARCH)}
    named |= set(re.findall(r"\b([A-Z][a-z]+(?:[A-Z][a-z]+)+)\b", ARCH))
    missing = sorted(n for n in named if n not in defined)
    assert not missing, f"docs/ARCHITECTURE.md names classes that do not exist: {missing}"


def test_every_file_the_architecture_names_exists():
    paths = set(re.findall(r"\b([\w/]+\.(?:py|glsl|frag|comp|vert|sh))\b", ARCH))
    tree = [q.relative_to(ROOT).as_posix() for folder in (*FOLDERS, "tools", "tests") for q in (ROOT / folder).rglob("*")]
    missing = [p for p in paths if not any(q == p or q.endswith("/" + p) for q in tree)]
    assert not missing, f"docs/ARCHITECTURE.md names files that do not exist: {sorted(missing)}"


@pytest.mark.skipif(shutil.which("vulture") is None and not (Path(sys.executable).parent / "vulture").exists(),
                    reason="vulture is a test dependency; install the test extra")
def test_no_definition_is_referenced_nowhere():
    exe = shutil.which("vulture") or str(Path(sys.executable).parent / "vulture")
    folders = ["cli", "neural", "training", "imaging", "viewer", "mitsuba_plugin", "tests", "tools"]
    out = subprocess.run([exe, *folders, "tools/vulture_whitelist.py", "--min-confidence", "60",
                          "--exclude", ".venv,build"], cwd=ROOT, capture_output=True, text=True)
    found = [line for line in out.stdout.splitlines() if not line.startswith(("tests/", "tools/"))]
    assert not found, "definitions referenced nowhere in the tree:\n" + "\n".join(found)
