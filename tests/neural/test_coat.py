"""The coat split (neural.coat): the closed-form coat, codes, its sampling,
and the body a coat-split decoder learns."""
from __future__ import annotations

import math

import pytest
import torch
from brdf_adapter import check_sampler, check_sampler_moments

from nbrdf.neural.coat import (
    NO_COAT,
    coat_eval,
    coat_features,
    coat_of,
    coat_pdf,
    coat_probability,
    coat_sample,
    code_coat,
    code_size,
    with_coat,
)
from nbrdf.neural.decoder import Decoder, DecoderSpec
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.geometry import cosine_hemisphere
from nbrdf.neural.neural_brdf import LatentBRDF
from nbrdf.neural.projection import ProjectionConfig, project
from nbrdf.training.analytic import GGXDielectric

ALPHA = 1e-3


def _pairs(n: int, seed: int = 0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    wi = cosine_hemisphere(torch.rand(n, generator=g, dtype=dtype), torch.rand(n, generator=g, dtype=dtype))
    wo = cosine_hemisphere(torch.rand(n, generator=g, dtype=dtype), torch.rand(n, generator=g, dtype=dtype))
    return wi, wo


@pytest.mark.parametrize("rough,ior", [(0.01, 1.5), (0.05, 1.3), (0.4, 2.2)])
def test_coat_is_the_interfaces_reflection(rough, ior):
    """The coat term is the reflection the ground truth adds for the top interface."""
    wi, wo = _pairs(4096)
    torch.testing.assert_close(coat_eval(torch.tensor([rough, ior], dtype=torch.float64), wi, wo), GGXDielectric(rough, ior).eval(wi, wo),
                               rtol=1e-10, atol=1e-12)


def test_no_coat_reflects_nothing_and_below_the_horizon_is_zero():
    wi, wo = _pairs(256)
    assert coat_eval(torch.tensor(NO_COAT), wi, wo).abs().max() == 0
    below = wo * torch.tensor([1.0, 1.0, -1.0], dtype=wo.dtype)
    assert coat_eval(torch.tensor([0.05, 1.5]), wi, below).abs().max() == 0
    assert coat_probability(torch.tensor(NO_COAT), wi).max() == 0


def test_codes_carry_and_clamp_the_coat():
    z = torch.randn(3, 32)
    code = with_coat(z, (0.02, 1.6))
    assert code.shape == (3, 34) and torch.equal(code[:, :32], z)
    torch.testing.assert_close(coat_of(code, 32), torch.tensor([[0.02, 1.6]]).expand(3, 2))
    wild = with_coat(z, (-1.0, 9.0))
    assert coat_of(wild, 32)[0].tolist() == pytest.approx([0.005, 3.0])
    with pytest.raises(NbrdfError, match=r"34 \(or 40 with anisotropy\) floats"):
        coat_of(z, 32)


def test_decoder_adds_the_coat_to_a_code_only():
    torch.manual_seed(0)
    dec = Decoder(DecoderSpec(coat=True))
    wi, wo = _pairs(512, dtype=torch.float32)
    z = torch.randn(3, 32) * 0.1
    body = dec.eval_rgb(z, wi, wo)
    full = dec.eval_rgb(with_coat(z, (0.03, 1.5)), wi, wo)
    torch.testing.assert_close(full - body, coat_eval(torch.tensor([0.03, 1.5]), wi, wo)[:, None].expand(-1, 3),
                               rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(dec.eval_rgb(with_coat(z, None), wi, wo), body)
    one = dec(with_coat(z, (0.03, 1.5))[1].expand(512, -1), wi, wo)
    torch.testing.assert_close(one, full[:, 1], rtol=1e-5, atol=1e-6)


class CoatLobe:
    """The coat's lobe as a BRDF for the sampler checks (u[:, 0] unused: one lobe)."""

    def __init__(self, roughness: float = 0.08, ior: float = 1.5):
        self.c = torch.tensor([roughness, ior], dtype=torch.float64)

    def sample(self, w, u):
        from nbrdf.neural.brdf import Sample

        wo = coat_sample(self.c, w, u[:, 1], u[:, 2])
        return Sample(wo, coat_eval(self.c, w, wo), self.pdf(w, wo))

    def pdf(self, w, w_other):
        return coat_pdf(self.c, w, w_other)

    def eval(self, wi, wo):
        return coat_eval(self.c, wi, wo)


@pytest.mark.parametrize("theta", [10.0, 55.0])
def test_coat_sampler_follows_its_pdf(theta):
    check_sampler("coat lobe", CoatLobe(), theta, alpha=ALPHA, n_samples=200_000)


@pytest.mark.parametrize("theta", [0.0, 35.0, 70.0])
def test_coat_sampler_moments_match_its_pdf(theta):
    """Fast and deterministic beside the chi-square test, on a lobe a quadrature resolves."""
    check_sampler_moments("coat lobe a=0.4", CoatLobe(0.4, 1.7), theta)


def test_coat_features_and_probability_values():
    f = coat_features(torch.tensor([[0.125, 1.5], [0.0, 0.5], [8.0, 9.0]], dtype=torch.float64))
    # cube-root roughness, ior - 1, normal-incidence reflectance; out-of-range coats clamped first
    torch.testing.assert_close(f[0], torch.tensor([0.5, 0.5, 0.04], dtype=torch.float64))
    torch.testing.assert_close(f[1], torch.tensor([0.005 ** (1 / 3), 0.0, 0.0], dtype=torch.float64))
    torch.testing.assert_close(f[2], torch.tensor([1.0, 2.0, 0.25], dtype=torch.float64))
    torch.testing.assert_close(coat_features(torch.tensor([0.125, 1.5], dtype=torch.float64)), f[0])  # one coat
    assert code_size(32, coat=True) == 34 and code_size(32, coat=False) == 32
    # the coat lobe's share: sqrt of the normal-incidence Fresnel term, held to [0.05, 0.95]
    up = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
    assert coat_probability(torch.tensor([0.1, 1.5], dtype=torch.float64), up).item() == pytest.approx(0.2)
    assert coat_probability(torch.tensor([0.1, 1.02], dtype=torch.float64), up).item() == pytest.approx(0.05)
    graze = torch.tensor([[math.sqrt(1 - 1e-6), 0.0, 1e-3]], dtype=torch.float64)
    assert coat_probability(torch.tensor([0.1, 1.5], dtype=torch.float64), graze).item() == pytest.approx(0.95)


def test_code_coat_reads_a_coat_split_code_only():
    spec = DecoderSpec(coat=True)
    z = with_coat(torch.zeros(3, spec.latent), (0.3, 1.8))
    assert code_coat(spec, z) == pytest.approx((0.3, 1.8))
    assert code_coat(spec, torch.zeros(3, spec.latent)) == NO_COAT  # a bare latent
    assert code_coat(DecoderSpec(coat=False), z) == NO_COAT
    assert code_coat(spec, with_coat(torch.zeros(3, spec.latent), (5.0, 0.2))) == pytest.approx((1.0, 1.0))


@pytest.mark.parametrize("theta", [5.0, 45.0, 75.0])
def test_coated_material_sampler_follows_its_pdf(theta):
    """The mixture of the coat's visible normals and the body's proxy (the
    coat's share changes with incidence through its Fresnel term)."""
    torch.manual_seed(1)
    dec = Decoder(DecoderSpec(coat=True))
    brdf = LatentBRDF(dec, with_coat(torch.randn(3, 32) * 0.1, (0.05, 1.5)), sigma=0.3, w=0.3)
    check_sampler("coated code", brdf, theta, alpha=ALPHA, n_samples=200_000, dtype=torch.float32)


@pytest.mark.slow
@pytest.mark.ci_slow
def test_projection_fits_the_body_under_a_known_coat():
    """Samples of coat + a decoded body: the projection returns the coat in
    the code and a body that decodes to the samples' body."""
    torch.manual_seed(2)
    dec = Decoder(DecoderSpec(coat=True))
    z_true = torch.randn(3, 32) * 0.3
    coat = torch.tensor([0.02, 1.5])
    wi, wo = _pairs(2048, seed=3, dtype=torch.float32)
    with torch.no_grad():
        f = dec.eval_rgb(with_coat(z_true, coat), wi, wo).T.contiguous()
    code = project(dec, wi[None].expand(3, -1, -1), wo[None].expand(3, -1, -1), f, ProjectionConfig(steps=300),
                   coat=coat[None].expand(3, 2))
    assert code.shape == (3, 34)
    torch.testing.assert_close(code[:, 32:], coat[None].expand(3, 2))
    with torch.no_grad():
        body_fit = dec.eval_rgb(code[:, :32], wi, wo)
        body_true = dec.eval_rgb(z_true, wi, wo)
    rel = ((body_fit - body_true).abs() / (body_true.abs() + 1e-2)).mean()
    assert rel < 0.05, rel
    # the coat's spike never leaks into the body: its peak stays in closed form
    peak = coat_eval(coat, wi, wo).max()
    assert body_fit.max() < 0.2 * peak


def test_body_of_a_simulated_stack_is_the_value_without_the_top_reflection():
    """The data set's bodies (value minus the coat) are what the simulator
    computes without its closed-form top reflection, to round-off."""
    from nbrdf.neural.stack import CLASSES, PARAM_NAMES, P, params_to_stack
    from nbrdf.training.dataset import BRDFSet, body_values
    from nbrdf.training.layered import simulate
    from nbrdf.training.reference import simulator_params

    p = torch.zeros(1, len(PARAM_NAMES), dtype=torch.float64)
    p[0, P["class"]] = CLASSES.index("two_layer")
    p[0, [P["top_roughness"], P["top_ior"], P["albedo_1"], P["sigma_t_1"], P["base_roughness"], P["base_value"]]] = \
        torch.tensor([0.03, 1.5, 0.9, 0.5, 0.2, 0.9], dtype=torch.float64)
    wi, wo = _pairs(64, seed=4, dtype=torch.float32)
    wo[:8] = wi[:8] * torch.tensor([-1.0, -1.0, 1.0])  # mirror pairs: on the coat's spike
    stack = simulator_params(params_to_stack(p).repeat_interleave(64))
    full, _ = simulate(stack, wi, wo, spp=64, seed=5)
    body, se = simulate(stack, wi, wo, spp=64, seed=5, include_top_reflection=False)
    data = BRDFSet(p.float(), wi[None], wo[None], full.reshape(1, -1).float(), torch.zeros(1, 64))
    b = body_values(data)[0]
    from nbrdf.neural.coat import coat_eval

    torch.testing.assert_close(b, (full.reshape(-1) - coat_eval(torch.tensor([0.03, 1.5]), wi, wo)).clamp_min(0),
                               rtol=1e-5, atol=1e-5)
    z = (b - body.reshape(-1)) / se.reshape(-1).clamp_min(1e-6)
    assert z.abs().max() < 5.0, z.abs().max()  # the same estimator's sampled part, within its noise
    assert (full.reshape(-1) - body.reshape(-1)).max() > 1.0  # the coat's spike is in the pairs
    assert math.isfinite(float(body.sum()))
