"""Texel lookups per hit in Dr.Jit, shared by every texture the plugins read
(a latent texture's shares, a parametric table's maps, a normal map): a mip
chain in one flat buffer, looked up bilinearly on one level or trilinearly
between two by the hit's ray cone.

uv follows Mitsuba (its bitmap texture): v = 0 is the image's top row, so a
map painted upright appears upright (an equirectangular map on a sphere has
its north at the top). Wrapping repeats.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np


def texture_rows_uv(u, v):
    """Mitsuba's (u, v) -> the latent texture's (u, v) (row 0 at the image's bottom)."""
    return u, 1.0 - v


def level_of_detail(si, pixel_angle: float, size: tuple[int, int]):
    """The mip level of a hit: its footprint, the ray cone of ``pixel_angle``
    radians at the hit distance ``si.t``, in uv units (the larger of the u
    and v extents, from ``si.dp_du``/``si.dp_dv``) times the texture's larger
    side, in log2. None (the finest level only) with ``pixel_angle`` 0."""
    if pixel_angle <= 0:
        return None
    world = dr.select(dr.isfinite(si.t), si.t, 0.0) * pixel_angle
    fu = world / dr.maximum(dr.norm(si.dp_du), 1e-12)
    fv = world / dr.maximum(dr.norm(si.dp_dv), 1e-12)
    return dr.log2(dr.maximum(dr.maximum(fu, fv) * max(size), 1e-8))


def mip_chain(image: np.ndarray) -> list[np.ndarray]:
    """(H, W, C) -> its mip levels down to 1 x 1, each the 2 x 2 mean of the
    one above (an odd side repeats its last row or column), as
    ``neural.latent_texture`` builds a latent texture's chain."""
    levels = [np.ascontiguousarray(image, np.float32)]
    while max(levels[-1].shape[:2]) > 1:
        lv = levels[-1]
        if lv.shape[0] % 2:
            lv = np.concatenate([lv, lv[-1:]], 0)
        if lv.shape[1] % 2:
            lv = np.concatenate([lv, lv[:, -1:]], 1)
        levels.append(0.25 * (lv[0::2, 0::2] + lv[1::2, 0::2] + lv[0::2, 1::2] + lv[1::2, 1::2]))
    return levels


class MipBuffer:
    """A mip chain of (H, W, stride) float texels in one flat ``mi.Float``
    buffer, looked up per lane at Mitsuba uv (repeat wrapping): bilinear on
    one level, or trilinear between the two levels around a per-lane level
    of detail (their offsets and sizes gathered per lane from three small
    tables, so a lookup touches two levels whatever the chain's length)."""

    def __init__(self, levels: list[np.ndarray]):
        """``levels``: (H, W, stride) arrays, finest first, row 0 = v 0 (the image's bottom)."""
        self.stride = int(levels[0].shape[-1])
        chunks, self.levels = [], []
        offset = 0
        for lv in levels:
            h, w = lv.shape[:2]
            chunks.append(np.ascontiguousarray(lv, np.float32).reshape(-1))
            self.levels.append((offset, h, w))
            offset += h * w * self.stride
        self.buffer = mi.Float(np.concatenate(chunks))
        #: per level: offset, height, width (gathered per lane by level index)
        self._tables = tuple(mi.UInt32([lv[k] for lv in self.levels]) for k in range(3))
        self.size = (self.levels[0][1], self.levels[0][2])

    def _bilinear(self, level, u, v, weight, out: list) -> None:
        """Adds ``weight`` x the bilinear lookup on ``level`` (an int, or a
        per-lane ``mi.UInt32``) to ``out`` (stride floats per lane)."""
        if isinstance(level, int):
            off, h, w = (mi.UInt32(x) for x in self.levels[level])
        else:
            off, h, w = (dr.gather(mi.UInt32, t, level) for t in self._tables)
        # sizes as floats, at least 1: lanes a call masks off gather 0, and an integer modulo by 0 traps
        hf, wf = dr.maximum(mi.Float(h), 1.0), dr.maximum(mi.Float(w), 1.0)
        x = u * wf - 0.5
        y = v * hf - 0.5
        x0, y0 = dr.floor(x), dr.floor(y)
        fx, fy = x - x0, y - y0

        def wrap(i, n):
            """i mod n for whole-number floats (repeat wrapping) as an index."""
            return mi.UInt32(dr.clip(i - n * dr.floor(i / n), 0.0, n - 1.0))

        taps = []
        for dy, wy in ((0, 1.0 - fy), (1, fy)):
            for dx, wx in ((0, 1.0 - fx), (1, fx)):
                idx = off + (wrap(y0 + dy, hf) * w + wrap(x0 + dx, wf)) * self.stride
                taps.append((idx, weight * wy * wx))
        for c in range(self.stride):
            acc = out[c]
            for idx, wt in taps:
                acc = dr.fma(dr.gather(mi.Float, self.buffer, idx + c), wt, acc)
            out[c] = acc

    def lookup(self, uv, lod=None) -> list:
        """``stride`` floats per lane at Mitsuba uv: trilinear between the two
        mip levels around ``lod``, the finest level alone when ``lod`` is None."""
        u, v = texture_rows_uv(uv.x, uv.y)
        # lanes a call masks off may hold anything: a NaN index must not reach a gather
        u = dr.select(dr.isfinite(u), u - dr.floor(u), 0.0)
        v = dr.select(dr.isfinite(v), v - dr.floor(v), 0.0)
        out = [mi.Float(0.0) for _ in range(self.stride)]
        n = len(self.levels)
        if lod is None or n == 1:
            self._bilinear(0, u, v, mi.Float(1.0), out)
        else:
            lod = dr.clip(dr.select(dr.isfinite(lod), lod, 0.0), 0.0, float(n - 1))
            lo = dr.floor(lod)
            t = lod - lo
            lo_i = mi.UInt32(lo)
            self._bilinear(lo_i, u, v, 1.0 - t, out)
            self._bilinear(dr.minimum(lo_i + 1, n - 1), u, v, t, out)
        return out
