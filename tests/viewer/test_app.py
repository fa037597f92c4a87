"""The look-development app under Xvfb, driven through its own API.

One child process opens the window and runs a scripted session (the window's
GLX context and the offscreen tests' EGL context do not mix in one process);
this process checks what it saved against the offscreen renderer."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import torch

from nbrdf.imaging.image_io import tonemap
from nbrdf.neural.material import parse_material
from nbrdf.neural.model import default_model
from nbrdf.viewer.gpu.pipeline import gpu_brdf
from nbrdf.viewer.options import DEFAULT_MATERIAL

pytestmark = pytest.mark.gl

SCRIPT = textwrap.dedent("""
    import json, os, sys
    from pathlib import Path
    import numpy as np
    from nbrdf.viewer.ui.app import App
    from nbrdf.viewer.options import ViewOptions
    tmp = Path(sys.argv[2])
    app = App(ViewOptions(material=sys.argv[1], size=(64, 48)), size=(64, 48))
    app.refine.settings.adaptive = False   # full resolution: compared pixel for pixel
    app.lookdev.bodies.use_tables = False  # with the per-pixel decoder (as offscreen)
    app.panels.visible = False
    app.frame()  # the view is the whole window now (F)
    ld = app.lookdev
    out = {}
    try:
        for _ in range(2):
            app.step()
        a, za = app.read_pixels(), ld.latent().numpy()
        out["edit_ok"] = ld.set_param(2, "roughness", 0.45)
        for _ in range(2):
            app.step()
        b, zb = app.read_pixels(), ld.latent().numpy()
        out["doc"] = ld.editor.doc
        out["latent_ms"], out["edit_to_frame_ms"] = ld.timings.latent_ms, ld.timings.edit_to_frame_ms
        # Session round trip: change everything, reopen, the same frame comes back.
        out["saved"] = ld.save_session(tmp / "s.json")
        ld.state.camera.orbit(40, 10)
        ld.state.exposure = 2.0
        ld.set_param(2, "roughness", 0.9)
        out["reopened"] = ld.open_session(tmp / "s.json")
        for _ in range(2):
            app.step()
        c = app.read_pixels()
        # Bad files: an error in the UI, nothing changed, the app keeps running.
        (tmp / "bad.json").write_text("{ not json")
        out["bad"] = [ld.open_material(tmp / "missing.json"), ld.error,
                      ld.open_session(tmp / "bad.json"), ld.error,
                      ld.set_environment(str(tmp / "missing.hdr")), ld.error,
                      ld.set_mesh(str(tmp / "missing.obj")), ld.error,
                      ld.set_param(0, "ior", 7.0), ld.error]
        out["doc_after_bad"] = ld.editor.doc
        app.step()
        # Screenshots.
        out["shots"] = [ld.write_screenshot(tmp / "shot.png", (64, 48), 2),
                        ld.write_screenshot(tmp / "shot.exr", (32, 24), 2),
                        ld.write_screenshot(tmp / "shot.bmp", (8, 8), 1), ld.error]
        # Every panel and mode draws: compare modes, views, interpolation, a textured preset.
        app.panels.visible = app.panels.expand_all = True
        for view, mode in (("lobe", "side"), ("slice", "error"), ("object", "wipe"), ("lobe", "flip")):
            ld.state.view = view
            ld.set_compare(mode)
            app.step()
        ld.set_compare("off")
        out["interp"] = [ld.set_interpolation("rough_gold", 0.5, "latent"), ld.error]
        zi = ld.latent().numpy()
        app.step()
        ld.set_interpolation(mode="brdf")
        app.step()
        ld.clear_interpolation()
        out["preset"] = ld.load_preset("worn_tiles")
        ld.wait_svbrdf()
        app.step()
        out["textured"] = ld.brdf.latent_texture is not None
        ld.set_mipmapping(False)
        app.step()
        proc = ld.worker.process  # the stack's Monte Carlo reference ran in its own process
        out["worker_elsewhere"] = proc is not None and proc.pid != os.getpid()
        np.savez(tmp / "frames.npz", a=a, b=b, c=c, za=za, zb=zb, zi=zi)
    finally:
        app.close()
    out["worker_alive_after_close"] = proc.is_alive()
    (tmp / "out.json").write_text(json.dumps(out, default=str))
