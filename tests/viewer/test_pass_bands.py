"""A still view's pass shaded in bands of rows over several frames (viewer/gpu/renderer.py
``begin_pass`` / ``shade_rows`` / ``end_pass``, viewer/jobs/pass_bands.py): the same
estimator as passes shaded whole -- the accumulation after N complete passes is the
unsliced one's -- counted only when complete, with the last complete image shown until
the first pass is in, and bands sized from their measured cost."""
from __future__ import annotations

import numpy as np
import pytest

from nbrdf.neural.material import load_material
from nbrdf.viewer.gpu import gl
from nbrdf.viewer.gpu.pipeline import MaterialPipeline
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.jobs.pass_bands import PROBE_PIXELS, BandCost, CostFit, PassBands
from nbrdf.viewer.options import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl

W, H = 40, 36


def _image(tex) -> np.ndarray:
    w, h = tex.size
    return np.frombuffer(tex.read(), np.float32).reshape(h, w, 4).copy()


def _banded(r: Renderer, state: ViewState, passes: int, bands: list[int], slot: str) -> np.ndarray:
    """``passes`` passes, each shaded in bands of the given heights (repeated), merged when complete."""
    for k in range(passes):
        r.begin_pass(state, W, H, k, slot=slot)
        y, i = 0, 0
        while y < H:
            r.shade_rows(state, W, H, k, (y, y + bands[i % len(bands)]), slot=slot)
            y, i = y + bands[i % len(bands)], i + 1
        tex = r.end_pass(state, W, H, k, slot=slot)
    return _image(tex)


@pytest.mark.parametrize("compute", [True, False], ids=["compute", "fragment"])
@pytest.mark.parametrize("background", [False, True], ids=["object", "with-environment"])
def test_passes_in_bands_accumulate_the_image_of_whole_passes(gl_ctx, compute, background):
    if compute and gl_ctx.version_code < gl.COMPUTE_VERSION:
        pytest.skip("no OpenGL 4.3 here")
    brdf = MaterialPipeline(gl_ctx).build(load_material(DEFAULT_MATERIAL), "neural")
    r = Renderer(gl_ctx, brdf=brdf, compute=compute)
    state = ViewState(point_light=(1.5, -1.0, 2.0), background=background)
    whole = _image(r.accumulate(state, W, H, 0, 3, slot="whole"))
    banded = _banded(r, state, 3, [5, 13, 1, 8], "banded")
    assert whole[..., 3].max() == 3.0  # the object's pixels count 3 passes (a nonempty image)
    # The environment's alpha counts the calls that drew it (one here, one per pass banded): its
    # radiance is the same, and the window's view draws no environment into the accumulation.
    channels = slice(0, 3) if background else slice(0, 4)
    np.testing.assert_allclose(banded[..., channels], whole[..., channels], rtol=2e-5, atol=1e-6)


