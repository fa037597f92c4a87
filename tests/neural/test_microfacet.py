"""GGX building blocks (SPEC section 5) on their own: the normal distribution's
normalisation, Smith's G1, the visible-normal sampler against its density by
deterministic quadrature, Fresnel's limits and Snell's law. Deterministic and
fast: these are the checks the samplers' chi-square tests stand on."""
from __future__ import annotations

import math

import pytest
import torch

from nbrdf.neural.microfacet import (
    F82_MU,
    f82_coefficient,
    fresnel_dielectric,
    fresnel_f82,
    fresnel_schlick,
    ggx_d,
    reflect,
    refract,
    sample_vndf,
    smith_g1,
    smith_g1_dir,
    vndf_pdf,
)

F64 = torch.float64
ALPHAS = [0.05, 0.3, 0.8]


def _dir(theta_deg: float, phi_deg: float = 30.0) -> torch.Tensor:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return torch.tensor([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)], dtype=F64)


def _hemisphere_grid(n: int):
    """Midpoint quadrature over the upper hemisphere: directions (4 n^2, 3) and solid-angle weights. Nodes
    cluster toward the normal (cos theta = 1 - x^3, x uniform) to resolve the sharp lobes of small alphas."""
    x = (torch.arange(n, dtype=F64) + 0.5) / n
    cz, dcz = 1 - x ** 3, 3 * x ** 2 / n
    p = (torch.arange(4 * n, dtype=F64) + 0.5) / (4 * n) * 2 * math.pi
    c, ph = torch.meshgrid(cz, p, indexing="ij")
    s = torch.sqrt(1 - c * c)
    m = torch.stack([s * torch.cos(ph), s * torch.sin(ph), c], -1).reshape(-1, 3)
    w = (dcz[:, None] * (2 * math.pi / (4 * n))).expand(n, 4 * n).reshape(-1)
    return m, w


def _stratified_u(n: int):
    u = (torch.arange(n, dtype=F64) + 0.5) / n
    u1, u2 = torch.meshgrid(u, u, indexing="ij")
    return u1.reshape(-1), u2.reshape(-1)


@pytest.mark.parametrize("a", ALPHAS)
def test_ggx_d_closed_form_and_projected_area_is_one(a):
    alpha = torch.tensor(a, dtype=F64)
    # At the normal D = 1 / (pi a^2); at 60 degrees the SPEC's formula evaluated by hand.
    assert ggx_d(torch.tensor([0.0, 0.0, 1.0], dtype=F64), alpha) == pytest.approx(1 / (math.pi * a * a), rel=1e-12)
    c = 0.5
    tan2 = (1 - c * c) / (c * c)
    want = 1 / (math.pi * a * a * c ** 4 * (1 + tan2 / (a * a)) ** 2)
    assert ggx_d(torch.tensor([math.sqrt(1 - c * c), 0.0, c], dtype=F64), alpha) == pytest.approx(want, rel=1e-12)
    # Below the horizon: 0.
    assert ggx_d(torch.tensor([0.6, 0.0, -0.8], dtype=F64), alpha) == 0
    # Microfacets' projected area is the macro surface's: integral of D(m) cos(m) over the hemisphere = 1.
    n = 200 if a < 0.1 else 80
    m, w = _hemisphere_grid(n)
    assert (ggx_d(m, alpha) * m[:, 2] * w).sum() == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize("a", ALPHAS)
def test_smith_g1_values_and_side_test(a):
    alpha = torch.tensor(a, dtype=F64)
    w = _dir(60.0)
    tan2 = math.tan(math.radians(60.0)) ** 2
    want = 2 / (1 + math.sqrt(1 + a * a * tan2))
    up = torch.tensor([0.0, 0.0, 1.0], dtype=F64)
    assert smith_g1(w, up, alpha) == pytest.approx(want, rel=1e-12)
    assert smith_g1_dir(w, alpha) == pytest.approx(want, rel=1e-12)
    assert smith_g1_dir(-w, alpha) == pytest.approx(want, rel=1e-12)  # symmetric in the side
    assert smith_g1(up, up, alpha) == pytest.approx(1.0)
    # A facet seen from its back (w.m and w.z of opposite signs) is invisible.
    assert smith_g1(w, torch.tensor([-1.0, 0.0, 0.0], dtype=F64) * 0.9 + up * 0.1, alpha) == 0
    below = -w  # a direction under the surface sees an upper facet from the front only if w.m < 0
    assert smith_g1(below, up, alpha) == pytest.approx(want, rel=1e-12)
    assert smith_g1(below, torch.nn.functional.normalize(below + 1.2 * up, dim=0), alpha) == 0


