"""One installed name: a wheel built from this tree holds only ``nbrdf/...``
and its ``nbrdf-<version>.dist-info``; its console scripts point at
``nbrdf.cli``; and every package the source tree has is in it."""
from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """A wheel built (no isolation, no dependencies) from a copy of the tracked
    and new source files, so the build leaves nothing in the work tree."""
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("needs the git work tree")
    src = tmp_path_factory.mktemp("src")
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=REPO, check=True,
                           capture_output=True).stdout.decode().split("\0")
    for name in filter(None, files):
        if (REPO / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / name, src / name)
    out = tmp_path_factory.mktemp("wheel")
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                        "-w", str(out), str(src)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.fail(f"pip wheel failed: {r.stderr[-2000:]}")
    (whl,) = out.glob("nbrdf-*.whl")
    return whl


@pytest.mark.slow
@pytest.mark.ci_slow
def test_wheel_holds_only_the_nbrdf_package(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names}
    dist = [t for t in tops if t.endswith(".dist-info")]
    assert len(dist) == 1 and dist[0].startswith("nbrdf-"), tops
    assert tops == {"nbrdf", dist[0]}, tops
    for pkg in ("cli", "neural", "training", "imaging", "viewer", "viewer/ui", "viewer/assets", "viewer/gpu", "viewer/jobs",
                "viewer/reference", "viewer/scene", "viewer/session"):
        assert f"nbrdf/{pkg}/__init__.py" in names, pkg
    assert "nbrdf/cli/main.py" in names and "nbrdf/cli/view.py" in names
    assert "nbrdf/neural/data/nbrdf_default.safetensors" in names  # the shipped weights
    assert any(n.startswith("nbrdf/viewer/shaders/") and n.endswith(".frag") for n in names)
    assert not any(n.startswith("nbrdf/viewer/cli") or n.endswith("view_cli.py") for n in names)


@pytest.mark.slow
@pytest.mark.ci_slow
def test_wheel_console_scripts_point_at_the_cli(wheel):
    z = zipfile.ZipFile(wheel)
    (ep,) = [n for n in z.namelist() if n.endswith(".dist-info/entry_points.txt")]
    text = z.read(ep).decode()
    assert "nbrdf = nbrdf.cli.main:nbrdf_main" in text
    assert "nbrdf-view = nbrdf.cli.view:main" in text


def test_every_source_package_is_installed():
    """Each folder of the tree holding Python modules is listed in pyproject.toml
    (a new subpackage left out would be missing from a regular install)."""
    import tomllib

    conf = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    dirs = {v: k for k, v in conf["package-dir"].items()}
    assert set(conf["packages"]) == set(conf["package-dir"])
    for folder in ("cli", "neural", "training", "viewer"):
        for d in [REPO / folder, *(p for p in (REPO / folder).rglob("*") if p.is_dir())]:
            rel = d.relative_to(REPO).as_posix()
            if "__pycache__" in rel or not any(d.glob("*.py")):
                continue
            assert rel in dirs, f"{rel} holds modules but is not a package in pyproject.toml"


def test_console_scripts_run():
    """The installed entry points (editable here) import and answer --help."""
    bin_ = Path(sys.executable).parent
    for exe in ("nbrdf", "nbrdf-view"):
        r = subprocess.run([str(bin_ / exe), "--help"], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0 and "usage:" in r.stdout, r.stderr