def test_the_accumulation_holds_whole_passes_only(gl_ctx):
    """Until its last band, a pass is in the pending image: the accumulation (what the view
    divides by its pass count) is untouched, also by the first pass of a restart."""
    brdf = MaterialPipeline(gl_ctx).build(load_material(DEFAULT_MATERIAL), "neural")
    r = Renderer(gl_ctx, brdf=brdf)
    state = ViewState()
    before = _banded(r, state, 2, [H], "s")
    r.begin_pass(state, W, H, 2, slot="s")
    r.shade_rows(state, W, H, 2, (0, H // 2), slot="s")
    np.testing.assert_array_equal(_image(r.frame_texture("object", W, H, "s")), before)
    r.begin_pass(state, W, H, 0, slot="s")  # a restart: the old image stays until the new first pass is in
    r.shade_rows(state, W, H, 0, (0, H - 1), slot="s")
    np.testing.assert_array_equal(_image(r.frame_texture("object", W, H, "s")), before)
    r.shade_rows(state, W, H, 0, (H - 1, H), slot="s")
    one = _image(r.end_pass(state, W, H, 0, slot="s"))
    assert one[..., 3].max() == 1.0


def test_band_rows_follow_the_measured_cost_of_the_object_rows():
    """Rows off the object are nearly free: a band takes many of them, few of the object's;
    an unknown cost is probed with PROBE_PIXELS; a band never misses the budget by its merge."""
    coverage = np.array([0] * 64 + [100] * 64 + [0] * 64)
    weights = PassBands.weights(coverage, 100)
    line = (0.0, 0.01)  # ms per weighted pixel: an object row costs 1 ms, an empty one 1/8 ms
    end = PassBands._rows(0, weights, line, budget_ms=20.0, end_ms=0.0)
    assert end == 72  # every empty row (8 ms), then the 12 object rows of the rest: 76, aligned to 8
    assert PassBands._rows(64, weights, line, budget_ms=10.0, end_ms=0.0) == 72  # 10 rows fit: a work group's 8
    assert PassBands._rows(64, weights, (6.0, 0.01), budget_ms=10.0, end_ms=0.0) == 68  # the fixed 6 ms: 4 rows
    assert PassBands._rows(64, weights, (20.0, 0.01), budget_ms=10.0, end_ms=0.0) == 65  # one row at least
    assert PassBands._rows(64, weights, line, budget_ms=30.0, end_ms=0.0) == 88  # 30 rows fit: 24
    assert PassBands._rows(64, weights, line, budget_ms=30.0, end_ms=0.0, most=1000.0) == 72  # at most 10 rows
    assert PassBands._rows(128, weights, line, budget_ms=100.0, end_ms=0.0) == 192  # the rest fits
    assert PassBands._rows(128, weights, line, budget_ms=2.0, end_ms=5.0) < 192  # not with the merge
    big = PassBands.weights(np.full(1000, 100), 100)
    probe = PassBands._rows(0, big, None, budget_ms=10.0, end_ms=0.0)
    assert abs(big[:probe].sum() - PROBE_PIXELS) <= 8 * 100  # PROBE_PIXELS, to a work group's rows


def test_the_cost_fit_separates_a_bands_fixed_cost_from_its_pixels():
    fit = CostFit()
    for weight in (1000.0, 4000.0, 2000.0, 8000.0):
        fit.add(weight, 5.0 + 0.002 * weight)  # 5 ms per dispatch, 2 us per pixel
    fixed, per_px = fit.line()
    assert fixed == pytest.approx(5.0) and per_px == pytest.approx(0.002)
    alike = CostFit()
    alike.add(1000.0, 7.0)
    assert alike.line() == (0.0, pytest.approx(0.007))  # one band: through the origin
    c = BandCost()
    assert c.line("k") is None and c.most("k") == PROBE_PIXELS
    c.band("k", 10000.0, 70.0)
    assert c.most("k") == 20000.0  # a band grows to twice the largest measured
    c = BandCost()
    c.band("k", 1000.0, 7.0)
    assert c.line("k") == (0.0, pytest.approx(0.007))
    assert c.line("other") == (0.0, pytest.approx(0.014))  # not measured yet: twice the last cost


# --------------------------------------------------------------------- through the session's view
SIZE = (48, 40)


@pytest.fixture
def session(gl_ctx, monkeypatch):
    from nbrdf.viewer.jobs import pass_bands
    from nbrdf.viewer.session.lookdev import LookDev

    monkeypatch.setattr(pass_bands, "PROBE_PIXELS", 1)  # no whole first pass as the probe of an unknown cost
    ld = LookDev(gl_ctx, load_material(DEFAULT_MATERIAL))
    fbo = gl_ctx.simple_framebuffer(SIZE, components=4)
    yield ld, fbo
    ld.close()


def _shown(fbo) -> np.ndarray:
    return np.frombuffer(fbo.read(components=3), np.uint8).reshape(SIZE[1], SIZE[0], 3).astype(int)


def test_the_view_in_bands_counts_whole_passes_and_shows_the_unsliced_image(session, monkeypatch):
    from nbrdf.viewer.jobs import view_frames

    # every complete pass on screen at once (the window composites more passes of one image at most once a
    # second: tests/viewer/test_compose_throttle.py)
    monkeypatch.setattr(view_frames, "COMPOSE_INTERVAL_S", 0.0)
    ld, fbo = session
    tiny = 1e-6  # every band the least: one row
    frames = []
    while ld.passes < 3:
        ld.render(fbo, SIZE, budget_ms=tiny)
        frames.append(ld.passes)
        assert len(frames) < 400
    per_pass = SIZE[1]  # bands of one row
    assert frames[:per_pass] == [0] * (per_pass - 1) + [1]  # a pass counts when its last band is in
    assert len(frames) == 3 * per_pass
    banded = _shown(fbo)
    ld.invalidate()
    ld.render(fbo, SIZE, 3)  # three whole passes
    assert np.abs(banded - _shown(fbo)).max() <= 1  # the same image (8-bit rounding aside)


def test_a_restarted_view_shows_its_last_image_until_a_pass_is_complete(session):
    ld, fbo = session
    ld.render(fbo, SIZE, 4)
    before = _shown(fbo)
    ld.invalidate()  # what the refinement does when its preview gives way to the full estimator
    assert ld.restarted
    ld.render(fbo, SIZE, budget_ms=1e-6)
    assert ld.passes == 0 and not ld.restarted  # a band shaded: drawing goes on, no change seen
    assert np.array_equal(_shown(fbo), before)  # not black, not a partial pass


def test_a_mapped_still_view_stops_at_its_cap(session):
    # The still view that reads the body environment map (viewer/gpu/env_prefilter.py) stops at
    # MAPPED_MAX_PASSES: later frames draw the kept image again and shade nothing.
    from nbrdf.viewer.gpu.env_prefilter import PrefilterSettings
    from nbrdf.viewer.jobs.view_frames import MAPPED_MAX_PASSES

    ld, fbo = session
    ld.bodies.use_tables = True  # frames shaded from baked tables, as on software OpenGL
    ld.renderer.table_sampling = ld.bodies.sampling(ld.renderer.sampling)
    ld.renderer.settings.prefilter = PrefilterSettings(size=16, draws=1)
    try:
        ld.invalidate()
        for _ in range(2000):
            ld.render(fbo, SIZE, budget_ms=1000.0)
            if ld.passes >= MAPPED_MAX_PASSES:
                break
        assert ld.passes == MAPPED_MAX_PASSES and ld.frames.cap == MAPPED_MAX_PASSES
        shown = _shown(fbo)
        for _ in range(3):
            ld.render(fbo, SIZE, budget_ms=1000.0)
            assert ld.passes == MAPPED_MAX_PASSES and ld.frames.accum_ms == 0.0  # nothing shaded
        assert np.array_equal(_shown(fbo), shown)  # the same image on screen
    finally:
        ld.renderer.settings.prefilter = None
        ld.renderer.table_sampling = None
        ld.bodies.use_tables = None


def test_the_compare_view_is_shaded_in_bands_with_its_reference_coat(session, monkeypatch):
    """Side by side with a stack's reference, still frames shade in bands too (they were whole passes: 1.2 s
    frames at 1080p, the interface answering once a second): the neural half and the reference's coat
    accumulation (its own estimator, in the same bands) are those of whole passes."""
    from nbrdf.viewer.jobs import view_frames
    from nbrdf.viewer.modes import View
    from nbrdf.viewer.reference.compare import REFERENCE_SLOT

    monkeypatch.setattr(view_frames, "COMPOSE_INTERVAL_S", 0.0)
    ld, fbo = session
    assert ld.set_compare("side")
    half = (SIZE[0] // 2, SIZE[1])

    def coat() -> np.ndarray:
        tex = ld.renderer.frame_texture(View.OBJECT, *half, REFERENCE_SLOT)
        return np.frombuffer(tex.read(), np.float32).reshape(half[1], half[0], 4)

    frames = 0
    while ld.passes < 2:
        ld.render(fbo, SIZE, budget_ms=1e-6)
        frames += 1
        assert frames < 400
    assert frames > 2  # in bands, not a whole pass a frame
    banded_coat, banded = coat(), _shown(fbo)[:, : half[0]]
    ld.invalidate()
    ld.render(fbo, SIZE, 2)  # two whole passes
    assert banded_coat[..., 3].max() == 2.0  # the coat's accumulation holds two passes (a nonempty image)
    np.testing.assert_allclose(banded_coat, coat(), rtol=2e-5, atol=1e-6)
    assert np.abs(banded - _shown(fbo)[:, : half[0]]).max() <= 1  # the neural half, 8-bit rounding aside
