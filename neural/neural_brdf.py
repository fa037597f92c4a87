"""A neural BRDF behind the one BRDF interface (eval, sample, pdf).

One colour channel of a material latent, decoded by the shared decoder and
importance sampled through the material's proxy pdf, whose parameters are
computed once when the BRDF is made.
"""
from __future__ import annotations

import torch

from nbrdf.neural.brdf import Sample
from nbrdf.neural.decoder import Decoder
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
        p = proxy_pdf(w, w_other, torch.tensor(self.sigma, dtype=w.dtype), torch.tensor(self.w, dtype=w.dtype))
        return torch.where((w[:, 2] > 0) & (w_other[:, 2] > 0), p, torch.zeros_like(p))

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        wo, pdf = proxy_sample(w, u, self.sigma, self.w)
        ok = (wo[:, 2] > 0) & (w[:, 2] > 0)
        f = torch.where(ok, self.eval(w, wo), torch.zeros_like(pdf))
        return Sample(wo, f, torch.where(ok, pdf, torch.zeros_like(pdf)))


def material_brdfs(material, model=None) -> list[NeuralBRDF]:
    """The three channel BRDFs of a material through the full neural path."""
    from nbrdf.neural.model import default_model

    model = model or default_model()
    z = model.material_latent(material)
    sigma, w = model.proxy(z)
    return [NeuralBRDF(model.decoder, z[c], sigma, w) for c in range(3)]
