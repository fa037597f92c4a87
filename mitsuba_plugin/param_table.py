"""A texture-mapped material's body from a parametric table (``neural.param_table``).

Per hit, the varying parameters (at most two per-channel albedos) are read
from the material's maps at the hit's uv (``mip.MipBuffer``: bilinear,
trilinear between mip levels by the hit's ray cone, as the latent texture is
read), then per colour channel c the body is bilinear in (a_c, b_c) over four
trilinear angular fetches of one ``Texture3f``. No weights and no per-texel
latents: it renders fast in Dr.Jit's symbolic mode.

The latent texture filters codes across texels; this filters the parameters
and decodes their filtered values: the same at the finest level, different
where a footprint straddles texels (the body is not linear in its parameters).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import torch

from nbrdf.mitsuba.kernel import Coat, CodeKernel, Proxy, table_coordinates
from nbrdf.mitsuba.mip import MipBuffer, level_of_detail, mip_chain
from nbrdf.neural.body_table import TableSize
from nbrdf.neural.coat import code_coat
from nbrdf.neural.param_table import ParamGrid, bake_param_body, node_codes, param_value, table_params
from nbrdf.neural.svbrdf import TextureValues, latent_texture

#: Nodes per varying parameter and angle: over the globe's map ranges (medium albedo 0.30-0.97, base albedo
#: 0.05-0.75) against the neural path at random (a, b) and directions, 13 x 13 nodes at 64 x 32 x 16 gives
#: a mean relative error of 0.41 %, 99th percentile 1.8 % (9 x 9: 0.75 %, 3.4 %; the angular size matters
#: less: 96 x 48 x 24 at 9 x 9 gave the same); 22 MB.
GRID = (13, 13)
ANGLES = (64, 32, 16)


class ParamTableBody:
    """Body values from a parametric table (A, B, K, M, N) of log f: bilinear in
    the two parameters (in f) over trilinear angular fetches (in log f)."""

    def __init__(self, values: np.ndarray, ranges: tuple[tuple[float, float], ...]):
        """``values``: ``neural.param_table.bake_param_body``'s (A, B, K, M, N);
        ``ranges``: (lo, hi) of each varying parameter (one or two)."""
        values = np.ascontiguousarray(values, np.float32)
        if values.ndim != 5 or min(values.shape[2:]) < 2:
            raise ValueError(f"a parametric body table is (A, B, K, M, N) with K, M, N >= 2, got {values.shape}")
        a, b, k, m, n = values.shape
        self.nodes, self.shape = (a, b), (k, m, n)
        self.ranges = tuple(ranges) + ((0.0, 1.0),) * (2 - len(ranges))
        # slabs of K phi_d nodes stacked along depth, slab (i, j) at i B + j: a fetch stays inside its slab
        self.texture = mi.Texture3f(mi.TensorXf(values.reshape(a * b * k, m, n, 1)), use_accel=False,
                                    filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp)

    def _cell(self, x, d: int):
        """(lower node index, weight of the upper one) of parameter ``d`` at values ``x``."""
        n = self.nodes[d]
        if n == 1:
            return mi.UInt32(0), mi.Float(0.0)
        lo, hi = self.ranges[d]
        t = dr.clip((x - lo) * ((n - 1) / (hi - lo)), 0.0, float(n - 1))
        t = dr.select(dr.isfinite(t), t, 0.0)
        i0 = dr.minimum(dr.floor(t), float(n - 2))
        return mi.UInt32(i0), t - i0

    def body(self, wi, wo, params: list | None = None) -> list:
        """[f_r, f_g, f_b] (1/sr), zero below the horizon; ``params``: per
        channel [x_0, x_1] per lane (the varying parameters' values)."""
        if params is None:
            raise ValueError("a parametric body table needs the hit's parameters")
        k = self.shape[0]
        na, nb = self.nodes
        u, v, w = table_coordinates(wi, wo, self.shape)  # w: texels into a slab
        depth = float(na * nb * k)
        up = (wi.z > 0) & (wo.z > 0)
        out = []
        for x in params:
            ia, fa = self._cell(x[0], 0)
            ib, fb = self._cell(x[1] if len(x) > 1 else mi.Float(0.0), 1)
            f = mi.Float(0.0)
            for da in ((0, 1) if na > 1 else (0,)):
                for db in ((0, 1) if nb > 1 else (0,)):
                    slab = mi.Float((ia + da) * nb + ib + db)
                    y = self.texture.eval(mi.Point3f(u, v, (slab * k + w) / depth))[0]
                    wt = (fa if da else 1.0 - fa) * (fb if db else 1.0 - fb)
                    f = dr.fma(wt, dr.exp(dr.minimum(y, 80.0)), f)
            out.append(dr.select(up, f, 0.0))
        return out


class ParamTableCodeKernel(CodeKernel):
    """A texture-mapped material read through a parametric body table: the
    parameters per hit from its maps (``MipBuffer``, stride 3 per parameter),
    a uniform coat, and the latent texture's mean-code proxy (the decoder
    path's sampler, so both draw the same directions)."""

    textured = True

    def __init__(self, body: ParamTableBody, maps, coat: Coat, proxy: Proxy, pixel_angle: float = 0.0):
        """``maps``: a ``mip.MipBuffer`` of the parameters' texels, (x_0 rgb, x_1 rgb)."""
        super().__init__(body, coat, proxy)
        self.maps, self.pixel_angle = maps, float(pixel_angle)

    def at(self, si):
        if si is None:
            raise ValueError("a textured nbrdf material is evaluated at a hit (si)")
        x = self.maps.lookup(si.uv, level_of_detail(si, self.pixel_angle, self.maps.size))
        n = len(x) // 3
        return [[x[3 * d + c] for d in range(n)] for c in range(3)], self.coat


def param_table_kernel(material, model, pixel_angle: float) -> ParamTableCodeKernel:
    """The kernel of a texture-mapped material whose maps vary at most two
    per-channel albedos (else a one-line ``NbrdfError``, ``neural.param_table.table_params``)."""
    texels = TextureValues(material)
    params = table_params(material, texels)
    grid = ParamGrid(*GRID)
    values = bake_param_body(model, material, params, grid, TableSize(*ANGLES))
    h, w = texels.size
    cols = []
    for place in params.places:
        # the parameter's three channels (a uniform channel of a partly mapped albedo stays constant)
        v = texels(param_value(material, place), place)
        cols.append(v.expand(h * w, 3).reshape(h, w, 3))
    maps = MipBuffer(mip_chain(torch.cat(cols, -1).numpy()))
    spec = model.decoder.spec
    code = node_codes(model, material, params, ParamGrid(1, 1))[0, 0][None].expand(3, -1)
    r, ior = code_coat(spec, code)
    mean = latent_texture(model, material).levels[-1][0, 0]
    sigma, wgt = model.proxy(mean)
    return ParamTableCodeKernel(ParamTableBody(values.numpy(), params.ranges), maps, Coat(float(r), float(ior)),
                                Proxy(sigma, wgt), pixel_angle)

