"""The resampling target of the per-pixel decoder's lit pass: the body baked into a small table.

The decoder's lit pass resamples the body's environment light (lit_shade.glsl
``ris_body_sample``): cheap candidate directions are weighted by a target and
the decoder runs at the one kept. The estimate stays the decoder's (unbiased for
any target positive where the integrand is); only its noise depends on how
closely the target follows the body times the lighting. The lobe sampler's proxy
pdf never sees the real body; the body baked into a small table (the decoder
over a grid, neural/body_table.py) does, at one texture fetch per candidate
(docs/decisions/095). ``BodyGuides`` bakes that table once per decoder and
latent and keeps the last few (the window, its reference and a glTF file's
parts draw several materials). A latent texture has no single body: its draws
keep the proxy target.
"""
from __future__ import annotations

import time
from collections import OrderedDict

import moderngl
import torch

from nbrdf.neural.body_table import TableSize
from nbrdf.viewer.gpu.body_table_gpu import BodyTables, table_texture
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf

#: The target's table. Coarser than the window's interactive body table (32 x 16 x 8): the
#: target need not be exact, and a bake per edit costs a CPU decoder pass over its nodes.
GUIDE = TableSize(24, 12, 6)


class BodyGuides:
    """The resampling-target tables of uniform neural materials, by decoder and latent."""

    def __init__(self, ctx: moderngl.Context, size: TableSize = GUIDE, keep: int = 8):
        self.ctx = ctx
        self.size = size.check()
        self.keep = max(1, keep)
        self._baker = BodyTables(ctx)
        self._tex: OrderedDict[tuple[int, bytes], tuple[object, moderngl.Texture]] = OrderedDict()
        self.bake_ms: float = 0.0
        """The last bake's milliseconds (decoder pass and upload)."""

    def texture(self, brdf: GpuBrdf) -> moderngl.Texture | None:
        """The table of ``brdf``'s body (a NEURAL ``GpuBrdf``: the decoder at a uniform,
        finite latent), baked on first use; None for other kinds (no single body)."""
        if brdf.kind != BrdfKind.NEURAL or brdf.latent is None or brdf.decoder is None:
            return None
        z = brdf.latent.detach().float().cpu()
        if not torch.isfinite(z).all():
            return None
        dec = brdf.decoder.dec
        key = (id(dec), z.numpy().tobytes())
        hit = self._tex.get(key)
        if hit is not None and hit[0] is dec:
            self._tex.move_to_end(key)
            return hit[1]
        t0 = time.perf_counter()
        values = self._baker.bake(dec, z, self.size)
        tex = table_texture(self.ctx, self.size)
        tex.write(values.numpy().astype("f4").tobytes())
        if hit is not None:
            hit[1].release()
        self._tex[key] = (dec, tex)
        while len(self._tex) > self.keep:
            self._tex.popitem(last=False)[1][1].release()
        self.bake_ms = (time.perf_counter() - t0) * 1000.0
        return tex

    def release(self) -> None:
        for _, tex in self._tex.values():
            tex.release()
        self._tex.clear()
        self._baker.release()


__all__ = ["GUIDE", "BodyGuides"]
