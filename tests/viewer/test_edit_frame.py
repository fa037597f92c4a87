"""What makes an edit's frame fast on software OpenGL (docs/decisions/113), each against the
image it replaces: the compute pass covers the object's box on screen only; a slider's frames
reuse the G-buffer of the same surface; the compositor's own program for A alone; the
interactive frames' coarse body environment map."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from gpu_brdfs import table_renderer as make_table_renderer

from nbrdf.imaging.tonemap import ToneMap
from nbrdf.viewer.gpu import gl
from nbrdf.viewer.gpu.body_table_gpu import INTERACTIVE
from nbrdf.viewer.gpu.env_prefilter import QUICK_PREFILTER
from nbrdf.viewer.gpu.lit_passes import screen_box
from nbrdf.viewer.gpu.renderer import Renderer, ViewState
from nbrdf.viewer.modes import CompareMode
from nbrdf.viewer.reference.compare import Compare
from nbrdf.viewer.scene.camera import OrbitCamera

pytestmark = pytest.mark.gl

SIZE = 48


@pytest.fixture(scope="module")
def table_renderer(gl_ctx):
    if gl_ctx.version_code < gl.COMPUTE_VERSION:
        pytest.skip("no OpenGL 4.3 here: a compute path")
    r, body, tables = make_table_renderer(gl_ctx, INTERACTIVE)
    yield r, body
    tables.release()


def _coverage(r: Renderer, state: ViewState, w: int, h: int) -> np.ndarray:
    """(h, w) bool, GL's rows (bottom up): the pixels the G-buffer covers."""
    tex = r.accumulate(state, w, h, 0, 1, slot="box")
    return np.frombuffer(tex.read(), np.float32).reshape(h, w, 4)[..., 3] > 0


@pytest.mark.parametrize("distance,yaw,pitch,size", [(3.2, -55, 22, (64, 48)), (1.6, 30, -40, (40, 72)),
                                                     (1.15, 0, 80, (56, 56))])
def test_the_screen_box_holds_every_pixel_of_the_object_and_little_else(table_renderer, distance, yaw, pitch,
                                                                         size):
    r, _ = table_renderer
    w, h = size
    cam = OrbitCamera(yaw=yaw, pitch=pitch, distance=distance)
    state = ViewState(background=False, camera=cam)
    x0, x1, y0, y1 = screen_box(r.lit.bounds, cam.view(), cam.projection(w / h), w, h)
    r.lit.bounds, bounds = None, r.lit.bounds  # the whole target shaded: the coverage to hold
    try:
        cover = _coverage(r, state, w, h)
    finally:
        r.lit.bounds = bounds
    ys, xs = np.nonzero(cover)
    assert len(xs) > 0
    assert xs.min() >= x0 and xs.max() < x1 and ys.min() >= y0 and ys.max() < y1, ((x0, x1, y0, y1), cover.shape)
    # tight: at most 2 pixels wider than the object each side (where the object is not cut by the frame)
    assert (x1 - x0) <= xs.max() - xs.min() + 1 + 4 and (y1 - y0) <= ys.max() - ys.min() + 1 + 4
    # and the pass shaded within it leaves the same image
    box = _coverage(r, state, w, h)
    np.testing.assert_array_equal(box, cover)


def test_the_screen_box_is_the_whole_axis_where_the_eye_is_inside_the_ball():
    cam = OrbitCamera(distance=0.5)
    assert screen_box((np.zeros(3), 1.0), cam.view(), cam.projection(1.0), 30, 20) == (0, 30, 0, 20)
    assert screen_box(None, cam.view(), cam.projection(1.0), 30, 20) == (0, 30, 0, 20)


