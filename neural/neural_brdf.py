"""Neural BRDFs behind the BRDF interfaces (``neural.brdf``).

``LatentBRDF``: a material's code (3, 34) (body latents and clear coat,
``neural.coat``) decoded by the shared decoder plus the coat in closed form,
RGB, importance sampled by the coat's visible normals mixed with the body's
proxy pdf (sigma, w), computed once when the BRDF is made (``neural_brdf``:
the full neural path of a material). ``NeuralBRDF``: one colour channel.
"""
from __future__ import annotations

import torch

from nbrdf.neural.anisotropy import body_tail
from nbrdf.neural.body_scale import BodyScale
from nbrdf.neural.brdf import ExactRGB, Sample
from nbrdf.neural.coat import coat_of, has_coat
from nbrdf.neural.decoder import Decoder
from nbrdf.neural.geometry import incidence
from nbrdf.neural.material import Diffuse, Material
from nbrdf.neural.model import default_model
from nbrdf.neural.sampling import coated_pdf, coated_sample

Tensor = torch.Tensor


class _CodeSampler:
    """Sampling shared by both classes: the coat's lobe (when the code has
    one) mixed with the body's proxy (sigma, w)."""

    decoder: Decoder
    z: Tensor
    sigma: float
    w: float

    def _coat(self, like: Tensor) -> Tensor | None:
        spec = self.decoder.spec
        if not has_coat(spec, self.z):
            return None
        return coat_of(self.z[:1], spec.latent)[0].to(like.dtype)

    def _body_vector(self, like: Tensor) -> Tensor | None:
        """An anisotropic body's vector (its proxy is stretched with it), None for an isotropic code."""
        tail = body_tail(self.z[:1], self.decoder.spec.code) if self.decoder.spec.coat else None
        return None if tail is None else tail[0, :2].to(like.dtype)

    def pdf(self, w: Tensor, w_other: Tensor) -> Tensor:
        s, lam = torch.tensor(self.sigma, dtype=w.dtype), torch.tensor(self.w, dtype=w.dtype)
        p = coated_pdf(w, w_other, self._coat(w), s, lam, self._body_vector(w))
        return torch.where((w[:, 2] > 0) & (w_other[:, 2] > 0), p, torch.zeros_like(p))

    def _draw(self, w: Tensor, u: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        s, lam = torch.tensor(self.sigma, dtype=w.dtype), torch.tensor(self.w, dtype=w.dtype)
        wo, pdf = coated_sample(w, u, self._coat(w), s, lam, self._body_vector(w))
        ok = (wo[:, 2] > 0) & (w[:, 2] > 0)
        return wo, torch.where(ok, pdf, torch.zeros_like(pdf)), ok


class NeuralBRDF(_CodeSampler):
    """Channel ``z`` (34,) of a material code under ``decoder``, with proxy (sigma, w)."""

    def __init__(self, decoder: Decoder, z: Tensor, sigma: float, w: float):
        self.decoder, self.z = decoder, z.reshape(1, -1).float()
        self.sigma, self.w = float(sigma), float(w)

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        with torch.no_grad():
            return self.decoder(self.z.expand(wi.shape[0], -1), wi.float(), wo.float()).to(wi.dtype)

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        wo, pdf, ok = self._draw(w, u)
        f = torch.where(ok, self.eval(w, wo), torch.zeros_like(pdf))
        return Sample(wo, f, pdf)


class LatentBRDF(_CodeSampler, ExactRGB):
    """The decoder at a material's code ``z`` (3, 34): RGB values (body plus
    coat), one sampler for all three channels; the body times ``scale``
    where given (``neural.body_scale``: the walk's energy on the networks' lobe)."""

    def __init__(self, decoder: Decoder, z: Tensor, sigma: float, w: float, scale: BodyScale | None = None):
        self.decoder, self.z = decoder, z.reshape(3, -1).float()
        self.sigma, self.w = float(sigma), float(w)
        self.scale = scale

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        with torch.no_grad():
            return self.decoder.eval_rgb(self.z, wi.float(), wo.float(), self.scale)

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        wo, pdf, ok = self._draw(w, u)
        f = torch.where(ok[:, None], self.eval(w, wo).to(pdf.dtype), torch.zeros(1, dtype=pdf.dtype))
        return Sample(wo, f, pdf)

    def sample_at(self, theta_i: float, n: int, seed: int = 0) -> Sample:
        """``n`` directions drawn at the standard incidence ``theta_i`` (degrees,
        phi_i = 0) from uniforms of ``seed``: what ``nbrdf sample`` writes."""
        wi = incidence(theta_i).expand(n, 3).contiguous()
        u = torch.rand(n, 3, generator=torch.Generator().manual_seed(seed))
        return self.sample(wi, u)


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


def latent_brdf(decoder: Decoder, z: Tensor, material: Material, sampler=None,
                scale: BodyScale | None = None) -> LatentBRDF:
    """The decoder at code z (3, 34) of ``material`` (its body times ``scale`` where given), sampled through
    the sampler network's proxy when given, else through ``proxy_hint``."""
    if sampler is not None:
        with torch.no_grad():
            s, w = sampler.material_params(z)
        return LatentBRDF(decoder, z, float(s), float(w), scale)
    return LatentBRDF(decoder, z, *proxy_hint(material), scale)


def neural_brdf(material: Material, model=None) -> LatentBRDF:
    """A uniform material through the full neural path (leaf encoders,
    layering, decoder) of ``model`` (default: the shipped bundle)."""
    model = model or default_model()
    return latent_brdf(model.decoder, model.material_latent(material), material, model.sampler)


def material_brdfs(material, model=None) -> list[NeuralBRDF]:
    """The three channel BRDFs of a material through the full neural path."""
    model = model or default_model()
    z = model.material_latent(material)
    sigma, w = model.proxy(z)
    return [NeuralBRDF(model.decoder, z[c], sigma, w) for c in range(3)]
