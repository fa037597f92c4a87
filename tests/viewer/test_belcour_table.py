"""Belcour's model baked into the window's body table (viewer/gpu/belcour_gpu.py
``bake_body``, ``BodyTables.belcour``): what the window shades on software
OpenGL, where the per-pixel model costs about three table passes.

The renders are lit by the directional light alone, so both are f(l, wo) cos L
at every pixel with no Monte Carlo noise between them: their difference is the
table's interpolation error (the coat is closed form on both sides)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from nbrdf.neural.body_table import TableSize, table_directions
from nbrdf.neural.coat import coat_eval
from nbrdf.neural.material import load_material
from nbrdf.training.belcour import atoms_of, belcour_eval_atoms
from nbrdf.training.belcour_tables import default_tables
from nbrdf.viewer.gpu.belcour_gpu import bake_body, coat_of, table_uniforms
from nbrdf.viewer.gpu.body_table_gpu import INTERACTIVE, STILL, BodyTables
from nbrdf.viewer.gpu.pipeline import BrdfKind, MaterialPipeline
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.options import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl

ASSETS = DEFAULT_MATERIAL.parent


@pytest.fixture(scope="module")
def setup(gl_ctx):
    pipe = MaterialPipeline(gl_ctx)
    r = Renderer(gl_ctx, mesh="sphere")
    state = ViewState(background=False, env_on=False)
    state.camera.distance = 2.2
    yield gl_ctx, pipe, r, state
    pipe.release()


def per_pixel_and_table(setup, material, size, table_of=None):
    ctx, pipe, r, state = setup
    brdf = pipe.build(material, "belcour")
    assert brdf.kind == BrdfKind.BELCOUR
    ref = r.render_linear(state, (48, 48), 1, brdf)
    tables = BodyTables(ctx)
    try:
        tb = tables.belcour(pipe.build(table_of or material, "belcour"), size, pipe.decoder)
        assert tb.kind == BrdfKind.TABLE
        img = r.render_linear(state, (48, 48), 1, tb)
    finally:
        tables.release()
    return ref, img


@pytest.mark.parametrize("name", ["varnished_copper.json", "car_paint.json", "clear_coat_plastic.json"])
@pytest.mark.parametrize("size,flip_max", [(INTERACTIVE, 0.02), (STILL, 0.01)], ids=["interactive", "still"])
def test_the_table_shades_what_the_model_does(setup, name, size, flip_max):
    from nbrdf.imaging.flip import flip

    m = load_material(ASSETS / name) if name != "varnished_copper.json" else load_material(DEFAULT_MATERIAL)
    ref, img = per_pixel_and_table(setup, m, size)
    mask = ref.sum(-1) > 1e-4
    assert mask.mean() > 0.2
    mean_rel = np.abs(img - ref)[mask].sum() / ref[mask].sum()
    f, _ = flip(ref, img)
    assert f <= flip_max and mean_rel < 0.03, (name, f, mean_rel)


def test_another_materials_table_is_seen(setup):
    """The check has teeth: the car paint's table under the default material's coat."""
    from nbrdf.imaging.flip import flip

    ref, img = per_pixel_and_table(setup, load_material(DEFAULT_MATERIAL), STILL,
                                   table_of=load_material(ASSETS / "car_paint.json"))
    assert flip(ref, img)[0] > 0.05


def test_the_baked_body_and_the_coat_are_the_model():
    """At the table's nodes, exp(body) + the closed-form coat is the Python model."""
    m = load_material(ASSETS / "car_paint.json")
    size = TableSize(12, 8, 4, ordered=True)
    wi, wo = (d.reshape(-1, 3).double() for d in table_directions(size))
    body = bake_body(m, size).reshape(-1, 3).double().exp()
    coat = coat_of(m)
    assert coat is not None and coat[1] > 1.0
    whole = body + coat_eval(torch.tensor(coat, dtype=torch.float64), wi, wo)[:, None]
    ref = belcour_eval_atoms(atoms_of(m), wi, wo, default_tables())
    np.testing.assert_allclose(whole.numpy(), ref.numpy(), rtol=1e-4, atol=1e-6)  # the coat: alpha round trip


def test_the_proxy_is_the_body_lobe_strategy():
    """A coat over a conductor samples the conductor's lobe (no cosine share to speak of);
    a coat over a diffuse base, having no lobe left, samples the cosine lobe."""
    metal = table_uniforms(load_material(DEFAULT_MATERIAL))
    plastic = table_uniforms(load_material(ASSETS / "clear_coat_plastic.json"))
    assert metal["u_proxy_w"] <= 0.5 and 0.02 <= metal["u_proxy_sigma"] <= 1.0
    assert plastic["u_proxy_w"] == 1.0
    assert metal["u_coat"][1] > 1.0 and plastic["u_coat"][1] > 1.0


def test_the_window_bakes_belcour_when_it_bakes_bodies(setup):
    """A Belcour material gets the table where the window uses tables, and the probe
    that decides is timed with the shared decoder when the first material is not neural."""
    from nbrdf.viewer.gpu.body_source import BodySettings, BodySource

    ctx, pipe, _, _ = setup
    brdf = pipe.build(load_material(DEFAULT_MATERIAL), "belcour")
    slow = BodySource(ctx, BodySettings(fast_ns_per_pixel=0.0), decoder=lambda: pipe.decoder)
    fast = BodySource(ctx, BodySettings(fast_ns_per_pixel=float("inf")), decoder=lambda: pipe.decoder)
    try:
        assert "baked body tables" in slow.calibrate(brdf) and slow.use_tables
        a = slow.for_frame(brdf, interactive=True)
        assert a.kind == BrdfKind.TABLE and a.body_table.size == (32, 16, 8)
        assert a.uniforms == table_uniforms(brdf.material)  # from the GpuBrdf's own decomposition
        assert slow.for_frame(brdf, interactive=True) is a  # one bake per edit
        assert "decoder in every frame" in fast.calibrate(brdf)
        assert fast.for_frame(brdf, interactive=True) is brdf  # a fast GPU shades the model per pixel
    finally:
        slow.release()
        fast.release()


def test_the_split_takes_the_top_interface_as_the_coat_and_samples_the_rest():
    """The lit pass's split (belcour_brdf.glsl NB_SPLIT_COAT): a coat over more stack is the coat, its lobe left
    out of the body's mixture (which sums to 1, or is empty over a diffuse base: the cosine lobe then); a stack
    whose top is no interface (a lone conductor) has no coat and keeps its whole mixture as the body's."""
    from nbrdf.neural.material import parse_material
    from nbrdf.viewer.gpu.belcour_gpu import belcour_uniforms

    metal = belcour_uniforms(load_material(DEFAULT_MATERIAL))
    top = load_material(DEFAULT_MATERIAL).layers[0]
    assert metal["u_bc_coat"] == (top.roughness, top.ior)
    assert metal["u_bc_body_w"][0] == 0.0 and abs(sum(metal["u_bc_body_w"]) - 1.0) < 1e-12
    plastic = belcour_uniforms(load_material(ASSETS / "clear_coat_plastic.json"))
    assert plastic["u_bc_coat"][1] > 1.0 and sum(plastic["u_bc_body_w"]) == 0.0
    gold = belcour_uniforms(parse_material({"format": "nbrdf-material/1", "name": "au", "layers": [
        {"type": "conductor", "roughness": 0.3, "r0": [1.0, 0.8, 0.3]}]}))
    assert gold["u_bc_coat"][1] == 1.0 and gold["u_bc_body_w"] == gold["u_bc_sample_w"]