""")


@pytest.fixture(scope="module")
def session_run(xvfb_display, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("app")
    env = dict(os.environ, DISPLAY=xvfb_display)
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(DEFAULT_MATERIAL), str(tmp)], env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return tmp, json.loads((tmp / "out.json").read_text()), np.load(tmp / "frames.npz")


def test_slider_changes_latents_and_pixels_as_offscreen(session_run, gl_ctx):
    from nbrdf.imaging.env_presets import resolve_environment
    from nbrdf.viewer.gpu.backdrop import Backdrop
    from nbrdf.viewer.gpu.neural_gpu import GpuDecoder
    from nbrdf.viewer.gpu.renderer import Renderer, ViewState
    from nbrdf.viewer.options import ViewOptions

    _, out, f = session_run
    assert out["edit_ok"]
    assert np.abs(f["za"] - f["zb"]).max() > 1e-3 and np.abs(f["a"].astype(int) - f["b"]).mean() > 0.5
    model = default_model()
    m = parse_material(out["doc"])
    z = model.material_latent(m)
    np.testing.assert_allclose(f["zb"], z.numpy(), atol=1e-5)
    opts = ViewOptions()  # the window's defaults: studio environment, backdrop, tone mapper
    r = Renderer(gl_ctx, gpu_brdf(gl_ctx, m, GpuDecoder(gl_ctx, model.decoder), z, model.proxy(z)),
                 environment=resolve_environment(opts.env))
    img = Backdrop(gl_ctx, r).render_linear(ViewState(), (64, 48), 2, r.brdf, opts.backdrop())
    expected = tonemap(img, opts.state.exposure, opts.state.tonemap.value).astype(int)
    assert np.abs(f["b"].astype(int) - expected).max() <= 2
    assert 0 < out["latent_ms"] <= out["edit_to_frame_ms"]  # the frame follows the latent (timings: nbrdf bench app)


def test_session_reopens_exactly(session_run):
    tmp, out, f = session_run
    assert out["saved"] and out["reopened"]
    np.testing.assert_array_equal(f["c"], f["b"])
    data = json.loads((tmp / "s.json").read_text())
    assert data["format"] == "nbrdf-session/1" and data["material"]["layers"][2]["roughness"] == 0.45


def test_bad_files_show_an_error_and_change_nothing(session_run):
    _, out, _ = session_run
    bad = out["bad"]
    for ok, msg in zip(bad[0::2], bad[1::2]):
        assert ok is False and msg and "\n" not in msg
    assert "missing.json" in bad[1] and "not JSON" in bad[3] and "missing.hdr" in bad[5]
    assert "ior" in bad[9]
    assert out["doc_after_bad"] == out["doc"]


def test_screenshots(session_run):
    import imageio.v3 as iio

    from nbrdf.imaging.image_io import read_exr

    tmp, out, _ = session_run
    assert out["shots"][:2] == [True, True] and out["shots"][2] is False and ".png" in out["shots"][3]
    assert iio.imread(tmp / "shot.png").shape == (48, 64, 3)
    exr = read_exr(tmp / "shot.exr")
    assert exr.shape[:2] == (24, 32) and np.isfinite(exr).all() and exr.max() > 0


def test_interpolation_and_svbrdf_in_the_app(session_run):
    from nbrdf.neural.latent_texture import blend
    from nbrdf.neural.material import load_material
    from nbrdf.viewer.session.edits import presets

    _, out, f = session_run
    assert out["interp"] == [True, None]
    model = default_model()
    other = model.material_latent(load_material(presets()["rough_gold"]))
    expected = blend([torch.from_numpy(f["zb"]), other], [0.5, 0.5]).numpy()
    np.testing.assert_allclose(f["zi"], expected, atol=1e-5)
    assert out["preset"] and out["textured"]


def test_reference_worker_is_a_process_ended_with_the_app(session_run):
    _, out, _ = session_run
    assert out["worker_elsewhere"] is True and out["worker_alive_after_close"] is False
