"""Closed-form BxDFs: values against an independent scalar implementation,
reciprocity, energy, and chi-square tests of every sampler against its pdf."""
from __future__ import annotations

import math

import pytest
import torch
from brdf_adapter import check_sampler, check_sampler_moments
from scalar_reference import ref_conductor, ref_dielectric

from nbrdf.training.analytic import GGXConductor, GGXDielectric, Lambertian

ALPHA = 1e-3  # significance level of each chi-square test (fixed seeds: deterministic)


def _dirs(n, seed, lower=False):
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(n, 3, generator=g, dtype=torch.float64)
    v = v / v.norm(dim=-1, keepdim=True)
    if not lower:
        v[:, 2] = v[:, 2].abs()
    return v


@pytest.mark.parametrize("a,r0", [(0.01, 0.04), (0.2, 0.9), (1.0, 0.5)])
def test_conductor_matches_independent_formulas(a, r0):
    wi, wo = _dirs(300, 1), _dirs(300, 2)
    got = GGXConductor(a, r0).eval(wi, wo)
    want = torch.tensor([ref_conductor(x.tolist(), y.tolist(), a, r0) for x, y in zip(wi, wo)], dtype=torch.float64)
    torch.testing.assert_close(got, want, rtol=1e-9, atol=1e-300)


@pytest.mark.parametrize("a,ior", [(0.05, 1.5), (0.3, 1.05), (1.0, 2.0)])
def test_dielectric_matches_independent_formulas(a, ior):
    wi, wo = _dirs(400, 3, lower=True), _dirs(400, 4, lower=True)
    got = GGXDielectric(a, ior).eval(wi, wo)
    want = torch.tensor([ref_dielectric(x.tolist(), y.tolist(), a, ior) for x, y in zip(wi, wo)], dtype=torch.float64)
    torch.testing.assert_close(got, want, rtol=1e-9, atol=1e-12)


def test_float32_matches_float64():
    wi, wo = _dirs(500, 5), _dirs(500, 6)
    for b in (GGXConductor(0.3, 0.8), GGXDielectric(0.3, 1.5), Lambertian(0.5)):
        f64 = b.eval(wi, wo)
        f32 = b.eval(wi.float(), wo.float()).double()
        assert torch.allclose(f32, f64, rtol=1e-4, atol=1e-6)


def test_lambertian_value():
    wi, wo = _dirs(10, 7), _dirs(10, 8)
    assert torch.allclose(Lambertian(0.6).eval(wi, wo), torch.full((10,), 0.6 / math.pi, dtype=torch.float64))
    wo[:, 2] *= -1
    assert (Lambertian(0.6).eval(wi, wo) == 0).all()


def test_reciprocity():
    wi, wo = _dirs(500, 9, lower=True), _dirs(500, 10, lower=True)
    for b in (GGXConductor(0.25, 0.7), Lambertian(0.8)):
        torch.testing.assert_close(b.eval(wi, wo), b.eval(wo, wi))
    # Refraction obeys the generalised reciprocity f(i,o)/eta_o^2 = f(o,i)/eta_i^2.
    ior = 1.4
    d = GGXDielectric(0.3, ior)
    eta = lambda w: torch.where(w[:, 2] > 0, 1.0, ior)
    torch.testing.assert_close(d.eval(wi, wo) / eta(wo) ** 2, d.eval(wo, wi) / eta(wi) ** 2)


@pytest.mark.parametrize("bsdf", [GGXConductor(0.01, 1.0), GGXConductor(1.0, 1.0), GGXDielectric(0.01, 1.5),
                                  GGXDielectric(0.7, 1.9), Lambertian(1.0)], ids=repr)
def test_directional_albedo_at_most_one(bsdf):
    """Estimated with the sampler's own weights, over many incidence angles."""
    g = torch.Generator().manual_seed(11)
    n = 20_000
    for mu in (1.0, 0.7, 0.3, 0.05):
        w = torch.tensor([math.sqrt(1 - mu * mu), 0.0, mu], dtype=torch.float64).expand(n, 3)
        s = bsdf.sample(w, torch.rand(n, 3, generator=g, dtype=torch.float64))
        est = s.weight.mean().item()
        assert est <= 1.0 + 3 * s.weight.std().item() / math.sqrt(n) + 1e-12
        assert (s.weight <= 1.0 + 1e-9).all(), "a single sample's weight exceeds 1"


SAMPLERS = [
    ("conductor a=0.1", GGXConductor(0.1, 0.9), 30),
    ("conductor a=0.5", GGXConductor(0.5, 0.9), 60),
    ("conductor a=1", GGXConductor(1.0, 0.3), 75),
    ("dielectric a=0.15 from above", GGXDielectric(0.15, 1.5), 40),
    ("dielectric a=0.6 from above", GGXDielectric(0.6, 1.33), 70),
    ("dielectric a=0.3 from below", GGXDielectric(0.3, 1.5), 160),
    ("dielectric a=0.8 from below", GGXDielectric(0.8, 1.9), 120),
    ("lambertian", Lambertian(0.7), 20),
]


@pytest.mark.parametrize("name,bsdf,theta_deg", SAMPLERS, ids=[s[0] for s in SAMPLERS])
def test_sampler_chi2(name, bsdf, theta_deg):
    check_sampler(name, bsdf, theta_deg, alpha=ALPHA)


MOMENT_SAMPLERS = [
    ("conductor a=0.3", GGXConductor(0.3, 0.9), 30),
    ("conductor a=0.8", GGXConductor(0.8, 0.3), 70),
    ("dielectric a=0.3 from above", GGXDielectric(0.3, 1.5), 40),
    ("dielectric a=0.5 from below", GGXDielectric(0.5, 1.5), 160),
    ("dielectric a=0.4 from below, past the critical angle", GGXDielectric(0.4, 1.5), 125),
    ("lambertian", Lambertian(0.7), 20),
]


@pytest.mark.parametrize("name,bsdf,theta_deg", MOMENT_SAMPLERS, ids=[s[0] for s in MOMENT_SAMPLERS])
def test_sampler_moments_match_the_pdf(name, bsdf, theta_deg):
    """Fast and deterministic beside the chi-square tests: the samples' mass and mean direction are the pdf's."""
    check_sampler_moments(name, bsdf, theta_deg)