@pytest.mark.parametrize("a", ALPHAS)
@pytest.mark.parametrize("theta", [0.0, 40.0, 80.0])
def test_visible_normals_integrate_to_one(a, theta):
    """The density of the visible normals integrates to one (G1(w) = w.z / integral of <w.m> D(m))."""
    alpha = torch.tensor(a, dtype=F64)
    n = 200 if a < 0.1 else 80
    m, wt = _hemisphere_grid(n)
    w = _dir(theta).expand_as(m)
    total = (vndf_pdf(w, m, alpha) * wt).sum()
    assert total == pytest.approx(1.0, abs=5e-3)
    # The lower hemisphere's view is the mirrored upper one's.
    assert torch.allclose(vndf_pdf(-w, m, alpha), vndf_pdf(w, m, alpha))
    # Normals facing away from w are never visible.
    far = m[(m * w).sum(-1) < 0]
    assert (vndf_pdf(w[: far.shape[0]], far, alpha) == 0).all()


@pytest.mark.parametrize("a", ALPHAS)
@pytest.mark.parametrize("theta", [0.0, 30.0, 75.0])
def test_vndf_sampler_moments_match_its_density(a, theta):
    """Stratified samples' means of m.x, m.y, m.z, m.z^2 equal the density's moments by quadrature
    (a wrong sampler moves a moment by far more than the tolerances: about 1e-2 here)."""
    alpha = torch.tensor(a, dtype=F64)
    u1, u2 = _stratified_u(128)
    w = _dir(theta)
    ms = sample_vndf(w.expand(u1.shape[0], 3), alpha, u1, u2)
    assert torch.allclose(ms.norm(dim=-1), torch.ones(ms.shape[0], dtype=F64))
    assert (ms[:, 2] > 0).all()
    assert ((ms * w).sum(-1) >= -1e-9).all()  # every sampled normal is visible from w
    n = 200 if a < 0.1 else 80
    m, wt = _hemisphere_grid(n)
    p = vndf_pdf(w.expand_as(m), m, alpha) * wt
    for g in (lambda v: v[:, 0], lambda v: v[:, 1], lambda v: v[:, 2], lambda v: v[:, 2] ** 2):
        assert g(ms).mean() == pytest.approx(float((g(m) * p).sum()), abs=3e-3)
    # A direction below the surface samples the mirrored upper one's normals.
    assert torch.allclose(sample_vndf(-w.expand(u1.shape[0], 3), alpha, u1, u2), ms)


def test_fresnel_dielectric_limits_and_brewster():
    eta = torch.tensor(1.5, dtype=F64)
    assert fresnel_dielectric(torch.tensor(1.0, dtype=F64), eta) == pytest.approx(0.04, rel=1e-12)
    assert fresnel_dielectric(torch.tensor(-1.0, dtype=F64), eta) == pytest.approx(0.04, rel=1e-12)  # |cos|
    assert fresnel_dielectric(torch.tensor(0.0, dtype=F64), eta) == pytest.approx(1.0)  # grazing
    # At Brewster's angle (tan = eta) the p-polarised part vanishes: F = rs^2 / 2.
    tb = math.atan(1.5)
    ci, ct = math.cos(tb), math.cos(math.pi / 2 - tb)
    rs = (ci - 1.5 * ct) / (ci + 1.5 * ct)
    assert fresnel_dielectric(torch.tensor(ci, dtype=F64), eta) == pytest.approx(rs * rs / 2, rel=1e-10)
    # From inside (eta < 1): total internal reflection past the critical angle, and below it a value < 1.
    inside = torch.tensor(1 / 1.5, dtype=F64)
    crit = math.sqrt(1 - (1 / 1.5) ** 2)
    assert fresnel_dielectric(torch.tensor(crit - 1e-3, dtype=F64), inside) == 1
    assert fresnel_dielectric(torch.tensor(crit + 0.05, dtype=F64), inside) < 0.5
    assert fresnel_dielectric(torch.tensor(1.0, dtype=F64), inside) == pytest.approx(0.04, rel=1e-12)
    # Matched indices reflect nothing.
    assert fresnel_dielectric(torch.tensor([0.3, 0.9], dtype=F64), torch.tensor(1.0, dtype=F64)).abs().max() < 1e-15


