"""Anisotropic interfaces (SPEC section 10), the conventions in one place.

A ``dielectric`` or ``conductor`` layer's ``anisotropy`` a turns its GGX
alpha (``roughness``) into OpenPBR's pair alpha_x = alpha sqrt(2 / (1 + (1 -
a)^2)), alpha_y = (1 - a) alpha_x, along the tangent frame that the
material's ``anisotropy_rotation`` (degrees) turns about the normal,
counter-clockwise seen from above; every interface of a stack shares it.
Here: the alphas, the change of frame, the anisotropic tail of a material
code and the warp the decoder reads it through, and the one-line refusal of
the paths that cannot take anisotropy yet (``require_isotropic``).

A code's anisotropic tail (``FRAME_PARAMS`` floats after the coat) holds two
*anisotropy vectors* v = a (cos 2 rho, sin 2 rho), rho the tangent's turn: the
coat's and the body's (the same in the three channels), the body's masking
alpha, and the *glow* K of the channel: the light a scattering medium sends back
(it comes out nearly isotropic), K t(wi) t(wo) / pi with t the coat's 1 - F
(``glow_basis``). Over a scattering medium the body latent is then the *direct*
light's, the stack with its media's albedo 0 (``neural.scattered_glow``;
docs/decisions/123); K is 0 without one. GGX is unchanged by a half
turn of its frame, so the doubled angle makes v continuous: codes blend and
mip-map as vectors, and two crossed brushings average to an isotropic one.
The first 34 floats of such a code are its *isotropic equivalent*: the body
latent and coat of the stack with each alpha replaced by the geometric mean
alpha_0 = sqrt(alpha_x alpha_y). The tail stretches them back with
k = sqrt(1 - a): alpha_x = alpha_0 / k, alpha_y = alpha_0 k (SPEC section 10's
pair, exactly). The coat stays in closed form (anisotropic GGX); the body is
the decoder evaluated at the pair turned so its half vector h becomes the
stretched h' ~ (k h_x, h_y / k, h_z) (``warp_pair``): GGX's D of the stretched
pair is the anisotropic D, exact up to its Jacobian (docs/decisions/116).
"""
from __future__ import annotations

import math

import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import Material, TextureRef
from nbrdf.neural.microfacet import fresnel_dielectric, smith_g1_dir

Tensor = torch.Tensor


def alphas(alpha, a):
    """(alpha_x, alpha_y) of GGX alpha ``alpha`` and anisotropy ``a`` (floats, arrays or tensors). a = 0
    gives (alpha, alpha) bit for bit: sqrt(2 / 2) is 1 exactly."""
    one_minus = 1.0 - a
    scale = (2.0 / (1.0 + one_minus * one_minus)) ** 0.5
    ax = alpha * scale
    return ax, one_minus * ax


def to_frame(w: Tensor, rotation_deg) -> Tensor:
    """Directions (..., 3) in the material's rotated frame: their coordinates along the tangent turned by
    ``rotation_deg`` (broadcast to the batch) counter-clockwise about z, the bitangent and z."""
    t = torch.as_tensor(rotation_deg, dtype=w.dtype, device=w.device) * (math.pi / 180.0)
    c, s = torch.cos(t), torch.sin(t)
    x, y = w[..., 0], w[..., 1]
    return torch.stack([c * x + s * y, c * y - s * x, w[..., 2]], -1)


def from_frame(w: Tensor, rotation_deg) -> Tensor:
    """The inverse of ``to_frame``: directions given in the rotated frame, back in the shading frame."""
    return to_frame(w, -torch.as_tensor(rotation_deg, dtype=w.dtype, device=w.device))


#: Floats of a code's anisotropic tail: the coat's anisotropy vector, the body's, the body's masking
#: alpha (the geometric-mean alpha of the interface whose anisotropy the body takes) and the channel's glow.
FRAME_PARAMS = 6
#: The largest anisotropy a stretch takes (SPEC section 10's range).
A_MAX = 0.95
#: The version of the warp's arithmetic (``body_pair``): codes refined through an older one are refitted
#: (``training.refine``). 2: J's D(h') / D(h_e) (decision 120); 3: the glow of a scattering medium (decision 123).
WARP_VERSION = 3


def geometric_alpha(alpha, a):
    """alpha_0 = sqrt(alpha_x alpha_y) of GGX alpha ``alpha`` and anisotropy ``a``: the roughness of a
    code's isotropic equivalent (what the leaf encoders and the layering network see)."""
    ax, ay = alphas(alpha, a)
    return (ax * ay) ** 0.5


