"""GGX microfacet building blocks (SPEC section 5), batched torch.

Every function takes directions as (..., 3) tensors in the local frame and
roughness ``alpha`` (the GGX alpha itself) broadcastable to the batch. The
microfacet normal ``m`` always lies in the upper hemisphere. ``alpha_y``
(None: isotropic, ``alpha`` on both axes, the isotropic formulas exactly)
makes them the anisotropic GGX of Heitz 2014 / 2018 with ``alpha`` along x
and ``alpha_y`` along y (SPEC section 10; the frame is the caller's).
"""
from __future__ import annotations

import math

import torch

Tensor = torch.Tensor


def ggx_d(m: Tensor, alpha: Tensor, alpha_y: Tensor | None = None) -> Tensor:
    """D(m) = 1 / (pi a^2 cos^4 t (1 + tan^2 t / a^2)^2), 0 below the horizon; with ``alpha_y``
    1 / (pi ax ay (mx^2 / ax^2 + my^2 / ay^2 + mz^2)^2)."""
    if alpha_y is not None:
        s = m[..., 0] ** 2 / (alpha * alpha) + m[..., 1] ** 2 / (alpha_y * alpha_y) + m[..., 2] ** 2
        d = 1.0 / (math.pi * alpha * alpha_y * s * s)
        return torch.where(m[..., 2] > 0, d, torch.zeros_like(d))
    sin2 = m[..., 0] ** 2 + m[..., 1] ** 2
    cos2 = m[..., 2] ** 2
    a2 = alpha * alpha
    denom = sin2 + cos2 * a2
    d = a2 / (math.pi * denom * denom)
    return torch.where(m[..., 2] > 0, d, torch.zeros_like(d))


def _a2_tan2(w: Tensor, alpha: Tensor, alpha_y: Tensor | None) -> Tensor:
    """alpha_w^2 tan^2 t_w, the argument of Smith's Lambda (alpha_w: the roughness along w's azimuth)."""
    z2 = (w[..., 2] ** 2).clamp_min(1e-30)
    if alpha_y is not None:
        return (alpha * alpha * w[..., 0] ** 2 + alpha_y * alpha_y * w[..., 1] ** 2) / z2
    tan2 = (w[..., 0] ** 2 + w[..., 1] ** 2) / z2
    return alpha * alpha * tan2


def smith_g1(w: Tensor, m: Tensor, alpha: Tensor, alpha_y: Tensor | None = None) -> Tensor:
    """G1(w) = 2 / (1 + sqrt(1 + a^2 tan^2 t_w)); 0 when w and m disagree in side."""
    g = 2.0 / (1.0 + torch.sqrt(1.0 + _a2_tan2(w, alpha, alpha_y)))
    side = (w * m).sum(-1) * w[..., 2] > 0
    return torch.where(side, g, torch.zeros_like(g))


def smith_g1_dir(w: Tensor, alpha: Tensor, alpha_y: Tensor | None = None) -> Tensor:
    """G1 of a direction alone (no side test): the visible fraction toward w."""
    return 2.0 / (1.0 + torch.sqrt(1.0 + _a2_tan2(w, alpha, alpha_y)))


def sample_vndf(w: Tensor, alpha: Tensor, u1: Tensor, u2: Tensor, alpha_y: Tensor | None = None) -> Tensor:
    """A normal m drawn from the distribution of normals visible from w
    (Heitz 2018). w may lie in either hemisphere: it is mirrored to the upper
    one, which leaves the visible-normal distribution of the upper-hemisphere
    microsurface unchanged."""
    sgn = torch.where(w[..., 2] < 0, -1.0, 1.0).to(w.dtype)
    wx, wy, wz = w[..., 0] * sgn, w[..., 1] * sgn, w[..., 2] * sgn
    ay = alpha if alpha_y is None else alpha_y  # the stretch: (ax wx, ay wy, wz), unstretched by (ax, ay, 1)
    vx, vy, vz = alpha * wx, ay * wy, wz
    inv = torch.rsqrt((vx * vx + vy * vy + vz * vz).clamp_min(1e-30))
    vx, vy, vz = vx * inv, vy * inv, vz * inv
    lensq = vx * vx + vy * vy
    safe = lensq > 1e-14
    il = torch.rsqrt(torch.where(safe, lensq, torch.ones_like(lensq)))
    t1x = torch.where(safe, -vy * il, torch.ones_like(vx))
    t1y = torch.where(safe, vx * il, torch.zeros_like(vx))
    # T2 = V x T1 (T1 has no z component)
    t2x = -vz * t1y
    t2y = vz * t1x
    t2z = vx * t1y - vy * t1x
    r = torch.sqrt(u1)
    phi = 2.0 * math.pi * u2
    p1 = r * torch.cos(phi)
    p2 = r * torch.sin(phi)
    s = 0.5 * (1.0 + vz)
    p2 = (1.0 - s) * torch.sqrt((1.0 - p1 * p1).clamp_min(0.0)) + s * p2
    p3 = torch.sqrt((1.0 - p1 * p1 - p2 * p2).clamp_min(0.0))
    nx = p1 * t1x + p2 * t2x + p3 * vx
    ny = p1 * t1y + p2 * t2y + p3 * vy
    nz = p2 * t2z + p3 * vz
    m = torch.stack([alpha * nx, ay * ny, nz.clamp_min(1e-12)], dim=-1)
    return m / m.norm(dim=-1, keepdim=True)


