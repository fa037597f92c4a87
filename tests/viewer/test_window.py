"""The window under Xvfb: the App's frame equals the offscreen renderer's
for the same state (same Renderer code path, different framebuffer)."""
from __future__ import annotations

import numpy as np
import pytest

from viewer.image_io import tonemap
from viewer.view_cli import DEFAULT_MATERIAL, ViewOptions

pytestmark = pytest.mark.gl


def test_window_matches_offscreen(xvfb_display, monkeypatch, gl_ctx):
    monkeypatch.setenv("DISPLAY", xvfb_display)
    from viewer.app import App
    from viewer.renderer import Renderer, ViewState
    from neural.material import load_material

    opts = ViewOptions(material=DEFAULT_MATERIAL, size=(64, 48))
    app = App(opts, size=(64, 48))
    try:
        for _ in range(4):
            app.step()
        shown = app.read_pixels().astype(int)
        assert app.passes == 4 and app.frame_ms > 0
    finally:
        app.close()
    ref = Renderer(gl_ctx, load_material(DEFAULT_MATERIAL)).render_linear(ViewState(), (64, 48), spp=4)
    expected = tonemap(ref).astype(int)
    assert shown.shape == expected.shape
    assert np.abs(shown - expected).max() <= 2  # 8-bit rounding in GLSL vs numpy
