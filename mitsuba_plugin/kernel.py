"""A material code's BRDF in Dr.Jit: the same arithmetic as the torch path
(``neural.coat``, ``neural.microfacet``, ``neural.decoder``, ``neural.sampling``,
``neural.anisotropy``), written over Dr.Jit arrays so it runs inside Mitsuba's
rendering kernel.

The decoder runs through ``drjit.nn`` (cooperative vectors: vectorised on the
CPU, tensor cores on NVIDIA GPUs); the latent's share of the first layer is a
per-channel bias computed once per material. Directions are in the local
frame (z the normal, x the material's tangent before its ``anisotropy_rotation``);
``wi`` and ``wo`` are the project's (light, viewer). A code with an anisotropic
tail has an anisotropic coat (``Coat.stretch``), a body read at the warped pair
times its factor J (``BodyWarp``) and a stretched proxy (``Proxy.stretch``); an
isotropic code runs the isotropic arithmetic unchanged.
Every function reads the array types of the Mitsuba variant in force.
No torch here: ``materials`` builds these kernels from the torch network.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import drjit.nn as nn
import mitsuba as mi
import numpy as np

from nbrdf.mitsuba.mip import level_of_detail
from nbrdf.neural.methods import WordEnum

#: The lobes11 features' GGX-like widths and the ior of their refracted half vector (``neural.decoder``).
LOBE_ALPHAS = (0.03, 0.1, 0.3)
LOBE_IOR = 1.5


class Body(WordEnum):
    """How the ``nbrdf`` plugin evaluates a material's body (its ``body``
    parameter): a choice inside ``neural.methods.Method.NEURAL``, not a
    method of its own. Both are the neural path; they differ only in where
    the body's values come from (the coat and the sampler are the same)."""
    DECODER = "decoder"  #: the shipped decoder per query (``DecoderKernel``)
    TABLE = "table"      #: the decoder baked once into a table (``TableBody``, ``param_table.ParamTableBody``)


# --- small vector helpers -----------------------------------------------------------------
def _normalize(v, eps: float):
    return v / dr.maximum(dr.norm(v), eps)


def _sq(x):
    return x * x


def _turn(w, c: float, s: float):
    """w in the frame turned by (cos, sin) about z (``neural.anisotropy.in_frame``); (c, -s) turns back."""
    return mi.Vector3f(c * w.x + s * w.y, c * w.y - s * w.x, w.z)


def _stretched(h, stretch: tuple[float, float, float], inverse: bool = False):
    """Unit half vectors h' ~ (k h_x, h_y / k, h_z) in the tangent frame of ``stretch`` (k, cos rho,
    sin rho); ``inverse``: the stretch undone (``neural.sampling._stretched``)."""
    k, c, s = stretch
    if inverse:
        k = 1.0 / k
    hf = _turn(h, c, s)
    return _normalize(_turn(mi.Vector3f(k * hf.x, hf.y / k, hf.z), c, -s), 1e-30)


# --- GGX and Fresnel (neural.microfacet) --------------------------------------------------
def fresnel_dielectric(cos_i, eta: float):
    """Exact unpolarised Fresnel reflectance; 1 under total internal reflection."""
    c = dr.minimum(dr.abs(cos_i), 1.0)
    sin2_t = (1.0 - c * c) / (eta * eta)
    cos_t = dr.sqrt(dr.maximum(1.0 - sin2_t, 0.0))
    rs = (c - eta * cos_t) / (c + eta * cos_t)
    rp = (eta * c - cos_t) / (eta * c + cos_t)
    return dr.select(sin2_t >= 1.0, 1.0, 0.5 * (rs * rs + rp * rp))


def ggx_d(m, alpha: float, alpha_y: float | None = None):
    """GGX's D; with ``alpha_y`` the anisotropic D of alpha along x and alpha_y along y."""
    if alpha_y is not None:
        s = _sq(m.x) / (alpha * alpha) + _sq(m.y) / (alpha_y * alpha_y) + _sq(m.z)
        return dr.select(m.z > 0, 1.0 / (math.pi * alpha * alpha_y * s * s), 0.0)
    a2 = alpha * alpha
    denom = _sq(m.x) + _sq(m.y) + _sq(m.z) * a2
    return dr.select(m.z > 0, a2 / (math.pi * denom * denom), 0.0)


