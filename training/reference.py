"""Ground truth of a material (SPEC section 8, ``--method reference``).

Single interfaces are evaluated in closed form (standard error 0); layered
stacks by the Monte Carlo simulator, all three channels on shared paths.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.geometry import incidence, lobe_grid
from nbrdf.neural.layer_kinds import PARAMETRIC_BASES
from nbrdf.neural.material import Conductor, Dielectric, Diffuse, LatentBase, Material, Measured, Medium
from nbrdf.neural.metrics import noise_psnr
from nbrdf.neural.mix import material_mix, weighted_with_error
from nbrdf.neural.stack import Stack, material_stack
from nbrdf.training.analytic import GGXConductor, GGXDielectric, Lambertian
from nbrdf.training.layered import SimStats, StackParams, simulate
from nbrdf.training.merl import MerlBRDF

Tensor = torch.Tensor

#: Paths traced at once; bounds memory (about 200 bytes a lane in float32).
MAX_LANES = 1 << 21


def _rgb(v) -> Tensor:
    return torch.tensor(Material.rgb(v), dtype=torch.float64)


def check_uniform(material: Material) -> None:
    """One line for a texture-mapped material: a reference is for uniform materials (or one texel)."""
    if material.is_textured:
        place = material.textures()[0][0]
        raise NbrdfError(f"{place}: a texture-mapped parameter has no single reference; "
                         "evaluate a uniform material (or one texel of it)")


def simulator_params(stack: Stack) -> StackParams:
    """A batched stack (``neural.stack``) as the simulator's parameters."""
    if stack.layers == 0:
        raise NbrdfError("a single-layer material needs no simulation")
    if stack.base not in PARAMETRIC_BASES:
        raise NbrdfError(f"a {stack.base} base has no Monte Carlo reference under other layers")
    kw = {k: v for k, v in stack.tensors().items() if k.startswith("base_")}
    return StackParams(roughness=stack.roughness, ior=stack.ior, albedo=stack.albedo, sigma_t=stack.sigma_t,
                       base=stack.base, anisotropy=stack.anisotropy, rotation=stack.rotation, **kw)


def stack_params(material: Material, n: int = 1) -> StackParams:
    """The material's layer stack as simulator parameters, 3 channels, n copies."""
    check_uniform(material)
    if not material.interfaces:
        raise NbrdfError("a single-layer material needs no simulation")
    base = material.base
    if isinstance(base, (LatentBase, Measured)):
        raise NbrdfError(f"layers[{len(material.layers) - 1}]: a {type(base).__name__.lower()} base "
                         "has no Monte Carlo reference under other layers")
    return simulator_params(material_stack(material).expand(n))


