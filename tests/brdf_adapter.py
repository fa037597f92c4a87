"""One chi-square adapter for every BRDF sampler (in the manner of Mitsuba 3's
BSDF adapter): any object with ``sample(w, u) -> Sample`` and
``pdf(w, w_other)`` -- single-channel ``neural.brdf.BRDF`` or RGB
``neural.brdf.RGBBRDF`` -- is sampled from a fixed incidence with a fixed
seed and judged by ``stattools.chi2_sphere`` at significance ``alpha``; the
pdf must integrate to the fraction of valid samples, and every sample must
report the value and pdf that ``eval`` and ``pdf`` give for its direction.
"""
from __future__ import annotations

import math

import torch
from stattools import Chi2Result, chi2_sphere


def incidence(theta_deg: float, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    t = math.radians(theta_deg)
    return torch.tensor([math.sin(t), 0.0, math.cos(t)], dtype=dtype)


def check_sampler(name: str, brdf, theta_deg: float, alpha: float = 1e-3, n_samples: int = 400_000,
                  seed: int = 1234, dtype: torch.dtype = torch.float64, check_values: bool = True,
                  **chi2_args) -> Chi2Result:
    """Asserts that ``brdf``'s sampler follows its pdf; returns the chi-square result."""
    w = incidence(theta_deg, dtype)
    g = torch.Generator().manual_seed(seed)
    kept: list = []

    def sample_fn(n):
        s = brdf.sample(w.expand(n, 3), torch.rand(n, 3, generator=g, dtype=torch.float64).to(dtype))
        kept.append(s)
        return s.w, s.pdf

    res = chi2_sphere(sample_fn, lambda d: brdf.pdf(w.to(d.dtype).expand(d.shape[0], 3), d.to(dtype)),
                      n_samples=n_samples, **chi2_args)
    assert res.p_value > alpha, f"{name}: {res}"
    se = math.sqrt(res.valid_fraction * (1 - res.valid_fraction) / res.n_samples)
    assert abs(res.pdf_integral - res.valid_fraction) < 4 * se + 2e-3, f"{name}: the pdf integrates wrongly: {res}"
    if check_values:  # the sample's own value and pdf are eval's and pdf's (first 4096 samples)
        s = kept[0]
        k = min(4096, s.pdf.shape[0])
        wk, ok = s.w[:k], s.pdf[:k] > 0
        wi = w.expand(k, 3)
        torch.testing.assert_close(s.pdf[:k][ok].double(), brdf.pdf(wi, wk)[ok].double(), rtol=1e-4, atol=1e-8)
        f = brdf.eval(wi, wk)
        torch.testing.assert_close(s.f[:k][ok].double(), f[ok].double(), rtol=1e-4, atol=1e-6)
    return res


def sphere_quadrature(n: int, dtype: torch.dtype = torch.float64) -> tuple[torch.Tensor, torch.Tensor]:
    """Midpoint quadrature over the whole sphere in (cos theta, phi): directions (4 n^2, 3), solid-angle weights."""
    c = (torch.arange(2 * n, dtype=dtype) + 0.5) / n - 1.0
    p = (torch.arange(2 * n, dtype=dtype) + 0.5) / (2 * n) * 2 * math.pi
    cz, ph = torch.meshgrid(c, p, indexing="ij")
    s = torch.sqrt(1 - cz * cz)
    d = torch.stack([s * torch.cos(ph), s * torch.sin(ph), cz], -1).reshape(-1, 3)
    return d, torch.full((d.shape[0],), 4 * math.pi / d.shape[0], dtype=dtype)


def check_sampler_moments(name: str, brdf, theta_deg: float, n_samples: int = 1 << 14, grid: int = 200,
                          tol: float = 4e-3) -> None:
    """A deterministic, fast companion of ``check_sampler``: ``n_samples`` scrambled Sobol points (fixed seed)
    drive the sampler; the share of valid samples and their mean x, y, z and z^2 (over all samples, 0 where
    invalid) must equal the pdf's mass and moments by quadrature to ``tol``, and each sample must report eval's
    value and pdf's density for its direction. For lobes a ``grid`` x ``4 grid`` quadrature resolves (roughness
    >= about 0.2): a sampler or pdf off by a few percent of its mass or mean direction fails."""
    from scipy.stats import qmc

    w = incidence(theta_deg)
    u = torch.from_numpy(qmc.Sobol(3, scramble=True, seed=7).random(n_samples))
    s = brdf.sample(w.expand(n_samples, 3), u)
    ok = s.pdf > 0
    d, wt = sphere_quadrature(grid)
    p = brdf.pdf(w.expand(d.shape[0], 3), d) * wt
    share = float(ok.double().mean())
    assert abs(share - float(p.sum())) < tol, f"{name}: valid share {share} vs the pdf's mass {float(p.sum())}"
    for k, g in enumerate((lambda v: v[:, 0], lambda v: v[:, 1], lambda v: v[:, 2], lambda v: v[:, 2] ** 2)):
        got = float(torch.where(ok, g(s.w), torch.zeros_like(s.pdf)).mean())
        assert abs(got - float((g(d) * p).sum())) < tol, f"{name}: moment {k} of the samples {got}"
    wk = w.expand(int(ok.sum()), 3)
    torch.testing.assert_close(s.pdf[ok], brdf.pdf(wk, s.w[ok]), rtol=1e-6, atol=1e-10)
    torch.testing.assert_close(s.f[ok], brdf.eval(wk, s.w[ok]), rtol=1e-6, atol=1e-10)

