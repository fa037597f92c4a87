"""Importance sampling of neural BRDFs through a proxy pdf (SPEC section 6).

The proxy is (1 - w) times an isotropic Gaussian of width sigma over the
projected half vector (h_x, h_y), normalised on the unit disk, plus w times
a Lambertian (cosine) lobe. A small network predicts (sigma, w) from the
material's latent once per material; sampling then costs a few
transcendental functions and the returned pdf is exact for the proxy
(half-vector Jacobian included), so estimators f cos / pdf stay unbiased
however well the proxy fits.

The Gaussian half-vector lobe is a bijection from the upper hemisphere of h
onto the sphere of wo (wo = reflect(wi, h)), so the proxy pdf integrates to 1
over the sphere; samples below the horizon are failures (f = 0).
"""
from __future__ import annotations

import math

import torch
from torch import nn

from nbrdf.neural.anisotropy import stretched_half
from nbrdf.neural.coat import coat_pdf, coat_probability, coat_sample
from nbrdf.neural.geometry import cosine_hemisphere
from nbrdf.neural.nets import MLP, MLPSpec

Tensor = torch.Tensor
SIGMA_RANGE = (0.003, 2.0)
W_RANGE = (0.02, 0.98)  # a floor on both lobes keeps the weights f cos / pdf bounded


def sampler_spec(width: int = 64, depth: int = 2) -> MLPSpec:
    return MLPSpec(inputs=32, outputs=2, width=width, depth=depth)


class SamplerNet(nn.Module):
    """Material latent (3, 32) or (N, 32) -> proxy parameters (sigma, w)."""

    def __init__(self, spec: MLPSpec | None = None):
        super().__init__()
        self.spec = spec or sampler_spec()
        self.mlp = MLP(self.spec)

    def forward(self, z: Tensor) -> tuple[Tensor, Tensor]:
        """(sigma, w), each (N,), for latents or codes (N, 32 or 34): the
        proxy of the body (a code's coat is sampled exactly, ``neural.coat``)."""
        a = self.mlp(z[..., : self.spec.inputs])
        lo, hi = SIGMA_RANGE
        sigma = lo + (hi - lo) * torch.sigmoid(a[:, 0])
        w = W_RANGE[0] + (W_RANGE[1] - W_RANGE[0]) * torch.sigmoid(a[:, 1])
        return sigma, w

    def material_params(self, z_rgb: Tensor) -> tuple[Tensor, Tensor]:
        """One (sigma, w) for an RGB material: the proxy of its mean-channel latent."""
        sigma, w = self(z_rgb.mean(0, keepdim=True))
        return sigma[0], w[0]


# --- the proxy ---------------------------------------------------------------------------
def _disk_norm(sigma: Tensor) -> Tensor:
    """Normaliser of exp(-r^2 / (2 sigma^2)) over the unit disk."""
    return 2 * math.pi * sigma * sigma * -torch.expm1(-0.5 / (sigma * sigma))


def gaussian_pdf(wi: Tensor, wo: Tensor, sigma: Tensor, v: Tensor | None = None) -> Tensor:
    """Solid-angle pdf of wo under the half-vector Gaussian, over the sphere. ``v``: an anisotropic
    body's vector; the Gaussian is then over the stretched half vector h' (the body's lobe is round
    there), times the Jacobian (h'_z / h_z)^3 of the stretch on the sphere."""
    h = wi + wo
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    h = torch.where(h[..., 2:3] < 0, -h, h)
    q, jac = h, None
    if v is not None:
        q = stretched_half(h, v)
        r = q[..., 2] / h[..., 2].clamp_min(1e-12)
        jac = r * r * r
    r2 = q[..., 0] ** 2 + q[..., 1] ** 2
    p_disk = torch.exp(-0.5 * r2 / (sigma * sigma)) / _disk_norm(sigma)
    p = p_disk * q[..., 2] / (4 * (wi * h).sum(-1).abs().clamp_min(1e-12))
    return p if jac is None else p * jac


def lambert_pdf(wo: Tensor) -> Tensor:
    return wo[..., 2].clamp_min(0) / math.pi


def proxy_pdf(wi: Tensor, wo: Tensor, sigma: Tensor, w: Tensor, v: Tensor | None = None) -> Tensor:
    """The proxy's solid-angle pdf of wo given wi; sigma and w broadcast (``v``: ``gaussian_pdf``)."""
    return (1 - w) * gaussian_pdf(wi, wo, sigma, v) + w * lambert_pdf(wo)


