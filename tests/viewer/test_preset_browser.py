"""The preset browser in the window (Xvfb, through the app's API): every
bundled preset gets a thumbnail, drawn in the material panel; a second start
reads them all from the cache (none rendered)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

pytestmark = [pytest.mark.gl, pytest.mark.slow]

SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    from nbrdf.viewer.ui.app import App
    from nbrdf.viewer.options import ViewOptions
    size = (900, 700)
    app = App(ViewOptions(size=size), size=size)
    app._adapt_scale = lambda w, h: 0.125
    browser = app.panels.presets
    browser.default_open = True
    browser.cache.spp = 2
    out = {}
    try:
        for _ in range(40):
            app.step()
            if browser.pending() == 0:  # every thumbnail made (the header opened at once)
                break
        app.step()
        out = {"pending": browser.pending(), "failed": browser.failed, "rendered": browser.cache.rendered,
               "shown": len(browser._textures)}
        np.save(sys.argv[1] + ".npy", app.read_pixels())
        x0, y0, vw, vh = app.viewport()
        out["view_x"] = x0
    finally:
        app.close()
    json.dump(out, open(sys.argv[1], "w"))
""")


def _run(env, path):
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(path)], env=env, capture_output=True, text=True,
                       timeout=1200)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(path.read_text()), np.load(str(path) + ".npy")


def test_browser_shows_cached_thumbnails(xvfb_display, tmp_path):
    from nbrdf.viewer.session.edits import presets

    env = dict(os.environ, DISPLAY=xvfb_display, HOME=str(tmp_path), XDG_CACHE_HOME=str(tmp_path / "cache"))
    first, screen = _run(env, tmp_path / "a.json")
    n = len(presets())
    assert first["pending"] == 0 and first["failed"] == {} and first["shown"] == n and first["rendered"] == n
    assert len(list((tmp_path / "cache" / "nbrdf" / "thumbnails").glob("*.png"))) == n
    # The thumbnails are on screen in the left panel: gold presets put saturated warm pixels there.
    panel = screen[:, :first["view_x"]].astype(int)
    warm = (panel[..., 0] - panel[..., 2] > 60) & (panel[..., 0] > 120)
    assert warm.sum() > 200
    second, _ = _run(env, tmp_path / "b.json")
    assert second["shown"] == n and second["rendered"] == 0  # read from the cache, none rendered again