def anisotropy_vector(a, rotation_deg) -> Tensor:
    """v (..., 2) = a (cos 2 rho, sin 2 rho) of anisotropy ``a`` along the tangent turned by ``rotation_deg``."""
    a = torch.as_tensor(a, dtype=torch.float32)
    t = torch.as_tensor(rotation_deg, dtype=a.dtype) * (math.pi / 90.0)
    return torch.stack([a * torch.cos(t), a * torch.sin(t)], -1)


def stretch(v: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """(k, cos rho, sin rho) of anisotropy vectors v (..., 2): k = sqrt(1 - a), rho the tangent's turn."""
    a = torch.sqrt(v[..., 0] ** 2 + v[..., 1] ** 2).clamp(max=A_MAX)
    t = 0.5 * torch.atan2(v[..., 1], v[..., 0])
    return torch.sqrt(1.0 - a), torch.cos(t), torch.sin(t)


def _turn(w: Tensor, c: Tensor, s: Tensor) -> Tensor:
    """Directions (..., 3) in the frame turned by (cos, sin) about z (``to_frame`` with a given angle)."""
    x, y = w[..., 0], w[..., 1]
    return torch.stack([c * x + s * y, c * y - s * x, w[..., 2]], -1)


def with_frame(code: Tensor, coat_v: Tensor, body_v: Tensor, body_alpha: Tensor,
               glow: Tensor | float = 0.0) -> Tensor:
    """Codes (..., 34 + FRAME_PARAMS) of isotropic-equivalent codes (..., 34), the anisotropy vectors
    (..., 2) of their coat and body, the body's masking alpha (..., 1) and the glow (..., 1) (broadcast)."""
    shape = code.shape[:-1]
    tail = torch.cat([torch.as_tensor(coat_v, dtype=code.dtype).expand(*shape, 2),
                      torch.as_tensor(body_v, dtype=code.dtype).expand(*shape, 2),
                      torch.as_tensor(body_alpha, dtype=code.dtype).expand(*shape, 1),
                      torch.as_tensor(glow, dtype=code.dtype).expand(*shape, 1)], -1)
    return torch.cat([code, tail], -1)


def body_tail(code: Tensor, iso_size: int) -> Tensor | None:
    """The body's part of the tail (..., 3): its anisotropy vector and masking alpha, of codes
    (..., iso_size + FRAME_PARAMS); None for any other code (isotropic codes, bare latents)."""
    if code.shape[-1] != iso_size + FRAME_PARAMS:
        return None
    return code[..., iso_size + 2:iso_size + 5]


def body_glow(code: Tensor, iso_size: int) -> Tensor | None:
    """The glow K (...,) of codes (..., iso_size + FRAME_PARAMS), per channel; None for any other code."""
    if code.shape[-1] != iso_size + FRAME_PARAMS:
        return None
    return code[..., iso_size + 5]


def glow_basis(wi: Tensor, wo: Tensor, coat_ior: Tensor | float | None) -> Tensor:
    """t(wi) t(wo) / pi (...,): the shape of a scattering medium's glow, t the coat's smooth 1 - F (1 without
    a coat); 0 below the horizon."""
    eta = torch.as_tensor(1.0 if coat_ior is None else coat_ior, dtype=wi.dtype).clamp_min(1.0)
    b = _transmittance(wi, eta) * _transmittance(wo, eta) / math.pi
    return torch.where((wi[..., 2] > 0) & (wo[..., 2] > 0), b, torch.zeros_like(b))


def tail_turn(code: Tensor, iso_size: int) -> Tensor | None:
    """The turn rho of the tangent of a material's code (..., iso_size + FRAME_PARAMS; its first row):
    half the angle of its body's anisotropy vector, else of its coat's; None for a code without a tail."""
    if code.shape[-1] != iso_size + FRAME_PARAMS:
        return None
    coat_v, body_v = code[0, iso_size:iso_size + 2].float(), code[0, iso_size + 2:iso_size + 4].float()
    v = coat_v if float(body_v.norm()) == 0.0 else body_v
    return 0.5 * torch.atan2(v[1], v[0])


def turned_tail(code: Tensor, iso_size: int, angle: float) -> Tensor:
    """Codes (..., iso_size + FRAME_PARAMS) with their coat's and body's anisotropy vectors turned by
    ``angle`` about the normal (a vector's angle is twice the tangent's: it turns by 2 ``angle``)."""
    out = code.clone()
    c2, s2 = math.cos(2.0 * angle), math.sin(2.0 * angle)
    for i in (iso_size, iso_size + 2):
        x, y = code[..., i], code[..., i + 1]
        out[..., i], out[..., i + 1] = c2 * x - s2 * y, s2 * x + c2 * y
    return out


def code_tail(code: Tensor, iso_size: int) -> dict[str, object]:
    """The GPU's uniforms of a code's tail (one material code (3, n)): ``u_aniso`` (the coat's and the
    body's anisotropy vectors), ``u_body_alpha`` and ``u_body_glow`` (per channel); empty for a code without
    a tail."""
    if code.shape[-1] != iso_size + FRAME_PARAMS:
        return {}
    rows = code.reshape(-1, code.shape[-1])
    t = [float(x) for x in rows[0, iso_size:iso_size + FRAME_PARAMS]]
    glow = torch.broadcast_to(rows[:, iso_size + 5], (3,))  # per channel (a single row: the same in all three)
    return {"u_aniso": tuple(t[:4]), "u_body_alpha": t[4], "u_body_glow": tuple(float(x) for x in glow)}


def stretched_half(h: Tensor, v: Tensor, inverse: bool = False) -> Tensor:
    """Unit half vectors h stretched as an anisotropic body's: h' ~ (k h_x, h_y / k, h_z) in the tangent
    frame of the anisotropy vectors v (module docstring); ``inverse``: the stretch undone."""
    k, c, s = stretch(v.to(h.dtype))
    if inverse:
        k = 1.0 / k
    hf = _turn(h, c, s)  # h in the tangent frame
    hp = _turn(torch.stack([k * hf[..., 0], hf[..., 1] / k, hf[..., 2]], -1), c, -s)  # back in the shading frame
    return hp / hp.norm(dim=-1, keepdim=True).clamp_min(1e-30)


def warp_pair(v: Tensor, wi: Tensor, wo: Tensor) -> tuple[Tensor, Tensor]:
    """The pair (wi, wo) turned about their half vector's plane so that h becomes the stretched h'
    (module docstring): what the isotropic decoder sees of an anisotropic body. v (..., 2) broadcasts
    against the pairs; v = 0 returns the pair unchanged (bit for bit)."""
    k = stretch(v.to(wi.dtype))[0]
    h = wi + wo
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    hp = stretched_half(h, v)
    # the rotation taking h to h' (both unit, upper hemisphere): R w = w cos + (n x w) + n (n . w) / (1 + cos),
    # n = h x h' (unnormalised, |n| = sin)
    n = torch.linalg.cross(h, hp, dim=-1)
    cos = (h * hp).sum(-1, keepdim=True)

    def rot(w: Tensor) -> Tensor:
        return (w * cos + torch.linalg.cross(n, w, dim=-1)
                + n * (n * w).sum(-1, keepdim=True) / (1.0 + cos).clamp_min(1e-12))

    flat = (k == 1.0)[..., None]
    return torch.where(flat, wi, rot(wi)), torch.where(flat, wo, rot(wo))


#: The lowest elevation cosine of a warped direction: one the warp turns below it is lifted to it
#: (docs/decisions/116).
LIFT_Z = 0.02
#: How low the decoder is read, as an elevation cosine (outside the coat): a warped direction lower than
#: min(floor, its unwarped direction's) is raised to it along its azimuth (``_floored``), and J's ratios,
#: taken at the pair read, carry the value there (exact for closed forms, decision 120). The decoder is
#: least accurate, and a coat's 1 - F smallest, at grazing. Bare: 1 (the warp never lowers a direction);
#: under a coat 0.35 (chosen on a validation set, tools/anisotropy_floor.py).
FLOOR_Z_BARE = 1.0
FLOOR_Z_COATED = 0.35


#: The most the coat's transmittance ratio may raise an anisotropic body: a warped pair turned past the
#: coat's critical angle leaves it grazing, where 1 - F is near 0 and the ratio would amplify the
#: decoder's grazing error (cap 2: the held-out coated lobes 1-8 dB better than 1 or none, decision 116).
TRANSMITTANCE_CAP = 2.0


def _lifted(w: Tensor) -> Tensor:
    """Unit directions with a z under ``LIFT_Z`` raised to it along their azimuth. The warp turns
    some grazing pairs of an anisotropic lobe below the horizon, where the isotropic equivalent
    has no value; lifted, the decoder's grazing value and J's masking ratio (both taken at the
    lifted direction) give the anisotropic one, as exactly as the closed forms show: 0.7-2.6 % FLIP
    on lit spheres where dropping them (J = 0) cost 9.5-29 %."""
    xy = w[..., :2]
    n = xy.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    up = torch.cat([xy / n * (1.0 - LIFT_Z * LIFT_Z) ** 0.5, torch.full_like(w[..., 2:], LIFT_Z)], -1)
    return torch.where(w[..., 2:] < LIFT_Z, up, w)


def _floored(w2: Tensor, w: Tensor, floor_z: Tensor) -> Tensor:
    """Warped directions w2 raised along their azimuth to z = min(``floor_z``, the z of their unwarped
    direction w): the decoder is read no lower than that (``FLOOR_Z_BARE``, ``FLOOR_Z_COATED``). A pair
    the warp leaves at or above its own elevations is unchanged."""
    floor = torch.minimum(floor_z[..., None].to(w.dtype), w[..., 2:].clamp_min(LIFT_Z))
    xy = w2[..., :2]
    n = xy.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    up = torch.cat([xy / n * (1.0 - floor * floor).clamp_min(0.0).sqrt(), floor], -1)
    return torch.where(w2[..., 2:] < floor, up, w2)


def _inside(w: Tensor, eta: Tensor) -> Tensor:
    """Directions refracted through a smooth interface of relative ior ``eta`` (the coat's)."""
    t = w[..., :2] / eta[..., None]
    return torch.cat([t, torch.sqrt((1.0 - (t * t).sum(-1, keepdim=True)).clamp_min(0.0))], -1)


def _outside(w: Tensor, eta: Tensor) -> Tensor:
    """Directions inside a smooth interface of relative ior ``eta`` refracted out (``_inside``'s inverse);
    one beyond the critical angle leaves at ``LIFT_Z`` (grazing) along its azimuth."""
    t = w[..., :2] * eta[..., None]
    n = t.norm(dim=-1, keepdim=True)
    most = (1.0 - LIFT_Z * LIFT_Z) ** 0.5
    t = torch.where(n > most, t / n.clamp_min(1e-12) * most, t)
    return torch.cat([t, torch.sqrt((1.0 - (t * t).sum(-1, keepdim=True)).clamp_min(0.0))], -1)


def _transmittance(w: Tensor, eta: Tensor) -> Tensor:
    """1 - F of a smooth interface of relative ior ``eta`` at the outside direction w."""
    return 1.0 - fresnel_dielectric(w[..., 2].clamp(0.0, 1.0), eta)


def _d_ratio(hpz: Tensor, he: Tensor, a0: Tensor) -> Tensor:
    """D(h') / D(h_e) of isotropic GGX at alpha ``a0``: h' the warped half vector (its z ``hpz``), h_e
    the half vector (unnormalised) of the pair the decoder is read at. They differ where a warped
    direction was lifted (``_lifted``), clamped to a coat's critical cone (``_outside``) or raised to
    the floor (``_floored``): the decoder's value there has the D of h_e, not of h' (1 up to rounding
    elsewhere; decision 120)."""
    hez = he[..., 2] / he.norm(dim=-1).clamp_min(1e-30)
    a2m1 = a0 * a0 - 1.0
    d = (hez * hez * a2m1 + 1.0) / (hpz * hpz * a2m1 + 1.0)
    return d * d


def body_pair(tail: Tensor, wi: Tensor, wo: Tensor, coat_ior: Tensor | None = None
              ) -> tuple[Tensor, Tensor, Tensor]:
    """(wi', wo', J): the warped pair the decoder evaluates an anisotropic body at, and the factor its
    value takes. ``tail`` (..., 3): the body's anisotropy vector and masking alpha (``body_tail``).
    Under a coat (``coat_ior`` > 1) the lobe lives inside it: the pair is refracted in, warped there and
    refracted out. A warped direction under ``LIFT_Z`` is lifted to it (``_lifted``, ``_outside``), and
    the pair read is raised to the floor (``_floored``). J, at the pair read: (h'_z / h_z)^4 (D's
    Jacobian) times D(h') / D(h_e) (``_d_ratio``) times cos(theta_i') cos(theta_o') / (cos(theta_i)
    cos(theta_o)) (the microfacet denominator) times the ratio of the anisotropic to the isotropic
    Smith masking of both directions, all inside, times the ratio of the coat's transmittances at the
    pair and at the pair read (at most ``TRANSMITTANCE_CAP``). For closed forms the value is the
    anisotropic one exactly, alone or under a smooth coat (the cap aside); for a decoded body under a
    coat and a medium an approximation (docs/decisions/116, 120). J is 0 where wi or wo is below the
    horizon."""
    v, a0 = tail[..., :2], tail[..., 2].clamp(0.005, 1.0)
    eta = torch.ones_like(a0) if coat_ior is None else torch.as_tensor(coat_ior, dtype=wi.dtype).clamp_min(1.0)
    wi_in, wo_in = _inside(wi, eta), _inside(wo, eta)
    wi2_in, wo2_in = warp_pair(v, wi_in, wo_in)
    h = wi_in + wo_in
    hp = wi2_in + wo2_in
    wi2, wo2 = _outside(_lifted(wi2_in), eta), _outside(_lifted(wo2_in), eta)
    floor_z = torch.where(eta > 1.0, torch.full_like(eta, FLOOR_Z_COATED), torch.full_like(eta, FLOOR_Z_BARE))
    wi2, wo2 = _floored(wi2, wi, floor_z), _floored(wo2, wo, floor_z)
    hz = h[..., 2] / h.norm(dim=-1).clamp_min(1e-30)
    hpz = hp[..., 2] / hp.norm(dim=-1).clamp_min(1e-30)
    r = hpz / hz.clamp_min(1e-12)
    wi2_in, wo2_in = _inside(wi2, eta), _inside(wo2, eta)
    dfix = _d_ratio(hpz, wi2_in + wo2_in, a0)
    cc = (wi2_in[..., 2] * wo2_in[..., 2]).clamp_min(0.0) / (wi_in[..., 2] * wo_in[..., 2]).clamp_min(1e-12)
    j = (r * r) * (r * r) * cc * dfix
    ax, ay, c, s = coat_alphas(a0, v)
    aniso = smith_g1_dir(in_frame(wi_in, c, s), ax, ay) * smith_g1_dir(in_frame(wo_in, c, s), ax, ay)
    iso = smith_g1_dir(wi2_in, a0) * smith_g1_dir(wo2_in, a0)
    j = j * aniso / iso.clamp_min(1e-12)
    coated = eta > 1.0
    t = (_transmittance(wi, eta) * _transmittance(wo, eta)
         / (_transmittance(wi2, eta) * _transmittance(wo2, eta)).clamp_min(1e-6))
    j = torch.where(coated, j * t.clamp(max=TRANSMITTANCE_CAP), j)
    j = torch.where((wi[..., 2] > 0) & (wo[..., 2] > 0), j, torch.zeros_like(j))
    return wi2, wo2, torch.where(ax == ay, torch.ones_like(j), j)  # isotropic: 1 exactly, not 1 + rounding


def coat_alphas(alpha0: Tensor, v: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """(alpha_x, alpha_y, cos rho, sin rho) of a coat of geometric-mean alpha ``alpha0`` and anisotropy
    vector v: alpha_x = alpha0 / k, alpha_y = alpha0 k."""
    k, c, s = stretch(v)
    return alpha0 / k, alpha0 * k, c, s


def in_frame(w: Tensor, c: Tensor, s: Tensor) -> Tensor:
    """Directions (..., 3) in the tangent frame of (cos rho, sin rho)."""
    return _turn(w, c, s)


def from_tangent_frame(w: Tensor, c: Tensor, s: Tensor) -> Tensor:
    """The inverse of ``in_frame``."""
    return _turn(w, c, -s)


def anisotropic_layers(material: Material) -> list[int]:
    """Indices of the layers with a non-zero (or texture-mapped) anisotropy."""
    out = []
    for i, layer in enumerate(material.layers):
        a = getattr(layer, "anisotropy", 0.0)
        if isinstance(a, TextureRef) or a != 0:
            out.append(i)
    return out


def require_isotropic(material: Material, path: str) -> None:
    """One line (``NbrdfError``) naming the first anisotropic layer when ``path`` (e.g. "the neural
    leaf encoders and layering") cannot take anisotropy yet: never a silent drop."""
    found = anisotropic_layers(material)
    if found:
        raise NbrdfError(f"layers[{found[0]}].anisotropy: anisotropy is not yet supported by {path}")
