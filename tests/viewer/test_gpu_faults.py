"""GL faults: a latent texture over the GL's size limit or over the memory
available is one line (the command line exits 2; the window keeps the
material it shows). The limits are made small by injection (``texture_limits``,
``available_bytes``): a real 16384-texel limit or tens of gigabytes of maps are
not practical in the suite."""
from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pytest

from nbrdf.viewer import gpu_memory

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
    from nbrdf.viewer.lookdev import LookDev
    from nbrdf.viewer.options import DEFAULT_MATERIAL
    from nbrdf.viewer.pipeline import material_key

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
