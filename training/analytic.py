"""Closed-form ground-truth BxDFs of single interfaces (SPEC sections 3, 5).

Each class keeps one colour channel; its parameters are tensors (or floats)
broadcastable to the batch (N,), so one object can hold N different BRDFs
(one per lane), which is how the Monte Carlo simulator and the data sets use
them. All follow the ``neural.brdf.BRDF`` interface:

- ``eval(wi, wo)``: value in 1/sr without cosine (radiance convention: for
  refraction the factor eta_o^2 of the side of ``wo``);
- ``sample(w, u)``: given ``w`` in the role of ``wi`` draws ``wo`` by
  visible-normal sampling and returns it with ``f(w, wo)`` and its pdf;
- ``pdf(w, w_other)``: the solid-angle density of that sampler.

The GGX interfaces take SPEC section 10's ``anisotropy`` and the material's
``rotation`` (degrees): the anisotropic D, masking and visible-normal
sampling in the rotated tangent frame. Where every anisotropy is 0 they run
the isotropic formulas untouched (the rotation then changes nothing).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from nbrdf.neural.anisotropy import alphas, from_frame, to_frame
from nbrdf.neural.brdf import Sample
from nbrdf.neural.geometry import cosine_hemisphere
from nbrdf.neural.microfacet import (
    f82_coefficient,
    fresnel_dielectric,
    fresnel_f82,
    ggx_d,
    reflect,
    refract,
    sample_vndf,
    smith_g1,
    vndf_pdf,
)

Tensor = torch.Tensor


def _param(p: Tensor | float, like: Tensor) -> Tensor:
    return torch.as_tensor(p, dtype=like.dtype, device=like.device)


def _dot(a: Tensor, b: Tensor) -> Tensor:
    return (a * b).sum(-1)


def _safe_div(a: Tensor, b: Tensor) -> Tensor:
    ok = b != 0
    return torch.where(ok, a / torch.where(ok, b, torch.ones_like(b)), torch.zeros_like(a))


class _Anisotropic:
    """The frame and alphas of an interface with ``roughness``, ``anisotropy`` and ``rotation``."""

    roughness: Tensor | float
    anisotropy: Tensor | float
    rotation: Tensor | float

    def _isotropic(self) -> bool:
        return not bool((torch.as_tensor(self.anisotropy) != 0).any())

    def _alphas(self, like: Tensor) -> tuple[Tensor, Tensor | None]:
        """(alpha_x, alpha_y); alpha_y None where every anisotropy is 0 (the isotropic code paths)."""
        a = _param(self.roughness, like)
        if self._isotropic():
            return a, None
        return alphas(a, _param(self.anisotropy, like))

    def _in(self, w: Tensor) -> Tensor:
        """w in the rotated tangent frame (itself when isotropic)."""
        return w if self._isotropic() else to_frame(w, _param(self.rotation, w))

    def _out(self, w: Tensor) -> Tensor:
        """w from the rotated tangent frame back in the shading frame."""
        return w if self._isotropic() else from_frame(w, _param(self.rotation, w))


@dataclass
class GGXConductor(_Anisotropic):
    """Rough conductor: GGX D, separable Smith G, OpenPBR's F82-tint Fresnel (Schlick's
    when ``f82_tint`` is 1). Reflects in the upper hemisphere only."""

    roughness: Tensor | float
    r0: Tensor | float
    f82_tint: Tensor | float = 1.0
    anisotropy: Tensor | float = 0.0
    """SPEC section 10's a (0: isotropic)"""
    rotation: Tensor | float = 0.0
    """the tangent's turn about the normal in degrees, counter-clockwise seen from above"""

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        a, ay = self._alphas(wi)
        wi, wo = self._in(wi), self._in(wo)
        r0 = _param(self.r0, wi)
        b = f82_coefficient(r0, _param(self.f82_tint, wi))
        h = wi + wo
        h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        f = (fresnel_f82(_dot(wi, h), r0, b) * ggx_d(h, a, ay) * smith_g1(wi, h, a, ay) * smith_g1(wo, h, a, ay)
             / (4.0 * wi[..., 2].abs() * wo[..., 2].abs()).clamp_min(1e-30))
        return torch.where(up, f, torch.zeros_like(f))

    def pdf(self, w: Tensor, w_other: Tensor) -> Tensor:
        a, ay = self._alphas(w)
        w, w_other = self._in(w), self._in(w_other)
        h = w + w_other
        h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
        p = _safe_div(vndf_pdf(w, h, a, ay), 4.0 * _dot(w, h).abs())
        return torch.where((w[..., 2] > 0) & (w_other[..., 2] > 0), p, torch.zeros_like(p))

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        a, ay = self._alphas(w)
        wl = self._in(w)
        m = sample_vndf(wl, a, u[..., 0], u[..., 1], ay)
        wo = reflect(wl, m)
        ok = (wl[..., 2] > 0) & (wo[..., 2] > 0)
        pdf = torch.where(ok, _safe_div(vndf_pdf(wl, m, a, ay), 4.0 * _dot(wl, m).abs()),
                          torch.zeros_like(a * wl[..., 2]))
        wo = self._out(wo)
        f = torch.where(pdf > 0, self.eval(w, wo), torch.zeros_like(pdf))
        return Sample(wo, f, pdf)


