"""OpenPBR's linear mixes on the GPU (viewer/gpu/pipeline.py ``GpuBrdf.mixed``): a material with a
fractional base_metalness or coat_weight is drawn as its components, each shading the same surface
with the same random numbers and adding its weighted share, so the image of the mix is the weighted
sum of its components' images -- in the compute and the fragment lit paths, the lobe and slice views,
from baked body tables -- and differs from its largest component alone (what was shown before)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from nbrdf.neural.material import parse_material
from nbrdf.neural.mix import is_mix, material_mix, mix_split
from nbrdf.neural.openpbr import OpenPbr, openpbr_to_material
from nbrdf.viewer.gpu import gl
from nbrdf.viewer.gpu.body_source import BodySettings, BodySource
from nbrdf.viewer.gpu.pipeline import BrdfKind, MaterialPipeline, analytic_capable
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.reference.compare import coat_brdf

#: four components (metal / dielectric x coated / not): weights 0.18, 0.12, 0.42, 0.28
MIXED = OpenPbr(base_color=(0.8, 0.5, 0.3), base_metalness=0.3, coat_weight=0.6, coat_roughness=0.3)
SIZE = 20


def _material(p: OpenPbr = MIXED):
    d, _ = openpbr_to_material(p, "mix")
    return parse_material(d)


@pytest.fixture(scope="module")
def pipeline(gl_ctx):
    return MaterialPipeline(gl_ctx)


def _image(r: Renderer, state: ViewState, brdf, passes: int = 2) -> np.ndarray:
    tex = r.accumulate(state, SIZE, SIZE, 0, passes, brdf, slot="mix")
    return np.frombuffer(tex.read(), np.float32).reshape(SIZE, SIZE, 4)[..., :3].copy()


def _weighted(r: Renderer, state: ViewState, pipeline, material, passes: int = 2) -> np.ndarray:
    """The components drawn one by one (each a material of its own, weight 1), weighted on the CPU."""
    return sum(w * _image(r, state, pipeline.build(c, "neural"), passes) for w, c in material_mix(material))


def test_the_pipeline_attaches_the_other_components_with_their_weights(pipeline):
    m = _material()
    brdf = pipeline.build(m, "neural")
    weight, others = mix_split(m)
    assert is_mix(m) and not analytic_capable(m)  # its layers are one component: no closed-form stand-in
    assert brdf.weight == pytest.approx(0.42) and weight == pytest.approx(0.42)  # dielectric, coated: the largest
    assert [b.weight for b in brdf.mixed] == pytest.approx([0.18, 0.12, 0.28])
    assert sum(b.weight for b in brdf.components()) == pytest.approx(1.0)
    assert all(b.kind == BrdfKind.NEURAL and not b.mixed for b in brdf.mixed)
    plain = _material(OpenPbr(base_metalness=1.0, coat_weight=1.0))
    single = pipeline.build(plain, "neural")
    assert single.weight == 1.0 and single.mixed == () and single.components() == (single,)


@pytest.mark.parametrize("compute", [True, False], ids=["compute", "fragment"])
def test_a_mix_renders_as_its_components_weighted(gl_ctx, pipeline, compute):
    if compute and gl_ctx.version_code < gl.COMPUTE_VERSION:
        pytest.skip("no OpenGL 4.3 here")
    m = _material()
    r = Renderer(gl_ctx, compute=compute)
    state = ViewState(point_light=(1.5, -1.0, 2.0))
    got = _image(r, state, pipeline.build(m, "neural"))
    want = _weighted(r, state, pipeline, m)
    on = np.abs(want).sum(-1) > 0
    assert on.mean() > 0.2
    # the same samples per pixel and pass: only the order of the float sums differs
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-6)
    # and not the largest component alone, the stand-in shown before (the check can fail)
    alone = _image(r, state, pipeline.build(parse_material({"format": "nbrdf-material/1", "name": "x",
                                                              "layers": openpbr_to_material(MIXED, "x")[0]["layers"]}),
                                            "neural"))
    assert np.abs(alone - want)[on].mean() > 0.1 * np.abs(want)[on].mean()


@pytest.mark.parametrize("view", ["lobe", "slice"])
@pytest.mark.parametrize("compute", [True, False], ids=["compute", "fragment"])
def test_the_lobe_and_slice_views_of_a_mix_are_its_components_weighted(gl_ctx, pipeline, view, compute):
    if compute and gl_ctx.version_code < gl.COMPUTE_VERSION:
        pytest.skip("no OpenGL 4.3 here")
    m = _material()
    r = Renderer(gl_ctx, compute=compute)
    state = ViewState(view=view, theta_i=40.0)
    got = r.render_linear(state, (SIZE, SIZE), 1, pipeline.build(m, "neural"))
    want = sum(w * r.render_linear(state, (SIZE, SIZE), 1, pipeline.build(c, "neural")) for w, c in material_mix(m))
    assert float(np.abs(want).max()) > 0.01
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-6)


def test_baked_body_tables_keep_every_component(gl_ctx, pipeline):
    if gl_ctx.version_code < gl.COMPUTE_VERSION:
        pytest.skip("no OpenGL 4.3 here")
    m = _material()
    brdf = pipeline.build(m, "neural")
    source = BodySource(gl_ctx, BodySettings(), lambda: pipeline.decoder)
    source.use_tables = True  # as calibrate decides where the decoder is slow
    baked = source.for_frame(brdf, interactive=False)
    assert [b.kind for b in baked.components()] == [BrdfKind.TABLE] * 4
    assert [b.weight for b in baked.components()] == [b.weight for b in brdf.components()]
    assert len({id(b.body_table) for b in baked.components()}) == 4  # one texture each, none overwritten
    assert source.for_frame(brdf, interactive=False) is baked  # baked once per edit
    r = Renderer(gl_ctx)
    state = ViewState()
    got = _image(r, state, baked)
    parts = [source.tables.brdf(b, source.settings.still, slot=10 + k) for k, b in enumerate(brdf.components())]
    want = sum(b.weight * _image(r, state, replace(b, weight=1.0, mixed=())) for b in parts)
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-6)


def test_the_compare_views_coat_is_each_components_own(pipeline):
    m = _material()
    brdf = pipeline.build(m, "neural")
    exact = coat_brdf(brdf, m)
    assert len(exact.mixed) == 3
    for b, e in zip(brdf.components(), exact.components()):
        if b.material.interfaces:
            top = b.material.interfaces[0][0]
            assert e.uniforms["u_coat"] == pytest.approx((float(top.roughness), float(top.ior)))
        assert e.weight == b.weight


def test_an_openpbr_slider_makes_a_mix_the_window_draws(gl_ctx):
    from pathlib import Path

    from nbrdf.neural.material import load_material
    from nbrdf.viewer.session.lookdev import LookDev

    gold = Path(__file__).parents[1] / "neural" / "data" / "mtlx" / "openpbr_coated_gold.mtlx"
    ld = LookDev(gl_ctx, load_material(gold, []))
    try:
        assert ld.open_material(gold) and ld.brdf is not None and ld.brdf.mixed == ()
        assert ld.set_openpbr("coat_weight", 0.3)
        assert "coat_weight 0.3: a partial coat" in ld.notice  # the notice says the notes of now, not of the opening
        shown = ld.brdf.components()
        assert [b.weight for b in shown] == pytest.approx([0.7, 0.3])  # uncoated gold is the larger share
        assert [bool(b.material.interfaces) for b in shown] == [False, True]
        assert ld.set_openpbr("coat_weight", 1.0) and ld.brdf.mixed == ()  # whole again: one BRDF
    finally:
        ld.close()


def test_the_handover_bounds_every_component_of_a_mix(gl_ctx):
    import time

    import torch

    from nbrdf.viewer.session.lookdev import LookDev

    # half coated: the uncoated half (a smooth dielectric over white diffuse) is the networks' glowing case
    glaze = OpenPbr(base_color=(1.0, 1.0, 1.0), specular_roughness=0.0, coat_weight=0.5, coat_roughness=0.0)
    ld = LookDev(gl_ctx, parse_material(openpbr_to_material(glaze, "glaze")[0]))
    try:
        assert ld.set_openpbr("coat_roughness", 0.01)  # a slider's frame: the networks' codes, unbounded
        other = ld.brdf.mixed[0]
        assert other.material.name.endswith("(dielectric)")  # the uncoated component
        assert not torch.equal(ld.pipeline.conserved(other.latent), other.latent)
        z, _ = ld._conserve_due
        ld._conserve_due = (z, time.monotonic() - 10.0)  # the edits paused
        ld.update()
        other = ld.brdf.mixed[0]
        assert torch.equal(ld.pipeline.conserved(other.latent), other.latent)  # bounded with the handover
    finally:
        ld.close()
