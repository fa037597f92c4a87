"""The previewer (``nbrdf-view --offscreen``, GLSL decoder) and Mitsuba 3
(the ``nbrdf`` plugin) render the same neural material on the same sphere
under the same environment preset and the previewer's directional key light,
from the previewer's default camera, with no backdrop: the images agree.

The previewer runs in a child process (its llvmpipe GL and Dr.Jit's LLVM are
kept apart). A previewer pixel is one point at the pixel's centre, a Mitsuba
pixel the mean over its square (box filter): where a highlight is smaller
than a pixel they differ by more than the materials do (car paint's 0.02 coat
under the key light: the point at the centre misses 8.5 % of the light's
share of the sphere, the whole sphere 3.5 % darker; decision 091). So the
previewer renders at SS x SS the size with SS^2 fewer passes (the same
samples per output pixel) and its image is averaged over SS x SS blocks.
Both images are Monte Carlo estimates: the previewer 256 samples per output
pixel, Mitsuba 4 x 1,024 with independent seeds (its direct integrator is
noisier per sample and heavy-tailed on car paint's sharp coat: four
1,024-spp renders' quadrant means scatter by 0.4 % (one was 1.1 % off), so
their mean carries ~0.2 %; rendered in wavefront mode, 5-10x faster on the
CPU). The sphere's mean and the means of its four quadrants must agree
within 1 % (the target)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

ROOT = Path(__file__).resolve().parents[2]
RES, SPP = 48, 256
#: Mitsuba's samples per pixel per render, and its renders (seeds) averaged: its estimator is noisier
#: per sample than the previewer's.
MITSUBA_SPP, MITSUBA_RENDERS = 1024, 4
#: Previewer supersampling per side (its pixels are points; Mitsuba's are box-filtered squares).
SS = 4


def _mitsuba_image(mi, material: str) -> np.ndarray:
    from nbrdf.imaging.env_presets import DEFAULT_SIZE
    from nbrdf.mitsuba import wavefront_mode
    from nbrdf.mitsuba.scenes import ENV_TO_WORLD, environment_bitmap
    from nbrdf.viewer.gpu.renderer import ViewState
    from nbrdf.viewer.scene.camera import OrbitCamera

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
                   "sampler": {"type": "independent", "sample_count": MITSUBA_SPP}}})
    with wavefront_mode():
        return sum(np.array(mi.render(scene, seed=5 + k)).reshape(RES, RES, 3)
                   for k in range(MITSUBA_RENDERS)) / MITSUBA_RENDERS


def _normal_mapped(tmp_path) -> str:
    """Coated copper under a generated low-frequency bump map (tilts up to 19
    degrees: 3 waves around the sphere, 2 from pole to pole), smooth enough
    that the previewer's mip-mapped map and the plugin's finest level agree."""
    import json

    import imageio.v3 as iio

    h, w = 32, 64
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    n = np.stack([0.35 * np.sin(6 * np.pi * u), 0.35 * np.sin(4 * np.pi * v), np.ones_like(u)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    iio.imwrite(tmp_path / "bumps.png", np.round((n * 0.5 + 0.5) * 255).astype(np.uint8))
    m = json.loads((ROOT / "viewer/assets/materials/coated_copper.json").read_text())
    m["normal_map"] = "bumps.png"
    (tmp_path / "bumped.json").write_text(json.dumps(m))
    return str(tmp_path / "bumped.json")


def _previewer_image(material: str, out: Path) -> np.ndarray:
    """The previewer's image at SS x SS the size, averaged down to RES x RES."""
    from nbrdf.imaging.image_io import read_exr

    size, spp = RES * SS, SPP // (SS * SS)
    subprocess.run([sys.executable, "-m", "nbrdf.cli.view", material, "--offscreen", "--out", str(out),
                    "--size", f"{size}x{size}", "--spp", str(spp), "--brdf", "neural", "--env", "studio",
                    "--env-intensity", "1", "--background", "none", "--no-ground"], check=True, cwd=ROOT,
                   capture_output=True, timeout=900)
    return read_exr(out).reshape(RES, SS, RES, SS, 3).mean((1, 3))


@pytest.mark.slow
@pytest.mark.gl
@pytest.mark.parametrize("name", ["coated_copper", "car_paint", "normal_mapped"])
def test_previewer_and_mitsuba_agree_on_a_sphere_under_an_environment(mi, tmp_path, name):
    from scipy.ndimage import binary_erosion

    material = (_normal_mapped(tmp_path) if name == "normal_mapped"
                else str(ROOT / "viewer/assets/materials" / f"{name}.json"))
    pv = _previewer_image(material, tmp_path / "previewer.exr")
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
