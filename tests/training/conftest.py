"""Fixtures shared by the render-space tests of the shipped networks and of the
projection: the cached sphere references, the sphere's geometry, the materials."""
from __future__ import annotations

import numpy as np
import pytest
import shipped_renders as sr


@pytest.fixture(scope="session")
def sphere_references():
    """The cached Monte Carlo sphere renders (``shipped_renders.REFERENCES``)."""
    return np.load(sr.REFERENCES)


@pytest.fixture(scope="session")
def sphere_geometry():
    """The 48 x 48 sphere's directions and cosines."""
    return sr.geometry()


@pytest.fixture(scope="session")
def sphere_materials():
    """The materials the references were rendered from, by name."""
    return {n: sr.material(n) for n in sr.NAMES}


@pytest.fixture
def refined_cache_dir(tmp_path, monkeypatch):
    """A private refined-code cache (``training.refined_cache``): its folder, not yet made."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return tmp_path / "cache" / "nbrdf" / "refined"