def proxy_sample(wi: Tensor, u: Tensor, sigma: Tensor, w: Tensor, v: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """wo (N, 3) drawn from the proxy with uniforms u (N, 3), and its pdf.
    wo may point below the horizon (a failed sample for a BRDF). ``v``: an anisotropic body's vector
    (the Gaussian's half vector is drawn stretched, then unstretched)."""
    sigma = torch.as_tensor(sigma, dtype=wi.dtype).expand(wi.shape[0])
    w = torch.as_tensor(w, dtype=wi.dtype).expand(wi.shape[0])
    u0, u1, u2 = u[:, 0], u[:, 1], u[:, 2]
    phi = 2 * math.pi * u2
    # Gaussian over the disk by inverting its radial CDF.
    trunc = -torch.expm1(-0.5 / (sigma * sigma))
    r = (sigma * torch.sqrt(-2 * torch.log1p(-u1 * trunc))).clamp(max=1.0)
    h = torch.stack([r * phi.cos(), r * phi.sin(), (1 - r * r).clamp_min(0).sqrt()], -1)
    if v is not None:
        h = stretched_half(h, v, inverse=True)
    wo_g = 2 * (wi * h).sum(-1, keepdim=True) * h - wi
    wo = torch.where((u0 < w)[:, None], cosine_hemisphere(u1, u2), wo_g)
    wo = wo / wo.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return wo, proxy_pdf(wi, wo, sigma, w, v)


def coated_pdf(wi: Tensor, wo: Tensor, coat: Tensor | None, sigma: Tensor, w: Tensor,
               v: Tensor | None = None) -> Tensor:
    """pdf of ``coated_sample``: the coat's visible-normal lobe with
    probability ``neural.coat.coat_probability``, the body's proxy otherwise
    (``v``: an anisotropic body's vector, ``proxy_pdf``)."""
    p = proxy_pdf(wi, wo, sigma, w, v)
    if coat is None:
        return p

    pc = coat_probability(coat, wi)
    return pc * coat_pdf(coat, wi, wo) + (1 - pc) * p


def coated_sample(wi: Tensor, u: Tensor, coat: Tensor | None, sigma: Tensor, w: Tensor,
                  v: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """wo (N, 3) and its pdf for a material code: u[:, 0] picks the coat
    (below its probability) or the body's proxy, and is rescaled to stay
    uniform for the proxy's own choice; u[:, 1:] draw the direction
    (``v``: an anisotropic body's vector, ``proxy_sample``)."""
    if coat is None:
        return proxy_sample(wi, u, sigma, w, v)

    pc = coat_probability(coat, wi)
    on_coat = u[:, 0] < pc
    u_proxy = torch.cat([((u[:, :1] - pc[:, None]) / (1 - pc[:, None]).clamp_min(1e-6)).clamp(0, 1 - 1e-7),
                         u[:, 1:]], -1)
    wo_p, _ = proxy_sample(wi, u_proxy, sigma, w, v)
    wo_c = coat_sample(coat, wi, u[:, 1], u[:, 2])
    wo = torch.where(on_coat[:, None], wo_c, wo_p)
    return wo, coated_pdf(wi, wo, coat, sigma, w, v)


def gndf(fn, n: int = 64, n_wi: int = 64, seed: int = 0) -> Tensor:
    """The GNDF of a single-channel BRDF ``fn(wi, wo)``: the density of the
    projected half vector (n x n grid over the unit disk, rows along y) of
    f cos(theta_o)-distributed wo, averaged over cosine-distributed wi."""
    g = torch.Generator().manual_seed(seed)
    a, b = torch.rand(n_wi, generator=g), torch.rand(n_wi, generator=g)
    wi = cosine_hemisphere(a, b)
    c = (torch.arange(n) + 0.5) / n * 2 - 1
    y, x = torch.meshgrid(c, c, indexing="ij")
    r2 = x * x + y * y
    inside = r2 < 1
    h = torch.stack([x, y, (1 - r2).clamp_min(0).sqrt()], -1)[inside]  # (P, 3)
    out = torch.zeros(n, n)
    acc = torch.zeros(h.shape[0])
    for k in range(n_wi):
        wik = wi[k].expand_as(h)
        wo = 2 * (wik * h).sum(-1, keepdim=True) * h - wik
        ok = wo[:, 2] > 0
        # density over the disk: f cos * |d wo / d h_disk| = f cos * 4 |wi.h| / h_z
        v = fn(wik, wo) * wo[:, 2].clamp_min(0) * 4 * (wik * h).sum(-1).abs() / h[:, 2].clamp_min(1e-6)
        v = torch.where(ok, v, torch.zeros_like(v))
        total = v.sum() * (2.0 / n) ** 2
        if total > 0:
            acc += v / total
    out[inside] = acc / n_wi
    return out
