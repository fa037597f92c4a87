"""The layered Monte Carlo simulator against an independent analog random walk
and the physical checks of SPEC section 5. Fixed seeds; z-score limits are
Bonferroni-corrected over every bin of every configuration."""
from __future__ import annotations

import itertools
import math

import pytest
import torch
from analog_walk import analog_bins, uniform_in_bins
from stattools import z_threshold

from nbrdf.training.analytic import GGXDielectric
from nbrdf.training.layered import StackParams, simulate

N_THETA, N_PHI, K = 4, 6, 800
CORNERS = list(itertools.product((0.05, 0.6), (1.1, 1.9), (0.2, 0.98), (0.2, 4.0)))
CONFIGS = (
    [([(a, ior, alb, tau)], ("conductor", 0.3, 0.9)) for a, ior, alb, tau in CORNERS]
    + [([(0.2, 1.5, 0.8, 1.0)], ("diffuse", 0.7)),
       ([(0.4, 1.3, 0.95, 2.0)], ("dielectric", 0.2, 1.6)),
       ([(0.3, 1.5, 0.9, 1.0), (0.2, 1.3, 0.5, 0.5)], ("conductor", 0.3, 0.9)),
       ([(0.1, 1.6, 0.7, 0.3), (0.5, 1.2, 0.9, 2.0)], ("diffuse", 0.5)),
       # empty top slabs over conductors: the two-bounce connection and the
       # reversed walk (light trapped by total internal reflection, issue 14)
       ([(0.15, 1.5, 0.0, 0.0)], ("conductor", 0.02, 1.0)),
       ([(0.3, 1.3, 0.0, 0.0)], ("conductor", 0.2, 0.7)),
       # sharp lobes in series (held-out three_layer-004, red; three_layer-012, green): next-event
       # estimation through the stack (issue 14)
       ([(0.059, 1.218, 0.901, 0.099), (0.117, 1.096, 0.282, 3.245)], ("conductor", 0.069, 0.156)),
       ([(0.054, 1.093, 0.524, 0.836), (0.134, 1.142, 0.166, 0.714)], ("conductor", 0.640, 0.103)),
       # a sharp coat over a medium and a near-mirror base (held-out two_layer-014, green): next-event
       # estimation by way of the base
       ([(0.0146, 1.616, 0.950, 1.888)], ("conductor", 0.0115, 0.945))]
)
Z_LIMIT = z_threshold(1e-3, len(CONFIGS) * N_THETA * N_PHI)


def _stack(layers, base, n, dtype=torch.float64, channels=None):
    col = lambda i: torch.tensor([[l[i] for l in layers]] * n, dtype=dtype)
    kind = base[0]
    return StackParams(
        roughness=col(0), ior=col(1), albedo=col(2), sigma_t=col(3), base=kind,
        base_roughness=torch.full((n,), base[1] if kind != "diffuse" else 0.5, dtype=dtype),
        base_r0=torch.full((n,), base[2] if kind == "conductor" else 0.0, dtype=dtype),
        base_ior=torch.full((n,), base[2] if kind == "dielectric" else 1.5, dtype=dtype),
        base_albedo=torch.full((n,), base[1] if kind == "diffuse" else 0.0, dtype=dtype))


def _wi(theta):
    return torch.tensor([math.sin(theta), 0.0, math.cos(theta)], dtype=torch.float64)


@pytest.mark.parametrize("index", range(len(CONFIGS)), ids=[f"{len(c[0])}L-{c[1][0]}-{i}" for i, c in enumerate(CONFIGS)])
def test_agrees_with_analog_walk(index):
    layers, base = CONFIGS[index]
    seed = 1000 + 17 * index
    wi = _wi(0.6)
    a, a_se = analog_bins(layers, base, wi, 120_000, N_THETA, N_PHI, seed)
    wo = uniform_in_bins(N_THETA, N_PHI, K, seed + 1)
    n = wo.shape[0]
    # 16 paths per direction: products of two sharp lobes (a smooth top over a
    # nearly index-matched interface) make single paths heavy-tailed.
    m, _ = simulate(_stack(layers, base, n), wi.expand(n, 3), wo, spp=16, seed=seed + 2,
                    dtype=torch.float64, include_top_reflection=False)
    area = (1 / N_THETA) * (2 * math.pi / N_PHI)
    v = (m * wo[:, 2] * area).view(N_THETA, N_PHI, K)
    e, e_se = v.mean(-1), v.std(-1) / math.sqrt(K)
    z = (e - a) / (e_se ** 2 + a_se ** 2).sqrt().clamp_min(1e-15)
    assert z.abs().max() < Z_LIMIT, f"max |z| {z.abs().max():.2f} >= {Z_LIMIT:.2f}\n{z}"