def vndf_pdf(w: Tensor, m: Tensor, alpha: Tensor, alpha_y: Tensor | None = None) -> Tensor:
    """Density of ``sample_vndf(w)`` returning m: G1(w) |w.m| D(m) / |w.z|,
    with w mirrored to the upper hemisphere as the sampler does."""
    sgn = torch.where(w[..., 2] < 0, -1.0, 1.0).to(w.dtype)
    wu = w * sgn[..., None]
    wm = (wu * m).sum(-1)
    g1 = smith_g1_dir(wu, alpha, alpha_y)
    pdf = g1 * wm.clamp_min(0.0) * ggx_d(m, alpha, alpha_y) / wu[..., 2].abs().clamp_min(1e-30)
    return torch.where(wm > 0, pdf, torch.zeros_like(pdf))


def fresnel_dielectric(cos_i: Tensor, eta: Tensor) -> Tensor:
    """Exact unpolarised Fresnel reflectance for |cos_i| toward a medium of
    relative index eta (transmitted over incident); 1 under total internal
    reflection."""
    c = cos_i.abs().clamp(max=1.0)
    sin2_t = (1.0 - c * c) / (eta * eta)
    tir = sin2_t >= 1.0
    cos_t = torch.sqrt((1.0 - sin2_t).clamp_min(0.0))
    rs = (c - eta * cos_t) / (c + eta * cos_t)
    rp = (eta * c - cos_t) / (eta * c + cos_t)
    f = 0.5 * (rs * rs + rp * rp)
    return torch.where(tir, torch.ones_like(f), f)


def fresnel_schlick(cos_i: Tensor, r0: Tensor) -> Tensor:
    """Schlick's approximation r0 + (1 - r0)(1 - |cos|)^5."""
    return r0 + (1.0 - r0) * (1.0 - cos_i.abs().clamp(max=1.0)) ** 5


#: The cosine of OpenPBR's F82-tint edge angle (about 82 degrees), mu_bar = 1/7.
F82_MU = 1.0 / 7.0


def f82_coefficient(r0, tint):
    """OpenPBR's F82-tint coefficient b = F_Schlick(mu_bar) (1 - tint) / (mu_bar (1 - mu_bar)^6): the
    weight of the correction that makes the conductor's reflectance at mu_bar its Schlick value times
    ``tint`` (tint 1: b = 0, Schlick itself). Works on floats, numpy arrays and tensors alike."""
    schlick = r0 + (1.0 - r0) * (1.0 - F82_MU) ** 5
    return schlick * (1.0 - tint) / (F82_MU * (1.0 - F82_MU) ** 6)


def fresnel_f82(cos_i: Tensor, r0: Tensor, b: Tensor | float) -> Tensor:
    """OpenPBR's F82-tint conductor Fresnel: Schlick minus b |cos| (1 - |cos|)^6 (b from
    ``f82_coefficient``), kept in [0, 1]; b = 0 is ``fresnel_schlick`` exactly."""
    c = cos_i.abs().clamp(max=1.0)
    return (fresnel_schlick(c, r0) - b * c * (1.0 - c) ** 6).clamp(0.0, 1.0)


def reflect(w: Tensor, m: Tensor) -> Tensor:
    """Mirror of w about m (both pointing away from the surface)."""
    return 2.0 * (w * m).sum(-1, keepdim=True) * m - w


def refract(w: Tensor, m: Tensor, eta_ratio: Tensor) -> tuple[Tensor, Tensor]:
    """Refraction of w (pointing away, on the incident side) through a facet
    with normal m; eta_ratio = eta_incident / eta_transmitted. Returns the
    transmitted direction (pointing away, on the other side) and a mask of
    lanes without total internal reflection."""
    c = (w * m).sum(-1)
    er = torch.as_tensor(eta_ratio, dtype=w.dtype, device=w.device).expand_as(c)
    sgn = torch.where(c < 0, -1.0, 1.0).to(w.dtype)
    mm = m * sgn[..., None]
    c = c.abs()
    k = 1.0 - er * er * (1.0 - c * c)
    ok = k > 0
    t = (er * c - torch.sqrt(k.clamp_min(0.0)))[..., None] * mm - er[..., None] * w
    t = t / t.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    return t, ok
