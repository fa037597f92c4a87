"""Projection and saved latents."""
from __future__ import annotations

import pytest
import torch
from test_decoder import rand_dirs

from nbrdf.neural.decoder import Decoder, DecoderSpec
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.latent import MaterialLatent, load_latent, save_latent
from nbrdf.neural.projection import ProjectionConfig, project


@pytest.fixture(scope="module")
def dec():
    torch.manual_seed(0)
    return Decoder(DecoderSpec(width=32, depth=2)).eval()


@pytest.mark.slow
@pytest.mark.ci_slow
def test_projection_recovers_a_brdf_the_decoder_can_represent(dec):
    """Values made by the decoder at some latents are fitted back to within a few percent."""
    torch.manual_seed(1)
    z_true = torch.randn(3, 32) * 0.5
    wi = rand_dirs(1024, 7).float()[None].expand(3, -1, -1)
    wo = rand_dirs(1024, 8).float()[None].expand(3, -1, -1)
    with torch.no_grad():
        f = dec(z_true[:, None, :], wi, wo)
    z = project(dec, wi, wo, f, ProjectionConfig(steps=600, lr=0.05, latent_reg=0.0))
    wi2, wo2 = rand_dirs(512, 9).float()[None].expand(3, -1, -1), rand_dirs(512, 10).float()[None].expand(3, -1, -1)
    with torch.no_grad():
        want, got = dec(z_true[:, None, :], wi2, wo2), dec(z[:, None, :], wi2, wo2)
    start = dec(dec.latent_mean.expand(3, 32)[:, None, :], wi2, wo2)
    err = (torch.log1p(got) - torch.log1p(want)).abs().mean()
    err0 = (torch.log1p(start) - torch.log1p(want)).abs().mean()
    assert err < 0.05 * err0 and err < 2e-3


def test_projection_leaves_the_decoder_frozen(dec):
    before = {k: v.clone() for k, v in dec.state_dict().items()}
    wi = rand_dirs(64, 1).float()[None]
    project(dec, wi, wi.flip(1), torch.rand(1, 64), ProjectionConfig(steps=5))
    for k, v in dec.state_dict().items():
        assert torch.equal(v, before[k])
    assert all(not p.requires_grad for p in dec.parameters()) or all(p.requires_grad for p in dec.parameters())


@pytest.mark.parametrize("bad", ["nan", "negative", "shape", "below"])
def test_bad_samples_are_clear_errors(dec, bad):
    wi = rand_dirs(16, 1).float()[None]
    wo = rand_dirs(16, 2).float()[None]
    f = torch.rand(1, 16)
    if bad == "nan":
        f[0, 3] = float("nan")
    elif bad == "negative":
        f[0, 3] = -1.0
    elif bad == "shape":
        f = torch.rand(1, 15)
    else:
        wi = wi * torch.tensor([1.0, 1.0, -1.0])
    with pytest.raises(NbrdfError):
        project(dec, wi, wo, f, ProjectionConfig(steps=2))


def test_latent_files_remember_their_decoder(tmp_path, dec):
    lat = MaterialLatent(torch.randn(3, 32), dec.weights_id(), {"material": "x.json"})
    save_latent(tmp_path / "z.safetensors", lat)
    back = load_latent(tmp_path / "z.safetensors", dec.weights_id())
    assert torch.equal(back.z, lat.z) and back.source == {"material": "x.json"}
    with pytest.raises(NbrdfError, match="belongs to decoder"):
        load_latent(tmp_path / "z.safetensors", "0123456789abcdef")
    (tmp_path / "bad.safetensors").write_bytes(b"junk")
    with pytest.raises(NbrdfError):
        load_latent(tmp_path / "bad.safetensors")
    with pytest.raises(NbrdfError):
        save_latent(tmp_path / "nan.safetensors", MaterialLatent(torch.full((3, 32), float("nan")), "x"))


@pytest.mark.slow
@pytest.mark.ci_slow
@pytest.mark.parametrize("share, lo, hi", [(0.5, 0.93, 1.07), (0.0, 0.0, 0.8)])
def test_projection_fits_the_mean_of_skewed_noise(dec, share, lo, hi):
    """Monte Carlo values are right-skewed: with f x E, E ~ Exp(1) (mean 1,
    geometric mean 0.56), the log loss alone fits a BRDF far too dark; the
    final steps on ``unbiased_error`` fit the mean."""
    torch.manual_seed(2)
    z_true = torch.randn(3, 32) * 0.5
    wi = rand_dirs(4096, 11).float()[None].expand(3, -1, -1)
    wo = rand_dirs(4096, 12).float()[None].expand(3, -1, -1)
    with torch.no_grad():
        f = dec(z_true[:, None, :], wi, wo)
    scale = 100.0 * dec.spec.loss_scale / f.mean()  # values well inside the loss's log regime
    noisy = f * scale * torch.empty_like(f).exponential_(generator=torch.Generator().manual_seed(3))
    z = project(dec, wi, wo, noisy, ProjectionConfig(steps=600, lr=0.05, latent_reg=0.0, unbiased_share=share))
    wi2, wo2 = rand_dirs(1024, 13).float()[None].expand(3, -1, -1), rand_dirs(1024, 14).float()[None].expand(3, -1, -1)
    with torch.no_grad():
        ratio = dec(z[:, None, :], wi2, wo2).mean() / (dec(z_true[:, None, :], wi2, wo2).mean() * scale)
    assert lo < float(ratio) < hi, float(ratio)
