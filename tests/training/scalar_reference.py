"""An independent scalar implementation of SPEC section 5's interfaces, one
direction pair at a time in plain Python: GGX D and Smith G1, exact Fresnel,
Walter et al. 2007 reflection and refraction, Schlick conductors, and the
densities of VNDF-based sampling (Heitz 2018's visible normals, Walter's
Jacobians). Written from the formulas, not from either implementation it
checks (``training.analytic`` in torch, ``training.walk`` in Numba).

Anisotropic interfaces (SPEC section 10): a roughness ``a`` may be a pair
(alpha_x, alpha_y), the alphas along the tangent t and bitangent b of the
frame. Heitz 2014 writes D and Smith's Lambda with the azimuth phi of a
direction in that frame: D = 1 / (pi ax ay cos^4 (1 + tan^2 (cos^2 phi / ax^2
+ sin^2 phi / ay^2))^2), Lambda = (-1 + sqrt(1 + alpha_o^2 tan^2)) / 2 with
alpha_o^2 = cos^2 phi ax^2 + sin^2 phi ay^2. ``in_frame`` gives a direction's
coordinates in the frame whose tangent is turned by ``rotation`` degrees
counter-clockwise about z."""
from __future__ import annotations

import math


def _alphas(a) -> tuple[float, float]:
    return (a, a) if isinstance(a, (int, float)) else (float(a[0]), float(a[1]))


def openpbr_alphas(roughness: float, anisotropy: float) -> tuple[float, float]:
    """SPEC section 10: alpha_x = alpha sqrt(2 / (1 + (1 - a)^2)), alpha_y = (1 - a) alpha_x."""
    ax = roughness * math.sqrt(2.0 / (1.0 + (1.0 - anisotropy) ** 2))
    return ax, (1.0 - anisotropy) * ax


def in_frame(w, rotation_deg: float):
    """w's coordinates along t = (cos r, sin r, 0), b = z x t = (-sin r, cos r, 0) and z."""
    r = math.radians(rotation_deg)
    t, b = (math.cos(r), math.sin(r), 0.0), (-math.sin(r), math.cos(r), 0.0)
    return [_dot(w, t), _dot(w, b), w[2]]


def _cos2_sin2_phi(v) -> tuple[float, float]:
    r2 = v[0] * v[0] + v[1] * v[1]
    if r2 == 0:
        return 1.0, 0.0
    return v[0] * v[0] / r2, v[1] * v[1] / r2


def _d(m, a) -> float:
    cos_m = m[2]
    if cos_m <= 0:
        return 0.0
    ax, ay = _alphas(a)
    c2, s2 = _cos2_sin2_phi(m)
    tan2 = (1 - cos_m * cos_m) / (cos_m * cos_m)
    return 1.0 / (math.pi * ax * ay * cos_m ** 4 * (1 + tan2 * (c2 / (ax * ax) + s2 / (ay * ay))) ** 2)


def _g1(w, m, a) -> float:
    wm = _dot(w, m)
    if wm * w[2] <= 0:
        return 0.0
    ax, ay = _alphas(a)
    c2, s2 = _cos2_sin2_phi(w)
    tan2 = (1 - w[2] ** 2) / (w[2] ** 2)
    lam = (-1.0 + math.sqrt(1.0 + (c2 * ax * ax + s2 * ay * ay) * tan2)) / 2.0
    return 1.0 / (1.0 + lam)


def _fresnel(cos_i: float, n1: float, n2: float) -> float:
    cos_i = abs(cos_i)
    sin_t = n1 / n2 * math.sqrt(max(0.0, 1 - cos_i * cos_i))
    if sin_t >= 1:
        return 1.0
    cos_t = math.sqrt(1 - sin_t * sin_t)
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t)
    return (rs * rs + rp * rp) / 2


def _dot(u, v) -> float:
    return sum(x * y for x, y in zip(u, v))


def _unit(v):
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def _half_reflect(wi, wo):
    h = _unit([x + y for x, y in zip(wi, wo)])
    return h if h[2] >= 0 else [-x for x in h]


def _half_refract(wi, wo, n_i, n_o):
    h = _unit([-(n_i * x + n_o * y) for x, y in zip(wi, wo)])
    return h if h[2] >= 0 else [-x for x in h]


def ref_conductor(wi, wo, a, r0):
    if wi[2] <= 0 or wo[2] <= 0:
        return 0.0
    h = _unit([x + y for x, y in zip(wi, wo)])
    c = _dot(wi, h)
    F = r0 + (1 - r0) * (1 - c) ** 5
    return F * _d(h, a) * _g1(wi, h, a) * _g1(wo, h, a) / (4 * wi[2] * wo[2])


def ref_dielectric(wi, wo, a, ior):
    """f(wi, wo) of a rough dielectric (index 1 above, ``ior`` below), either side."""
    n_i = 1.0 if wi[2] > 0 else ior
    if wi[2] * wo[2] > 0:
        h = _half_reflect(wi, wo)
        c = _dot(wi, h)
        n_t = ior if wi[2] > 0 else 1.0
        F = _fresnel(c, n_i, n_t)
        return F * _d(h, a) * _g1(wi, h, a) * _g1(wo, h, a) / abs(4 * wi[2] * wo[2])
    n_o = ior if wi[2] > 0 else 1.0
    h = _half_refract(wi, wo, n_i, n_o)
    ih = _dot(wi, h)
    oh = _dot(wo, h)
    if ih * oh >= 0:
        return 0.0
    F = _fresnel(ih, n_i, n_o)
    g = _g1(wi, h, a) * _g1(wo, h, a)
    return abs(ih * oh / (wi[2] * wo[2])) * n_o ** 2 * (1 - F) * _d(h, a) * g / (n_i * ih + n_o * oh) ** 2


def ref_visible_normals(w, m, a) -> float:
    """Heitz's distribution of visible normals D_w(m) = G1(w, m) |w.m| D(m) / |w_z|."""
    return _g1(w, m, a) * abs(_dot(w, m)) * _d(m, a) / abs(w[2])


def ref_reflection_pdf(wi, wo, a) -> float:
    """Density of wo when wi is reflected about a visible normal (same side)."""
    if wi[2] * wo[2] <= 0:
        return 0.0
    h = _half_reflect(wi, wo)
    return ref_visible_normals(wi, h, a) / (4 * abs(_dot(wo, h)))


def ref_refraction_pdf(wi, wo, a, n_i, n_o) -> float:
    """Density of wo when wi (in index n_i) is refracted into index n_o about a
    visible normal (no Fresnel choice): Walter's Jacobian."""
    if wi[2] * wo[2] >= 0:
        return 0.0
    h = _half_refract(wi, wo, n_i, n_o)
    ih, oh = _dot(wi, h), _dot(wo, h)
    if ih * oh >= 0:
        return 0.0
    return ref_visible_normals(wi, h, a) * n_o * n_o * abs(oh) / (n_i * ih + n_o * oh) ** 2


def ref_dielectric_pdf(wi, wo, a, ior) -> float:
    """Density of Walter sampling (a visible normal, then reflection with
    probability F, else refraction) producing wo from wi."""
    n_i = 1.0 if wi[2] > 0 else ior
    n_t = ior if wi[2] > 0 else 1.0
    if wi[2] * wo[2] > 0:
        h = _half_reflect(wi, wo)
        return _fresnel(_dot(wi, h), n_i, n_t) * ref_reflection_pdf(wi, wo, a)
    h = _half_refract(wi, wo, n_i, n_t)
    return (1 - _fresnel(_dot(wi, h), n_i, n_t)) * ref_refraction_pdf(wi, wo, a, n_i, n_t)
