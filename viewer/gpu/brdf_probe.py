"""A GPU BRDF evaluated at given direction pairs (shaders/brdf_probe.frag):
what the shaders compute for a ``GpuBrdf`` of a uniform material (closed form,
Belcour, the neural code's decoder or baked table), pair by pair, to hold beside
its Python model -- and its lit-pass lobe strategy."""
from __future__ import annotations

import numpy as np

from nbrdf.viewer.gpu.neural_gpu import probe_pass
from nbrdf.viewer.gpu.pipeline import BrdfKind, GpuBrdf
from nbrdf.viewer.gpu.programs import ProgramKey
from nbrdf.viewer.gpu.renderer import Renderer


def _run(renderer: Renderer, brdf: GpuBrdf, a: np.ndarray, b: np.ndarray, defines: dict | None) -> np.ndarray:
    if brdf.kind == BrdfKind.TEXTURED:
        raise ValueError("the BRDF probe takes uniform materials; a latent texture has neural_gpu.probe_fragment")
    a, b = np.asarray(a, np.float32), np.asarray(b, np.float32)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"the probe's inputs must both be (N, 3), got {a.shape} and {b.shape}")
    texels = np.zeros((2 * a.shape[0], 4), np.float32)
    texels[0::2, :3], texels[1::2, :3] = a, b
    prog = renderer.programs.get(ProgramKey.of("brdf_probe.frag", brdf, defines=defines), brdf)
    return probe_pass(renderer.ctx, prog, texels, a.shape[0], lambda p: renderer.bind_brdf(p, brdf))


def probe_brdf(renderer: Renderer, brdf: GpuBrdf, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """(N, 3) float32: the GLSL ``brdf(wi, wo)`` of ``brdf`` (a uniform material) at N local pairs."""
    return _run(renderer, brdf, wi, wo, None)[:, :3]


def probe_lobe_sampling(renderer: Renderer, brdf: GpuBrdf, wo: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(N, 4) float32: the direction ``sample_lobe(wo, u)`` draws and its ``pdf_lobe``, per item."""
    return _run(renderer, brdf, wo, u, {"NB_PROBE_SAMPLING": 1})
