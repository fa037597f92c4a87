"""Texture-mapped nbrdf materials in Mitsuba: per-hit lookups by the hit's uv.

``LatentTextureKernel``: the neural side. A latent texture (``neural.svbrdf``)
is kept as its decoder share (the latent's affine part of layer 1, per
channel) and its clear coat per texel, on every mip level, in one flat
buffer; a lookup is bilinear on the two mip levels around the hit's level of
detail and blends them (trilinear), as ``LatentTexture.trilinear`` and the
previewer's share texture do. The share is affine in the latent, so
filtering shares is filtering latents.

``ParamMaps``: the Monte Carlo side. The material's parameter maps sampled
bilinearly at the hits' uvs (finest level: the ground truth is not filtered),
as the ``ParamValues`` that ``neural.stack.material_stack`` turns into one
layer stack per hit.

uv follows Mitsuba (``mip.texture_rows_uv``); wrapping repeats.
"""
from __future__ import annotations

import numpy as np
import torch

from nbrdf.mitsuba.mip import MipBuffer, texture_rows_uv
from nbrdf.neural.material import Material, TextureRef
from nbrdf.neural.svbrdf import read_map


class LatentTextureKernel:
    """Per-texel decoder shares (3 x width) and coats (roughness, ior) of a
    latent texture's mip chain, looked up per lane (``MipBuffer``)."""

    def __init__(self, decoder, texture, coat_split: bool, no_coat: tuple[float, float]):
        """``decoder``: the torch ``Decoder``; ``texture``: a ``LatentTexture``
        of codes (H, W, 3, 34); ``coat_split``: whether its codes carry a
        coat (else ``no_coat`` everywhere)."""
        spec = decoder.spec
        self.width = spec.width
        levels = []
        with torch.no_grad():
            for lv in texture.levels:
                h, w = lv.shape[:2]
                share = decoder.latent_share(lv.float()).reshape(h, w, 3 * self.width)
                if coat_split:
                    coat = lv[:, :, 0, spec.latent:spec.latent + 2].float()
                else:
                    coat = torch.tensor(no_coat, dtype=torch.float32).expand(h, w, 2)
                levels.append(torch.cat([share, coat], -1).numpy())
        self.texels = MipBuffer(levels)
        self.stride = self.texels.stride
        self.levels = self.texels.levels
        self.size = tuple(texture.size)

    def lookup(self, uv, lod=None):
        """(shares [3][width] per lane, coat roughness, coat ior (unclamped))
        at Mitsuba uv (``MipBuffer.lookup``)."""
        out = self.texels.lookup(uv, lod)
        shares = [out[ch * self.width:(ch + 1) * self.width] for ch in range(3)]
        return shares, out[3 * self.width], out[3 * self.width + 1]


class ParamMaps:
    """A texture-mapped material's parameter maps, sampled at query uvs: call
    ``at(uv)`` (N, 2 Mitsuba uv) to get the ``ParamValues`` of those N hits."""

    def __init__(self, material: Material):
        self._maps: dict[tuple[str, str], np.ndarray] = {}
        for _, ref in material.textures():
            key = (str(ref.resolved), ref.channel)
            if key not in self._maps:
                self._maps[key] = read_map(ref.resolved, ref.channel)  # row 0 = the image's bottom

    def _sample(self, ref: TextureRef, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        m = self._maps[(str(ref.resolved), ref.channel)]
        h, w = m.shape
        x = u * w - 0.5
        y = v * h - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
        at = lambda yy, xx: m[yy % h, xx % w]
        val = ((1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1))
               + fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1)))
        lo, hi = ref.range
        return lo + val * (hi - lo)

    def at(self, uv: np.ndarray):
        """The ``ParamValues`` (value, place) -> (N, 3) of the hits at ``uv`` (N, 2)."""
        u, v = texture_rows_uv(uv[:, 0].astype(np.float64), uv[:, 1].astype(np.float64))
        u, v = u - np.floor(u), v - np.floor(v)
        n = uv.shape[0]

        def values(val, place: str) -> torch.Tensor:
            if isinstance(val, TextureRef):
                return torch.from_numpy(np.repeat(self._sample(val, u, v)[:, None], 3, 1))
            if isinstance(val, tuple) and any(isinstance(x, TextureRef) for x in val):
                cols = [self._sample(x, u, v) if isinstance(x, TextureRef) else np.full(n, float(x)) for x in val]
                return torch.from_numpy(np.stack(cols, -1))
            return torch.tensor([Material.rgb(val)], dtype=torch.float64)

        return values


def sharpest_top_roughness(material: Material) -> float:
    """The top interface's roughness, or the low end of its map's range when
    texture-mapped (the sampler's lobe must be at least as sharp as any texel's)."""
    r = getattr(material.layers[0], "roughness", None)
    if isinstance(r, TextureRef):
        return float(min(r.range))
    return float(r) if isinstance(r, (int, float)) else 1.0