def single_layer_eval(layer, wi: Tensor, wo: Tensor, rotation: float = 0.0) -> Tensor:
    """Closed-form RGB values (N, 3) of a lone conductor, dielectric or diffuse layer; ``rotation``: the
    material's anisotropy_rotation (degrees) for an anisotropic layer."""
    wi3 = wi[:, None, :].expand(-1, 3, -1)
    wo3 = wo[:, None, :].expand(-1, 3, -1)
    up = ((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None]
    if isinstance(layer, Conductor):
        f = GGXConductor(layer.roughness, _rgb(layer.r0).to(wi.dtype), _rgb(layer.f82_tint).to(wi.dtype),
                         layer.anisotropy, rotation).eval(wi3, wo3)
    elif isinstance(layer, Dielectric):
        f = GGXDielectric(layer.roughness, layer.ior, layer.anisotropy, rotation).eval(wi, wo)[:, None].expand(-1, 3)
    elif isinstance(layer, Diffuse):
        f = Lambertian(_rgb(layer.albedo).to(wi.dtype)).eval(wi3, wo3)
    else:
        raise TypeError(type(layer))
    return torch.where(up, f, torch.zeros_like(f))


def reference_eval(material: Material, wi: Tensor, wo: Tensor, spp: int = 256, seed: int = 0, *,
                   dtype: torch.dtype = torch.float32, stats: SimStats | None = None,
                   progress: Callable[[int], None] | None = None,
                   top_reflection: bool = True) -> tuple[Tensor, Tensor]:
    """Reference f(wi, wo) (N, 3) and its standard error (N, 3) for N pairs.
    Pairs with a direction below the horizon give 0 (the BRDF's support).
    ``top_reflection=False`` (stacks only): the light that entered the stack
    alone, without the top interface's closed-form single reflection (the
    body of ``neural.coat``'s split)."""
    check_uniform(material)
    wi = wi.to(dtype)
    wo = wo.to(dtype)
    n = wi.shape[0]
    base = material.base
    if isinstance(base, Medium):  # the parser forbids it; guard all the same
        raise NbrdfError("a medium cannot be the base")
    if not material.interfaces:
        if isinstance(base, Measured):
            f = MerlBRDF.load(base.resolved).eval(wi, wo)
        elif isinstance(base, LatentBase):
            raise NbrdfError("layers[0]: a latent base has no reference; use --method neural")
        else:
            f = single_layer_eval(base, wi, wo, material.anisotropy_rotation)
        return f.to(dtype), torch.zeros(n, 3, dtype=dtype)
    up = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    mean = torch.zeros(n, 3, dtype=dtype)
    err = torch.zeros(n, 3, dtype=dtype)
    idx = up.nonzero().squeeze(-1)
    chunk = max(1, MAX_LANES // max(spp, 1))
    stack_params(material, 1)  # a stack the simulator cannot take fails here, even with no pair above the horizon
    for k, start in enumerate(range(0, idx.numel(), chunk)):
        sel = idx[start:start + chunk]
        sp = stack_params(material, sel.numel())
        m, e = simulate(sp, wi[sel], wo[sel], spp=spp, seed=seed * 1_000_003 + k, dtype=dtype, stats=stats,
                        include_top_reflection=top_reflection)
        mean[sel], err[sel] = m, e
        if progress is not None:
            progress(sel.numel())
    return mean, err


def mix_reference_eval(material: Material, wi: Tensor, wo: Tensor, spp: int = 256, seed: int = 0,
                       **kw) -> tuple[Tensor, Tensor]:
    """``reference_eval`` of what the material shows: an OpenPBR mix (``neural.mix``) is its components'
    references weighted, their standard errors combined (the same paths per component), where
    ``reference_eval`` itself walks the material's own layers (its largest component) as a code fitted
    to them needs. ``progress`` counts each pair once."""
    parts = material_mix(material)
    if len(parts) == 1:
        return reference_eval(material, wi, wo, spp, seed, **kw)
    progress = kw.pop("progress", None)
    mean, err = weighted_with_error(
        (w, reference_eval(c, wi, wo, spp, seed, progress=progress if k == len(parts) - 1 else None, **kw))
        for k, (w, c) in enumerate(parts))
    assert err is not None  # the walk's estimates carry their errors
    return mean, err


def converged_lobe(material: Material, theta_i_deg: float, target_noise_psnr: float = 50.0,
                   start_spp: int = 64, max_spp: int = 1 << 16, seed: int = 0):
    """A reference lobe image refined until its own noise PSNR reaches the
    target. Returns (image, stderr image, total spp). Rounds double the paths
    and are pooled by their path counts."""
    wo, mask = lobe_grid()
    d = wo[mask]
    wi = incidence(theta_i_deg).expand(d.shape[0], 3)
    total, s1, var = 0, None, None
    spp, k = start_spp, 0
    while True:
        m, e = reference_eval(material, wi, d, spp=spp, seed=seed + 7919 * k)
        m, e = m.double() * d[:, 2:3].double(), e.double() * d[:, 2:3].double()
        s1 = m * spp if s1 is None else s1 + m * spp
        var = (e * spp) ** 2 if var is None else var + (e * spp) ** 2
        total += spp
        img = torch.zeros(64, 64, 3, dtype=torch.float64)
        se = torch.zeros_like(img)
        img[mask], se[mask] = s1 / total, var.sqrt() / total
        img_np, se_np = img.numpy().astype(np.float32), se.numpy().astype(np.float32)
        if noise_psnr(img_np, se_np) >= target_noise_psnr or total >= max_spp:
            return img_np, se_np, total
        spp, k = total, k + 1  # double the total each round
