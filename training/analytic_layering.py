"""A simple analytic layering model, the baseline the layering network must
beat (in the style of Weidlich and Wilkie 2007).

Each interface contributes its own rough reflection; what lies below is seen
through it along the smoothly refracted directions, scaled by the Fresnel
transmittances on the way in and out, the 1 / eta^2 of the solid-angle
compression, and the slab's extinction along both refracted paths
exp(-sigma_t (1 / cos theta_i' + 1 / cos theta_o')). Scattering in the medium
and inter-reflections between layers are ignored: that is what a layered
latent learns from the Monte Carlo ground truth and this model cannot.
"""
from __future__ import annotations

import torch

from nbrdf.neural.anisotropy import require_isotropic
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layer_kinds import PARAMETRIC_BASES
from nbrdf.neural.material import Material
from nbrdf.neural.microfacet import fresnel_dielectric
from nbrdf.training.analytic import GGXDielectric
from nbrdf.training.reference import single_layer_eval

Tensor = torch.Tensor


def _refract_down(w: Tensor, eta: float) -> Tensor:
    """Smooth refraction of an upper-hemisphere direction into a denser layer
    (kept pointing up, as seen from inside)."""
    xy = w[:, :2] / eta
    z = (1 - (xy * xy).sum(-1)).clamp_min(1e-12).sqrt()
    return torch.cat([xy, z[:, None]], -1)


def _stack_eval(interfaces, base, wi: Tensor, wo: Tensor) -> Tensor:
    if not interfaces:
        return single_layer_eval(base, wi, wo)
    (iface, med), rest = interfaces[0], interfaces[1:]
    eta = float(iface.ior)
    top = GGXDielectric(float(iface.roughness), eta).eval(wi, wo)[:, None]
    ti = 1 - fresnel_dielectric(wi[:, 2], torch.tensor(eta, dtype=wi.dtype))
    to = 1 - fresnel_dielectric(wo[:, 2], torch.tensor(eta, dtype=wi.dtype))
    wi_in, wo_in = _refract_down(wi, eta), _refract_down(wo, eta)
    sigma = torch.tensor(Material.rgb(med.sigma_t) if med is not None else (0.0, 0.0, 0.0), dtype=wi.dtype)
    atten = torch.exp(-sigma[None, :] * (1 / wi_in[:, 2] + 1 / wo_in[:, 2])[:, None])
    below = _stack_eval(rest, base, wi_in, wo_in)
    return top + (ti * to / (eta * eta))[:, None] * atten * below


def check_analytic(material: Material) -> None:
    """Raises unless the model covers the material (uniform layers over a
    conductor, diffuse or dielectric base)."""
    if material.is_textured:
        raise NbrdfError(f"{material.textures()[0][0]}: texture-mapped; the analytic model needs uniform layers")
    if material.base.type not in PARAMETRIC_BASES:
        raise NbrdfError(f"a {material.base.type} base has no analytic layering model")
    require_isotropic(material, "the analytic layering model")


def analytic_layered_eval(material: Material, wi: Tensor, wo: Tensor) -> Tensor:
    """RGB values (N, 3) of the analytic layering model; 0 below the horizon."""
    check_analytic(material)
    up = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    f = _stack_eval(material.interfaces, material.base, wi, wo)
    return torch.where(up, f, torch.zeros_like(f))
