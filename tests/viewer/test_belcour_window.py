"""``nbrdf-view M --brdf belcour`` in the window (Xvfb, driven through its API in
a child process as tests/viewer/test_app.py does): it opens on Belcour's model,
the panel's BRDF choice flips to the neural path and back on the same
material, and a material the model does not hold is shown neural with one line."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from nbrdf.imaging.image_io import tonemap
from nbrdf.viewer.gpu.belcour_gpu import MAX_ATOMS
from nbrdf.viewer.options import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl

CAR_PAINT = DEFAULT_MATERIAL.parent / "car_paint.json"

SCRIPT = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    import numpy as np
    from nbrdf.viewer.ui.app import App
    from nbrdf.viewer.options import ViewOptions
    tmp, deep = Path(sys.argv[2]), sys.argv[3]
    app = App(ViewOptions(material=sys.argv[1], size=(48, 40), brdf="belcour"), size=(48, 40))
    app.refine.settings.adaptive = False   # full resolution: compared pixel for pixel
    app.lookdev.bodies.use_tables = False  # the per-pixel decoder when neural (as offscreen)
    app.panels.visible = False
    app.frame()
    ld = app.lookdev
    out = {}
    try:
        def frame():
            for _ in range(2):
                app.step()
            return app.read_pixels()
        out["kinds"] = [ld.brdf.kind.value]
        a = frame()
        out["to_neural"] = ld.set_brdf_mode("neural")
        out["kinds"].append(ld.brdf.kind.value)
        b = frame()
        out["to_belcour"] = ld.set_brdf_mode("belcour")
        out["kinds"].append(ld.brdf.kind.value)
        c = frame()
        out["bad_mode"] = [ld.set_brdf_mode("belcor"), ld.error]
        out["undo_steps"] = len(ld.history.undo_stack)
        out["deep"] = [ld.open_material(deep), ld.brdf.kind.value, ld.notice, ld.brdf_note]
        app.panels.visible = app.panels.expand_all = True  # the panel with its BRDF combo draws
        app.step()
        out["back"] = [ld.open_material(sys.argv[1]), ld.brdf.kind.value, ld.notice]
        np.savez(tmp / "frames.npz", a=a, b=b, c=c)
    finally:
        app.close()
    (tmp / "out.json").write_text(json.dumps(out, default=str))
""")


@pytest.fixture(scope="module")
def window_run(xvfb_display, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("belcour_window")
    deep = tmp / "deep.json"
    layers = [{"type": "dielectric", "roughness": 0.1, "ior": 1.2}] * MAX_ATOMS
    deep.write_text(json.dumps({"format": "nbrdf-material/1", "name": "deep", "layers": layers + [
        {"type": "conductor", "roughness": 0.3, "r0": 0.9}]}))
    env = dict(os.environ, DISPLAY=xvfb_display)
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(CAR_PAINT), str(tmp), str(deep)], env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads((tmp / "out.json").read_text()), np.load(tmp / "frames.npz")


def test_window_opens_on_belcour_and_flips_to_neural_and_back(window_run):
    out, f = window_run
    assert out["kinds"] == ["belcour", "neural", "belcour"] and out["to_neural"] and out["to_belcour"]
    assert np.abs(f["a"].astype(int) - f["b"]).mean() > 1.0  # two different models of the car paint
    np.testing.assert_array_equal(f["c"], f["a"])  # back to Belcour: the same frame
    assert out["bad_mode"][0] is False and "belcor" in out["bad_mode"][1] and "\n" not in out["bad_mode"][1]
    assert out["undo_steps"] == 0  # a view choice, not an edit


def test_window_frame_is_the_offscreen_belcour_render(window_run, gl_ctx):
    from nbrdf.imaging.env_presets import resolve_environment
    from nbrdf.neural.material import load_material
    from nbrdf.viewer.gpu.backdrop import Backdrop
    from nbrdf.viewer.gpu.pipeline import MaterialPipeline
    from nbrdf.viewer.gpu.renderer import Renderer, ViewState
    from nbrdf.viewer.options import ViewOptions

    _, f = window_run
    opts = ViewOptions()
    pipe = MaterialPipeline(gl_ctx)
    brdf = pipe.build(load_material(CAR_PAINT), "belcour")
    r = Renderer(gl_ctx, brdf=brdf, environment=resolve_environment(opts.env))
    img = Backdrop(gl_ctx, r).render_linear(ViewState(), (48, 40), 2, brdf, opts.backdrop())
    expected = tonemap(img, opts.state.exposure, opts.state.tonemap.value).astype(int)
    assert np.abs(f["a"].astype(int) - expected).max() <= 2
    pipe.release()


def test_a_stack_too_deep_for_the_shader_is_shown_neural_with_one_line(window_run):
    out, _ = window_run
    ok, kind, notice, note = out["deep"]
    assert ok and kind == "neural" and notice == note
    assert f"at most {MAX_ATOMS} layers" in note and note.endswith("neural BRDF instead") and "\n" not in note
    ok, kind, notice = out["back"]
    assert ok and kind == "belcour" and notice == ""  # the line goes with the material it was about
