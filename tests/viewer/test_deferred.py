"""The deferred lit view (G-buffer + compute pass, OpenGL 4.3) against the
fragment fallback, its choice and notice, and its accumulation image's values."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material
from nbrdf.viewer.gpu import gl
from nbrdf.viewer.gpu.pipeline import MaterialPipeline
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.options import DEFAULT_MATERIAL

MATERIALS = DEFAULT_MATERIAL.parent
CASES = [  # material, brdf mode, mesh
    ("rough_gold.json", "analytic", "sphere"),
    ("default.json", "neural", "sphere"),
    ("worn_tiles.json", "neural", "testmesh"),  # latent texture (mip level from the G-buffer) + normal map
]


@pytest.fixture(scope="module")
def pipeline(gl_ctx):
    if gl_ctx.version_code < gl.COMPUTE_VERSION:
        pytest.skip("no OpenGL 4.3 here")
    return MaterialPipeline(gl_ctx)


@pytest.mark.parametrize("material,mode,mesh", CASES, ids=[c[0].split(".")[0] for c in CASES])
def test_compute_and_fragment_paths_give_the_same_image(gl_ctx, pipeline, material, mode, mesh):
    brdf = pipeline.build(load_material(MATERIALS / material), mode)
    state = ViewState(point_light=(1.5, -1.0, 2.0))  # every light the lit pass has
    imgs = []
    for compute in (True, False):
        r = Renderer(gl_ctx, mesh=mesh, brdf=brdf, compute=compute)
        assert r.deferred == compute
        # two calls: the progressive path (a later first pass reuses the G-buffer)
        r.accumulate(state, 24, 24, 0, 2, slot="t")
        tex = r.accumulate(state, 24, 24, 2, 1, slot="t")
        imgs.append(np.frombuffer(tex.read(), np.float32).reshape(24, 24, 4).copy())
    comp, frag = imgs
    on = frag[..., 3] > 0
    assert on.mean() > 0.2  # the object covers the frame's middle
    np.testing.assert_array_equal(comp[..., 3], frag[..., 3])  # same coverage, same pass count
    err = np.abs(comp[..., :3] - frag[..., :3]) / (1e-2 + np.abs(frag[..., :3]))
    # Same samples per pixel and pass: only rounding differs (FMA contraction, the
    # mip level read back from the G-buffer), so nearly every pixel agrees to 1e-3.
    assert np.quantile(err, 0.99) < 1e-3 and np.abs(comp - frag).mean() / np.abs(frag).mean() < 1e-3


def test_the_every_candidate_program_is_the_fragment_paths_estimator(gl_ctx, pipeline):
    # The compute path shades the baked table's estimator (the body at every candidate) with a
    # program of its own (lit_shade.glsl shade_lit_every); the fragment path with shade_lit.
    from nbrdf.viewer.gpu.body_source import table_sampling
    from nbrdf.viewer.gpu.body_table_gpu import STILL, BodyTables

    tables = BodyTables(gl_ctx)
    brdf = tables.brdf(pipeline.build(load_material(DEFAULT_MATERIAL), "neural"), STILL)
    state = ViewState(point_light=(1.5, -1.0, 2.0))
    imgs = []
    for compute in (True, False):
        r = Renderer(gl_ctx, brdf=brdf, compute=compute)
        r.sampling = table_sampling(r.sampling)
        if compute:
            assert r.lit.specialised(brdf) is not None
        tex = r.accumulate(state, 24, 24, 0, 2, slot="t")
        imgs.append(np.frombuffer(tex.read(), np.float32).reshape(24, 24, 4).copy())
    comp, frag = imgs
    assert (frag[..., 3] > 0).mean() > 0.2
    np.testing.assert_array_equal(comp[..., 3], frag[..., 3])
    err = np.abs(comp[..., :3] - frag[..., :3]) / (1e-2 + np.abs(frag[..., :3]))
    assert np.quantile(err, 0.99) < 1e-3 and np.abs(comp - frag).mean() / np.abs(frag).mean() < 1e-3
    tables.release()


def test_fallback_when_forced_prints_one_notice(gl_ctx, pipeline, monkeypatch, capsys):
    monkeypatch.setenv(gl.FRAGMENT_ENV, "1")
    monkeypatch.setattr(gl, "_noticed", set())
    brdf = pipeline.build(load_material(MATERIALS / "rough_gold.json"), "analytic")
    r = Renderer(gl_ctx, brdf=brdf)
    Renderer(gl_ctx, brdf=brdf)
    assert not r.deferred
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"nbrdf: {gl.FRAGMENT_ENV} is set: the lit view shades in fragment shaders (fallback path)"]
    img = r.render_linear(ViewState(), (16, 16), spp=1)
    assert np.isfinite(img).all() and img.max() > 0
    monkeypatch.delenv(gl.FRAGMENT_ENV)
    assert Renderer(gl_ctx, brdf=brdf).deferred


class _OldContext:
    version_code = 410
    info = {"GL_VERSION": "4.1 (test double)"}


def test_a_context_without_compute_shaders_falls_back_with_a_notice(monkeypatch, capsys):
    monkeypatch.setattr(gl, "_noticed", set())
    assert not gl.use_compute(_OldContext())  # type: ignore[arg-type]
    assert not gl.use_compute(_OldContext())  # type: ignore[arg-type]
    assert capsys.readouterr().err.count("has no compute shaders (4.3)") == 1
    with pytest.raises(NbrdfError, match="needs OpenGL 4.3"):
        gl.use_compute(_OldContext(), True)  # type: ignore[arg-type]


def test_no_nan_or_negative_value_reaches_the_accumulation_image(gl_ctx, pipeline):
    """Fuzzed latents (far outside the trained range), light directions (below
    the horizon included), cameras and environment rotations."""
    g = np.random.default_rng(7)
    m = load_material(MATERIALS / "default.json")
    base = pipeline.build(m, "neural")
    r = Renderer(gl_ctx, brdf=base, compute=True)
    dec = base.decoder.dec
    for k in range(4):
        z = dec.latent_mean + torch.from_numpy(g.normal(size=(3, 32)).astype(np.float32)) * (0.5 * 4 ** k)
        brdf = pipeline.build(m, "neural", latent=z)
        state = ViewState(light_dir=tuple(g.normal(size=3)), env_rotation=float(g.uniform(0, 360)),
                          point_light=tuple(g.normal(size=3) * 2))
        state.camera.yaw = float(g.uniform(-180, 180))
        state.camera.pitch = float(g.uniform(-80, 80))
        tex = r.accumulate(state, 24, 24, 0, 2, brdf, slot="fuzz")
        acc = np.frombuffer(tex.read(), np.float32).reshape(24, 24, 4)
        assert np.isfinite(acc).all() and (acc >= 0).all(), f"fuzz round {k}"
        assert acc[..., :3].max() > 0