def _pairs(n, seed):
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(2, n, 3, generator=g, dtype=torch.float64)
    v = v / v.norm(dim=-1, keepdim=True)
    v[..., 2] = v[..., 2].abs().clamp_min(0.05)
    v = v / v.norm(dim=-1, keepdim=True)
    return v[0], v[1]


def test_black_base_without_medium_is_top_reflection():
    wi, wo = _pairs(64, 3)
    layers, base = [(0.2, 1.5, 0.5, 0.0)], ("diffuse", 0.0)
    m, se = simulate(_stack(layers, base, 64), wi, wo, spp=64, seed=1, dtype=torch.float64)
    top = GGXDielectric(0.2, 1.5).eval(wi, wo)
    torch.testing.assert_close(m, top)
    assert (se == 0).all()


def test_absorbing_medium_falls_monotonically_with_sigma_t():
    """Albedo 0: every extra unit of optical depth only removes light. The
    pair-averaged value must fall at every step, beyond its noise."""
    wi, wo = _pairs(48, 4)
    means, errs = [], []
    for i, tau in enumerate((0.0, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0)):
        m, se = simulate(_stack([(0.3, 1.5, 0.0, tau)], ("conductor", 0.3, 0.9), 48), wi, wo, spp=512, seed=5 + i,
                         dtype=torch.float64, include_top_reflection=False)
        means.append(m.mean().item())
        errs.append(math.sqrt((se ** 2).sum().item()) / 48)
    for k in range(len(means) - 1):
        gap = means[k] - means[k + 1]
        assert gap > 3 * math.hypot(errs[k], errs[k + 1]), (k, means, errs)


def test_per_channel_extinction_walks_each_channel_as_its_own_stack():
    """A coloured absorbing coat (sigma_t per channel, OpenPBR's coat_color): each channel's estimate is, to the
    bit, the walk of a stack whose extinction is that channel's for every channel (same seed, same paths)."""
    wi, wo = _pairs(16, 11)
    n, sig = 16, (0.1, 0.8, 2.5)
    rgb = StackParams(roughness=torch.full((n, 1), 0.2, dtype=torch.float64), ior=torch.full((n, 1), 1.5, dtype=torch.float64),
                      albedo=torch.full((n, 1, 3), 0.3, dtype=torch.float64),
                      sigma_t=torch.tensor(sig, dtype=torch.float64).expand(n, 1, 3), base="conductor",
                      base_roughness=torch.full((n,), 0.3, dtype=torch.float64),
                      base_r0=torch.tensor([0.9, 0.6, 0.3], dtype=torch.float64).expand(n, 3))
    m, se = simulate(rgb, wi, wo, spp=64, seed=4, dtype=torch.float64)
    for c, tau in enumerate(sig):
        one = StackParams(roughness=rgb.roughness, ior=rgb.ior, albedo=rgb.albedo[..., c], sigma_t=torch.full((n, 1), tau, dtype=torch.float64),
                          base="conductor", base_roughness=rgb.base_roughness, base_r0=rgb.base_r0[:, c])
        mc, sc = simulate(one, wi, wo, spp=64, seed=4, dtype=torch.float64)
        assert torch.equal(m[:, c], mc) and torch.equal(se[:, c], sc)
    assert bool((m[:, 0] > m[:, 2]).all())  # the thinner channel's body is brighter