def test_fresnel_schlick_end_points():
    r0 = torch.tensor(0.2, dtype=F64)
    assert fresnel_schlick(torch.tensor(1.0, dtype=F64), r0) == pytest.approx(0.2)
    assert fresnel_schlick(torch.tensor(0.0, dtype=F64), r0) == pytest.approx(1.0)
    assert fresnel_schlick(torch.tensor(-0.5, dtype=F64), r0) == pytest.approx(0.2 + 0.8 / 32)
    assert fresnel_schlick(torch.tensor(2.0, dtype=F64), r0) == pytest.approx(0.2)  # |cos| clamped to 1


def test_f82_tint_sets_the_edge_reflectance_and_a_white_tint_is_schlick():
    """OpenPBR's F82-tint form: at mu_bar = 1/7 the reflectance is the Schlick value times the tint; a tint
    of 1 is Schlick's curve exactly; normal incidence keeps r0; values stay in [0, 1]."""
    r0 = torch.tensor([0.05, 0.5, 0.95], dtype=F64)
    tint = torch.tensor([0.0, 0.4, 0.9], dtype=F64)
    b = f82_coefficient(r0, tint)
    mu = torch.tensor(F82_MU, dtype=F64)
    assert torch.allclose(fresnel_f82(mu, r0, b), tint * fresnel_schlick(mu, r0), atol=1e-12)
    assert torch.allclose(fresnel_f82(torch.tensor(1.0, dtype=F64), r0, b), r0, atol=1e-12)
    c = torch.linspace(0, 1, 101, dtype=F64)[:, None]
    assert torch.equal(fresnel_f82(c, r0, f82_coefficient(r0, torch.ones(3, dtype=F64))), fresnel_schlick(c, r0))
    f = fresnel_f82(c, r0, b)
    assert bool((f >= 0).all()) and bool((f <= 1).all())
    assert bool((f[:, 1:] < fresnel_schlick(c, r0)[:, 1:] + 1e-15).all())  # a tint below 1 only darkens


def test_reflect_mirrors_about_the_normal():
    w = _dir(50.0, 20.0)
    up = torch.tensor([0.0, 0.0, 1.0], dtype=F64)
    assert torch.allclose(reflect(w, up), torch.stack([-w[0], -w[1], w[2]]))
    m = _dir(10.0, 100.0)
    r = reflect(w, m)
    assert torch.dot(r, m) == pytest.approx(float(torch.dot(w, m)))
    assert torch.allclose(reflect(r, m), w)


@pytest.mark.parametrize("theta", [0.0, 25.0, 60.0])
def test_refract_obeys_snell(theta):
    m = torch.tensor([0.0, 0.0, 1.0], dtype=F64)
    w = _dir(theta)
    t, ok = refract(w, m, torch.tensor(1 / 1.5, dtype=F64))
    assert bool(ok)
    assert t.norm() == pytest.approx(1.0)
    assert t[2] < 0  # crossed to the other side
    sin_i, sin_t = math.sin(math.radians(theta)), float(torch.hypot(t[0], t[1]))
    assert sin_t == pytest.approx(sin_i / 1.5, abs=1e-12)
    if theta > 0:  # the tangential part points away from w's
        assert torch.dot(t[:2], w[:2]) < 0
    # From below through the same facet (m flipped to w's side), back up with the inverse ratio.
    back, ok2 = refract(-t, m, torch.tensor(1.5, dtype=F64))
    assert bool(ok2) and torch.allclose(back, -w, atol=1e-12)
    # Past the critical angle from the dense side: total internal reflection.
    _, tir = refract(-_dir(180.0 - 60.0), m, torch.tensor(1.5, dtype=F64))
    assert not bool(tir)
