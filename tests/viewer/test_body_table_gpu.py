"""The baked body table on the GPU (viewer/gpu/body_table_gpu.py, body_table.glsl)
against the per-pixel decoder on a small offscreen render of the lit sphere.

Both renders use the same random numbers per pixel and pass, so their
difference is the table's error alone (no Monte Carlo noise between them)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from nbrdf.neural.body_table import TableSize
from nbrdf.neural.material import load_material
from nbrdf.viewer.gpu.body_table_gpu import INTERACTIVE, STILL, BodyTables
from nbrdf.viewer.gpu.lit_sampling import LitSampling
from nbrdf.viewer.gpu.pipeline import BrdfKind, MaterialPipeline
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.options import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def setup(gl_ctx):
    pipe = MaterialPipeline(gl_ctx)
    r = Renderer(gl_ctx, mesh="sphere")
    # one estimator for both draws (the decoder's table-guided resampling would draw other candidates)
    r.sampling = LitSampling(table_target=False)
    brdf = pipe.build(load_material(DEFAULT_MATERIAL), "neural")
    state = ViewState(background=False)
    state.camera.distance = 2.2
    ref = r.render_linear(state, (48, 48), 2, brdf)
    return gl_ctx, r, brdf, state, ref


@pytest.mark.parametrize("size,flip_max", [(INTERACTIVE, 0.02), (STILL, 0.01)], ids=["interactive", "still"])
def test_table_render_agrees_with_the_decoder(setup, size, flip_max):
    from nbrdf.imaging.flip import flip

    ctx, r, brdf, state, ref = setup
    tables = BodyTables(ctx)
    tb = tables.brdf(brdf, size)
    assert tb.kind == BrdfKind.TABLE and brdf.kind == BrdfKind.NEURAL
    img = r.render_linear(state, (48, 48), 2, tb)
    mask = ref.sum(-1) > 0
    assert mask.mean() > 0.2 and (img.sum(-1) > 0)[mask].all()
    mean_rel = np.abs(img - ref)[mask].sum() / ref[mask].sum()
    f, _ = flip(ref, img)
    assert f <= flip_max and mean_rel < 0.03, (f, mean_rel)
    tables.release()


def test_a_wrong_table_is_seen(setup):
    # The same check fails for a table of another material (the test can fail).
    from nbrdf.imaging.flip import flip

    ctx, r, brdf, state, ref = setup
    tables = BodyTables(ctx)
    other = MaterialPipeline(ctx).build(load_material(DEFAULT_MATERIAL), "neural",
                                        latent=brdf.latent[:, :32] * 0.5)
    img = r.render_linear(state, (48, 48), 2, tables.brdf(other, INTERACTIVE))
    assert flip(ref, img)[0] > 0.02
    tables.release()


def test_gpu_bake_equals_the_reference_bake(setup):
    from nbrdf.neural.body_table import bake_body

    ctx, _, brdf, _, _ = setup
    s = TableSize(12, 8, 4)
    a = BodyTables(ctx).bake(brdf.decoder.dec, brdf.latent, s)
    b = bake_body(brdf.decoder.dec, brdf.latent, s)
    assert torch.allclose(a, b, atol=1e-4)


def test_only_uniform_neural_materials_are_baked(setup):
    from nbrdf.neural.errors import NbrdfError

    ctx, _, brdf, _, _ = setup
    with pytest.raises(NbrdfError):
        BodyTables(ctx).brdf(type(brdf)(brdf.material, BrdfKind.ANALYTIC), INTERACTIVE)


def test_body_source_decides_from_the_measured_decoder_and_bakes_once_per_edit(setup):
    from nbrdf.viewer.gpu.body_source import BodySettings, BodySource

    ctx, _, brdf, _, _ = setup
    slow = BodySource(ctx, BodySettings(fast_ns_per_pixel=0.0))  # any measured cost is too slow
    assert "baked body tables" in slow.calibrate(brdf) and slow.use_tables and slow.ns_per_pixel > 0
    a = slow.for_frame(brdf, interactive=True)
    assert a.kind == BrdfKind.TABLE and a.body_table.size == (32, 16, 8)
    assert slow.for_frame(brdf, interactive=True) is a  # one bake per edit, not per frame
    still = slow.for_frame(brdf, interactive=False)
    assert still.kind == BrdfKind.TABLE and still.body_table.size == (48, 24, 12)
    edited = MaterialPipeline(ctx).build(brdf.material, "neural")
    assert slow.for_frame(edited, interactive=True) is not a
    assert slow.sampling(LitSampling()).every_candidate
    fast = BodySource(ctx, BodySettings(fast_ns_per_pixel=float("inf")))
    assert "decoder in every frame" in fast.calibrate(brdf) and not fast.use_tables
    assert fast.for_frame(brdf, interactive=True) is brdf
    base = LitSampling()
    assert fast.sampling(base) is base
    slow.release()
    fast.release()


def test_table_sampling_applies_to_table_draws_only(setup):
    ctx, r, brdf, state, ref = setup
    tb = BodyTables(ctx).brdf(brdf, STILL)
    plain = r.render_linear(state, (48, 48), 2, tb)
    r.table_sampling = LitSampling(ris_samples=2, ris_candidates=8)
    try:
        assert not np.array_equal(r.render_linear(state, (48, 48), 2, tb), plain)
        np.testing.assert_array_equal(r.render_linear(state, (48, 48), 2, brdf), ref)
    finally:
        r.table_sampling = None
