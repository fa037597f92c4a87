"""A code calibrated against the walk (``training.calibration``): its albedo is the walk's, measured by an
estimator and a walk of its own; the walk's albedo is cached per material; what is not calibrated keeps the
bounded code."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import FORMAT, material_to_dict, parse_material
from nbrdf.neural.methods import Method
from nbrdf.neural.model import default_model
from nbrdf.neural.neural_brdf import latent_brdf
from nbrdf.training import calibration
from nbrdf.training.brdfs import brdf_for
from nbrdf.training.furnace import FURNACE_THETAS, furnace_set, reference_albedo, sampled_albedo

#: Quick enough for the test suite (2-4 s on a two-layer stack here): about 0.4 % relative error at 32k paths.
QUICK = calibration.WalkAlbedoSettings(paths=4096, max_paths=1 << 15, target=0.004)


@pytest.fixture
def albedo_cache(tmp_path, monkeypatch):
    """A private walk-albedo cache: its folder, not yet made."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return tmp_path / "cache" / "nbrdf" / "albedo"


@pytest.fixture(scope="module")
def lossless_pair():
    """A held-out lossless two-layer stack of the furnace set whose networks' albedo is 7 % off (v10)."""
    return next(m for _, _, m in furnace_set() if m.name == "lossless-d2-09")


def test_a_calibrated_code_reflects_what_the_walk_does(albedo_cache, lossless_pair):
    model = default_model()
    code, scale = calibration.calibrate(model, lossless_pair, settings=QUICK)
    # judged by other hands: the furnace report's estimator (its own Sobol points) and a walk of another seed
    ref = reference_albedo(lossless_pair, FURNACE_THETAS, 8192, 1 << 16, 0.003, seed=99)
    before = sampled_albedo(latent_brdf(model.decoder, model.material_latent(lossless_pair), lossless_pair,
                                        model.sampler), FURNACE_THETAS, 1024, 4, 0)
    assert torch.equal(code, model.material_latent(lossless_pair))  # the lobe is the networks': only scaled
    after = sampled_albedo(latent_brdf(model.decoder, code, lossless_pair, model.sampler, scale), FURNACE_THETAS,
                           1024, 4, 0)
    rel = lambda a: np.abs(a.mean - ref.mean) / ref.mean  # noqa: E731
    # the networks' code is several per cent off, so a calibration that did nothing fails below
    assert rel(before).max() > 0.04
    # 1 % plus the noise of the two walks and the estimator (each about 0.3-0.4 %, so their difference's three
    # sigma is under 2 %): a code 10 % off is far outside, the networks' own 4-11 % too
    assert rel(after).max() < 0.02, rel(after).max()
    assert np.median(rel(after)) < 0.01
    assert after.mean.max() <= 1.0


def test_the_walk_albedo_is_taken_once_per_material(albedo_cache, lossless_pair, monkeypatch):
    thetas = (0.0, 60.0)
    first, se = calibration.walk_albedo(lossless_pair, thetas, QUICK)
    files = list(albedo_cache.glob("*.json"))
    assert first.shape == se.shape == (3, 2) and len(files) == 1
    assert float((se / first).max()) < 0.006  # the settings' precision (0.4 %), or the cap of 32k paths

    def no_walk(*a, **k):
        raise AssertionError("the cached albedo was walked again")

    monkeypatch.setattr(calibration, "AlbedoWalk", no_walk)
    assert torch.equal(calibration.walk_albedo(lossless_pair, thetas, QUICK)[0], first)
    renamed = parse_material({**material_to_dict(lossless_pair), "name": "other name"})
    assert torch.equal(calibration.walk_albedo(renamed, thetas, QUICK)[0], first)  # content, not name
    with pytest.raises(AssertionError):  # other settings, another walk
        calibration.walk_albedo(lossless_pair, thetas, calibration.WalkAlbedoSettings(seed=1))
    files[0].write_text("{not json")
    with pytest.raises(AssertionError):  # a damaged entry is walked again, not served
        calibration.walk_albedo(lossless_pair, thetas, QUICK)


def test_what_the_walk_cannot_take_keeps_the_bounded_code(albedo_cache):
    model = default_model()
    single = parse_material({"format": FORMAT, "layers": [{"type": "conductor", "roughness": 0.3, "r0": [0.95, 0.64, 0.54]}]})
    assert calibration.uncalibrated(single) == "a single layer"
    z, scale = calibration.calibrate(model, single)
    assert torch.equal(z, model.material_latent(single)) and scale is None
    brushed = parse_material({"format": FORMAT, "anisotropy_rotation": 30.0, "layers": [
        {"type": "dielectric", "roughness": 0.1, "ior": 1.5},
        {"type": "conductor", "roughness": 0.3, "anisotropy": 0.7, "r0": [0.95, 0.64, 0.54]}]})
    assert "anisotropic" in calibration.uncalibrated(brushed)
    z, scale = calibration.calibrate(model, brushed)
    assert torch.equal(z, model.material_latent(brushed)) and scale is None
    with pytest.raises(NbrdfError, match="no walk albedo for a single layer"):
        calibration.walk_albedo(single, (0.0,))
    assert not albedo_cache.exists()  # nothing was walked


def test_the_calibrated_method_is_the_calibrated_code(albedo_cache, lossless_pair, monkeypatch):
    model = default_model()
    monkeypatch.setattr(calibration, "WalkAlbedoSettings", lambda: QUICK)
    b = brdf_for(lossless_pair, Method.CALIBRATED, model=model)
    z, scale = calibration.calibrate(model, lossless_pair, settings=QUICK)
    assert torch.equal(b.z, z) and torch.equal(b.scale.g, scale.g)