def test_a_sliders_frames_reuse_the_gbuffer_of_the_same_surface_only(table_renderer, gl_ctx):
    r, body = table_renderer
    state = ViewState(background=False)
    moved = replace(state, camera=OrbitCamera(yaw=10.0, pitch=5.0, distance=2.8))
    fresh = Renderer(gl_ctx, brdf=body, mesh="sphere")
    fresh.sampling = r.sampling

    fresh_slots = iter(range(100))

    def image(renderer, s):
        # ``fresh`` draws each image into a slot of its own: a G-buffer rastered for it
        slot = "reuse" if renderer is r else f"fresh{next(fresh_slots)}"
        tex = renderer.accumulate(s, SIZE, SIZE, 0, 1, slot=slot)
        return np.frombuffer(tex.read(), np.float32).reshape(SIZE, SIZE, 4).copy()

    image(r, state)
    held = r.lit._surfaces[("reuse", SIZE, SIZE)]
    again = image(r, state)  # first pass again, same surface: no raster
    assert r.lit._surfaces[("reuse", SIZE, SIZE)] is held
    np.testing.assert_array_equal(again, image(fresh, state))
    # the camera moved (the same camera object changed in place, as the window's orbit does): rastered again
    state.camera.yaw += 25.0
    np.testing.assert_array_equal(image(r, state), image(fresh, state))
    np.testing.assert_array_equal(image(r, moved), image(fresh, moved))
    r.set_mesh("testmesh")
    fresh.set_mesh("testmesh")
    try:
        np.testing.assert_array_equal(image(r, moved), image(fresh, moved))
    finally:
        r.set_mesh("sphere")
        fresh.release_targets()


@pytest.mark.parametrize("tonemap", list(ToneMap))
def test_the_compositors_own_program_for_one_image_draws_what_the_general_one_does(table_renderer, gl_ctx,
                                                                                   tonemap):
    r, _ = table_renderer
    compare = Compare(gl_ctx, r)
    try:
        rng = np.random.default_rng(3)
        data = (rng.random((20, 30, 4)) * 4.0).astype("f4")
        src = gl_ctx.texture((30, 20), 4, data.tobytes(), dtype="f4")
        outs = []
        for plain in (True, False):
            fbo = gl_ctx.simple_framebuffer((30, 20), components=4)
            # the general program drawing A alone, forced
            if not plain:
                compare._compositors[(True, tonemap.code)] = compare.compositor(False, tonemap.code)
            compare.composite(fbo, src, 2.0, src, 2.0, CompareMode.OFF, None, 0.5, 1.0, 0.7, tonemap)
            outs.append(np.frombuffer(fbo.read(components=4), np.uint8).reshape(20, 30, 4).copy())
            fbo.release()
            compare._compositors.pop((True, tonemap.code), None)
        assert outs[0][..., :3].std() > 5  # a picture, not a constant
        np.testing.assert_array_equal(outs[0], outs[1])
        src.release()
    finally:
        compare.close()


def test_interactive_frames_read_their_own_coarse_map_and_show_the_still_image(table_renderer):
    r, body = table_renderer
    state = ViewState(background=False)
    state.camera.distance = 2.6
    ref = r.render_linear(state, (SIZE, SIZE), 64)  # the accumulated estimator, converged
    r.quick = True
    try:
        sampled = r.render_linear(state, (SIZE, SIZE), 1)  # the quick estimator: one pass
        r.settings.quick_prefilter = QUICK_PREFILTER
        assert r.lit.prefiltered(state, body) and r.lit.prefilter().settings == QUICK_PREFILTER
        mapped = r.render_linear(state, (SIZE, SIZE), 1)
        r.quick = False
        assert not r.lit.prefiltered(state, body)  # the still view: no map unless its own is set
    finally:
        r.quick = False
        r.settings.quick_prefilter = None
    mask = ref.sum(-1) > 0

    def error(img):
        return float(np.abs(img - ref)[mask].sum() / ref[mask].sum())
    e_map, e_sampled = error(mapped), error(sampled)
    # measured: the map's one frame 1.3 % from the converged image (bias -0.3 %), the quick estimator's 16 %
    assert e_map < 0.03 and e_map < 0.25 * e_sampled, (e_map, e_sampled)
    bias = mapped[mask].sum() / ref[mask].sum() - 1.0
    assert math.isfinite(bias) and abs(bias) < 0.01, bias