def test_an_f82_tint_darkens_the_base_seen_through_a_coat():
    """The walk's conductor takes OpenPBR's F82 tint: a tint of 1 is the plain walk bit for bit, a tint of 0
    darkens every pair's body (the correction only subtracts), beyond the noise."""
    wi, wo = _pairs(32, 12)
    n = 32
    st = lambda tint: StackParams(roughness=torch.full((n, 1), 0.3, dtype=torch.float64), ior=torch.full((n, 1), 1.1, dtype=torch.float64),
                                  albedo=torch.zeros(n, 1, dtype=torch.float64), sigma_t=torch.zeros(n, 1, dtype=torch.float64),
                                  base="conductor", base_roughness=torch.full((n,), 0.6, dtype=torch.float64),
                                  base_r0=torch.full((n,), 0.5, dtype=torch.float64),
                                  base_f82=None if tint is None else torch.full((n,), tint, dtype=torch.float64))
    plain, _ = simulate(st(None), wi, wo, spp=256, seed=9, dtype=torch.float64, include_top_reflection=False)
    white, _ = simulate(st(1.0), wi, wo, spp=256, seed=9, dtype=torch.float64, include_top_reflection=False)
    dark, se = simulate(st(0.0), wi, wo, spp=256, seed=9, dtype=torch.float64, include_top_reflection=False)
    assert torch.equal(plain, white)
    assert float((white - dark).sum()) > 5 * float(se.pow(2).sum().sqrt())


@pytest.mark.parametrize("layers,base", [CONFIGS[0], CONFIGS[5], CONFIGS[-2], CONFIGS[-1]])
def test_reciprocity(layers, base):
    n = 24
    wi, wo = _pairs(n, 6)
    m1, s1 = simulate(_stack(layers, base, n), wi, wo, spp=4000, seed=7, dtype=torch.float64)
    m2, s2 = simulate(_stack(layers, base, n), wo, wi, spp=4000, seed=8, dtype=torch.float64)
    z = (m1 - m2) / (s1 ** 2 + s2 ** 2).sqrt().clamp_min(1e-15)
    assert z.abs().max() < z_threshold(1e-3, 4 * n), z


@pytest.mark.parametrize("layers,base", [([(0.05, 1.05, 1.0, 5.0)], ("conductor", 0.05, 1.0)),
                                         ([(0.6, 1.9, 1.0, 0.5)], ("diffuse", 1.0)),
                                         ([(0.3, 1.5, 1.0, 2.0), (0.3, 1.5, 1.0, 2.0)], ("diffuse", 1.0))])
def test_albedo_at_most_one(layers, base):
    """Lossless stacks: directional albedo (cosine-weighted integral over wo) <= 1."""
    n = 4000
    g = torch.Generator().manual_seed(9)
    u = torch.rand(n, 2, generator=g, dtype=torch.float64)
    r, ph = torch.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
    wo = torch.stack([r * torch.cos(ph), r * torch.sin(ph), torch.sqrt(1 - u[:, 0])], -1)
    for theta in (0.0, 1.0, 1.4):
        m, _ = simulate(_stack(layers, base, n), _wi(theta).expand(n, 3), wo, spp=4, seed=10, dtype=torch.float64)
        est = m * math.pi  # cosine-weighted sampling: f cos / (cos / pi)
        alb, se = est.mean().item(), est.std().item() / math.sqrt(n)
        assert alb <= 1.0 + 4 * se, (theta, alb, se)
        assert alb > 0.3


def test_seeded_and_float32_agrees():
    wi, wo = _pairs(16, 12)
    st = _stack([(0.1, 1.5, 0.9, 1.0)], ("conductor", 0.3, 0.9), 16)
    a, _ = simulate(st, wi, wo, spp=128, seed=3)
    b, _ = simulate(st, wi, wo, spp=128, seed=3)
    assert torch.equal(a, b)
    c, se = simulate(st, wi, wo, spp=4096, seed=4, dtype=torch.float64)
    z = (a.double() - c) / se.clamp_min(1e-12)
    assert z.abs().max() < 60  # same estimator: float32 only differs by noise (a has spp=128)