def _g1_dir(w, alpha: float, alpha_y: float | None = None):
    if alpha_y is not None:
        a2_tan2 = (alpha * alpha * _sq(w.x) + alpha_y * alpha_y * _sq(w.y)) / dr.maximum(_sq(w.z), 1e-30)
        return 2.0 / (1.0 + dr.sqrt(1.0 + a2_tan2))
    tan2 = (_sq(w.x) + _sq(w.y)) / dr.maximum(_sq(w.z), 1e-30)
    return 2.0 / (1.0 + dr.sqrt(1.0 + alpha * alpha * tan2))


def smith_g1(w, m, alpha: float, alpha_y: float | None = None):
    return dr.select(dr.dot(w, m) * w.z > 0, _g1_dir(w, alpha, alpha_y), 0.0)


def sample_vndf(w, alpha: float, u1, u2, alpha_y: float | None = None):
    """Heitz 2018's visible-normal sample, w mirrored to the upper hemisphere; ``alpha_y``: anisotropic."""
    sgn = dr.select(w.z < 0, -1.0, 1.0)
    ay = alpha if alpha_y is None else alpha_y
    v = _normalize(mi.Vector3f(alpha * w.x * sgn, ay * w.y * sgn, w.z * sgn), 1e-15)
    lensq = _sq(v.x) + _sq(v.y)
    safe = lensq > 1e-14
    il = dr.rsqrt(dr.select(safe, lensq, 1.0))
    t1x = dr.select(safe, -v.y * il, 1.0)
    t1y = dr.select(safe, v.x * il, 0.0)
    t2x, t2y, t2z = -v.z * t1y, v.z * t1x, v.x * t1y - v.y * t1x
    r = dr.sqrt(u1)
    s_phi, c_phi = dr.sincos(2.0 * math.pi * u2)
    p1, p2 = r * c_phi, r * s_phi
    s = 0.5 * (1.0 + v.z)
    p2 = (1.0 - s) * dr.sqrt(dr.maximum(1.0 - p1 * p1, 0.0)) + s * p2
    p3 = dr.sqrt(dr.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))
    m = mi.Vector3f(alpha * (p1 * t1x + p2 * t2x + p3 * v.x), ay * (p1 * t1y + p2 * t2y + p3 * v.y),
                    dr.maximum(p2 * t2z + p3 * v.z, 1e-12))
    return dr.normalize(m)


def vndf_pdf(w, m, alpha: float, alpha_y: float | None = None):
    wu = w * dr.select(w.z < 0, -1.0, 1.0)
    wm = dr.dot(wu, m)
    pdf = (_g1_dir(wu, alpha, alpha_y) * dr.maximum(wm, 0.0) * ggx_d(m, alpha, alpha_y)
           / dr.maximum(dr.abs(wu.z), 1e-30))
    return dr.select(wm > 0, pdf, 0.0)


def reflect(w, m):
    return 2.0 * dr.dot(w, m) * m - w


