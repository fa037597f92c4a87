"""Energy conservation of material codes (neural/energy.py): a code that reflects more light than
arrives is bounded, by an estimate independent of the one that bounded it; a code within the bound
is left as it is; the full neural path applies it after settling (tests/neural/test_albedo_net.py; the window:
tests/viewer/test_conserved_code.py)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from nbrdf.neural.energy import EnergySettings, albedo, conserve
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material
from nbrdf.neural.model import default_model
from nbrdf.neural.neural_brdf import latent_brdf
from nbrdf.training import furnace
from nbrdf.viewer.options import DEFAULT_MATERIAL

#: The furnace set's lossless two-layer stack whose network code reflects up to 6.9 % more than arrives.
GLOWING = "lossless-d2-03"


@pytest.fixture(scope="module")
def model():
    return default_model()


@pytest.fixture(scope="module")
def glowing(model):
    m = next(m for _, _, m in furnace.furnace_set(10) if m.name == GLOWING)
    z = model.material_latent(m, conserve=False)
    return m, z, model.proxy(z)


def _independent_albedo(model, m, code) -> np.ndarray:
    """(T, 3) albedo at the furnace report's incidences from other Sobol points (8 x 1024) than the bound's."""
    return furnace.sampled_albedo(latent_brdf(model.decoder, code, m, model.sampler), furnace.FURNACE_THETAS,
                                  1024, 8, seed=5).mean


def test_a_glowing_code_is_bounded_and_keeps_its_lobe(model, glowing):
    m, z, (s, w) = glowing
    before = _independent_albedo(model, m, z)
    assert before.max() > 1.03  # the test has something to fix (measured 1.069)
    zc = conserve(model.decoder, z, s, w)
    after = _independent_albedo(model, m, zc)
    # every incidence and channel at most 1 by an estimate the bound never saw (measured max 0.980)
    assert after.max() <= 1.0, after.max()
    # the albedo falls where it was above 1, and little elsewhere: measured against the walk, this stack's
    # median error went from 8.1 % to 1.2 % (docs/RESULTS.md section 15)
    assert np.all(after <= before + 0.01)
    assert torch.equal(zc[:, 32:], z[:, 32:])  # the coat is closed form: untouched
    wi = furnace._wi((0.0, 30.0, 60.0), 64).float()
    wo = torch.flip(wi, [0]) * torch.tensor([-1.0, 1.0, 1.0])
    ratio = torch.log(model.decoder.eval_rgb(zc, wi, wo) / model.decoder.eval_rgb(z, wi, wo))
    assert float(ratio.abs().median()) < 0.1  # the same lobe, scaled down by a few per cent


def test_a_code_within_the_bound_is_left_as_it_is(model):
    m = load_material(DEFAULT_MATERIAL)
    z = model.material_latent(m, conserve=False)
    s, w = model.proxy(z)
    assert float(albedo(model.decoder, z, s, w).max()) < 0.9
    assert conserve(model.decoder, z, s, w) is z
    assert torch.equal(model.conserved(z), z)  # the bound leaves it; the full path settles it (test_albedo_net.py)


def test_the_bound_is_deterministic_and_the_full_path_applies_it(model, glowing):
    m, z, (s, w) = glowing
    a, b = conserve(model.decoder, z, s, w), model.conserved(z)
    assert torch.equal(a, b) and not torch.equal(a, z)
    settled = model.material_latent(m)  # the full path: settled to the albedo network, then bounded
    assert torch.equal(settled, model.settled(z))
    assert float(albedo(model.decoder, settled, s, w).max()) <= EnergySettings().bound
    with torch.no_grad():  # as the window's plots call it (the soak found a traceback here)
        assert torch.equal(model.material_latent(m), settled)


@pytest.mark.parametrize("bad", [dict(bound=1.2), dict(samples=2), dict(thetas=()), dict(thetas=(90.0,)),
                                 dict(screen_bound=0.99, bound=0.9)])
def test_bad_settings_and_codes_are_one_line_errors(model, bad):
    z = torch.zeros(3, model.decoder.spec.code)
    with pytest.raises(NbrdfError, match="energy"):
        conserve(model.decoder, z, 0.3, 0.5, EnergySettings(**bad))
    with pytest.raises(NbrdfError, match="energy"):
        conserve(model.decoder, torch.full((3, model.decoder.spec.code), float("nan")), 0.3, 0.5)
