"""Layering network (SPEC section 6): per channel (z_top, z_bottom, albedo,
sigma_t) -> the latent of the stack "top interface over a medium slab over
bottom". Three or more layers apply it recursively from the bottom up, the
bottom latent then being itself a layered latent.

sigma_t enters as the slab's normal transmittance exp(-sigma_t) and its
square as well as linearly, so thin and thick slabs are both well resolved
over the whole legal range [0, 5].
"""
from __future__ import annotations

import torch
from torch import nn

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.nets import MLP, MLPSpec

Tensor = torch.Tensor
LATENT = 32
MEDIUM_FEATURES = 5


def medium_features(albedo: Tensor, sigma_t: Tensor) -> Tensor:
    """(N, 5) inputs describing the slab."""
    return torch.stack([albedo, 1 - (1 - albedo).clamp_min(0).sqrt(), sigma_t / 5, torch.exp(-sigma_t),
                        torch.exp(-2 * sigma_t)], -1)


def layering_spec(width: int = 256, depth: int = 3) -> MLPSpec:
    return MLPSpec(inputs=2 * LATENT + MEDIUM_FEATURES, outputs=LATENT, width=width, depth=depth)


class LayeringNet(nn.Module):
    """z = bottom + MLP(top, bottom, medium): the residual form starts from
    "the medium hides nothing", which is right for a clear coat."""

    def __init__(self, spec: MLPSpec | None = None):
        super().__init__()
        self.spec = spec or layering_spec()
        self.mlp = MLP(self.spec)

    def forward(self, z_top: Tensor, z_bottom: Tensor, albedo: Tensor, sigma_t: Tensor) -> Tensor:
        """Latents (N, 32) of N stacks; albedo and sigma_t (N,) or scalars."""
        n = z_top.shape[0]
        if z_top.shape != (n, LATENT) or z_bottom.shape != (n, LATENT):
            raise NbrdfError(f"layering: latents must be (N, {LATENT}) and alike, got {tuple(z_top.shape)} "
                             f"and {tuple(z_bottom.shape)}")
        albedo = torch.as_tensor(albedo, dtype=z_top.dtype).expand(n)
        sigma_t = torch.as_tensor(sigma_t, dtype=z_top.dtype).expand(n)
        for name, v, hi in (("albedo", albedo, 1.0), ("sigma_t", sigma_t, 5.0)):
            if not torch.isfinite(v).all() or (v < 0).any() or (v > hi).any():
                raise NbrdfError(f"layering: {name} must lie in [0, {hi:g}]")
        x = torch.cat([z_top, z_bottom, medium_features(albedo, sigma_t)], -1)
        return z_bottom + self.mlp(x)
