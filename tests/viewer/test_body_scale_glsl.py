"""A calibrated code's body scale in GLSL (body_scale.glsl) against the torch path (``neural.body_scale``):
the whole BRDF with the scale equals torch's, and the same BRDF without its scale does not."""
from __future__ import annotations

import dataclasses

import numpy as np
import torch
from gpu_brdfs import upper_pairs

from nbrdf.neural.body_scale import BodyScale
from nbrdf.neural.energy import EnergySettings
from nbrdf.neural.material import parse_material
from nbrdf.neural.neural_brdf import latent_brdf
from nbrdf.viewer.gpu.brdf_probe import probe_brdf
from nbrdf.viewer.gpu.pipeline import MaterialPipeline
from nbrdf.viewer.gpu.renderer import Renderer

DOC = {"format": "nbrdf-material/1", "name": "lacquer", "layers": [
    {"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "medium", "albedo": 0.9, "sigma_t": 0.5},
    {"type": "diffuse", "albedo": [0.8, 0.6, 0.4]}]}


def test_the_glsl_body_scale_is_the_torch_one(gl_ctx):
    pipeline = MaterialPipeline(gl_ctx)
    m = parse_material(DOC)
    knots = EnergySettings().thetas
    # a scale that bends across the knots, differently per channel (the walk's corrections are a few per cent)
    g = torch.stack([1.0 + 0.1 * torch.sin(torch.arange(len(knots)) * 0.9 + c) for c in range(3)])
    scale = BodyScale(knots, g)
    z = pipeline.model.material_latent(m)
    brdf = pipeline.build(m, "neural", latent=z, body_scale=scale)
    assert len(brdf.uniforms["u_body_scale"]) == len(knots)
    r = Renderer(gl_ctx, brdf=brdf, mesh="sphere")
    wi, wo = upper_pairs(1500, 2)
    cpu = latent_brdf(pipeline.model.decoder, z, m, pipeline.model.sampler, scale).eval(wi, wo).numpy()
    glsl = probe_brdf(r, brdf, wi.numpy(), wo.numpy())
    rel = np.abs(glsl - cpu) / (np.abs(cpu) + 1e-3)
    assert np.quantile(rel, 0.999) < 1e-3, rel.max()
    plain = dataclasses.replace(brdf, body_scale=None, uniforms={k: v for k, v in brdf.uniforms.items()
                                                                if k != "u_body_scale"})
    wrong = probe_brdf(r, plain, wi.numpy(), wo.numpy())
    assert np.quantile(np.abs(wrong - cpu) / (np.abs(cpu) + 1e-3), 0.5) > 0.02  # the scale is seen
