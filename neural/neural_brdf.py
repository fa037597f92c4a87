"""Neural BRDFs behind the BRDF interfaces (``neural.brdf``).

``LatentBRDF``: a material's three channel latents (3, 32) decoded by the
shared decoder, RGB, importance sampled through the proxy pdf (sigma, w)
computed once when the BRDF is made (``neural_brdf``: the full neural path
of a material). ``NeuralBRDF``: one colour channel of it.
"""
from __future__ import annotations

import torch

from nbrdf.neural.brdf import ExactRGB, Sample
from nbrdf.neural.decoder import Decoder
from nbrdf.neural.material import Diffuse, Material
from nbrdf.neural.sampling import proxy_pdf, proxy_sample

Tensor = torch.Tensor


class NeuralBRDF:
    """Channel ``z`` (32,) of a material under ``decoder``, with proxy (sigma, w)."""

    def __init__(self, decoder: Decoder, z: Tensor, sigma: float, w: float):
        self.decoder, self.z = decoder, z.reshape(1, -1).float()
        self.sigma, self.w = float(sigma), float(w)

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        with torch.no_grad():
            return self.decoder(self.z.expand(wi.shape[0], -1), wi.float(), wo.float()).to(wi.dtype)

    def pdf(self, w: Tensor, w_other: Tensor) -> Tensor:
        return _proxy_pdf(w, w_other, self.sigma, self.w)

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        wo, pdf = proxy_sample(w, u, self.sigma, self.w)
        ok = (wo[:, 2] > 0) & (w[:, 2] > 0)
        f = torch.where(ok, self.eval(w, wo), torch.zeros_like(pdf))
        return Sample(wo, f, torch.where(ok, pdf, torch.zeros_like(pdf)))


def _proxy_pdf(w: Tensor, w_other: Tensor, sigma: float, lam: float) -> Tensor:
    p = proxy_pdf(w, w_other, torch.tensor(sigma, dtype=w.dtype), torch.tensor(lam, dtype=w.dtype))
    return torch.where((w[:, 2] > 0) & (w_other[:, 2] > 0), p, torch.zeros_like(p))


class LatentBRDF(ExactRGB):
    """The decoder at a material's latents ``z`` (3, 32): RGB values, one
    proxy sampler (sigma, w) for all three channels."""

    def __init__(self, decoder: Decoder, z: Tensor, sigma: float, w: float):
        self.decoder, self.z = decoder, z.reshape(3, -1).float()
        self.sigma, self.w = float(sigma), float(w)

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        with torch.no_grad():
            return self.decoder.eval_rgb(self.z, wi.float(), wo.float())

    def pdf(self, w: Tensor, w_other: Tensor) -> Tensor:
        return _proxy_pdf(w, w_other, self.sigma, self.w)

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        wo, pdf = proxy_sample(w, u, self.sigma, self.w)
        ok = (wo[:, 2] > 0) & (w[:, 2] > 0)
        f = torch.where(ok[:, None], self.eval(w, wo).to(pdf.dtype), torch.zeros(1, dtype=pdf.dtype))
        return Sample(wo, f, torch.where(ok, pdf, torch.zeros_like(pdf)))


def proxy_hint(m: Material) -> tuple[float, float]:
    """A proxy pdf (sigma, w) guessed from the top layer when no sampler
    network is at hand: the half-vector spread of its GGX lobe (about
    roughness / sqrt 2), half of the samples cosine-distributed."""
    top = m.layers[0]
    r = getattr(top, "roughness", None)
    if isinstance(top, Diffuse):
        return 1.0, 0.9
    r = float(r) if isinstance(r, (int, float)) else 0.3  # texture-mapped: a middle value
    return max(0.01, 0.71 * r), 0.5


def latent_brdf(decoder: Decoder, z: Tensor, material: Material, sampler=None) -> LatentBRDF:
    """The decoder at latents z (3, 32) of ``material``, sampled through the
    sampler network's proxy when given, else through ``proxy_hint``."""
    if sampler is not None:
        with torch.no_grad():
            s, w = sampler.material_params(z)
        return LatentBRDF(decoder, z, float(s), float(w))
    return LatentBRDF(decoder, z, *proxy_hint(material))


def neural_brdf(material: Material, model=None) -> LatentBRDF:
    """A uniform material through the full neural path (leaf encoders,
    layering, decoder) of ``model`` (default: the shipped bundle)."""
    from nbrdf.neural.model import default_model

    model = model or default_model()
    return latent_brdf(model.decoder, model.material_latent(material), material, model.sampler)


def material_brdfs(material, model=None) -> list[NeuralBRDF]:
    """The three channel BRDFs of a material through the full neural path."""
    from nbrdf.neural.model import default_model

    model = model or default_model()
    z = model.material_latent(material)
    sigma, w = model.proxy(z)
    return [NeuralBRDF(model.decoder, z[c], sigma, w) for c in range(3)]
