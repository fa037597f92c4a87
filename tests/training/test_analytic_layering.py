"""The analytic layering baseline keeps the limits it is built on."""
from __future__ import annotations

import torch

from nbrdf.neural.material import parse_material
from nbrdf.training.analytic import GGXDielectric
from nbrdf.training.analytic_layering import analytic_layered_eval
from nbrdf.training.dataset import sample_pairs


def _stack(r0, sigma, albedo=0.5, base=None):
    return parse_material({"format": "nbrdf-material/1", "name": "t", "layers": [
        {"type": "dielectric", "roughness": 0.2, "ior": 1.5},
        {"type": "medium", "albedo": albedo, "sigma_t": sigma},
        base or {"type": "conductor", "roughness": 0.3, "r0": r0}]})


def _pairs(n=2000):
    wi, wo = sample_pairs(n, torch.Generator().manual_seed(3))
    return wi, wo


def test_black_base_leaves_the_top_reflection():
    wi, wo = _pairs()
    top = GGXDielectric(0.2, 1.5).eval(wi, wo)
    f = analytic_layered_eval(_stack(0.0, 0.0, base={"type": "diffuse", "albedo": 0.0}), wi, wo)
    assert torch.allclose(f, top[:, None].expand(-1, 3), rtol=1e-6, atol=1e-9)


def test_thicker_media_only_darken_and_reciprocity_holds():
    wi, wo = _pairs()
    prev = None
    for sigma in (0.0, 0.5, 2.0, 5.0):
        f = analytic_layered_eval(_stack(0.9, sigma), wi, wo)
        if prev is not None:
            assert bool((f <= prev + 1e-9).all())
        prev = f
    assert torch.allclose(analytic_layered_eval(_stack(0.9, 1.0), wi, wo),
                          analytic_layered_eval(_stack(0.9, 1.0), wo, wi), rtol=1e-6, atol=1e-9)


def test_three_layers_nest_and_stay_below_the_horizon_zero():
    m = parse_material({"format": "nbrdf-material/1", "name": "t3", "layers": [
        {"type": "dielectric", "roughness": 0.1, "ior": 1.4}, {"type": "medium", "albedo": 0.9, "sigma_t": 0.5},
        {"type": "dielectric", "roughness": 0.3, "ior": 1.2}, {"type": "medium", "albedo": 0.9, "sigma_t": 0.5},
        {"type": "diffuse", "albedo": [0.8, 0.5, 0.2]}]})
    wi, wo = _pairs(500)
    f = analytic_layered_eval(m, wi, wo)
    assert f.shape == (500, 3) and bool((f >= 0).all()) and bool(torch.isfinite(f).all())
    assert bool((f[:, 0] >= f[:, 2]).all())  # the base colour shows through
    wo_down = wo * torch.tensor([1.0, 1.0, -1.0])
    assert bool((analytic_layered_eval(m, wi, wo_down) == 0).all())
