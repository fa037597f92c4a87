"""Mutation testing of the pure-Python core with mutmut (`make mutation`).

mutmut imports the mutated copy of a module under the name its path gives, and the repository's folders
install as ``nbrdf.<folder>`` through setuptools' package-dir mapping, so it cannot run from the repository
root. This script lays out a staging tree under ``build/mutation`` whose ``nbrdf/<package>`` entries link to
the repository's folders (``tests`` and ``pyproject.toml`` beside them), runs ``mutmut run`` there (mutmut
copies the sources into ``mutants/nbrdf/...``, which the tests then import as ``nbrdf.*``) and prints the kill
rate per module and overall from mutmut's result files. The modules mutated and the fast unit tests that
run against them are ``[tool.mutmut]`` in pyproject.toml.

A kept staging tree is reused (mutmut retests only mutants whose function changed); ``--fresh`` removes it.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tomllib
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: nbrdf.<name> -> repository folder (pyproject's [tool.setuptools.package-dir]).
PACKAGES = {"neural": "neural", "training": "training", "imaging": "imaging", "viewer": "viewer", "cli": "cli"}
#: Verdicts that count as killed: a test failed, the mutant ran past its time, or it crashed the interpreter.
KILLED = ("killed", "timeout", "segfault", "caught by type check")
#: Verdicts that count as alive: every selected test passed, or none of them reaches the mutated function.
ALIVE = ("survived", "no tests", "suspicious")


def verdict(code: int | None) -> str:
    """mutmut's own name for a mutant's recorded exit code."""
    from mutmut.stats import status_by_exit_code

    return status_by_exit_code[code]


def stage(staging: Path) -> None:
    """Links the packages, the tests and pyproject.toml into the staging tree. The repository's folders are
    also linked beside the copied tests in ``mutants/`` (read-only data there: tests that find presets or
    shaders from their own path); the code the tests import comes from ``mutants/nbrdf``."""
    (staging / "nbrdf").mkdir(parents=True, exist_ok=True)
    (staging / "mutants").mkdir(exist_ok=True)
    for name, folder in PACKAGES.items():
        for link in (staging / "nbrdf" / name, staging / "mutants" / folder):
            if not link.exists():
                link.symlink_to(ROOT / folder, target_is_directory=True)
    if not (staging / "tests").exists():
        (staging / "tests").symlink_to(ROOT / "tests", target_is_directory=True)
    shutil.copy2(ROOT / "pyproject.toml", staging / "pyproject.toml")


def summarise(staging: Path) -> dict[str, Counter]:
    """Per mutated module, the count of each verdict, read from mutmut's ``mutants/**/*.py.meta`` files."""
    out: dict[str, Counter] = {}
    for meta in sorted((staging / "mutants").rglob("*.py.meta")):
        data = json.loads(meta.read_text())
        module = meta.relative_to(staging / "mutants").with_suffix("").with_suffix("").as_posix()
        out[module] = Counter(verdict(c) for c in data.get("exit_code_by_key", {}).values())
    return out


def report(counts: dict[str, Counter]) -> str:
    """A table of the kill rate (killed / (killed + alive)) per module and overall; "other" are mutants not
    run (skipped, interrupted), left out of the rate."""
    lines = [f"{'module':36s} {'killed':>7s} {'alive':>8s} {'other':>6s} {'kill rate':>9s}"]
    total: Counter = Counter()
    for module, c in counts.items():
        total.update(c)
        lines.append(_row(module, c))
    lines.append(_row("overall", total))
    return "\n".join(lines)


def _row(name: str, c: Counter) -> str:
    killed = sum(c[v] for v in KILLED)
    alive = sum(c[v] for v in ALIVE)
    rate = f"{100.0 * killed / (killed + alive):8.1f}%" if killed + alive else "      -"
    other = sum(c.values()) - killed - alive
    return f"{name:36s} {killed:7d} {alive:8d} {other:6d} {rate:>9s}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--staging", type=Path, default=ROOT / "build" / "mutation", help="the staging tree")
    ap.add_argument("--fresh", action="store_true", help="remove a kept staging tree (and its results) first")
    ap.add_argument("--max-children", type=int, default=2, help="mutants tested at once")
    ap.add_argument("--report-only", action="store_true", help="print the table of the last run, run nothing")
    ap.add_argument("--json", type=Path, help="also write the per-module counts here")
    args = ap.parse_args(argv)
    if "mutmut" not in tomllib.loads((ROOT / "pyproject.toml").read_text()).get("tool", {}):
        print("mutation: pyproject.toml has no [tool.mutmut] section", file=sys.stderr)
        return 2
    staging = args.staging
    if args.fresh and staging.exists():
        shutil.rmtree(staging)
    if not args.report_only:
        stage(staging)
        mutmut = Path(sys.executable).parent / "mutmut"
        # One thread per worker: the mutants run side by side on a shared machine.
        env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
        rc = subprocess.call([str(mutmut), "run", "--max-children", str(args.max_children)], cwd=staging, env=env)
        if rc not in (0, 1):
            print(f"mutation: mutmut run exited {rc}", file=sys.stderr)
            return rc
    counts = summarise(staging)
    if not counts:
        print(f"mutation: no mutmut results under {staging / 'mutants'}", file=sys.stderr)
        return 2
    print(report(counts))
    if args.json:
        args.json.write_text(json.dumps({m: dict(c) for m, c in counts.items()}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