@dataclass
class GGXDielectric(_Anisotropic):
    """Rough dielectric interface (Walter et al. 2007): reflection and
    refraction, exact unpolarised Fresnel with total internal reflection.
    ``ior`` is the relative index below over above; light may arrive from
    either side."""

    roughness: Tensor | float
    ior: Tensor | float
    anisotropy: Tensor | float = 0.0
    """SPEC section 10's a (0: isotropic)"""
    rotation: Tensor | float = 0.0
    """the tangent's turn about the normal in degrees, counter-clockwise seen from above"""

    def _setup(self, wi: Tensor, wo: Tensor):
        """wi, wo are in the rotated frame already."""
        eta = _param(self.ior, wi)
        above_i = wi[..., 2] > 0
        reflection = wi[..., 2] * wo[..., 2] > 0
        eta_i = torch.where(above_i, torch.ones_like(eta), eta).expand_as(wi[..., 2])
        eta_o = torch.where(reflection, eta_i, torch.where(above_i, eta, torch.ones_like(eta)))
        h = torch.where(reflection[..., None], wi + wo, -(eta_i[..., None] * wi + eta_o[..., None] * wo))
        h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
        h = torch.where(h[..., 2:3] < 0, -h, h)
        # Fresnel sees the index across the interface from wi's side.
        eta_rel = torch.where(above_i, eta, 1.0 / eta).expand_as(eta_i)
        return eta_i, eta_o, h, reflection, eta_rel

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        a, ay = self._alphas(wi)
        wi, wo = self._in(wi), self._in(wo)
        eta_i, eta_o, h, refl, eta_rel = self._setup(wi, wo)
        ih, oh = _dot(wi, h), _dot(wo, h)
        F = fresnel_dielectric(ih, eta_rel)
        dg = ggx_d(h, a, ay) * smith_g1(wi, h, a, ay) * smith_g1(wo, h, a, ay)
        cos_io = (wi[..., 2] * wo[..., 2]).abs().clamp_min(1e-30)
        f_r = F * dg / (4.0 * cos_io)
        denom = eta_i * ih + eta_o * oh
        f_t = _safe_div((ih * oh).abs() * eta_o * eta_o * (1.0 - F) * dg, cos_io * denom * denom)
        f_t = torch.where(ih * oh < 0, f_t, torch.zeros_like(f_t))
        f = torch.where(refl, f_r, f_t)
        valid = (wi[..., 2] != 0) & (wo[..., 2] != 0)
        return torch.where(valid, f, torch.zeros_like(f))

    def pdf(self, w: Tensor, w_other: Tensor) -> Tensor:
        a, ay = self._alphas(w)
        w, w_other = self._in(w), self._in(w_other)
        eta_i, eta_o, h, refl, eta_rel = self._setup(w, w_other)
        ih, oh = _dot(w, h), _dot(w_other, h)
        F = fresnel_dielectric(ih, eta_rel)
        pm = vndf_pdf(w, h, a, ay)
        p_r = F * _safe_div(pm, 4.0 * ih.abs())
        denom = eta_i * ih + eta_o * oh
        p_t = (1.0 - F) * _safe_div(pm * eta_o * eta_o * oh.abs(), denom * denom)
        p_t = torch.where(ih * oh < 0, p_t, torch.zeros_like(p_t))
        p = torch.where(refl, p_r, p_t)
        valid = (w[..., 2] != 0) & (w_other[..., 2] != 0)
        return torch.where(valid, p, torch.zeros_like(p))

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        a, ay = self._alphas(w)
        eta = _param(self.ior, w)
        w_shading, w = w, self._in(w)
        m = sample_vndf(w, a, u[..., 0], u[..., 1], ay)
        above = w[..., 2] > 0
        eta_i = torch.where(above, torch.ones_like(eta), eta).expand_as(w[..., 2])
        eta_t = torch.where(above, eta, torch.ones_like(eta)).expand_as(w[..., 2])
        F = fresnel_dielectric(_dot(w, m), eta_t / eta_i)
        wr = reflect(w, m)
        wt, ok_t = refract(w, m, eta_i / eta_t)
        choose_r = (u[..., 2] < F) | ~ok_t
        wo = torch.where(choose_r[..., None], wr, wt)
        # A reflection must stay on w's side, a refraction must cross.
        side_ok = torch.where(choose_r, w[..., 2] * wo[..., 2] > 0, w[..., 2] * wo[..., 2] < 0)
        wo = self._out(wo)
        pdf = torch.where(side_ok, self.pdf(w_shading, wo), torch.zeros_like(F))
        f = torch.where(pdf > 0, self.eval(w_shading, wo), torch.zeros_like(pdf))
        return Sample(wo, f, pdf)


