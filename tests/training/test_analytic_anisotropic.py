"""The closed forms of anisotropic interfaces (SPEC section 10): the
anisotropic GGX D and masking of ``neural.microfacet`` and the analytic
``GGXConductor`` / ``GGXDielectric`` with ``anisotropy`` and ``rotation``.

Checks: D integrates, projected, to 1 and the visible normals of every view
to 1; VNDF sampling at alpha 1e-3 passes a chi-square against the pdf, and
the same test rejects a sampler whose anisotropy is 10 % off or whose
rotation is 10 degrees off (its power); reciprocity; a = 0 is the isotropic
code bit for bit; a rotation by 90 degrees swaps alpha_x and alpha_y; the
rotation turns the tangent counter-clockwise seen from above."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy import stats

from nbrdf.neural.anisotropy import alphas, from_frame, to_frame
from nbrdf.neural.microfacet import fresnel_schlick, ggx_d, smith_g1, smith_g1_dir
from nbrdf.training.analytic import GGXConductor, GGXDielectric

D64 = torch.float64


def _dirs(n: int, seed: int, upper: bool = True) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(n, 3, generator=g, dtype=D64)
    v = v / v.norm(dim=-1, keepdim=True)
    z = v[:, 2].abs().clamp_min(0.05)
    v = torch.cat([v[:, :2], (z if upper else torch.where(v[:, 2] < 0, -z, z))[:, None]], -1)
    return v / v.norm(dim=-1, keepdim=True)


def _hemisphere_grid(ns: int = 2400, nphi: int = 1024):
    """Normals m over the upper hemisphere and their quadrature weights (tan theta = e^s, trapezoid in s over
    [-20, 12], midpoint rule in phi): sharp and rough lobes alike are resolved."""
    s = torch.linspace(-20.0, 12.0, ns, dtype=D64)
    ds = torch.full_like(s, float(s[1] - s[0]))
    ds[0] = ds[-1] = 0.5 * ds[0]
    t = s.exp()
    theta = torch.atan(t)
    phi = (torch.arange(nphi, dtype=D64) + 0.5) * (2 * math.pi / nphi)
    st, ct = theta.sin()[:, None], theta.cos()[:, None]
    m = torch.stack([st * phi.cos()[None], st * phi.sin()[None], ct.expand(-1, nphi)], -1)
    dw = (st * (t / (1 + t * t))[:, None] * ds[:, None]).expand(-1, nphi) * (2 * math.pi / nphi)  # sin dtheta dphi
    return m, dw


@pytest.mark.parametrize("alpha,a", [(0.2, 0.5), (0.01, 0.95), (1.0, 0.3), (1e-3, 0.6), (0.5, 0.0)])
def test_anisotropic_d_integrates_projected_to_one_and_so_do_the_visible_normals(alpha, a):
    """int D(m) cos theta_m dm = 1, and int G1(w) max(0, w.m) D(m) / w_z dm = 1 for several views (the masking
    matches the distribution: Heitz 2014)."""
    ax, ay = alphas(torch.tensor(alpha, dtype=D64), torch.tensor(a, dtype=D64))
    m, dw = _hemisphere_grid()
    d = ggx_d(m, ax, ay)
    assert abs(float((d * m[..., 2] * dw).sum()) - 1.0) < 1e-4
    for w in _dirs(4, 3):
        vis = smith_g1_dir(w, ax, ay) * (m @ w).clamp_min(0) * d / w[2]
        assert abs(float((vis * dw).sum()) - 1.0) < 1e-4, w


def _stretched_bins(wi: torch.Tensor, wo: torch.Tensor, ax: float, ay: float, rot: float, edges: np.ndarray):
    """Bin index of each (wi, wo) pair by the half vector's slopes in the rotated frame over (ax, ay); the
    last index: outside the grid (or no reflection)."""
    h = to_frame(wi + wo, rot)
    u = (h[:, 0] / h[:, 2] / ax).numpy()
    v = (h[:, 1] / h[:, 2] / ay).numpy()
    k = len(edges) - 1
    iu, iv = np.digitize(u, edges) - 1, np.digitize(v, edges) - 1
    inside = (iu >= 0) & (iu < k) & (iv >= 0) & (iv < k) & (wo[:, 2] > 0).numpy()
    return np.where(inside, iu * k + iv, k * k)


def _expected(brdf: GGXConductor, wi: torch.Tensor, ax: float, ay: float, rot: float, edges: np.ndarray,
              sub: int = 8) -> np.ndarray:
    """The sampler's pdf integrated over the bins of ``_stretched_bins`` (midpoint rule, sub x sub per bin):
    d omega_o = 4 |wo.h| d omega_h, d omega_h = cos^3 theta_h ax ay du dv."""
    k = len(edges) - 1
    fine = np.concatenate([np.linspace(lo, hi, sub + 1)[:-1] + (hi - lo) / (2 * sub)
                           for lo, hi in zip(edges[:-1], edges[1:])])
    du = np.repeat(np.diff(edges), sub) / sub
    U, V = np.meshgrid(fine, fine, indexing="ij")
    A = np.outer(du, du)
    hl = torch.from_numpy(np.stack([ax * U, ay * V, np.ones_like(U)], -1).reshape(-1, 3))
    hl = hl / hl.norm(dim=-1, keepdim=True)
    h = from_frame(hl, rot)
    w = wi.expand(h.shape[0], 3)
    wo = 2 * (w * h).sum(-1, keepdim=True) * h - w
    q = brdf.pdf(w, wo) * 4 * (wo * h).sum(-1).abs() * hl[:, 2] ** 3 * ax * ay
    q = torch.where(wo[:, 2] > 0, q, torch.zeros_like(q)).numpy().reshape(U.shape) * A
    p = q.reshape(k, sub, k, sub).sum((1, 3)).ravel()
    return np.append(p, 1.0 - p.sum())


def _chi2_p(counts: np.ndarray, probs: np.ndarray, n: int) -> float:
    exp = probs * n
    keep = exp >= 20
    obs, e = counts[keep], exp[keep]
    chi2 = float(((obs - e) ** 2 / e).sum())
    return float(stats.chi2.sf(chi2, keep.sum() - 1))


@pytest.mark.parametrize("theta,phi,a,rot", [(40.0, 10.0, 0.6, 30.0), (70.0, 200.0, 0.9, -50.0)])
def test_visible_normal_sampling_at_alpha_1e_3_passes_chi_square_and_has_power(theta, phi, a, rot):
    """200,000 samples of a conductor of alpha 1e-3 binned by the half vector's stretched slopes (12 x 12 bins
    over [-3, 3]^2 and the rest): chi-square against the pdf at p > 1e-3; the same test rejects (p < 1e-6)
    samplers with the anisotropy 10 % off and the rotation 10 degrees off."""
    alpha, n = 1e-3, 200_000
    t, ph = math.radians(theta), math.radians(phi)
    wi = torch.tensor([[math.sin(t) * math.cos(ph), math.sin(t) * math.sin(ph), math.cos(t)]], dtype=D64)
    ax, ay = (float(x) for x in alphas(torch.tensor(alpha, dtype=D64), torch.tensor(a, dtype=D64)))
    edges = np.linspace(-3.0, 3.0, 13)
    truth = GGXConductor(alpha, 1.0, 1.0, a, rot)
    probs = _expected(truth, wi, ax, ay, rot, edges)
    assert 0.0 < probs[-1] < 0.2 and abs(probs.sum() - 1.0) < 1e-12
    u = torch.rand(n, 2, generator=torch.Generator().manual_seed(5), dtype=D64)
    for k, brdf in enumerate((truth, GGXConductor(alpha, 1.0, 1.0, min(1.1 * a, 0.99), rot),
                              GGXConductor(alpha, 1.0, 1.0, a, rot + 10.0))):
        s = brdf.sample(wi.expand(n, 3), u)
        counts = np.bincount(_stretched_bins(wi.expand(n, 3), s.w, ax, ay, rot, edges), minlength=len(probs))
        p = _chi2_p(counts, probs, n)
        assert (p > 1e-3) if k == 0 else (p < 1e-6), (k, p)
    s = truth.sample(wi.expand(n, 3), u)
    ok = s.pdf > 0
    assert torch.allclose(s.pdf[ok], truth.pdf(wi.expand(n, 3)[ok], s.w[ok]), rtol=1e-9)
    assert torch.allclose(s.f[ok], truth.eval(wi.expand(n, 3)[ok], s.w[ok]), rtol=1e-9)


def test_anisotropic_interfaces_are_reciprocal():
    """f(wi, wo) = f(wo, wi) for the conductor and the dielectric's reflection, from either side; its
    transmission in the radiance convention: f(wi, wo) / eta_o^2 = f(wo, wi) / eta_i^2."""
    wi, wo = _dirs(2000, 1, upper=False), _dirs(2000, 2, upper=False)
    c = GGXConductor(0.3, torch.tensor(0.4, dtype=D64), 0.7, 0.8, 25.0)
    assert torch.allclose(c.eval(wi, wo), c.eval(wo, wi), rtol=1e-12, atol=0)
    eta = 1.4
    d = GGXDielectric(0.25, eta, 0.7, -110.0)
    f, b = d.eval(wi, wo), d.eval(wo, wi)
    one, e = torch.tensor(1.0, dtype=D64), torch.tensor(eta, dtype=D64)
    n_i, n_o = torch.where(wi[:, 2] > 0, one, e), torch.where(wo[:, 2] > 0, one, e)
    assert int((f > 0).sum()) > 1000
    assert torch.allclose(f / n_o ** 2, b / n_i ** 2, rtol=1e-8, atol=0)  # tails: the half vector cancels


def test_zero_anisotropy_is_the_isotropic_code_bit_for_bit():
    """a = 0 (any rotation) gives exactly the numbers of the isotropic classes: values, pdfs and samples."""
    wi, wo = _dirs(500, 3, upper=False), _dirs(500, 4, upper=False)
    u = torch.rand(500, 3, generator=torch.Generator().manual_seed(6), dtype=D64)
    r = torch.rand(500, generator=torch.Generator().manual_seed(7), dtype=D64) * 0.9 + 0.05
    for iso, zero in ((GGXConductor(r, 0.3, 0.8), GGXConductor(r, 0.3, 0.8, 0.0, 40.0)),
                      (GGXDielectric(r, 1.45), GGXDielectric(r, 1.45, torch.zeros(500, dtype=D64), 40.0))):
        assert torch.equal(iso.eval(wi, wo), zero.eval(wi, wo))
        assert torch.equal(iso.pdf(wi, wo), zero.pdf(wi, wo))
        a, b = iso.sample(wi, u), zero.sample(wi, u)
        assert torch.equal(a.w, b.w) and torch.equal(a.f, b.f) and torch.equal(a.pdf, b.pdf)


def test_a_rotation_by_90_degrees_swaps_alpha_x_and_alpha_y():
    """The conductor at rotation 90 is the conductor at rotation 0 with alpha_x and alpha_y exchanged, written
    here with the microfacet terms directly."""
    wi, wo = _dirs(1000, 8), _dirs(1000, 9)
    alpha, a, r0 = 0.3, 0.7, 0.5
    ax, ay = alphas(torch.tensor(alpha, dtype=D64), torch.tensor(a, dtype=D64))
    h = wi + wo
    h = h / h.norm(dim=-1, keepdim=True)
    want = (fresnel_schlick((wi * h).sum(-1), torch.tensor(r0, dtype=D64)) * ggx_d(h, ay, ax)
            * smith_g1(wi, h, ay, ax) * smith_g1(wo, h, ay, ax) / (4 * wi[:, 2] * wo[:, 2]))
    got = GGXConductor(alpha, r0, 1.0, a, 90.0).eval(wi, wo)
    assert torch.allclose(got, want, rtol=1e-12, atol=0)
    assert not torch.allclose(GGXConductor(alpha, r0, 1.0, a, 0.0).eval(wi, wo), want, rtol=1e-3)


@pytest.mark.parametrize("rot", [30.0, -75.0, 200.0])
def test_the_rotation_turns_the_tangent_counter_clockwise_seen_from_above(rot):
    """Turning the material by rot and both directions by rot counter-clockwise about z (x toward y) leaves
    f unchanged, for the conductor and the dielectric."""
    c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
    R = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=D64)
    wi, wo = _dirs(800, 10, upper=False), _dirs(800, 11, upper=False)
    for make in (lambda r: GGXConductor(0.2, 0.6, 1.0, 0.8, r), lambda r: GGXDielectric(0.2, 1.5, 0.8, r)):
        base, turned = make(0.0).eval(wi, wo), make(rot).eval(wi @ R.T, wo @ R.T)
        assert torch.allclose(turned, base, rtol=1e-10, atol=1e-14)
        assert not torch.allclose(make(rot).eval(wi, wo), base, rtol=1e-3)
