"""The previewer (``nbrdf-view --offscreen``, GLSL decoder) and Mitsuba 3
(the ``nbrdf`` plugin) render the same neural material on the same sphere
under the same environment preset and the previewer's directional key light,
from the previewer's default camera, with no backdrop: the images agree.

The previewer runs in a child process (its llvmpipe GL and Dr.Jit's LLVM are
kept apart). Both images are Monte Carlo estimates (256 samples per pixel
each); the sphere's mean and the means of its four quadrants must agree
within 1 % (the target). Their noise: the per-pixel relative difference is
about 4 % at this spp, so a quadrant's mean (~400 pixels) carries ~0.3 %."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

ROOT = Path(__file__).resolve().parents[2]
RES, SPP = 48, 256


def _mitsuba_image(mi, material: str) -> np.ndarray:
    from nbrdf.mitsuba.scenes import ENV_TO_WORLD, environment_bitmap
    from nbrdf.viewer.camera import OrbitCamera
    from nbrdf.viewer.env_presets import DEFAULT_SIZE
    from nbrdf.viewer.renderer import ViewState

    cam, state = OrbitCamera(), ViewState()
    to_light = np.asarray(state.light_dir, np.float64)
    to_light /= np.linalg.norm(to_light)
    T = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "env": {"type": "envmap", "bitmap": environment_bitmap("studio", 1.0, DEFAULT_SIZE), "to_world": T(ENV_TO_WORLD)},
        "key": {"type": "directional", "direction": (-to_light).tolist(), "irradiance": state.light_radiance},
        "sphere": {"type": "sphere", "bsdf": {"type": "nbrdf", "material": material}},
        "camera": {"type": "perspective", "fov": cam.fov, "fov_axis": "y",
                   "to_world": T().look_at(origin=cam.eye().tolist(), target=list(cam.target), up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": RES, "height": RES, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": SPP}}})
    return np.array(mi.render(scene, seed=5)).reshape(RES, RES, 3)


@pytest.mark.slow
@pytest.mark.gl
@pytest.mark.parametrize("name", [
    "coated_copper",
    # measured: the previewer 2.5 % darker over the sphere; a coat of roughness 0.02 mirrors the studio's
    # panels, where the previewer clamps single-sample contributions (clamp_contribution) - the likely cause,
    # not yet confirmed
    pytest.param("car_paint", marks=pytest.mark.xfail(strict=True, reason="previewer 2.5 % darker on a 0.02 coat")),
])
def test_previewer_and_mitsuba_agree_on_a_sphere_under_an_environment(mi, tmp_path, name):
    from scipy.ndimage import binary_erosion

    from nbrdf.viewer.image_io import read_exr

    material = str(ROOT / "viewer/assets/materials" / f"{name}.json")
    out = tmp_path / "previewer.exr"
    subprocess.run([sys.executable, "-m", "nbrdf.cli.view", material, "--offscreen", "--out", str(out),
                    "--size", f"{RES}x{RES}", "--spp", str(SPP), "--brdf", "neural", "--env", "studio",
                    "--env-intensity", "1", "--background", "none", "--no-ground"], check=True, cwd=ROOT,
                   capture_output=True, timeout=900)
    pv = read_exr(out)
    mt = _mitsuba_image(mi, material)
    # the sphere's inside (the previewer's tessellated silhouette differs from Mitsuba's exact one by a pixel)
    mask = binary_erosion(pv.sum(2) > 0, iterations=2)
    assert mask.sum() > 0.25 * RES * RES
    rel = pv[mask].mean() / mt[mask].mean() - 1
    assert abs(rel) < 0.01, f"sphere mean: previewer / Mitsuba - 1 = {rel:+.4f}"
    h = RES // 2
    for rows, cols in ((slice(0, h), slice(None)), (slice(h, None), slice(None)),
                       (slice(None), slice(0, h)), (slice(None), slice(h, None))):
        q = np.zeros_like(mask)
        q[rows, cols] = True
        q &= mask
        rq = pv[q].mean() / mt[q].mean() - 1
        assert abs(rq) < 0.01, f"quadrant {rows}, {cols}: previewer / Mitsuba - 1 = {rq:+.4f}"
