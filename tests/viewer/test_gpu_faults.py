"""GL faults: a latent texture over the GL's size limit or over the memory
available is one line (the command line exits 2; the window keeps the
material it shows). The limits are made small by injection (``texture_limits``,
``available_bytes``): a real 16384-texel limit or tens of gigabytes of maps are
not practical in the suite."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import imageio.v3 as iio
import numpy as np
import pytest

from nbrdf.viewer.gpu import gpu_memory

pytestmark = pytest.mark.gl


def textured_material(folder, n: int = 8):
    """A small texture-mapped material (an n x n roughness map)."""
    ramp = np.tile(np.linspace(0, 255, n).astype(np.uint8), (n, 1))
    iio.imwrite(folder / "rough.png", np.stack([ramp] * 3, -1))
    doc = {"format": "nbrdf-material/1", "name": "mapped", "layers": [
        {"type": "dielectric", "roughness": 0.1, "ior": 1.5},
        {"type": "conductor", "roughness": {"texture": "rough.png", "channel": "r", "range": [0.05, 0.6]},
         "r0": [0.9, 0.6, 0.3]}]}
    path = folder / "mapped.json"
    path.write_text(json.dumps(doc))
    return path


LIMITS = {
    "size": ("texture_limits", lambda ctx: (4, 2048), "GL_MAX_TEXTURE_SIZE"),
    "memory": ("available_bytes", lambda: 4096, "available"),
}


@pytest.mark.parametrize("limit", sorted(LIMITS))
def test_the_command_line_says_one_line_and_exits_2(tmp_path, capsys, monkeypatch, limit):
    from nbrdf.cli.view import main

    name, fake, words = LIMITS[limit]
    monkeypatch.setattr(gpu_memory, name, fake)
    out = tmp_path / "o.png"
    rc = main([str(textured_material(tmp_path)), "--offscreen", "--out", str(out), "--size", "16x16", "--spp", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "latent texture" in err[0] and words in err[0], (rc, err)
    assert not out.exists()


@pytest.mark.parametrize("limit", sorted(LIMITS))
def test_the_window_keeps_the_material_it_shows(gl_ctx, tmp_path, monkeypatch, limit):
    from nbrdf.neural.material import load_material
    from nbrdf.viewer.gpu.pipeline import material_key
    from nbrdf.viewer.options import DEFAULT_MATERIAL
    from nbrdf.viewer.session.lookdev import LookDev

    name, fake, words = LIMITS[limit]
    ld = LookDev(gl_ctx, load_material(DEFAULT_MATERIAL))
    try:
        shown, steps = ld.material, len(ld.history.undo_stack)
        monkeypatch.setattr(gpu_memory, name, fake)
        assert ld.open_material(textured_material(tmp_path))  # accepted: the latent texture builds meanwhile
        ld.wait_svbrdf()
        assert ld.error is not None and "\n" not in ld.error and words in ld.error, ld.error
        assert material_key(ld.material) == material_key(shown) == material_key(ld.brdf.material)
        assert len(ld.history.undo_stack) == steps  # the failed edit is no undo step
        fbo = gl_ctx.simple_framebuffer((8, 8))
        ld.render(fbo, (8, 8), 1)  # the window goes on drawing the material it showed
        img = np.frombuffer(fbo.read(components=4), np.uint8)
        assert img.any()
        monkeypatch.undo()  # within the limits again: the same material opens
        assert ld.open_material(textured_material(tmp_path))
        ld.wait_svbrdf()
        assert ld.error is None and ld.brdf.latent_texture is not None
    finally:
        ld.close()


# ------------------------------------------------------------ a GL failure in a frame of the window
# A real context loss cannot be provoked on llvmpipe: the failure is injected at the renderer
# boundary (``LookDev.render`` raising moderngl.Error, as a draw on a lost context does).
WINDOW = textwrap.dedent("""
    import json, sys
    import moderngl
    from nbrdf.viewer.ui.app import App
    from nbrdf.viewer.ui.gl_faults import GlContextLost
    from nbrdf.viewer.session.lookdev import LookDev
    from nbrdf.viewer.options import ViewOptions

    def lost(*args, **kwargs):
        raise moderngl.Error("GL_CONTEXT_LOST (injected)\\nsecond line")

    out = {}
    if sys.argv[1] == "window":
        app = App(ViewOptions(size=(48, 32)), size=(48, 32))
        ld = app.lookdev
        app.step()
        ld.render = lost  # one frame fails
        app.step()
        out["error"] = ld.error
        del ld.render     # the GL answers again
        app.step()
        out["after"] = [ld.error, ld.notice, int(app.read_pixels().sum() > 0)]
        ld.render = lost  # it never answers again: the third failing frame gives up
        out["steps"] = []
        try:
            for _ in range(5):
                app.step()
                out["steps"].append(ld.error)
        except GlContextLost as e:
            out["gave_up"] = str(e)
        app.close(abnormal=True)
    else:  # the command line, its GL failing in every frame
        from nbrdf.cli.view import main
        LookDev.render = lost
        out["rc"] = main(["--mesh", "sphere"])
    print(json.dumps(out), flush=True)
""")


def _window(xvfb_display, tmp_path, mode: str) -> tuple[dict, str]:
    env = dict(os.environ, DISPLAY=xvfb_display, NBRDF_STATE_DIR=str(tmp_path / "state"))
    r = subprocess.run([sys.executable, "-c", WINDOW, mode], env=env, capture_output=True, text=True, timeout=600,
                       cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1]), r.stderr


def test_a_frame_the_gl_fails_is_one_line_and_the_window_recovers(xvfb_display, tmp_path):
    out, _ = _window(xvfb_display, tmp_path, "window")
    assert out["error"] == "OpenGL error while drawing (GL_CONTEXT_LOST (injected)); trying again"
    assert out["after"] == [None, "recovered from an OpenGL error (GL_CONTEXT_LOST (injected))", 1]
    assert len(out["steps"]) == 2 and "gave_up" in out  # the third failing frame in a row
    assert out["gave_up"].startswith("OpenGL failed 3 frames in a row") and "\n" not in out["gave_up"]


def test_the_command_line_exits_with_one_line_and_keeps_the_session(xvfb_display, tmp_path):
    from nbrdf.viewer.session.autosave import Autosave

    out, err = _window(xvfb_display, tmp_path, "cli")
    lines = [x for x in err.strip().splitlines() if x.startswith("nbrdf-view:")]
    assert out["rc"] == 2 and "Traceback" not in err, err[-3000:]
    assert len(lines) == 1 and "OpenGL failed 3 frames in a row" in lines[0] and "restore" in lines[0]
    assert Autosave(folder=tmp_path / "state").start()  # the next start offers the session back
