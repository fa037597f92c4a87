"""A GPU BRDF evaluated at given direction pairs (shaders/brdf_probe.frag):
what the shaders compute for a ``GpuBrdf`` of a closed-form kind, pair by
pair, to hold beside its Python model."""
from __future__ import annotations

import numpy as np

from nbrdf.viewer.neural_gpu import probe_pass
from nbrdf.viewer.pipeline import GpuBrdf
from nbrdf.viewer.renderer import Renderer


def probe_brdf(renderer: Renderer, brdf: GpuBrdf, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """(N, 3) float32: the GLSL ``brdf(wi, wo)`` of ``brdf`` (not a neural kind) at N local pairs."""
    if brdf.neural:
        raise ValueError("probe_brdf takes closed-form kinds; the decoder has neural_gpu.probe_fragment")
    wi, wo = np.asarray(wi, np.float32), np.asarray(wo, np.float32)
    if wi.shape != wo.shape or wi.ndim != 2 or wi.shape[1] != 3:
        raise ValueError(f"wi and wo must both be (N, 3), got {wi.shape} and {wo.shape}")
    texels = np.zeros((2 * wi.shape[0], 4), np.float32)
    texels[0::2, :3], texels[1::2, :3] = wi, wo
    prog = renderer.program("brdf_probe.frag", brdf)
    return probe_pass(renderer.ctx, prog, texels, wi.shape[0], lambda p: renderer.bind_brdf(p, brdf))[:, :3]
