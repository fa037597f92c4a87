"""The proxy pdf: it integrates to 1, sampling follows it (chi-square), and the
neural BRDF's sample / pdf agree."""
from __future__ import annotations

import math

import pytest
import torch
from stattools import chi2_sphere

from nbrdf.neural.sampling import SamplerNet, gndf, proxy_pdf, proxy_sample

ALPHA = 1e-3


def _wi(theta_deg: float, n: int = 1) -> torch.Tensor:
    t = math.radians(theta_deg)
    return torch.tensor([[math.sin(t), 0.0, math.cos(t)]], dtype=torch.float64).expand(n, 3).contiguous()


@pytest.mark.parametrize("sigma,w,theta", [(0.05, 0.1, 0.0), (0.2, 0.5, 45.0), (0.6, 0.02, 70.0), (1.5, 0.9, 30.0)])
def test_sampling_follows_the_proxy_pdf(sigma, w, theta):
    g = torch.Generator().manual_seed(7)
    s, lam = torch.tensor(sigma, dtype=torch.float64), torch.tensor(w, dtype=torch.float64)

    def sample_fn(n):
        wo, pdf = proxy_sample(_wi(theta, n), torch.rand(n, 3, generator=g, dtype=torch.float64), s, lam)
        return wo, pdf

    res = chi2_sphere(sample_fn, lambda d: proxy_pdf(_wi(theta, d.shape[0]), d, s, lam), n_samples=200_000,
                      sub=24)
    assert res.p_value > ALPHA, str(res)
    assert abs(res.pdf_integral - 1) < 5e-3, str(res)


def test_pdf_of_a_sample_is_the_pdf_function():
    g = torch.Generator().manual_seed(1)
    wi = _wi(40.0, 1000)
    wo, pdf = proxy_sample(wi, torch.rand(1000, 3, generator=g, dtype=torch.float64), 0.1, 0.3)
    assert torch.allclose(pdf, proxy_pdf(wi, wo, torch.tensor(0.1, dtype=torch.float64), torch.tensor(0.3, dtype=torch.float64)), rtol=1e-9)


def test_sampler_net_keeps_parameters_in_range():
    net = SamplerNet()
    sigma, w = net(torch.randn(64, 32) * 10)
    assert bool(((sigma >= 0.003) & (sigma <= 2.0) & (w >= 0.02) & (w <= 0.98)).all())


def test_gndf_of_a_narrow_lobe_concentrates_at_the_pole():
    from nbrdf.training.analytic import GGXConductor

    b = GGXConductor(0.05, 1.0)
    img = gndf(lambda wi, wo: b.eval(wi, wo), n=32, n_wi=16)
    cell = (2 / 32) ** 2
    assert abs(float(img.sum()) * cell - 1) < 0.05
    centre = img[12:20, 12:20].sum() * cell
    assert centre > 0.8
