"""Test helper: a material's ``GpuBrdf`` through the pipeline, the one way to hand the renderer a material."""
from __future__ import annotations

import torch

from nbrdf.neural.material import load_material
from nbrdf.viewer.gpu.body_source import table_sampling
from nbrdf.viewer.gpu.body_table_gpu import BodyTables
from nbrdf.viewer.gpu.pipeline import GpuBrdf, MaterialPipeline
from nbrdf.viewer.gpu.renderer import Renderer
from nbrdf.viewer.modes import BrdfMode
from nbrdf.viewer.options import DEFAULT_MATERIAL


def closed_form(ctx, material) -> GpuBrdf:
    """The closed-form BRDF of ``material`` (analytic layering for stacks) on ``ctx``."""
    return MaterialPipeline(ctx).build(material, BrdfMode.ANALYTIC)


def table_renderer(ctx, size, material=DEFAULT_MATERIAL):
    """(renderer, body, tables) of ``material`` (default: the default material) with its body baked in a table
    of ``size``, shaded with the window's table estimator on the sphere (compute paths only: the caller skips
    without 4.3); release ``tables`` when done."""
    tables = BodyTables(ctx)
    body = tables.brdf(MaterialPipeline(ctx).build(load_material(material), BrdfMode.NEURAL), size)
    r = Renderer(ctx, brdf=body, mesh="sphere")
    r.sampling = table_sampling(r.sampling)
    return r, body, tables


def run_pairs(prog, ctx, a, b, mode: int, in_width: int, out_width: int):
    """(n, 4) outputs of a pair-probe program at the n pairs (a, b): the pairs as texels 2k, 2k + 1 of an
    ``in_width``-wide float texture on unit 0 (``u_in``), one output pixel each in an ``out_width``-wide
    target (``u_mode`` set where the program has it); the program's texel and pixel layout must match."""
    import moderngl
    import numpy as np

    n = a.shape[0]
    texels = np.zeros((2 * n, 4), np.float32)
    texels[0::2, :3], texels[1::2, :3] = a, b
    tex = ctx.texture((in_width, 2 * n // in_width), 4, texels.tobytes(), dtype="f4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    target = ctx.texture((out_width, n // out_width), 4, dtype="f4")
    fbo = ctx.framebuffer([target])
    fbo.use()
    tex.use(0)
    prog["u_in"].value = 0
    if "u_mode" in prog:
        prog["u_mode"].value = mode
    ctx.vertex_array(prog, []).render(moderngl.TRIANGLES, vertices=3)
    out = np.frombuffer(target.read(), np.float32).reshape(n, 4).copy()
    for r in (fbo, target, tex):
        r.release()
    return out


def upper_pairs(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` random (wi, wo) pairs above the horizon (z >= about 0.05), from ``seed``."""
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(2 * n, 3, generator=g)
    v[:, 2] = v[:, 2].abs() + 0.05
    v = v / v.norm(dim=-1, keepdim=True)
    return v[:n], v[n:]
