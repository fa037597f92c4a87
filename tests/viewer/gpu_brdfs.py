"""Test helper: a material's ``GpuBrdf`` through the pipeline, the one way to hand the renderer a material."""
from __future__ import annotations

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