# --- the clear coat (neural.coat) --------------------------------------------------------
@dataclass(frozen=True)
class Coat:
    """A code's clear coat, already clamped to its legal range; ior 1: none.
    Floats for a uniform material, per-lane arrays for a textured one.
    ``stretch``: (k, cos rho, sin rho) of the coat's anisotropy vector, a code
    with an anisotropic tail's (``neural.anisotropy.stretch``): anisotropic GGX
    of alpha_x = roughness / k, alpha_y = roughness k in the tangent frame
    turned by rho (``neural.coat``); None: the isotropic coat."""

    roughness: float
    ior: float
    stretch: tuple[float, float, float] | None = None

    @property
    def present(self) -> bool:
        """Whether any lane may have a coat (per-lane arrays: always)."""
        return self.ior > 1.0 + 1e-4 if isinstance(self.ior, (int, float)) else True

    def _frame(self) -> tuple[float, float | None, float, float]:
        """(alpha_x, alpha_y or None, cos rho, sin rho): an isotropic coat keeps its alpha and frame."""
        if self.stretch is None:
            return self.roughness, None, 1.0, 0.0
        k, c, s = self.stretch
        return self.roughness / k, self.roughness * k, c, s

    def eval(self, wi, wo):
        """The coat's reflection in 1/sr (no cosine)."""
        a, ay, c, s = self._frame()
        if ay is not None:
            wi, wo = _turn(wi, c, s), _turn(wo, c, s)
        eta = self.ior
        h = _normalize(wi + wo, 1e-30)
        f = (fresnel_dielectric(dr.dot(wi, h), eta) * ggx_d(h, a, ay) * smith_g1(wi, h, a, ay)
             * smith_g1(wo, h, a, ay) / dr.maximum(4.0 * wi.z * wo.z, 1e-30))
        return dr.select((wi.z > 0) & (wo.z > 0) & (eta > 1.0), f, 0.0)

    def pdf(self, w, w_other):
        a, ay, c, s = self._frame()
        if ay is not None:
            w, w_other = _turn(w, c, s), _turn(w_other, c, s)
        h = _normalize(w + w_other, 1e-30)
        p = vndf_pdf(w, h, a, ay) / (4.0 * dr.maximum(dr.abs(dr.dot(w, h)), 1e-30))
        return dr.select((w.z > 0) & (w_other.z > 0), p, 0.0)

    def sample(self, w, u1, u2):
        a, ay, c, s = self._frame()
        if ay is None:
            return reflect(w, sample_vndf(w, a, u1, u2))
        wf = _turn(w, c, s)
        return _turn(reflect(wf, sample_vndf(wf, a, u1, u2, ay)), c, -s)

    def probability(self, w):
        """Share of samples given to the coat at incidence w (``neural.coat.coat_probability``)."""
        if not self.present:
            return mi.Float(0.0)
        p = dr.clip(dr.sqrt(fresnel_dielectric(dr.clip(w.z, 0.0, 1.0), self.ior)), 0.05, 0.95)
        return p if isinstance(self.ior, (int, float)) else dr.select(self.ior > 1.0 + 1e-4, p, 0.0)


# --- an anisotropic body (neural.anisotropy) ---------------------------------------------
def _inside(w, eta: float):
    """w refracted through a smooth interface of relative ior ``eta`` (the coat's)."""
    tx, ty = w.x / eta, w.y / eta
    return mi.Vector3f(tx, ty, dr.sqrt(dr.maximum(1.0 - tx * tx - ty * ty, 0.0)))


def _outside(w, eta: float, lift_z: float):
    """``_inside``'s inverse; a direction beyond the critical angle leaves at ``lift_z`` along its azimuth."""
    tx, ty = w.x * eta, w.y * eta
    n = dr.sqrt(tx * tx + ty * ty)
    most = (1.0 - lift_z * lift_z) ** 0.5
    over = n > most
    tx = dr.select(over, tx / dr.maximum(n, 1e-12) * most, tx)
    ty = dr.select(over, ty / dr.maximum(n, 1e-12) * most, ty)
    return mi.Vector3f(tx, ty, dr.sqrt(dr.maximum(1.0 - tx * tx - ty * ty, 0.0)))


def _lifted(w, lift_z: float):
    """Unit directions with a z under ``lift_z`` raised to it along their azimuth."""
    n = dr.maximum(dr.sqrt(_sq(w.x) + _sq(w.y)), 1e-12)
    most = (1.0 - lift_z * lift_z) ** 0.5
    return dr.select(w.z < lift_z, mi.Vector3f(w.x / n * most, w.y / n * most, lift_z), w)


def _floored(w2, w, floor_z: float, lift_z: float):
    """Warped directions w2 raised along their azimuth to z = min(``floor_z``, the z of their unwarped w)
    (``neural.anisotropy._floored``)."""
    f = dr.minimum(floor_z, dr.maximum(w.z, lift_z))
    n = dr.maximum(dr.sqrt(_sq(w2.x) + _sq(w2.y)), 1e-12)
    most = dr.sqrt(dr.maximum(1.0 - f * f, 0.0))
    return dr.select(w2.z < f, mi.Vector3f(w2.x / n * most, w2.y / n * most, f), w2)


