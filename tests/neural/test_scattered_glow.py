"""The glow of a thin scattering medium over an anisotropic base (neural/scattered_glow.py, decision 123): which
stacks are split, what the glow holds per channel, and that a code's value is its warped direct body plus the
glow, exactly."""
from __future__ import annotations

import json
import math

import pytest
import torch

from nbrdf.neural.anisotropy import FRAME_PARAMS, body_glow, glow_basis
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.model import default_model, layered_latents, uniform_values
from nbrdf.neural.scattered_glow import thinly_scattering
from nbrdf.neural.stack import material_stack
from nbrdf.viewer.options import DEFAULT_MATERIAL

BRUSHED = DEFAULT_MATERIAL.parents[3] / "training" / "sets" / "brushed"
METAL = {"type": "conductor", "roughness": 0.3, "r0": [0.9, 0.6, 0.5], "anisotropy": 0.8}


def _stack(albedo, sigma_t, base=METAL):
    return parse_material({"format": "nbrdf-material/1", "name": "s", "layers": [
        {"type": "dielectric", "roughness": 0.05, "ior": 1.5},
        {"type": "medium", "albedo": albedo, "sigma_t": sigma_t}, base]})


def _split(m) -> bool:
    return thinly_scattering(material_stack(m, uniform_values, dtype=torch.float32))


@pytest.fixture(scope="module")
def model():
    return default_model()


def test_only_thin_scattering_over_a_warped_body_is_split():
    assert _split(_stack([0.3, 0.15, 0.0], 0.25))  # brass under amber's varnish: depth 0.0375
    assert not _split(_stack([0.0, 0.0, 0.0], 0.25))  # absorbs only: nothing scattered
    assert not _split(_stack([0.9, 0.9, 0.9], 3.0))  # deep: many scatterings, the whole body (decision 116)
    assert not _split(_stack([0.3, 0.15, 0.0], 0.25, dict(METAL, anisotropy=0.0)))  # isotropic: no tail at all


@pytest.mark.parametrize("anisotropy", [0.8, 0.6])
def test_the_glow_follows_the_varnish_per_channel(model, anisotropy):
    amber = next(p for p in BRUSHED.glob("*.json") if "amber" in p.name)
    doc = json.loads(amber.read_text())
    doc["layers"][-1]["anisotropy"] = anisotropy  # at 0.6 a fit cut to the pairs the glow dominates gave green 0
    code = model.material_latent(parse_material(doc))
    k = body_glow(code, 34)
    assert code.shape == (3, 34 + FRAME_PARAMS)
    # the varnish scatters red most, green less, blue not at all (its albedo 0.3, 0.15, 0)
    assert k[0] > k[1] > 0.0 and k[2] == 0.0
    steel = next(p for p in BRUSHED.glob("*.json") if "steel" in p.name)  # a clear lacquer: no glow
    assert (body_glow(model.material_latent(load_material(steel)), 34) == 0).all()


def test_a_codes_value_is_its_warped_body_plus_the_glow(model):
    code = model.material_latent(_stack([0.4, 0.3, 0.2], 0.5))
    g = torch.Generator().manual_seed(3)
    v = torch.randn(2000, 3, generator=g)
    v[:, 2] = v[:, 2].abs() + 0.05
    v = v / v.norm(dim=-1, keepdim=True)
    wi, wo = v[:1000], v[1000:]
    dark = code.clone()
    dark[:, -1] = 0.0
    glow = body_glow(code, 34)[None, :] * glow_basis(wi, wo, code[0, 33])[:, None]
    torch.testing.assert_close(model.decoder.eval_rgb(code, wi, wo), model.decoder.eval_rgb(dark, wi, wo) + glow)
    assert float(glow.mean()) > 1e-3
    # the basis is the coat's transmittance on both sides over pi, and 0 below the horizon
    up = torch.tensor([[0.0, 0.0, 1.0]])
    assert float(glow_basis(up, up, torch.tensor(1.0))) == pytest.approx(1.0 / math.pi)
    assert float(glow_basis(up, up, torch.tensor(1.5))) == pytest.approx(0.96 * 0.96 / math.pi, rel=1e-5)
    assert float(glow_basis(up, -up, torch.tensor(1.5))) == 0.0


def test_without_the_decoder_a_split_stack_is_a_one_line_error():
    with pytest.raises(NbrdfError, match="^an anisotropic stack over a scattering medium needs the decoder"):
        layered_latents(None, None, material_stack(_stack([0.4, 0.3, 0.2], 0.5), uniform_values))
