"""The refined-code cache (``training.refined_cache``): keyed on the material's content, the decoder and the
warm start; a damaged file is no entry."""
from __future__ import annotations

from pathlib import Path

import pytest

from nbrdf.neural.material import load_material
from nbrdf.neural.model import default_model
from nbrdf.training import refined_cache as C
from nbrdf.training.refine import RefineState

LOOKDEV = Path(C.__file__).parent / "sets" / "lookdev"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return tmp_path / "cache" / "nbrdf" / "refined"


@pytest.fixture(scope="module")
def model():
    return default_model()


def gold():
    return load_material(LOOKDEV / "coated-gold.json")


def test_a_cached_code_is_keyed_on_its_warm_start(cache, model):
    """A refined code made from another network code (a bundle's new encoder, decision 124) is not served; float
    jitter of the same start (relative 1e-6, as between callers) is."""
    m = gold()
    z = model.material_latent(m)
    C.save_cached(m, model.decoder.weights_id(), z, RefineState(z + 0.1, 1.0, 0.5, converged=True), budget=10.0)
    assert C.load_cached(m, model.decoder.weights_id(), z * (1 + 1e-6)) is not None
    moved = z.clone()
    moved[1, 5] += 0.05
    assert C.load_cached(m, model.decoder.weights_id(), moved) is None


def test_a_damaged_cache_file_is_ignored(cache, model):
    m = gold()
    cache.mkdir(parents=True)
    z = model.material_latent(m)
    C.cache_path(m, model.decoder.weights_id(), z).write_text("{not json")
    assert C.load_cached(m, model.decoder.weights_id(), z) is None
