"""Anisotropic interfaces (SPEC section 10), the conventions in one place.

A ``dielectric`` or ``conductor`` layer's ``anisotropy`` a turns its GGX
alpha (``roughness``) into OpenPBR's pair alpha_x = alpha sqrt(2 / (1 + (1 -
a)^2)), alpha_y = (1 - a) alpha_x, along the tangent frame that the
material's ``anisotropy_rotation`` (degrees) turns about the normal,
counter-clockwise seen from above; every interface of a stack shares it.
Here: the alphas, the change of frame, the anisotropic tail of a material
code and the warp the decoder reads it through, and the one-line refusal of
the paths that cannot take anisotropy yet (``require_isotropic``).

A code's anisotropic tail (``FRAME_PARAMS`` floats after the coat, the same in
the three channels) holds two *anisotropy vectors* v = a (cos 2 rho, sin 2 rho),
rho the tangent's turn: the coat's and the body's. GGX is unchanged by a half
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
from nbrdf.neural.microfacet import smith_g1_dir

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


#: Floats of a code's anisotropic tail: the coat's anisotropy vector, the body's, and the body's masking
#: alpha (the geometric-mean alpha of the interface whose anisotropy the body takes).
FRAME_PARAMS = 5
#: The largest anisotropy a stretch takes (SPEC section 10's range).
A_MAX = 0.95


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


def with_frame(code: Tensor, coat_v: Tensor, body_v: Tensor, body_alpha: Tensor) -> Tensor:
    """Codes (..., 34 + FRAME_PARAMS) of isotropic-equivalent codes (..., 34), the anisotropy vectors
    (..., 2) of their coat and body and the body's masking alpha (..., 1) (broadcast)."""
    shape = code.shape[:-1]
    tail = torch.cat([torch.as_tensor(coat_v, dtype=code.dtype).expand(*shape, 2),
                      torch.as_tensor(body_v, dtype=code.dtype).expand(*shape, 2),
                      torch.as_tensor(body_alpha, dtype=code.dtype).expand(*shape, 1)], -1)
    return torch.cat([code, tail], -1)


def body_tail(code: Tensor, iso_size: int) -> Tensor | None:
    """The body's part of the tail (..., 3): its anisotropy vector and masking alpha, of codes
    (..., iso_size + FRAME_PARAMS); None for any other code (isotropic codes, bare latents)."""
    if code.shape[-1] != iso_size + FRAME_PARAMS:
        return None
    return code[..., iso_size + 2:iso_size + 5]


def code_tail(code: Tensor, iso_size: int) -> dict[str, object]:
    """The GPU's uniforms of a code's tail (one material code (3, n)): ``u_aniso`` (the coat's and the
    body's anisotropy vectors) and ``u_body_alpha``; empty for a code without a tail."""
    if code.shape[-1] != iso_size + FRAME_PARAMS:
        return {}
    t = [float(x) for x in code.reshape(-1, code.shape[-1])[0, iso_size:iso_size + FRAME_PARAMS]]
    return {"u_aniso": tuple(t[:4]), "u_body_alpha": t[4]}


def warp_pair(v: Tensor, wi: Tensor, wo: Tensor) -> tuple[Tensor, Tensor]:
    """The pair (wi, wo) turned about their half vector's plane so that h becomes the stretched h'
    (module docstring): what the isotropic decoder sees of an anisotropic body. v (..., 2) broadcasts
    against the pairs; v = 0 returns the pair unchanged (bit for bit)."""
    k, c, s = stretch(v.to(wi.dtype))
    h = wi + wo
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    hf = _turn(h, c, s)  # h in the tangent frame
    hp = torch.stack([k * hf[..., 0], hf[..., 1] / k, hf[..., 2]], -1)
    hp = _turn(hp, c, -s)  # back in the shading frame (z rotations commute with nothing else here)
    hp = hp / hp.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    # the rotation taking h to h' (both unit, upper hemisphere): R w = w cos + (n x w) + n (n . w) / (1 + cos),
    # n = h x h' (unnormalised, |n| = sin)
    n = torch.linalg.cross(h, hp, dim=-1)
    cos = (h * hp).sum(-1, keepdim=True)

    def rot(w: Tensor) -> Tensor:
        return (w * cos + torch.linalg.cross(n, w, dim=-1)
                + n * (n * w).sum(-1, keepdim=True) / (1.0 + cos).clamp_min(1e-12))

    flat = (k == 1.0)[..., None]
    return torch.where(flat, wi, rot(wi)), torch.where(flat, wo, rot(wo))


def _inside(w: Tensor, eta: Tensor) -> Tensor:
    """Directions refracted through a smooth interface of relative ior ``eta`` (the coat's)."""
    t = w[..., :2] / eta[..., None]
    return torch.cat([t, torch.sqrt((1.0 - (t * t).sum(-1, keepdim=True)).clamp_min(0.0))], -1)


def body_pair(tail: Tensor, wi: Tensor, wo: Tensor, coat_ior: Tensor | None = None
              ) -> tuple[Tensor, Tensor, Tensor]:
    """(wi', wo', J): the warped pair the decoder evaluates an anisotropic body at, and the factor its
    value takes. ``tail`` (..., 3): the body's anisotropy vector and masking alpha (``body_tail``).
    J = (h'_z / h_z)^4 (D's Jacobian) times cos(theta_i') cos(theta_o') / (cos(theta_i) cos(theta_o))
    (the microfacet denominator) times the ratio of the anisotropic to the isotropic Smith masking
    of both directions, refracted through the coat (``coat_ior``) when there is one: for a lone
    interface the warped value is then exact; under a coat an approximation (docs/decisions/116).
    J is 0 where the warp turns a direction below the horizon."""
    v, a0 = tail[..., :2], tail[..., 2].clamp(0.005, 1.0)
    wi2, wo2 = warp_pair(v, wi, wo)
    h = wi + wo
    hp = wi2 + wo2
    hz = h[..., 2] / h.norm(dim=-1).clamp_min(1e-30)
    hpz = hp[..., 2] / hp.norm(dim=-1).clamp_min(1e-30)
    r = hpz / hz.clamp_min(1e-12)
    cc = (wi2[..., 2] * wo2[..., 2]).clamp_min(0.0) / (wi[..., 2] * wo[..., 2]).clamp_min(1e-12)
    j = (r * r) * (r * r) * cc
    eta = torch.ones_like(a0) if coat_ior is None else torch.as_tensor(coat_ior, dtype=wi.dtype).clamp_min(1.0)
    ax, ay, c, s = coat_alphas(a0, v)
    aniso = (smith_g1_dir(in_frame(_inside(wi, eta), c, s), ax, ay)
             * smith_g1_dir(in_frame(_inside(wo, eta), c, s), ax, ay))
    iso = smith_g1_dir(_inside(wi2, eta), a0) * smith_g1_dir(_inside(wo2, eta), a0)
    j = j * aniso / iso.clamp_min(1e-12)
    j = torch.where((wi2[..., 2] > 0) & (wo2[..., 2] > 0), j, torch.zeros_like(j))
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
