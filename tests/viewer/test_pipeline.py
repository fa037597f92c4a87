"""The material pipeline and the one renderer: an edit computes one latent
share and reads no file; the offscreen path and the window's share the
pipeline; one renderer draws any material's GPU resources."""
from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pytest

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.methods import Method
from nbrdf.neural.model import default_model
from nbrdf.viewer.gpu.pipeline import BrdfKind, MaterialPipeline, brdf_kind, gpu_brdf
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.modes import BrdfMode
from nbrdf.viewer.options import DEFAULT_MATERIAL

ROUGH_GOLD = {"format": "nbrdf-material/1", "name": "rough gold",
              "layers": [{"type": "conductor", "roughness": 0.4, "r0": [1.0, 0.78, 0.34]}]}


def test_modes_resolve_like_the_command_line():
    stack, gold = load_material(DEFAULT_MATERIAL), parse_material(ROUGH_GOLD)
    assert MaterialPipeline.resolve(stack, "auto") is BrdfMode.NEURAL
    assert MaterialPipeline.resolve(gold, "auto") is BrdfMode.ANALYTIC
    assert MaterialPipeline.resolve(gold, BrdfMode.PROJECTED) is BrdfMode.PROJECTED
    with pytest.raises(ValueError, match="--brdf"):
        MaterialPipeline.resolve(gold, "spectral")


def test_brdf_modes_are_methods_plus_auto():
    """``--brdf``'s words are unchanged; each but auto is the ``Method`` of that word, and
    ``brdf_kind`` says how each is shaded."""
    assert BrdfMode.words() == ("auto", "analytic", "neural", "projected", "belcour")
    assert BrdfMode.AUTO.method is None
    for mode in BrdfMode:
        if mode is not BrdfMode.AUTO:
            assert mode.method is Method(mode.value)
    stack, gold = load_material(DEFAULT_MATERIAL), parse_material(ROUGH_GOLD)
    assert brdf_kind(BrdfMode.ANALYTIC, stack) is BrdfKind.ANALYTIC
    assert brdf_kind(BrdfMode.BELCOUR, stack) is BrdfKind.BELCOUR
    assert brdf_kind(BrdfMode.NEURAL, gold) is brdf_kind(BrdfMode.PROJECTED, gold) is BrdfKind.NEURAL
    with pytest.raises(ValueError, match="resolved"):
        brdf_kind(BrdfMode.AUTO, gold)


def test_an_edit_computes_one_latent_share_and_reads_no_file(gl_ctx, tmp_path, monkeypatch):
    from nbrdf.viewer.gpu import pipeline
    from nbrdf.viewer.session.lookdev import LookDev

    iio.imwrite(tmp_path / "n.png", np.tile(np.array([150, 128, 240], np.uint8), (4, 4, 1)))
    doc = {"format": "nbrdf-material/1", "name": "coated", "normal_map": "n.png", "layers": [
        {"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "conductor", "roughness": 0.3,
                                                               "r0": [1.0, 0.78, 0.34]}]}
    (tmp_path / "m.json").write_text(json.dumps(doc))
    calls = {"share": 0, "normal": 0}
    share, read = pipeline.latent_share, pipeline.read_normal_map

    def count_share(*a):
        calls["share"] += 1
        return share(*a)

    def count_read(*a):
        calls["normal"] += 1
        return read(*a)

    monkeypatch.setattr(pipeline, "latent_share", count_share)  # the names the pipeline calls
    monkeypatch.setattr(pipeline, "read_normal_map", count_read)
    ld = LookDev(gl_ctx, load_material(tmp_path / "m.json"))
    try:
        assert calls == {"share": 1, "normal": 1}
        for k, r in enumerate((0.2, 0.35, 0.5)):
            assert ld.set_param(1, "roughness", r), ld.error
            assert calls == {"share": 2 + k, "normal": 1}
        ld.set_compare("side")
        for view in ("object", "lobe", "slice"):  # every program draws the one share
            ld.set_view(view)
            ld.render(gl_ctx.simple_framebuffer((8, 8)), (8, 8), 1)
        assert calls == {"share": 4, "normal": 1}
    finally:
        ld.close()


