"""The clear coat of a material code (SPEC section 6, coat split).

A layered material's BRDF is the single reflection off its top interface,
known in closed form, plus the light that entered the stack (the *body*).
The coat is the sharp, nearly white part that look-development judges, and
the body is smooth next to it, so the representation keeps the coat exact and
gives the decoder only the body:

    f(wi, wo) = coat(roughness_c, ior_c; wi, wo) + decoder(z_body; wi, wo).

A *material code* is therefore, per colour channel, the decoder's 32-float
body latent followed by the coat's two parameters (GGX roughness, relative
ior), identical in the three channels (and, for an anisotropic material, the
tail of ``neural.anisotropy``: the coat's and the body's anisotropy vectors). A material without a coat (a bare
conductor, a diffuse base, a measured table) has ``NO_COAT``: ior 1 reflects
nothing. Codes interpolate, blend and mip-map as vectors, so the coat's
parameters follow the latents in every latent operation.

The coat term is the GGX reflection of a dielectric interface (Walter et al.
2007: exact Fresnel, separable Smith G), the same expression the Monte Carlo
reference adds for the top interface, and it is importance-sampled exactly
through its visible normals.
"""
from __future__ import annotations

import torch

from nbrdf.neural.anisotropy import FRAME_PARAMS, coat_alphas, from_tangent_frame, in_frame
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.microfacet import fresnel_dielectric, ggx_d, reflect, sample_vndf, smith_g1, vndf_pdf

Tensor = torch.Tensor

COAT_PARAMS = 2
#: (roughness, ior) of "no coat": ior 1 reflects nothing; the roughness only
#: matters while a code is blended toward a coated one (the coat fades in sharp).
NO_COAT = (0.05, 1.0)
#: The coat's legal range inside a code (a code is clamped here before use).
ROUGHNESS_RANGE = (0.005, 1.0)
IOR_RANGE = (1.0, 3.0)


def code_size(latent: int, coat: bool) -> int:
    """Floats per channel of a material code."""
    return latent + (COAT_PARAMS if coat else 0)


def with_coat(z_body: Tensor, coat: Tensor | tuple[float, float] | None) -> Tensor:
    """Code (..., latent + 2) of body latents (..., latent) under a coat
    (..., 2) or (roughness, ior) (broadcast); None: ``NO_COAT``."""
    c = torch.as_tensor(NO_COAT if coat is None else coat, dtype=z_body.dtype, device=z_body.device)
    return torch.cat([z_body, c.expand(*z_body.shape[:-1], COAT_PARAMS)], -1)


def coat_of(code: Tensor, latent: int) -> Tensor:
    """The coat of codes, clamped to the legal range: (..., 2) (roughness, ior) of codes (..., latent + 2);
    (..., 4), the coat's anisotropy vector after them (``neural.anisotropy``), of codes with an
    anisotropic tail (..., latent + 2 + FRAME_PARAMS)."""
    if code.shape[-1] not in (latent + COAT_PARAMS, latent + COAT_PARAMS + FRAME_PARAMS):
        raise NbrdfError(f"a material code has {latent + COAT_PARAMS} (or {latent + COAT_PARAMS + FRAME_PARAMS} "
                         f"with anisotropy) floats per channel, got {code.shape[-1]}")
    c = code[..., latent:]
    rough_ior = [c[..., 0].clamp(*ROUGHNESS_RANGE), c[..., 1].clamp(*IOR_RANGE)]
    if code.shape[-1] == latent + COAT_PARAMS:
        return torch.stack(rough_ior, -1)
    return torch.stack(rough_ior + [c[..., 2], c[..., 3]], -1)


def has_coat(spec, z: Tensor) -> bool:
    """Whether ``z`` (..., n) is a whole material code of a decoder of ``spec`` (a ``DecoderSpec``) with
    the coat split, isotropic or with its anisotropic tail; False for a bare latent."""
    return bool(spec.coat) and z.shape[-1] in (spec.code, spec.code + FRAME_PARAMS)


def code_coat(spec, z: Tensor) -> tuple[float, float]:
    """The clear coat (roughness, ior) of one material's code (3, 34) for a
    decoder of ``spec`` (a ``DecoderSpec``): ``NO_COAT`` for a bare latent or
    a decoder without the coat split. What the GPU's ``u_coat`` receives."""
    if not has_coat(spec, z):
        return NO_COAT
    r, ior = coat_of(z.reshape(-1, z.shape[-1])[0], spec.latent).tolist()[:2]
    return float(r), float(ior)


