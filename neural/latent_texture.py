"""Latent interpolation and latent textures (SPEC section 6).

A blend of materials is a weighted sum of their latents. A spatially varying
material is a texture of material codes, H x W x 3 x 34 (latents and the
clear coat's parameters, ``neural.coat``), sampled bilinearly; its mip
chain averages 2 x 2 texels per level (an odd edge keeps its last texel), and
a lookup by pixel footprint blends the two nearest levels (trilinear), which
is what removes the aliasing of a minified latent texture.
"""
from __future__ import annotations

from collections.abc import Sequence

import torch

from nbrdf.neural.errors import NbrdfError

Tensor = torch.Tensor


def blend(latents: Sequence[Tensor], weights: Sequence[float]) -> Tensor:
    """sum_k w_k z_k; weights must be finite (they are normalised to sum 1)."""
    if len(latents) != len(weights) or not latents:
        raise NbrdfError(f"blend: {len(latents)} latents and {len(weights)} weights")
    w = torch.as_tensor(list(weights), dtype=torch.float32)
    if not torch.isfinite(w).all() or float(w.sum()) == 0:
        raise NbrdfError("blend: weights must be finite and not sum to 0")
    w = w / w.sum()
    return sum(wk * z for wk, z in zip(w, latents))


def _downsample(level: Tensor) -> Tensor:
    """(H, W, C, L) -> (ceil(H/2), ceil(W/2), C, L) averaging 2 x 2 texels."""
    h, w = level.shape[:2]
    if h % 2:
        level = torch.cat([level, level[-1:]], 0)
    if w % 2:
        level = torch.cat([level, level[:, -1:]], 1)
    return 0.25 * (level[0::2, 0::2] + level[1::2, 0::2] + level[0::2, 1::2] + level[1::2, 1::2])


class LatentTexture:
    """An (H, W, 3, 32) latent texture and its mip chain; uv in [0, 1]^2 with
    v along rows, repeat wrapping (as a tiling material expects)."""

    def __init__(self, texels: Tensor):
        if texels.dim() != 4 or texels.shape[2] != 3 or texels.shape[3] not in (32, 34):
            raise NbrdfError(f"a latent texture is (H, W, 3, 34) (codes: latents and coat), got {tuple(texels.shape)}")
        if not torch.isfinite(texels).all():
            raise NbrdfError("a latent texture holds NaN or infinite values")
        self.levels = [texels.float()]
        while max(self.levels[-1].shape[:2]) > 1:
            self.levels.append(_downsample(self.levels[-1]))

    @property
    def size(self) -> tuple[int, int]:
        return tuple(self.levels[0].shape[:2])  # type: ignore[return-value]

    def bilinear(self, uv: Tensor, level: int = 0) -> Tensor:
        """Codes (N, 3, 34) at uv (N, 2) on one mip level."""
        lv = self.levels[max(0, min(level, len(self.levels) - 1))]
        h, w = lv.shape[:2]
        x = uv[:, 0] * w - 0.5
        y = uv[:, 1] * h - 0.5
        x0, y0 = torch.floor(x), torch.floor(y)
        fx, fy = (x - x0)[:, None, None], (y - y0)[:, None, None]
        x0, y0 = x0.long(), y0.long()
        at = lambda yy, xx: lv[yy % h, xx % w]
        return ((1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1))
                + fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1)))

    def trilinear(self, uv: Tensor, footprint: Tensor | float) -> Tensor:
        """Codes (N, 3, 34) at uv for a pixel footprint in uv units (N,):
        level log2(footprint * size), blended between its two neighbours."""
        fp = torch.as_tensor(footprint, dtype=torch.float32).expand(uv.shape[0])
        lod = torch.log2((fp * max(self.size)).clamp_min(1e-8)).clamp(0, len(self.levels) - 1)
        lo = torch.floor(lod).long()
        t = (lod - lo)[:, None, None]
        out = torch.empty(uv.shape[0], 3, self.levels[0].shape[-1])
        for k in torch.unique(lo).tolist():
            sel = lo == k
            a = self.bilinear(uv[sel], k)
            b = self.bilinear(uv[sel], k + 1) if k + 1 < len(self.levels) else a
            out[sel] = (1 - t[sel]) * a + t[sel] * b
        return out
