"""Texture-mapped materials (SPEC section 4) -> latent textures (SPEC section 6).

Every texture-mapped parameter is read from its image, all maps are brought
to one resolution, and the leaf encoders and the layering network run once
per texel (in chunks, batched) exactly as for a uniform material. The result
is a ``LatentTexture`` whose mip chain is the paper's latent mip-mapping.

Texel rows follow OpenGL: row 0 is v = 0, the bottom of the image file, so an
OBJ/glTF mesh's uv coordinates address the maps the way an artist painted them.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import torch
import torch.nn.functional as F

from nbrdf.neural.anisotropy import require_isotropic
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.latent_texture import LatentTexture
from nbrdf.neural.material import Material, TextureRef

Tensor = torch.Tensor
MAX_SIZE = 2048
_LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)


def read_texels(path: str | Path) -> np.ndarray:
    """An 8/16-bit or float image as float32 (H, W, k), row 0 = v 0 (the file's
    bottom row); integer texels scale to [0, 1]."""
    try:
        img = np.asarray(iio.imread(path))
    except Exception as e:  # noqa: BLE001 - any reader failure is a bad file
        raise NbrdfError(f"{path}: cannot read the texture ({str(e).splitlines()[0] if str(e) else type(e).__name__})") from None
    if img.dtype == np.uint8:
        x = img.astype(np.float32) / 255.0
    elif img.dtype == np.uint16:
        x = img.astype(np.float32) / 65535.0
    elif img.dtype.kind == "f":
        x = img.astype(np.float32)
    else:
        raise NbrdfError(f"{path}: unsupported texel type {img.dtype}")
    if x.ndim == 2:
        x = x[..., None]
    if x.ndim != 3 or x.shape[2] > 4:
        raise NbrdfError(f"{path}: expected a 2D image, got shape {img.shape}")
    if not np.isfinite(x).all():
        raise NbrdfError(f"{path}: the texture holds NaN or infinite values")
    return np.ascontiguousarray(x[::-1])


def read_map(path: str | Path, channel: str) -> np.ndarray:
    """One channel ("l": luminance) of an image as float32 (H, W) in [0, 1], row 0 = v 0."""
    x = read_texels(path)
    k = x.shape[2]
    if channel == "l":
        v = x[..., 0] if k < 3 else x[..., :3] @ _LUMA
    else:
        idx = "rgba".index(channel)
        if idx >= k:
            if k in (1, 2) and idx < 3:  # grey (+alpha): r, g, b are the grey value
                idx = 0
            else:
                raise NbrdfError(f"{path}: channel {channel!r} requested but the image has {k} channel(s)")
        v = x[..., idx]
    return np.ascontiguousarray(np.clip(v, 0.0, 1.0))


class TextureValues:
    """Parameter values per texel: a ``ParamValues`` for ``NeuralModel.stack_latents``
    that returns (P, 3) tensors, P = H x W texels (uniform values broadcast)."""

    def __init__(self, material: Material, size: tuple[int, int] | None = None):
        refs = [ref for _, ref in material.textures()]
        if not refs:
            raise NbrdfError(f"{material.name}: no texture-mapped parameter (a uniform material needs no latent texture)")
        self._maps: dict[tuple[str, str], np.ndarray] = {}
        for ref in refs:
            key = (str(ref.resolved), ref.channel)
            if key not in self._maps:
                self._maps[key] = read_map(ref.resolved, ref.channel)
        if size is None:
            size = (max(m.shape[0] for m in self._maps.values()), max(m.shape[1] for m in self._maps.values()))
        h, w = size
        if not (1 <= h <= MAX_SIZE and 1 <= w <= MAX_SIZE):
            raise NbrdfError(f"latent texture size {h}x{w} is outside 1..{MAX_SIZE} per side")
        self.size = (h, w)
        self._cache: dict[tuple[str, str], Tensor] = {}

    @property
    def count(self) -> int:
        return self.size[0] * self.size[1]

    def _texels(self, ref: TextureRef, sl: slice) -> Tensor:
        key = (str(ref.resolved), ref.channel)
        if key not in self._cache:
            m = torch.from_numpy(self._maps[key])
            if tuple(m.shape) != self.size:
                m = F.interpolate(m[None, None], size=self.size, mode="bilinear", align_corners=False)[0, 0]
            self._cache[key] = m.reshape(-1)
        lo, hi = ref.range
        return lo + self._cache[key][sl] * (hi - lo)

    def __call__(self, v, place: str, sl: slice = slice(None)) -> Tensor:
        """(P, 3) values of the texels ``sl`` (a uniform value stays (1, 3))."""
        if isinstance(v, TextureRef):
            return self._texels(v, sl)[:, None].expand(-1, 3)
        if isinstance(v, tuple) and any(isinstance(x, TextureRef) for x in v):
            n = len(range(*sl.indices(self.count)))
            cols = [self._texels(x, sl) if isinstance(x, TextureRef) else torch.full((n,), float(x)) for x in v]
            return torch.stack(cols, -1)
        return torch.tensor([Material.rgb(v)], dtype=torch.float32)


def latent_texture(model, material: Material, size: tuple[int, int] | None = None, chunk: int = 16384,
                   progress: Callable[[int, int], None] | None = None) -> LatentTexture:
    """The (H, W, 3, 34) code texture of a texture-mapped material (a textured
    coat roughness or ior becomes a texture channel of the codes), with its
    mip chain; the networks run ``chunk`` texels at a time (``progress(done, total)``
    after each)."""
    require_isotropic(material, "latent textures")
    values = TextureValues(material, size)
    h, w = values.size
    out = torch.empty(values.count, 3, model.decoder.spec.code)
    for start in range(0, values.count, chunk):
        sl = slice(start, min(start + chunk, values.count))
        out[sl] = model.stack_latents(material, lambda v, place: values(v, place, sl))
        if progress is not None:
            progress(sl.stop, values.count)
    return LatentTexture(out.reshape(h, w, 3, -1))