def _transmittance(w, eta: float):
    """1 - F of a smooth interface of relative ior ``eta`` at the outside direction w."""
    return 1.0 - fresnel_dielectric(dr.clip(w.z, 0.0, 1.0), eta)


@dataclass(frozen=True)
class BodyScaleKernel:
    """A calibrated code's body scale g(theta_i) g(theta_o) per channel (``neural.body_scale.BodyScale``): g
    linear in the angle between the knots, flat outside them; the same arithmetic in Dr.Jit."""

    knots: tuple[float, ...]
    """the knots' angles (degrees, increasing)"""
    g: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]
    """g per channel at the knots"""

    def at(self, w) -> list:
        """[g_r, g_g, g_b] at the directions w (their angle from the normal)."""
        k = self.knots
        t = dr.clip(dr.acos(dr.clip(w.z, -1.0, 1.0)) * (180.0 / math.pi), k[0], k[-1])
        out = [0.0, 0.0, 0.0]
        for j in range(len(k)):  # hat functions on the knots; they sum to 1 on [k_0, k_last]
            up = (t - k[j - 1]) / (k[j] - k[j - 1]) if j > 0 else None
            down = (k[j + 1] - t) / (k[j + 1] - k[j]) if j + 1 < len(k) else None
            hat = dr.clip(down if up is None else up if down is None else dr.minimum(up, down), 0.0, 1.0)
            out = [o + hat * g[j] for o, g in zip(out, self.g)]
        return out

    def __call__(self, wi, wo) -> list:
        return [a * b for a, b in zip(self.at(wi), self.at(wo))]


@dataclass(frozen=True)
class BodyWarp:
    """The body's part of an anisotropic code's tail: the decoder (or its table) reads the body at the
    warped pair and its value takes the factor J (``neural.anisotropy.body_pair``: under a coat the pair
    is refracted in, warped there and refracted out), the same arithmetic in Dr.Jit. For a body with
    anisotropy only (k < 1): at k = 1 the torch path leaves the pair unchanged and J = 1 exactly, as no
    warp does."""

    stretch: tuple[float, float, float]
    """(k, cos rho, sin rho) of the body's anisotropy vector (``neural.anisotropy.stretch``)"""
    alpha: float
    """the body's masking alpha, clamped to [0.005, 1] as ``body_pair`` does"""
    eta: float
    """the code's coat ior, at least 1 (1: no coat)"""
    lift_z: float
    """the lowest z of a warped direction (``neural.anisotropy.LIFT_Z``)"""
    cap: float
    """the most the coat's transmittance ratio raises J (``neural.anisotropy.TRANSMITTANCE_CAP``)"""
    floor_z: float
    """how low the decoder is read (``neural.anisotropy.FLOOR_Z_BARE`` or ``FLOOR_Z_COATED``, by ``eta``)"""
    glow: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """a scattering medium's glow per channel, added unwarped (``neural.anisotropy.glow_basis``, decision 123)"""

    def glow_basis(self, wi, wo):
        """t(wi) t(wo) / pi, t the coat's 1 - F (``neural.anisotropy.glow_basis``)."""
        return _transmittance(wi, self.eta) * _transmittance(wo, self.eta) / math.pi

    def warp(self, wi, wo) -> tuple:
        """The pair turned about its half vector's plane so that h becomes the stretched h'
        (``neural.anisotropy.warp_pair``)."""
        h = _normalize(wi + wo, 1e-30)
        hp = _stretched(h, self.stretch)
        n = dr.cross(h, hp)  # |n| = sin of the turn
        cos = dr.dot(h, hp)

        def rot(w):
            return w * cos + dr.cross(n, w) + n * dr.dot(n, w) / dr.maximum(1.0 + cos, 1e-12)

        return rot(wi), rot(wo)

    def pair(self, wi, wo) -> tuple:
        """(wi', wo', J): the warped pair and the factor the body's value takes there; a warped
        direction under ``lift_z`` is lifted to it; J is 0 where wi or wo is below the horizon."""
        k, c, s = self.stretch
        a0, eta, lift = self.alpha, self.eta, self.lift_z
        wi_in, wo_in = _inside(wi, eta), _inside(wo, eta)
        wi2_in, wo2_in = self.warp(wi_in, wo_in)
        h, hp = wi_in + wo_in, wi2_in + wo2_in
        wi2, wo2 = _outside(_lifted(wi2_in, lift), eta, lift), _outside(_lifted(wo2_in, lift), eta, lift)
        wi2, wo2 = _floored(wi2, wi, self.floor_z, lift), _floored(wo2, wo, self.floor_z, lift)
        hz = h.z / dr.maximum(dr.norm(h), 1e-30)
        hpz = hp.z / dr.maximum(dr.norm(hp), 1e-30)
        r = hpz / dr.maximum(hz, 1e-12)
        wi2_in, wo2_in = _inside(wi2, eta), _inside(wo2, eta)
        he = wi2_in + wo2_in  # the pair read: D(h') / D(h_e) (neural.anisotropy._d_ratio)
        hez = he.z / dr.maximum(dr.norm(he), 1e-30)
        d = (hez * hez * (a0 * a0 - 1.0) + 1.0) / (hpz * hpz * (a0 * a0 - 1.0) + 1.0)
        cc = dr.maximum(wi2_in.z * wo2_in.z, 0.0) / dr.maximum(wi_in.z * wo_in.z, 1e-12)
        j = (r * r) * (r * r) * cc * d * d
        ax, ay = a0 / k, a0 * k
        aniso = _g1_dir(_turn(wi_in, c, s), ax, ay) * _g1_dir(_turn(wo_in, c, s), ax, ay)
        iso = _g1_dir(wi2_in, a0) * _g1_dir(wo2_in, a0)
        j = j * aniso / dr.maximum(iso, 1e-12)
        if eta > 1.0:
            t = (_transmittance(wi, eta) * _transmittance(wo, eta)
                 / dr.maximum(_transmittance(wi2, eta) * _transmittance(wo2, eta), 1e-6))
            j = j * dr.minimum(t, self.cap)
        return wi2, wo2, dr.select((wi.z > 0) & (wo.z > 0), j, 0.0)


