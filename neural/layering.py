"""Layering network (SPEC section 6): per channel (top interface, bottom
code, albedo, sigma_t) -> the code of the stack "top interface over a medium
slab over bottom". Three or more layers apply it recursively from the bottom
up, the bottom code then being itself a layered code.

Under the coat split (``neural.coat``) every code is a body latent plus a
clear coat. The top of a layering is always a dielectric interface, so it
enters by its two parameters (they are the new code's coat, exact); the
network predicts the new body, the light that entered through that
interface, from the bottom's body latent and coat and the slab.

sigma_t enters as the slab's normal transmittance exp(-sigma_t) and its
square as well as linearly, so thin and thick slabs are both well resolved
over the whole legal range [0, 5].
"""
from __future__ import annotations

import torch
from torch import nn

from nbrdf.neural.coat import COAT_PARAMS, coat_features, with_coat
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.nets import MLP, MLPSpec

Tensor = torch.Tensor
LATENT = 32
CODE = LATENT + COAT_PARAMS
MEDIUM_FEATURES = 5
COAT_FEATURES = 3


def medium_features(albedo: Tensor, sigma_t: Tensor) -> Tensor:
    """(N, 5) inputs describing the slab."""
    return torch.stack([albedo, 1 - (1 - albedo).clamp_min(0).sqrt(), sigma_t / 5, torch.exp(-sigma_t),
                        torch.exp(-2 * sigma_t)], -1)


def layering_spec(width: int = 256, depth: int = 3) -> MLPSpec:
    return MLPSpec(inputs=COAT_FEATURES + LATENT + COAT_FEATURES + MEDIUM_FEATURES, outputs=LATENT, width=width,
                   depth=depth)


class LayeringNet(nn.Module):
    """body = bottom body + MLP(top, bottom, medium), coat = top: the residual
    form starts from "the medium hides nothing", right for a clear coat."""

    def __init__(self, spec: MLPSpec | None = None):
        super().__init__()
        self.spec = spec or layering_spec()
        self.mlp = MLP(self.spec)

    def forward(self, top: Tensor, bottom: Tensor, albedo: Tensor, sigma_t: Tensor) -> Tensor:
        """Codes (N, 34) of N stacks from the top interfaces' (roughness, ior)
        (N, 2), the bottom codes (N, 34), albedo and sigma_t (N,) or scalars."""
        n = bottom.shape[0]
        if top.shape != (n, COAT_PARAMS) or bottom.shape != (n, CODE):
            raise NbrdfError(f"layering: expected top interfaces (N, {COAT_PARAMS}) and bottom codes (N, {CODE}), "
                             f"got {tuple(top.shape)} and {tuple(bottom.shape)}")
        albedo = torch.as_tensor(albedo, dtype=bottom.dtype).expand(n)
        sigma_t = torch.as_tensor(sigma_t, dtype=bottom.dtype).expand(n)
        for name, v, hi in (("albedo", albedo, 1.0), ("sigma_t", sigma_t, 5.0)):
            if not torch.isfinite(v).all() or (v < 0).any() or (v > hi).any():
                raise NbrdfError(f"layering: {name} must lie in [0, {hi:g}]")
        z_b, c_b = bottom[:, :LATENT], bottom[:, LATENT:]
        x = torch.cat([coat_features(top), z_b, coat_features(c_b), medium_features(albedo, sigma_t)], -1)
        return with_coat(z_b + self.mlp(x), top)
