"""The window never waits on the renderer (issue 41): with a deliberately slow pass (the
lit passes made to sleep 0.8 s per pass over the whole view, in proportion to the
rows they shade), the still view's frames stay within a frame budget while its passes
accumulate -- the pass is shaded in bands over several frames (viewer/jobs/pass_bands.py),
not in one frame that holds the interface for the whole pass."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from nbrdf.viewer.options import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl

SCRIPT = textwrap.dedent("""
    import json, sys, time
    import nbrdf.viewer.gpu.lit_passes as lit_passes
    from nbrdf.viewer.ui.app import App
    from nbrdf.viewer.options import ViewOptions

    PASS_S = 0.8  # a slow GPU: one pass over the whole view takes this long

    def slowed(real):
        def lit(self, state, w, h, first, passes, *a, **k):
            out = real(self, state, w, h, first, passes, *a, **k)
            y0, y1 = k.get("rows") or (0, h)
            time.sleep(PASS_S * max(passes, 0) * (y1 - y0) / h)
            return out
        return lit

    lit_passes.LitPasses.deferred = slowed(lit_passes.LitPasses.deferred)
    lit_passes.LitPasses.fragment = slowed(lit_passes.LitPasses.fragment)
    try:  # this slow GPU's rows cost alike, on the object or off it: the bands weigh them so
        from nbrdf.viewer.jobs.pass_bands import PassBands
        PassBands.weights = staticmethod(lambda coverage, w: coverage * 0.0 + float(w))
    except ImportError:  # a window without bands
        pass
    app = App(ViewOptions(material=sys.argv[1], size=(320, 240)), size=(320, 240))
    app.panels.visible = False
    app.frame()
    app.warmup.settings.enabled = False  # no shader compiles in the timed frames
    ld = app.lookdev
    try:
        for _ in range(400):  # until the still view shows a complete full-resolution pass
            app.step()
            if app.scale == 1.0 and not app.interactive and ld.passes > 0:
                break
        frames, passes = [], []
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < 6.0:
            t = time.perf_counter()
            app._on_cursor(app.window, 100.0 + len(frames) % 5, 100.0)  # a person's pointer: the interface is not idle
            app.step()
            frames.append((time.perf_counter() - t) * 1000.0)
            passes.append(ld.passes)
        print(json.dumps({"frames": frames, "passes": passes, "scale": app.scale}))
    finally:
        app.close()
""")


@pytest.fixture(scope="module")
def still(xvfb_display):
    env = dict(os.environ, DISPLAY=xvfb_display)
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(DEFAULT_MATERIAL)], env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_still_frames_stay_within_a_frame_budget_with_a_slow_pass(still):
    frames = np.array(still["frames"])
    # A whole pass takes 0.8 s or more here; the interface's frames stay near the 40 ms budget
    # (bounds loose for a loaded machine, far under one pass).
    assert len(frames) >= 20, still
    assert np.median(frames) < 120.0, still
    assert np.percentile(frames, 90) < 250.0, still


def test_the_still_view_accumulates_while_the_frames_stay_short(still):
    passes = still["passes"]
    assert still["scale"] == 1.0
    assert passes[-1] - passes[0] >= 2, still  # 6 s of frames: passes of 0.8 s complete all the same
    assert all(b - a in (0, 1) for a, b in zip(passes, passes[1:])), still  # a pass at a time, in order
