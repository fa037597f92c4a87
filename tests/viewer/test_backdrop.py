"""The backdrop pass: the background behind the object (environment, blurred
environment, flat colour, none) and the ground's contact shadow, composited
without touching the object's pixels."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from nbrdf.imaging.environment import default_environment
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import parse_material
from nbrdf.viewer.gpu.backdrop import Backdrop, BackdropSettings, blurred_environment, contact_shadow
from nbrdf.viewer.scene.mesh import named_mesh

GOLD = {"format": "nbrdf-material/1", "name": "g", "layers": [{"type": "conductor", "roughness": 0.3,
                                                             "r0": [1.0, 0.78, 0.34]}]}


def test_blurred_environment_keeps_the_energy_and_smooths():
    env = default_environment(256, 128)
    blur = blurred_environment(env, (128, 64), 9.0)
    assert blur.shape == (64, 128, 3) and np.isfinite(blur).all() and blur.min() >= 0
    # Row-weighted means (solid angle ~ sin theta) agree within 3 %; the sun's peak is spread out.
    w_env = np.sin((np.arange(128) + 0.5) / 128 * np.pi)[:, None, None]
    w_blur = np.sin((np.arange(64) + 0.5) / 64 * np.pi)[:, None, None]
    m_env = (env * w_env).sum((0, 1)) / (w_env.sum() * 256)
    m_blur = (blur * w_blur).sum((0, 1)) / (w_blur.sum() * 128)
    np.testing.assert_allclose(m_blur, m_env, rtol=0.03)
    assert blur.max() < 0.2 * env.max()


def test_contact_shadow_is_darkest_under_the_contact_point():
    m = named_mesh("sphere")
    shadow, z0 = contact_shadow(m.positions, m.indices, res=64, extent=1.8)
    assert z0 == pytest.approx(-1.0, abs=1e-3) and shadow.shape == (64, 64)
    assert 0.0 <= shadow.min() and shadow.max() <= 0.9
    centre, rim, far = shadow[32, 32], shadow[32, 32 + 18], shadow[2, 2]  # 0, ~1 and 2.4 units out
    assert centre > 0.6 and centre > rim > far and far < 0.01


@pytest.fixture(scope="module")
def scene(gl_ctx):
    from nbrdf.viewer.gpu.pipeline import MaterialPipeline
    from nbrdf.viewer.gpu.renderer import Renderer, ViewState

    r = Renderer(gl_ctx, mesh="sphere")
    brdf = MaterialPipeline(gl_ctx).build(parse_material(GOLD), "analytic")
    return r, Backdrop(gl_ctx, r), brdf, ViewState(env_intensity=0.8, env_rotation=30.0)


def test_object_pixels_are_untouched_and_flat_background_is_exact(scene):
    r, backdrop, brdf, state = scene
    size = (32, 24)
    plain = r.render_linear(replace(state, background=False), size, 1, brdf)
    mask = r.gbuffer(state, size, brdf)[2]
    flat = backdrop.render_linear(state, size, 1, brdf, BackdropSettings("flat", (0.2, 0.3, 0.4), ground=False))
    np.testing.assert_allclose(flat[mask], plain[mask], rtol=1e-5, atol=1e-7)  # float32 rounding
    np.testing.assert_allclose(flat[~mask], np.broadcast_to([0.2, 0.3, 0.4], flat[~mask].shape), atol=1e-6)
    none = backdrop.render_linear(state, size, 1, brdf, BackdropSettings("none", ground=False))
    assert none[~mask].max() == 0.0


def test_environment_background_matches_the_renderers_own(scene):
    r, backdrop, brdf, state = scene
    size = (32, 24)
    own = r.render_linear(state, size, 1, brdf)  # the renderer draws the environment behind the object
    env = backdrop.render_linear(state, size, 1, brdf, BackdropSettings("env", ground=False))
    np.testing.assert_allclose(env, own, rtol=2e-3, atol=2e-4)


def test_ground_shadow_darkens_only_the_ground_under_the_object(scene):
    r, backdrop, brdf, state = scene
    size = (48, 36)
    mask = r.gbuffer(state, size, brdf)[2]
    lit = backdrop.render_linear(state, size, 1, brdf, BackdropSettings("flat", (0.5, 0.5, 0.5), ground=True))
    ratio = lit[..., 1] / 0.5
    rows = np.nonzero(mask.any(1))[0]
    below = ratio[rows.max() + 1:rows.max() + 3, 20:28]  # just under the sphere's lowest pixel
    assert below.size and below.max() < 0.8  # darkened
    assert ratio[0, 0] == pytest.approx(1.0, abs=1e-6) and ratio[0, -1] == pytest.approx(1.0, abs=1e-6)  # sky


def test_bad_settings_are_one_line_errors():
    with pytest.raises(NbrdfError, match="--background"):
        BackdropSettings("checker")
    with pytest.raises(NbrdfError, match="colour"):
        BackdropSettings("flat", (1.0, float("nan"), 0.0))


def test_the_background_is_kept_across_an_edits_frames_and_drawn_again_when_what_it_shows_changes(scene, gl_ctx):
    r, backdrop, brdf, state = scene
    size = (32, 24)
    settings = BackdropSettings("env", ground=True)

    def fresh(s):  # a backdrop of its own: its background drawn for this state alone
        other = Backdrop(gl_ctx, r)
        try:
            return other.render_linear(s, size, 1, brdf, settings)
        finally:
            other.release()

    first = backdrop.render_linear(state, size, 1, brdf, settings)
    kept = backdrop._bg_keys[("linear", *size)]
    np.testing.assert_array_equal(backdrop.render_linear(state, size, 1, brdf, settings), first)
    assert backdrop._bg_keys[("linear", *size)] is kept  # not drawn again
    turned = replace(state, env_rotation=120.0)
    np.testing.assert_array_equal(backdrop.render_linear(turned, size, 1, brdf, settings), fresh(turned))
    moved = replace(state, camera=replace(state.camera))
    backdrop.render_linear(moved, size, 1, brdf, settings)
    moved.camera.yaw += 40.0  # the same camera changed in place, as the window's orbit does
    np.testing.assert_array_equal(backdrop.render_linear(moved, size, 1, brdf, settings), fresh(moved))
    flat = BackdropSettings("flat", (0.2, 0.3, 0.4), ground=False)
    mask = r.gbuffer(state, size, brdf)[2]
    img = backdrop.render_linear(state, size, 1, brdf, flat)
    np.testing.assert_allclose(img[~mask], np.broadcast_to([0.2, 0.3, 0.4], img[~mask].shape), atol=1e-6)