def test_one_renderer_draws_any_material(gl_ctx):
    """A renderer without a material draws each GpuBrdf it is handed exactly as
    a renderer made for that material alone."""
    model = default_model()
    pipe = MaterialPipeline(gl_ctx, model)
    shared = Renderer(gl_ctx, mesh="testmesh")
    with pytest.raises(NbrdfError, match="no material"):
        shared.render_linear(ViewState(), (8, 8))
    gold, stack = parse_material(ROUGH_GOLD), load_material(DEFAULT_MATERIAL)
    state = ViewState(theta_i=40.0)
    for m, mode in ((gold, "analytic"), (stack, "neural"), (gold, "neural")):
        brdf = pipe.build(m, mode)
        assert brdf.kind == (BrdfKind.ANALYTIC if mode == "analytic" else BrdfKind.NEURAL)
        alone = gpu_brdf(gl_ctx, m, pipe.decoder if brdf.neural else None, brdf.latent,
                         (brdf.uniforms["u_proxy_sigma"], brdf.uniforms["u_proxy_w"]) if brdf.neural else None)
        own = Renderer(gl_ctx, alone, mesh="testmesh")
        for view in ("object", "lobe"):
            s = ViewState(view=view, theta_i=state.theta_i)
            np.testing.assert_array_equal(shared.render_linear(s, (20, 16), 2, brdf), own.render_linear(s, (20, 16), 2))


def test_the_offscreen_renderer_is_the_pipeline(gl_ctx):
    from nbrdf.viewer.gpu.renderer import make_renderer
    from nbrdf.viewer.options import ViewOptions

    m = load_material(DEFAULT_MATERIAL)
    r = make_renderer(gl_ctx, m, ViewOptions(material=DEFAULT_MATERIAL, brdf="neural"))
    z = default_model().material_latent(m)
    assert r.brdf.kind == BrdfKind.NEURAL
    np.testing.assert_allclose(r.brdf.latent.numpy(), z.numpy(), atol=1e-6)


@pytest.mark.gl
def test_latent_textures_of_earlier_edits_are_released(gl_ctx):
    """Each edit of a texture-mapped material is a new latent texture: the pipeline keeps
    those of the materials in use and the ``TEXTURES_KEPT`` most recently used, and
    releases the rest (a session editing one texture-mapped material stays flat)."""
    from dataclasses import replace

    from nbrdf.neural.latent_texture import LatentTexture
    from nbrdf.viewer.gpu.pipeline import TEXTURES_KEPT, material_key

    pipe = MaterialPipeline(gl_ctx)
    tiles = load_material(DEFAULT_MATERIAL.parent / "worn_tiles.json")
    assert tiles.is_textured
    edits = [replace(tiles, name=f"worn tiles, edit {k}") for k in range(TEXTURES_KEPT + 4)]
    z = pipe.latent(load_material(DEFAULT_MATERIAL))
    flat = LatentTexture(z.expand(2, 2, 3, z.shape[-1]).clone())
    made = []
    for m in edits:  # the first stays in use (another part of the mesh), the last is the one edited
        made.append(pipe.upload_texture(material_key(m), flat))
        pipe.retain([edits[0], m])
    kept = [m for m in edits if pipe.cached_texture(m) is not None]
    assert kept == [edits[0]] + edits[-TEXTURES_KEPT - 1:]
    released = [t for m, t in zip(edits, made) if m not in kept]
    assert len(released) == len(edits) - TEXTURES_KEPT - 2
    for t in released:
        with pytest.raises(AttributeError):
            t.texture.use(0)  # moderngl: a released texture has no GL object left to bind