# --- the body's proxy pdf (neural.sampling) ----------------------------------------------
@dataclass(frozen=True)
class Proxy:
    """(1 - w) Gaussian(sigma) over the projected half vector + w Lambertian. ``stretch``: (k, cos rho,
    sin rho) of an anisotropic code's body vector (``neural.anisotropy.stretch``): the Gaussian is over
    the stretched half vector, times the stretch's Jacobian (``neural.sampling.gaussian_pdf``); None:
    the isotropic proxy."""

    sigma: float
    w: float
    stretch: tuple[float, float, float] | None = None

    @property
    def disk_norm(self) -> float:
        return 2 * math.pi * self.sigma ** 2 * -math.expm1(-0.5 / self.sigma ** 2)

    def pdf(self, wi, wo):
        h = _normalize(wi + wo, 1e-12)
        h = dr.select(h.z < 0, -h, h)
        q = h if self.stretch is None else _stretched(h, self.stretch)
        r2 = _sq(q.x) + _sq(q.y)
        p_disk = dr.exp(-0.5 * r2 / self.sigma ** 2) / self.disk_norm
        g = p_disk * q.z / (4.0 * dr.maximum(dr.abs(dr.dot(wi, h)), 1e-12))
        if self.stretch is not None:
            r = q.z / dr.maximum(h.z, 1e-12)
            g = g * (r * r * r)
        return (1.0 - self.w) * g + self.w * dr.maximum(wo.z, 0.0) / math.pi

    def sample(self, wi, u0, u1, u2):
        s_phi, c_phi = dr.sincos(2.0 * math.pi * u2)
        trunc = -math.expm1(-0.5 / self.sigma ** 2)
        r = dr.minimum(self.sigma * dr.sqrt(-2.0 * dr.log(1.0 - u1 * trunc)), 1.0)
        h = mi.Vector3f(r * c_phi, r * s_phi, dr.sqrt(dr.maximum(1.0 - r * r, 0.0)))
        if self.stretch is not None:
            h = _stretched(h, self.stretch, inverse=True)
        wo_g = 2.0 * dr.dot(wi, h) * h - wi
        rc = dr.sqrt(u1)
        wo_c = mi.Vector3f(rc * c_phi, rc * s_phi, dr.sqrt(dr.maximum(1.0 - u1, 0.0)))
        return _normalize(dr.select(u0 < self.w, wo_c, wo_g), 1e-12)