def coat_features(coat: Tensor) -> Tensor:
    """Network inputs (..., 3) describing a coat: cube-root roughness (the
    paper's distributions are uniform in it), ior - 1 and the normal-incidence
    reflectance ((ior - 1) / (ior + 1))^2."""
    a = coat[..., 0].clamp(*ROUGHNESS_RANGE)
    eta = coat[..., 1].clamp(*IOR_RANGE)
    return torch.stack([a.pow(1 / 3), eta - 1.0, ((eta - 1.0) / (eta + 1.0)) ** 2], -1)


def _bcast(coat: Tensor, like: Tensor) -> tuple[Tensor, Tensor]:
    coat = torch.as_tensor(coat, dtype=like.dtype, device=like.device)
    return coat[..., 0].clamp(*ROUGHNESS_RANGE), coat[..., 1].clamp(*IOR_RANGE)


def _frame(coat: Tensor, like: Tensor, a: Tensor, *ws: Tensor) -> tuple[Tensor, Tensor | None, list[Tensor]]:
    """(alpha_x, alpha_y or None, directions in the coat's tangent frame) of a coat: an isotropic coat
    (2 floats) keeps its alpha and the directions as they are."""
    coat = torch.as_tensor(coat, dtype=like.dtype, device=like.device)
    if coat.shape[-1] == COAT_PARAMS:
        return a, None, list(ws)
    ax, ay, c, s = coat_alphas(a, coat[..., 2:4])
    return ax, ay, [in_frame(w, c, s) for w in ws]


def coat_eval(coat: Tensor, wi: Tensor, wo: Tensor) -> Tensor:
    """The coat's reflection (...,) in 1/sr (no cosine) at pairs (..., 3);
    coat (..., 2) broadcast against the pairs' batch. Zero unless both
    directions lie above the surface."""
    a, eta = _bcast(coat, wi)
    a, ay, (wi, wo) = _frame(coat, wi, a, wi, wo)
    h = wi + wo
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    F = fresnel_dielectric((wi * h).sum(-1), eta)
    f = (F * ggx_d(h, a, ay) * smith_g1(wi, h, a, ay) * smith_g1(wo, h, a, ay)
         / (4.0 * wi[..., 2] * wo[..., 2]).clamp_min(1e-30))
    up = (wi[..., 2] > 0) & (wo[..., 2] > 0) & (eta > 1.0)
    return torch.where(up, f, torch.zeros_like(f))


def coat_pdf(coat: Tensor, w: Tensor, w_other: Tensor) -> Tensor:
    """Solid-angle density of ``coat_sample(w)`` returning ``w_other``."""
    a, _ = _bcast(coat, w)
    a, ay, (w, w_other) = _frame(coat, w, a, w, w_other)
    h = w + w_other
    h = h / h.norm(dim=-1, keepdim=True).clamp_min(1e-30)
    d = (w * h).sum(-1).abs().clamp_min(1e-30)
    p = vndf_pdf(w, h, a, ay) / (4.0 * d)
    ok = (w[..., 2] > 0) & (w_other[..., 2] > 0)
    return torch.where(ok, p, torch.zeros_like(p))


def coat_sample(coat: Tensor, w: Tensor, u1: Tensor, u2: Tensor) -> Tensor:
    """A direction drawn from the coat's visible-normal reflection lobe
    around ``w`` (may fall below the horizon: a failed sample)."""
    a, _ = _bcast(coat, w)
    coat = torch.as_tensor(coat, dtype=w.dtype, device=w.device)
    if coat.shape[-1] == COAT_PARAMS:
        return reflect(w, sample_vndf(w, a, u1, u2))
    ax, ay, c, s = coat_alphas(a, coat[..., 2:4])
    wf = in_frame(w, c, s)
    return from_tangent_frame(reflect(wf, sample_vndf(wf, ax, u1, u2, ay)), c, s)


def coat_probability(coat: Tensor, w: Tensor) -> Tensor:
    """Share of samples given to the coat's lobe at incidence ``w``: the
    square root of its Fresnel reflectance at the normal, 0.05-0.95, 0 without
    a coat. A heuristic (sampling stays unbiased): the coat is a peak that
    the body's proxy cannot reach, the body holds the rest of the energy."""
    _, eta = _bcast(coat, w)
    F = fresnel_dielectric(w[..., 2].clamp(0.0, 1.0), eta)
    p = F.sqrt().clamp(0.05, 0.95)
    return torch.where(eta > 1.0 + 1e-4, p, torch.zeros_like(p))
