"""Environment lighting: the luminance sampler follows its pdf (chi-square),
GLSL samples like numpy, and a white Lambertian sphere in a uniform white
environment renders white (the furnace test of the whole MIS estimator)."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from gpu_brdfs import closed_form
from stattools import chi2_sphere

from nbrdf.imaging.environment import EnvironmentMap, GpuEnvironment, default_environment
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import parse_material

pytestmark = pytest.mark.gl


def _env():
    return EnvironmentMap(default_environment(64, 32))


def test_sampler_follows_its_pdf():
    env = _env()
    rng = np.random.default_rng(3)

    def sample_fn(n):
        d, pdf = env.sample(rng.random((n, 2)))
        return torch.from_numpy(d), torch.from_numpy(pdf)

    res = chi2_sphere(sample_fn, lambda d: torch.from_numpy(env.pdf(d.numpy())), n_samples=200_000, sub=12)
    assert res.p_value > 1e-3, str(res)
    assert abs(res.pdf_integral - 1) < 5e-3, str(res)


def test_bright_texels_are_sampled_more():
    env = _env()
    d, pdf = env.sample(np.random.default_rng(0).random((20_000, 2)))
    lum = env.lookup(d) @ np.array([0.2126, 0.7152, 0.0722])
    # the sun covers ~0.05 % of the sphere (more at this 64 x 32 resolution, < 0.2 %) and ~3 % of the light
    assert np.mean(lum > 10) > 0.02


def test_glsl_sampling_matches_numpy(gl_ctx):
    from nbrdf.viewer.gpu import shaders
    from nbrdf.viewer.gpu.neural_gpu import probe_pass

    env = _env()
    genv = GpuEnvironment(gl_ctx, env)
    prog = gl_ctx.program(vertex_shader=shaders.source("fullscreen.vert"),
                          fragment_shader=shaders.source("env_probe.frag"))
    try:
        u = np.random.default_rng(1).uniform(0.001, 0.999, (2000, 2)).astype(np.float32)
        texels = np.zeros((4000, 4), np.float32)
        texels[0::2, :2] = u
        out = probe_pass(gl_ctx, prog, texels, 2000, lambda p: genv.bind(p))
        d, pdf = env.sample(u.astype(np.float64))
        np.testing.assert_allclose(out[:, :3], d, atol=2e-3)
        np.testing.assert_allclose(out[:, 3], pdf, rtol=2e-3)
    finally:
        prog.release()
        genv.release()


def test_white_furnace(gl_ctx):
    """Albedo-1 Lambertian, uniform radiance 1, no light: every pixel is 1."""
    from nbrdf.viewer.gpu.renderer import Renderer, ViewState

    m = parse_material({"format": "nbrdf-material/1", "name": "white", "layers": [{"type": "diffuse", "albedo": 1.0}]})
    r = Renderer(gl_ctx, closed_form(gl_ctx, m), environment=np.ones((16, 32, 3), np.float32))
    state = ViewState(light_radiance=0.0, env_intensity=1.0)
    img = r.render_linear(state, (48, 48), spp=32)
    inside = img.sum(-1) > 0
    assert inside.mean() > 0.3
    assert abs(float(img[inside].mean()) - 1) < 0.01
    assert np.percentile(np.abs(img[inside] - 1), 95) < 0.1


def test_bad_environments_are_refused():
    with pytest.raises(NbrdfError, match="non-negative"):
        EnvironmentMap(-np.ones((4, 8, 3), np.float32))
    with pytest.raises(NbrdfError, match=r"\(H, W, 3\)"):
        EnvironmentMap(np.ones((4, 8), np.float32))
