"""``nbrdf_reference``: a fresh unbiased estimate of the walk's f per query,
agreeing with ``nbrdf eval --method reference``; it renders in Dr.Jit's
wavefront mode, and in symbolic mode reflects nothing and says why in Mitsuba's log."""
from __future__ import annotations

import numpy as np
import pytest
from hits import directions

from nbrdf.cli.main import nbrdf_main

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

CALLS, SPP = 24, 16  # 384 paths per pair through the plugin


@pytest.mark.slow
@pytest.mark.ci_slow
def test_reference_plugin_agrees_with_nbrdf_eval_reference(mi, materials, tmp_path):
    """z = (plugin mean - eval) / sqrt(se_plugin^2 + se_eval^2) over 48 pairs x 3
    channels: |mean z| < 4 / sqrt(144) and mean z^2 < 1.6 (its 99.9 % point
    for 144 independent standard normals is 1.43; heavier Monte Carlo tails
    allowed). A plugin off by 10 % on this stack gives mean z about 3."""
    import drjit as dr

    rng = np.random.default_rng(21)
    n = 48
    light, view = directions(rng, n, lift=0.2), directions(rng, n, lift=0.2)
    bsdf = mi.load_dict({"type": "nbrdf_reference", "material": materials["coated"], "spp": SPP, "seed": 4})
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(np.ascontiguousarray(view.T))
    wo = mi.Vector3f(np.ascontiguousarray(light.T))
    runs = np.stack([np.array(bsdf.eval(mi.BSDFContext(), si, wo)).T / light[:, 2:3] for _ in range(CALLS)])
    assert np.all(np.std(runs, 0) > 0)  # every call draws new paths
    mean, se = runs.mean(0), runs.std(0, ddof=1) / np.sqrt(CALLS)
    np.save(tmp_path / "pairs.npy", np.concatenate([light, view], 1))
    assert nbrdf_main(["eval", "--material", materials["coated"], "--pairs", str(tmp_path / "pairs.npy"),
                       "--out", str(tmp_path / "f.npy"), "--method", "reference", "--spp", "4096",
                       "--seed", "9"]) == 0
    ref, ref_se = np.load(tmp_path / "f.npy"), np.load(tmp_path / "f.stderr.npy")
    z = (mean - ref) / np.sqrt(se ** 2 + ref_se ** 2)
    assert abs(z.mean()) < 4 / np.sqrt(z.size), z.mean()
    assert (z ** 2).mean() < 1.6, (z ** 2).mean()


@pytest.mark.slow
@pytest.mark.ci_slow
def test_reference_plugin_renders_in_wavefront_mode_only(mi, materials, capfd):
    from nbrdf.mitsuba import wavefront_mode

    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "light": {"type": "constant", "radiance": 1.0},
        "sphere": {"type": "sphere", "bsdf": {"type": "nbrdf_reference", "material": materials["white_coat"]}},
        "camera": {"type": "perspective", "fov": 25,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 12, "height": 12},
                   "sampler": {"type": "independent", "sample_count": 32}}})
    with wavefront_mode():
        img = np.array(mi.render(scene, seed=0))
    centre = img[3:9, 3:9].mean()
    # the white furnace of a lossless stack: 1 up to the noise of 32 single-path estimates x 36 pixels
    assert np.isfinite(img).all() and abs(centre - 1) < 0.05, centre
    # symbolic mode: the walk cannot run; the sphere reflects nothing and Mitsuba's log says why
    capfd.readouterr()
    img = np.array(mi.render(scene, seed=0))
    assert np.all(img[5:7, 5:7] == 0) and abs(img[0, 0].mean() - 1) < 1e-3
    assert "nbrdf_reference: traced in a symbolic" in "".join(capfd.readouterr())
    # and a live nbrdf_reference does not break symbolic renders of other scenes
    other = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                          "light": {"type": "constant", "radiance": 1.0},
                          "sphere": {"type": "sphere", "bsdf": {"type": "nbrdf", "material": materials["white_coat"]}},
                          "camera": {"type": "perspective", "fov": 25, "to_world": mi.ScalarTransform4f().look_at(
                              origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                              "film": {"type": "hdrfilm", "width": 8, "height": 8},
                              "sampler": {"type": "independent", "sample_count": 16}}})
    assert np.array(mi.render(other))[4, 4].mean() > 0.5
