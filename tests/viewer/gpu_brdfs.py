"""Test helper: a material's ``GpuBrdf`` through the pipeline, the one way to hand the renderer a material."""
from __future__ import annotations

from nbrdf.viewer.gpu.pipeline import GpuBrdf, MaterialPipeline
from nbrdf.viewer.modes import BrdfMode


def closed_form(ctx, material) -> GpuBrdf:
    """The closed-form BRDF of ``material`` (analytic layering for stacks) on ``ctx``."""
    return MaterialPipeline(ctx).build(material, BrdfMode.ANALYTIC)
