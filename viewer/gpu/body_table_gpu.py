"""A uniform material's baked body table on the GPU.

``BodyTables.brdf`` turns a NEURAL ``GpuBrdf`` into a TABLE one: the body
baked on the CPU (neural/body_table.py, one batched torch decoder pass over
the table's nodes) and written into a float 3D texture, the coat unchanged
(closed form in the shader). ``BodyTables.belcour`` does the same for
Belcour's model (its body from the torch model, ``belcour_gpu.bake_body``).
The direction features of the nodes and their part of the decoder's first
layer do not depend on the material, so they are computed once per table
size; an edit then costs the decoder's hidden layers over the nodes. One
texture per size (and ordering) is kept and rewritten per edit.
"""
from __future__ import annotations

import time
from dataclasses import replace

import moderngl
import torch

from nbrdf.neural.body_table import TableSize, table_directions
from nbrdf.neural.decoder import Decoder
from nbrdf.neural.errors import NbrdfError
from nbrdf.viewer.gpu.belcour_gpu import bake_body, table_uniforms
from nbrdf.viewer.gpu.neural_gpu import GpuDecoder
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf

#: The texture unit a baked body table is bound to (the table body and the decoder's resampling guide).
TABLE_UNIT = 13
#: The table of interactive frames (while the user edits): HDR-FLIP against the per-pixel
#: decoder 0.007 mean, 0.013 worst over the look-development set (docs/decisions/020).
INTERACTIVE = TableSize(32, 16, 8)
#: The table of the still view where the per-pixel decoder is too slow: 0.004 mean, 0.007 worst.
STILL = TableSize(48, 24, 12)


def table_texture(ctx: moderngl.Context, size: TableSize) -> moderngl.Texture:
    """An empty RGB float 3D texture for a table of ``size``: trilinear between the nodes,
    clamped at the grid's edges (what ``body_table.glsl`` samples)."""
    k, m, n = size.shape
    tex = ctx.texture3d((n, m, k), 3, dtype="f4")
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    return tex


class BodyTables:
    """Bakes bodies into tables and keeps the textures (one per ``TableSize``)."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._tex: dict[tuple[TableSize, int], moderngl.Texture] = {}
        self._pre: dict[tuple[int, TableSize], torch.Tensor] = {}
        self.bake_ms: float = 0.0
        """The last bake's milliseconds (decoder pass and upload)."""

    def _preactivation(self, dec: Decoder, size: TableSize) -> torch.Tensor:
        """The nodes' direction features times the first layer's direction weights, (P, width)."""
        key = (id(dec), size)
        if key not in self._pre:
            wi, wo = table_directions(size)
            with torch.no_grad():
                feats = dec.encode(wi.reshape(-1, 3), wo.reshape(-1, 3))
                self._pre[key] = feats @ dec.hidden[0].weight[:, dec.spec.latent:].T
        return self._pre[key]

    @torch.no_grad()
    def bake(self, dec: Decoder, z: torch.Tensor, size: TableSize) -> torch.Tensor:
        """log f (K, M, N, 3) of the body of code ``z`` (3, >= latent) at the nodes of ``size``;
        equal to ``neural.body_table.bake_body`` (the same network, the first layer split)."""
        if not torch.isfinite(z).all():
            raise NbrdfError("body table: the latent has non-finite values")
        pre = self._preactivation(dec, size.check())
        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # small matrices beside llvmpipe's threads: 2 threads measured 5-10x slower
        try:
            x = dec.act(dec.latent_share(z.float())[:, None, :] + pre[None])  # (3, P, width)
            for layer in dec.hidden[1:]:
                x = dec.act(layer(x))
            y = dec.out(x)[..., 0].clamp(-80.0, 80.0)  # (3, P)
        finally:
            torch.set_num_threads(threads)
        return y.T.reshape(*size.shape, 3).contiguous()

    def brdf(self, base: GpuBrdf, size: TableSize, slot: int = 0) -> GpuBrdf:
        """``base`` (a NEURAL ``GpuBrdf``) with its body from a freshly baked table of ``size``, in the
        texture of ``slot`` (one per component of an OpenPBR mix shown at once)."""
        if base.kind != BrdfKind.NEURAL or base.latent is None:
            raise NbrdfError(f"body table: a uniform neural material only (got {base.kind.value})")
        t0 = time.perf_counter()
        tex = self._upload(self.bake(base.decoder.dec, base.latent, size), size, slot)
        self.bake_ms = (time.perf_counter() - t0) * 1000.0
        return replace(base, kind=BrdfKind.TABLE, body_table=tex, share=None,
                       uniforms={**base.uniforms, "u_body_table_ordered": 0})

    def belcour(self, base: GpuBrdf, size: TableSize, decoder: GpuDecoder, slot: int = 0) -> GpuBrdf:
        """``base`` (a BELCOUR ``GpuBrdf``) as a TABLE one: the model's body baked at the
        nodes of ``size`` (viewer/gpu/belcour_gpu.py ``bake_body``), its coat in closed form, its
        lobe strategy as the proxy pdf. ``decoder`` only assembles the table program's source
        (the table program is the neural one with the decoder left out); ``slot`` as in ``brdf``."""
        if base.kind != BrdfKind.BELCOUR:
            raise NbrdfError(f"body table: a belcour material only (got {base.kind.value})")
        t0 = time.perf_counter()
        size = replace(size, ordered=True)
        # base's uniforms are the model's decomposition for this material: made once per edit, reused here
        tex = self._upload(bake_body(base.material, size, uniforms=base.uniforms), size, slot)
        self.bake_ms = (time.perf_counter() - t0) * 1000.0
        return GpuBrdf(base.material, BrdfKind.TABLE, table_uniforms(base.material, base.uniforms), decoder,
                       normal_map=base.normal_map, body_table=tex, weight=base.weight)

    def _upload(self, values: torch.Tensor, size: TableSize, slot: int = 0) -> moderngl.Texture:
        """``values`` (K, M, N, 3) into the texture of (``size``, ``slot``) (made on first use)."""
        tex = self._tex.get((size, slot))
        if tex is None:
            tex = self._tex[(size, slot)] = table_texture(self.ctx, size)
        tex.write(values.numpy().astype("f4").tobytes())
        return tex

    def release(self) -> None:
        for t in self._tex.values():
            t.release()
        self._tex.clear()
        self._pre.clear()


__all__ = ["INTERACTIVE", "STILL", "BodyTables", "table_texture"]