def coated_pdf(coat: Coat, proxy: Proxy, wi, wo):
    """pdf of ``coated_sample`` given wi (``neural.sampling.coated_pdf``)."""
    p = proxy.pdf(wi, wo)
    if coat.present:
        pc = coat.probability(wi)
        p = pc * coat.pdf(wi, wo) + (1.0 - pc) * p
    return dr.select((wi.z > 0) & (wo.z > 0), p, 0.0)


def coated_sample(coat: Coat, proxy: Proxy, wi, u0, u1, u2):
    """The other direction given wi: u0 picks the coat or the proxy (and is
    rescaled to stay uniform for the proxy's own choice), u1, u2 draw it."""
    if not coat.present:
        return proxy.sample(wi, u0, u1, u2)
    pc = coat.probability(wi)
    u_p = dr.clip((u0 - pc) / dr.maximum(1.0 - pc, 1e-6), 0.0, 1.0 - 1e-7)
    return dr.select(u0 < pc, coat.sample(wi, u1, u2), proxy.sample(wi, u_p, u1, u2))


# --- the decoder's direction features (neural.decoder) ------------------------------------
def rusink5(wi, wo) -> list:
    h = _normalize(wi + wo, 1e-12)
    cos_d = dr.clip(dr.dot(wi, h), -1.0, 1.0)
    theta_h = dr.atan2(dr.sqrt(_sq(h.x) + _sq(h.y)), h.z)
    theta_d = dr.atan2(dr.norm(dr.cross(wi, h)), cos_d)
    t = wi - cos_d * h
    b = mi.Vector3f(-h.y, h.x, 0.0)
    bn = dr.norm(b)
    b = dr.select(bn > 1e-7, b / dr.maximum(bn, 1e-12), mi.Vector3f(0.0, 1.0, 0.0))
    tn2 = dr.squared_norm(t)
    ty = dr.dot(t, b)
    cos2 = dr.select(tn2 > 1e-14, 1.0 - 2.0 * ty * ty / dr.maximum(tn2, 1e-30), 1.0)
    return [dr.sqrt(theta_h * (2.0 / math.pi)), theta_d * (2.0 / math.pi), cos2, wi.z * wo.z, 0.5 * (wi.z + wo.z)]


def _bumps(h) -> list:
    c2, s2 = _sq(h.z), _sq(h.x) + _sq(h.y)
    return [a * a * c2 / dr.maximum(a * a * c2 + s2, 1e-30) for a in LOBE_ALPHAS]


def lobes11(wi, wo) -> list:
    def inside(w):
        tx, ty = w.x / LOBE_IOR, w.y / LOBE_IOR
        return mi.Vector3f(tx, ty, dr.sqrt(dr.maximum(1.0 - tx * tx - ty * ty, 0.0)))

    return (rusink5(wi, wo) + _bumps(_normalize(wi + wo, 1e-12))
            + _bumps(_normalize(inside(wi) + inside(wo), 1e-12)))


ENCODERS = {"rusink5": rusink5, "lobes11": lobes11}