@dataclass
class Lambertian:
    """Ideal diffuse reflector albedo / pi, upper hemisphere, cosine sampling."""

    albedo: Tensor | float

    def eval(self, wi: Tensor, wo: Tensor) -> Tensor:
        alb = _param(self.albedo, wi)
        up = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        v = (alb / math.pi).expand_as(wi[..., 2])
        return torch.where(up, v, torch.zeros_like(v))

    def pdf(self, w: Tensor, w_other: Tensor) -> Tensor:
        p = w_other[..., 2].clamp_min(0.0) / math.pi
        return torch.where(w[..., 2] > 0, p, torch.zeros_like(p))

    def sample(self, w: Tensor, u: Tensor) -> Sample:
        wo = cosine_hemisphere(u[..., 0], u[..., 1])
        z = wo[..., 2]
        pdf = torch.where((w[..., 2] > 0) & (z > 0), z / math.pi, torch.zeros_like(z))
        f = torch.where(pdf > 0, self.eval(w, wo), torch.zeros_like(pdf))
        return Sample(wo, f, pdf)


class DefensiveSampler:
    """Half cosine lobe, half GGX reflection lobe of ``roughness`` (upper
    hemisphere): a sampler for BRDFs that have none of their own."""

    def __init__(self, roughness: float):
        self.ggx = GGXConductor(roughness, 1.0)

    def pdf(self, w: Tensor, w_other: Tensor) -> Tensor:
        cos = torch.where(w[:, 2] > 0, w_other[:, 2].clamp_min(0) / math.pi, torch.zeros_like(w[:, 2]))
        return 0.5 * cos + 0.5 * self.ggx.pdf(w, w_other)

    def sample(self, w: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
        """(direction, pdf); u[:, 2] picks the lobe."""
        wc = cosine_hemisphere(u[:, 0], u[:, 1]).to(w.dtype)
        wg = self.ggx.sample(w, u).w
        wo = torch.where((u[:, 2] < 0.5)[:, None], wc, wg)
        pdf = self.pdf(w, wo)
        return wo, torch.where((wo[:, 2] > 0) & (w[:, 2] > 0), pdf, torch.zeros_like(pdf))
