"""The window shows the networks' code while a slider moves and bounds its albedo once the edits
pause (viewer/session/lookdev.py, neural/energy.py)."""
from __future__ import annotations

import pytest
import torch

from nbrdf.neural.material import material_to_dict, parse_material
from nbrdf.neural.model import default_model
from nbrdf.training import furnace
from nbrdf.viewer.session import lookdev as lookdev_module
from nbrdf.viewer.session.lookdev import LookDev

GLOWING = "lossless-d2-03"  # as tests/neural/test_energy.py: its network code reflects up to 6.9 % too much


@pytest.fixture(scope="module")
def glowing():
    m = next(m for _, _, m in furnace.furnace_set(10) if m.name == GLOWING)
    return m, default_model().material_latent(m, conserve=False)


@pytest.mark.gl
def test_the_window_bounds_the_code_once_the_edits_pause(gl_ctx, glowing, monkeypatch):
    m, z = glowing
    material = parse_material(material_to_dict(m))
    ld = LookDev(gl_ctx, material)
    try:
        assert torch.equal(ld.brdf.latent, z)  # the networks' code while editing
        ld.update()
        assert torch.equal(ld.brdf.latent, z)  # not yet: the edits have not paused
        monkeypatch.setattr(lookdev_module, "CONSERVE_AFTER_S", 0.0)
        ld.update()
        assert torch.equal(ld.brdf.latent, default_model().material_latent(m))  # bounded
    finally:
        ld.close()
