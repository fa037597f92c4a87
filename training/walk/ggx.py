"""Scalar GGX building blocks of the walk's interface kernels: the
distribution, Smith's G1, VNDF sampling and its density, Fresnel, reflection,
refraction and a slab's transmittance. The same formulas as
``training.microfacet`` (tests/training/test_walk_kernels.py checks them),
written per direction so that Numba compiles them into the per-path code.

Roughness is a pair (ax, ay): alpha along the x and y axes of the walk's
frame (SPEC section 10: the material's rotated tangent frame; the walk gets
its directions in it). Where ax == ay the isotropic formulas run exactly as
they did before anisotropy (the same numbers, bit for bit); the stretch of
the VNDF sampler is written per axis, which for equal alphas is the same
arithmetic."""
from __future__ import annotations

import math

from numba import njit

from nbrdf.training.walk.params import JIT

INV_PI = 1.0 / math.pi
INV_4PI = 1.0 / (4.0 * math.pi)
TWO_PI = 2.0 * math.pi


@njit(**JIT)
def conductor_f(x, r0, b):
    """A conductor's Fresnel from x = (1 - cos)^5 (what the samplers return): OpenPBR's F82-tint
    form r0 + (1 - r0) x - b cos (1 - cos)^6, kept in [0, 1]; b = 0 is Schlick's exactly
    (``neural.microfacet.fresnel_f82``; b from ``f82_coefficient``)."""
    f = x + r0 * (1.0 - x)
    if b != 0.0:
        y = x ** 0.2  # 1 - cos
        f -= b * (1.0 - y) * y ** 6
        f = min(max(f, 0.0), 1.0)
    return f


@njit(**JIT)
def cos_sin_2pi(u):
    """(cos 2 pi u, sin 2 pi u) for u in [0, 1]: reduction to a quarter turn
    (exact in binary) and Taylor polynomials; absolute error < 1e-15, about
    2.5x cheaper than libm's sincos (one pair per sampled direction)."""
    q = math.floor(4.0 * u + 0.5)
    x = TWO_PI * (u - 0.25 * q)  # [-pi/4, pi/4]
    x2 = x * x
    s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362880.0 + x2 * (
        -1.0 / 39916800.0 + x2 * (1.0 / 6227020800.0 + x2 * (-1.0 / 1307674368000.0))))))))
    c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0 + x2 * (
        -1.0 / 3628800.0 + x2 * (1.0 / 479001600.0 + x2 * (-1.0 / 87178291200.0 + x2 * (1.0 / 20922789888000.0))))))))
    qi = int(q) & 3
    odd = (qi & 1) == 1
    cc = s if odd else c
    ss = c if odd else s
    if qi == 1 or qi == 2:
        cc = -cc
    if qi >= 2:
        ss = -ss
    return cc, ss


