"""The window under Xvfb: the App's frame equals the offscreen renderer's
for the same state (same Renderer code path, different framebuffer).

The window runs in a child process: an EGL context current in this process
(the offscreen tests' fixture) and a GLX window context do not mix in one
thread, and Xlib answers that by ending the process."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from viewer.image_io import tonemap
from viewer.view_cli import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl

SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    from viewer.app import App
    from viewer.view_cli import ViewOptions
    app = App(ViewOptions(material=sys.argv[1], size=(64, 48)), size=(64, 48))
    try:
        for _ in range(4):
            app.step()
        assert app.passes == 4 and app.frame_ms > 0
        np.save(sys.argv[2], app.read_pixels())
    finally:
        app.close()
""")


def test_window_matches_offscreen(xvfb_display, gl_ctx, tmp_path):
    from neural.material import load_material
    from viewer.renderer import ViewState
    from viewer.view_cli import ViewOptions, make_renderer

    env = dict(os.environ, DISPLAY=xvfb_display)
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(DEFAULT_MATERIAL), str(tmp_path / "win.npy")],
                       env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    shown = np.load(tmp_path / "win.npy").astype(int)
    renderer = make_renderer(gl_ctx, load_material(DEFAULT_MATERIAL), ViewOptions(material=DEFAULT_MATERIAL))
    ref = renderer.render_linear(ViewState(), (64, 48), spp=4)
    expected = tonemap(ref).astype(int)
    assert shown.shape == expected.shape
    assert np.abs(shown - expected).max() <= 2  # 8-bit rounding in GLSL vs numpy
