"""Anisotropic material codes in GLSL (anisotropy.glsl, issue 39) against the torch path: the whole BRDF
(the anisotropic coat, the body at its warped pair: decoder and baked table), the sampler (the coat's
anisotropic visible normals, the stretched proxy), and the shading frame of the mesh's tangent in both lit
paths. Each comparison has a variant that must fail (the tail's uniforms zeroed, the rotation turned)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from gpu_brdfs import upper_pairs

from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.neural_brdf import neural_brdf
from nbrdf.viewer.gpu import gl
from nbrdf.viewer.gpu.brdf_probe import probe_brdf, probe_lobe_sampling
from nbrdf.viewer.gpu.pipeline import MaterialPipeline
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.options import DEFAULT_MATERIAL

PRESET = DEFAULT_MATERIAL.parent / "brushed_steel_lacquer.json"


def _doc(rotation: float) -> dict:
    return {"format": "nbrdf-material/1", "name": "b", "anisotropy_rotation": rotation, "layers": [
        {"type": "dielectric", "roughness": 0.05, "ior": 1.5, "anisotropy": 0.5},
        {"type": "medium", "albedo": 1.0, "sigma_t": 0.1},
        {"type": "conductor", "roughness": 0.3, "r0": [0.9, 0.8, 0.7], "anisotropy": 0.8}]}


@pytest.fixture(scope="module")
def pipeline(gl_ctx):
    return MaterialPipeline(gl_ctx)


def test_the_glsl_brdf_of_an_anisotropic_code_is_the_torch_one(gl_ctx, pipeline):
    m = parse_material(_doc(30.0))
    brdf = pipeline.build(m, "neural")
    assert brdf.anisotropic and len(brdf.uniforms["u_aniso"]) == 4
    r = Renderer(gl_ctx, brdf=brdf, mesh="sphere")
    wi, wo = upper_pairs(1500, 0)
    cpu = neural_brdf(m, pipeline.model).eval(wi, wo).numpy()
    glsl = probe_brdf(r, brdf, wi.numpy(), wo.numpy())
    rel = np.abs(glsl - cpu) / (np.abs(cpu) + 1e-3)
    assert np.quantile(rel, 0.999) < 1e-3, rel.max()
    flat = dataclasses.replace(brdf, uniforms={**brdf.uniforms, "u_aniso": (0.0, 0.0, 0.0, 0.0)})
    wrong = probe_brdf(r, flat, wi.numpy(), wo.numpy())
    assert np.quantile(np.abs(wrong - cpu) / (np.abs(cpu) + 1e-3), 0.5) > 0.02
    # its thin varnish scatters: the glow is part of the body (decision 123); without it the values are wrong
    assert min(brdf.uniforms["u_body_glow"]) > 0.0
    dark = dataclasses.replace(brdf, uniforms={**brdf.uniforms, "u_body_glow": (0.0, 0.0, 0.0)})
    wrong = probe_brdf(r, dark, wi.numpy(), wo.numpy())
    assert np.quantile(np.abs(wrong - cpu) / (np.abs(cpu) + 1e-3), 0.5) > 0.02


def test_the_baked_table_reads_the_warped_pair(gl_ctx, pipeline):
    """The TABLE kind of an anisotropic code: its table (the isotropic equivalent's body) read at the
    warped pair, times J, plus the coat: within the table's interpolation error of the decoder."""
    from nbrdf.viewer.gpu.body_table_gpu import STILL, BodyTables

    m = load_material(PRESET)
    tables = BodyTables(gl_ctx)
    try:
        brdf = tables.brdf(pipeline.build(m, "neural"), STILL)
        assert brdf.anisotropic
        r = Renderer(gl_ctx, brdf=brdf, mesh="sphere")
        wi, wo = upper_pairs(1500, 1)
        cpu = neural_brdf(m, pipeline.model).eval(wi, wo).numpy()
        glsl = probe_brdf(r, brdf, wi.numpy(), wo.numpy())
        err = np.abs(glsl - cpu) / (np.abs(cpu) + 1e-2)
        assert np.median(err) < 0.01 and np.quantile(err, 0.95) < 0.06, (np.median(err), np.quantile(err, 0.95))
    finally:
        tables.release()


def test_the_glsl_sampler_draws_the_torch_directions_with_the_torch_pdf(gl_ctx, pipeline):
    m = parse_material(_doc(-40.0))
    brdf = pipeline.build(m, "neural")
    r = Renderer(gl_ctx, brdf=brdf, mesh="sphere")
    _, wo = upper_pairs(2000, 2)
    u = torch.rand(2000, 3, generator=torch.Generator().manual_seed(3))
    out = probe_lobe_sampling(r, brdf, wo.numpy(), u.numpy())
    ws, pdf = neural_brdf(m, pipeline.model)._draw(wo, u)[:2]
    ok = pdf.numpy() > 1e-3
    assert ok.mean() > 0.8
    assert np.abs(out[ok, :3] - ws.numpy()[ok]).max() < 1e-3
    rel = np.abs(out[ok, 3] - pdf.numpy()[ok]) / pdf.numpy()[ok]
    assert np.quantile(rel, 0.99) < 1e-3
    turned = pipeline.build(parse_material(_doc(-30.0)), "neural")
    other = probe_lobe_sampling(Renderer(gl_ctx, brdf=turned, mesh="sphere"), turned, wo.numpy(), u.numpy())
    assert np.median(np.abs(other[ok, 3] - pdf.numpy()[ok]) / pdf.numpy()[ok]) > 0.01


def _image(gl_ctx, brdf, compute: bool, size: int = 32) -> np.ndarray:
    r = Renderer(gl_ctx, mesh="sphere", brdf=brdf, compute=compute)
    tex = r.accumulate(ViewState(point_light=(1.5, -1.0, 2.0)), size, size, 0, 2, slot="t")
    return np.frombuffer(tex.read(), np.float32).reshape(size, size, 4).copy()


def test_both_lit_paths_shade_in_the_frame_of_the_tangent(gl_ctx, pipeline):
    """The deferred pass rebuilds the tangent from the G-buffer's turn, the fragment path from the mesh:
    the same image; the material turned by 90 degrees gives another one."""
    if gl_ctx.version_code < gl.COMPUTE_VERSION:
        pytest.skip("no OpenGL 4.3 here")
    brdf = pipeline.build(load_material(PRESET), "neural")
    comp, frag = _image(gl_ctx, brdf, True), _image(gl_ctx, brdf, False)
    on = frag[..., 3] > 0
    assert on.mean() > 0.2
    err = np.abs(comp[..., :3] - frag[..., :3]) / (1e-2 + np.abs(frag[..., :3]))
    assert np.quantile(err, 0.99) < 2e-3
    m = load_material(PRESET)
    turned = pipeline.build(dataclasses.replace(m, anisotropy_rotation=m.anisotropy_rotation + 90.0), "neural")
    other = _image(gl_ctx, turned, True)
    diff = np.abs(other[..., :3] - comp[..., :3]).mean() / np.abs(comp[..., :3]).mean()
    assert diff > 0.05, diff


def test_a_bare_brushed_metal_opens_in_the_window_through_the_neural_path(gl_ctx):
    """A single anisotropic conductor has no GLSL closed form: the window shades it with the neural path and
    compares it with the Monte Carlo reference (it used to refuse to open it: the closed form's one-line error)."""
    from nbrdf.viewer.gpu.pipeline import BrdfKind, analytic_capable
    from nbrdf.viewer.session.lookdev import LookDev

    brushed = parse_material({"format": "nbrdf-material/1", "name": "brushed", "anisotropy_rotation": 30.0,
                              "layers": [{"type": "conductor", "roughness": 0.2, "r0": [0.9, 0.9, 0.9],
                                          "anisotropy": 0.8}]})
    assert not analytic_capable(brushed)
    assert analytic_capable(dataclasses.replace(brushed, layers=(dataclasses.replace(brushed.layers[0],
                                                                                      anisotropy=0.0),)))
    ld = LookDev(gl_ctx, brushed)
    try:
        assert ld.brdf.kind != BrdfKind.ANALYTIC and ld.ref_brdf is None
        assert "Monte Carlo" in ld.compare_part.status(ld.material, "object")
    finally:
        ld.close()
