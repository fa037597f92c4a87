"""The refined-code cache (``training.refined_cache``): keyed on the material's content, the decoder and the
warm start; a damaged file is no entry."""
from __future__ import annotations

from pathlib import Path

import pytest

from nbrdf.neural.material import load_material
from nbrdf.neural.model import default_model
from nbrdf.training import refined_cache as C
from nbrdf.training.refine import RefineState


@pytest.fixture(scope="module")
def gold_start():
    """(material, decoder id, network code) of the look-development coated gold."""
    m = load_material(Path(C.__file__).parent / "sets" / "lookdev" / "coated-gold.json")
    model = default_model()
    return m, model.decoder.weights_id(), model.material_latent(m)


def test_a_cached_code_is_keyed_on_its_warm_start(refined_cache_dir, gold_start):
    """A refined code made from another network code (a bundle's new encoder, decision 124) is not served; float
    jitter of the same start (relative 1e-6, as between callers) is."""
    m, did, z = gold_start
    C.save_cached(m, did, z, RefineState(z + 0.1, 1.0, 0.5, converged=True), budget=10.0)
    assert C.load_cached(m, did, z * (1 + 1e-6)) is not None
    moved = z.clone()
    moved[1, 5] += 0.05
    assert C.load_cached(m, did, moved) is None


def test_a_damaged_cache_file_is_ignored(refined_cache_dir, gold_start):
    m, did, z = gold_start
    refined_cache_dir.mkdir(parents=True)
    C.cache_path(m, did, z).write_text("{not json")
    assert C.load_cached(m, did, z) is None