@njit(**JIT)
def norm3(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    inv = 1.0 / max(n, 1e-30)
    return x * inv, y * inv, z * inv


@njit(**JIT)
def ggx_d(mx, my, mz, ax, ay):
    """D(m); anisotropic (Heitz 2014): 1 / (pi ax ay (mx^2 / ax^2 + my^2 / ay^2 + mz^2)^2)."""
    if mz <= 0.0:
        return 0.0
    if ax == ay:
        a2 = ax * ax
        den = mx * mx + my * my + mz * mz * a2
        return a2 / (math.pi * den * den)
    sx, sy = mx / ax, my / ay
    den = sx * sx + sy * sy + mz * mz
    return 1.0 / (math.pi * ax * ay * den * den)


@njit(**JIT)
def g1_dir(wx, wy, wz, ax, ay):
    """Smith G1 = 2 / (1 + sqrt(1 + a_w^2 tan^2)), written with one division; a_w^2 tan^2 =
    (ax^2 wx^2 + ay^2 wy^2) / wz^2 (Heitz 2014's Lambda along w's azimuth)."""
    z = abs(wz)
    if ax == ay:
        den = z + math.sqrt(wz * wz + ax * ax * (wx * wx + wy * wy))
    else:
        den = z + math.sqrt(wz * wz + ax * ax * wx * wx + ay * ay * wy * wy)
    return 2.0 * z / den if den > 0.0 else 0.0


@njit(**JIT)
def g1(wx, wy, wz, mx, my, mz, ax, ay):
    if (wx * mx + wy * my + wz * mz) * wz > 0.0:
        return g1_dir(wx, wy, wz, ax, ay)
    return 0.0


@njit(**JIT)
def sample_vndf(wx, wy, wz, ax, ay, u1, u2):
    """A VNDF facet normal for w (which may lie below: it is mirrored up)."""
    if wz < 0.0:
        wx, wy, wz = -wx, -wy, -wz
    vx, vy, vz = norm3(ax * wx, ay * wy, wz)
    return vndf_std(vx, vy, vz, ax, ay, u1, u2)


@njit(**JIT)
def vndf_std(vx, vy, vz, ax, ay, u1, u2):
    """A VNDF facet normal from the stretched, normalised view direction
    v = (ax wx, ay wy, wz) / |.| (vz >= 0; per pair for next-event estimation):
    Dupuy and Benyoub 2023 (exact; a point of the spherical cap below v, one
    square root fewer than Heitz's disk mapping and no frame), unstretched by
    (ax, ay, 1) as Heitz 2018's anisotropic sampler."""
    cph, sph = cos_sin_2pi(u2)
    z = (1.0 - u1) * (1.0 + vz) - vz
    st = math.sqrt(max(1.0 - z * z, 0.0))
    return norm3(ax * (st * cph + vx), ay * (st * sph + vy), max(z + vz, 1e-12))


@njit(**JIT)
def vndf_pdf(wx, wy, wz, mx, my, mz, ax, ay):
    if wz < 0.0:
        wx, wy, wz = -wx, -wy, -wz
    wm = wx * mx + wy * my + wz * mz
    if wm <= 0.0:
        return 0.0
    return g1_dir(wx, wy, wz, ax, ay) * wm * ggx_d(mx, my, mz, ax, ay) / max(abs(wz), 1e-30)


@njit(**JIT)
def fresnel(cos_i, eta):
    c = min(abs(cos_i), 1.0)
    sin2_t = (1.0 - c * c) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0
    cos_t = math.sqrt(max(1.0 - sin2_t, 0.0))
    rs = (c - eta * cos_t) / (c + eta * cos_t)
    rp = (eta * c - cos_t) / (eta * c + cos_t)
    return 0.5 * (rs * rs + rp * rp)


@njit(**JIT)
def reflect(wx, wy, wz, mx, my, mz):
    d = 2.0 * (wx * mx + wy * my + wz * mz)
    return d * mx - wx, d * my - wy, d * mz - wz


@njit(**JIT)
def refract(wx, wy, wz, mx, my, mz, er):
    """Returns (tx, ty, tz, ok); er = eta_incident / eta_transmitted."""
    c = wx * mx + wy * my + wz * mz
    if c < 0.0:
        mx, my, mz, c = -mx, -my, -mz, -c
    k = 1.0 - er * er * (1.0 - c * c)
    f = er * c - math.sqrt(max(k, 0.0))
    tx, ty, tz = norm3(f * mx - er * wx, f * my - er * wy, f * mz - er * wz)
    return tx, ty, tz, k > 0.0


@njit(**JIT)
def schlick5(c):
    """Schlick's (1 - |c|)^5."""
    t = 1.0 - min(abs(c), 1.0)
    t2 = t * t
    return t2 * t2 * t


@njit(**JIT)
def survival(tau, length, cz):
    """Tr = exp(-tau length / |cz|): the probability that a flight through
    ``length`` (in slab thicknesses) of a slab of optical thickness ``tau``
    along a direction of z component ``cz`` passes unscattered; 1 for an
    empty slab."""
    return math.exp(-tau * length / max(abs(cz), 1e-12)) if tau > 0.0 else 1.0