# --- the decoder network ------------------------------------------------------------------
class DecoderKernel:
    """The shipped decoder at one material: per channel, relu layers over the
    direction features with the latent's share as the first layer's bias,
    then y = log f; f = exp(min(y, 80)). Weights packed once for ``drjit.nn``;
    the shares are literal constants of the traced program (192 floats)."""

    def __init__(self, encoding: str, activation: str, w_dir: np.ndarray, shares: np.ndarray,
                 hidden: list[tuple[np.ndarray, np.ndarray]], out: tuple[np.ndarray, np.ndarray]):
        if activation != "relu":
            raise ValueError(f"the decoder's activation {activation!r} is not supported in Mitsuba (relu only)")
        if encoding not in ENCODERS:
            raise ValueError(f"the decoder's encoding {encoding!r} is unknown")
        self.encoding = encoding
        T = mi.TensorXf
        mats = [T(np.ascontiguousarray(w_dir, np.float32))]
        for w, b in hidden + [out]:
            mats += [T(np.ascontiguousarray(w, np.float32)), T(np.ascontiguousarray(b, np.float32))]
        packed = nn.pack(*mats, layout="inference")
        self.w_dir = packed[0]
        # exact float32 values as Python floats: Dr.Jit literals
        self.shares = np.asarray(shares, np.float32).astype(np.float64).tolist()
        rest = packed[1:]
        self.layers = [(rest[2 * k], rest[2 * k + 1]) for k in range(len(rest) // 2)]

    def body(self, wi, wo, shares: list | None = None) -> list:
        """Decoded body values [f_r, f_g, f_b] (1/sr), zero below the horizon;
        ``shares``: per-lane latent shares [3][width] (a latent texture's)
        instead of the material's own. The first layer's direction part is
        the same for the three channels and computed once."""
        x = nn.CoopVec(*ENCODERS[self.encoding](wi, wo))
        up = (wi.z > 0) & (wo.z > 0)
        d = nn.matvec(self.w_dir, x)
        out = []
        if shares is None:
            shares = [[mi.Float(v) for v in share] for share in self.shares]
        for share in shares:
            h = dr.maximum(d + nn.CoopVec(*share), 0.0)
            for j, (w, b) in enumerate(self.layers):
                h = nn.matvec(w, h, b)
                if j < len(self.layers) - 1:
                    h = dr.maximum(h, 0.0)
            y = list(h)[0]
            out.append(dr.select(up, dr.exp(dr.minimum(y, 80.0)), 0.0))
        return out


class TableBody:
    """A uniform material's decoded body read from a baked table
    (``neural.body_table``: log f per RGB channel over theta_h, theta_d and the
    folded phi_d) by one trilinear ``Texture3f`` lookup per query instead of the
    decoder. The table's interpolation error is a bias against the decoder
    (noise-free); the coat is not in the table (closed form, ``Coat``). Inside
    a symbolic call a lookup is 8 gathers per channel, where the decoder's
    weights would each be a per-lane gather on the LLVM backend."""

    def __init__(self, values: np.ndarray):
        """``values``: (K, M, N, 3) float32, ``neural.body_table.bake_body``'s layout."""
        values = np.ascontiguousarray(values, np.float32)
        if values.ndim != 4 or values.shape[-1] != 3 or min(values.shape[:3]) < 2:
            raise ValueError(f"a body table is (K, M, N, 3) with each side >= 2, got {values.shape}")
        self.shape = values.shape[:3]
        self.texture = mi.Texture3f(mi.TensorXf(values), use_accel=False, filter_mode=dr.FilterMode.Linear,
                                    wrap_mode=dr.WrapMode.Clamp)

    def body(self, wi, wo, shares: list | None = None) -> list:
        """Body values [f_r, f_g, f_b] (1/sr), zero below the horizon (``DecoderKernel.body``);
        a table holds one material, so per-lane ``shares`` are refused."""
        if shares is not None:
            raise ValueError("a body table holds one material's body: it takes no per-lane latent shares")
        u, v, w = table_coordinates(wi, wo, self.shape)
        y = self.texture.eval(mi.Point3f(u, v, w / self.shape[0]))
        up = (wi.z > 0) & (wo.z > 0)
        return [dr.select(up, dr.exp(dr.minimum(c, 80.0)), 0.0) for c in y]


def table_coordinates(wi, wo, shape: tuple[int, int, int]) -> tuple:
    """Where a direction pair reads a baked body table of ``shape`` (K, M, N) nodes
    (``neural.body_table``'s layout): u, v as texture coordinates of the N theta_h
    and M theta_d nodes, and the folded phi_d in texels (0.5 ... K - 0.5). Node i
    sits at the centre (i + 0.5) / n of a linear-filtered texel."""
    k, m, n = shape
    r = rusink5(wi, wo)  # sqrt(2 theta_h / pi), 2 theta_d / pi, cos 2 phi_d, ...
    u = (dr.clip(r[0], 0.0, 1.0) * (n - 1) + 0.5) / n
    v = (dr.clip(r[1], 0.0, 1.0) * (m - 1) + 0.5) / m
    w = dr.acos(dr.clip(r[2], -1.0, 1.0)) * ((k - 1) / math.pi) + 0.5
    return u, v, w


class CodeKernel:
    """A whole material code: decoded body plus closed-form coat, and its
    sampler. ``si`` (the hit) is what a textured material looks up; a
    uniform one ignores it."""

    #: Whether the body varies over the surface (looked up per hit by uv).
    textured = False

    def __init__(self, decoder: "DecoderKernel | TableBody", coat: Coat, proxy: Proxy, warp: BodyWarp | None = None,
                 scale: BodyScaleKernel | None = None):
        """``decoder``: what gives the body (``DecoderKernel`` or ``TableBody``); ``warp``: an
        anisotropic body's (``BodyWarp``), which either body is read through; None: isotropic; ``scale``:
        a calibrated code's body scale (None: none)."""
        self.decoder, self.coat, self.proxy, self.warp, self.scale = decoder, coat, proxy, warp, scale

    def body(self, wi, wo, shares: list | None) -> list:
        """[f_r, f_g, f_b] of the body (1/sr), at the warped pair times J for an anisotropic one, plus its
        glow; times the body scale of a calibrated code."""
        if self.scale is not None:
            return [f * g for f, g in zip(self._body(wi, wo, shares), self.scale(wi, wo))]
        return self._body(wi, wo, shares)

    def _body(self, wi, wo, shares: list | None) -> list:
        if self.warp is None:
            return self.decoder.body(wi, wo, shares)
        bi, bo, j = self.warp.pair(wi, wo)
        g = self.warp.glow_basis(wi, wo)
        up = (wi.z > 0) & (wo.z > 0)
        return [dr.select(up, f * j + k * g, 0.0) for f, k in zip(self.decoder.body(bi, bo, shares), self.warp.glow)]

    def at(self, si) -> tuple[list | None, Coat]:
        """(per-lane latent shares or None, the coat) at the hit ``si``."""
        return None, self.coat

    def eval(self, wi, wo, si=None):
        """RGB f(wi, wo) as a ``mi.Color3f`` (no cosine)."""
        shares, coat = self.at(si)
        r, g, b = self.body(wi, wo, shares)
        if coat.present:
            c = coat.eval(wi, wo)
            r, g, b = r + c, g + c, b + c
        return mi.Color3f(r, g, b)

    def pdf(self, w, w_other, si=None):
        return coated_pdf(self.at(si)[1], self.proxy, w, w_other)

    def sample(self, w, u0, u1, u2, si=None):
        """(other direction, its pdf); pdf 0 where the draw fell below the horizon."""
        coat = self.at(si)[1]
        wo = coated_sample(coat, self.proxy, w, u0, u1, u2)
        return wo, coated_pdf(coat, self.proxy, w, wo)


class TexturedCodeKernel(CodeKernel):
    """A latent texture's material: the shares and coat of the hit's texel
    (``textures.LatentTextureKernel``, trilinear by the hit's footprint when
    ``pixel_angle`` > 0); one proxy for all texels (the texture's mean code),
    which keeps sample and pdf consistent wherever it is looked up."""

    textured = True

    def __init__(self, decoder: DecoderKernel, texture, proxy: Proxy, coat_ranges: tuple, pixel_angle: float = 0.0):
        """``texture``: a ``textures.LatentTextureKernel``; ``coat_ranges``: the legal (lo, hi) of the
        coat's roughness and ior (``neural.coat``), which each texel's coat is clamped to."""
        super().__init__(decoder, Coat(0.0, 1.0), proxy)
        self.texture, self.pixel_angle = texture, float(pixel_angle)
        self._ranges = tuple(coat_ranges)

    def at(self, si):
        if si is None:
            raise ValueError("a textured nbrdf material is evaluated at a hit (si)")
        shares, r, ior = self.texture.lookup(si.uv, level_of_detail(si, self.pixel_angle, self.texture.size))
        (r0, r1), (i0, i1) = self._ranges
        return shares, Coat(dr.clip(r, r0, r1), dr.clip(ior, i0, i1))
