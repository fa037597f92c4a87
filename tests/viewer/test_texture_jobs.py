"""Latent textures built in a worker thread (viewer/jobs/texture_jobs.py): a build
the material shown no longer takes (the user moved on while it ran) is applied
once when it ends, then forgotten."""
from __future__ import annotations

import json
import time

import imageio.v3 as iio
import numpy as np
import pytest

pytestmark = pytest.mark.gl


def test_a_build_the_shown_material_left_is_dropped_when_it_ends(gl_ctx, tmp_path, monkeypatch):
    from nbrdf.neural.material import load_material
    from nbrdf.viewer.options import DEFAULT_MATERIAL
    from nbrdf.viewer.session.lookdev import LookDev

    ramp = np.tile(np.linspace(0, 255, 8).astype(np.uint8), (8, 1))
    iio.imwrite(tmp_path / "rough.png", np.stack([ramp] * 3, -1))
    (tmp_path / "mapped.json").write_text(json.dumps({"format": "nbrdf-material/1", "name": "mapped", "layers": [
        {"type": "conductor", "roughness": {"texture": "rough.png", "channel": "r", "range": [0.05, 0.6]},
         "r0": [0.9, 0.6, 0.3]}]}))
    ld = LookDev(gl_ctx, load_material(DEFAULT_MATERIAL))
    try:
        assert ld.open_material(tmp_path / "mapped.json")  # its latent texture builds in a worker thread
        job = ld.textures.job
        assert job is not None
        assert ld.load_preset("default")  # moved on: the build goes on, for a material no longer shown
        end = time.monotonic() + 120
        while job.result is None and job.error is None and time.monotonic() < end:
            time.sleep(0.01)
        assert job.result is not None
        applied = []
        apply = ld._apply_material
        monkeypatch.setattr(ld, "_apply_material", lambda: applied.append(1) or apply())
        for _ in range(3):
            ld.update()
        # applied once, not every frame (each restarted the still view), and the unused texture let go
        assert len(applied) <= 1 and ld.textures.job is None
        assert ld.brdf is not None and ld.brdf.latent_texture is None
    finally:
        ld.close()
