"""Spheres rendered by Mitsuba with the ``nbrdf`` plugin: under a directional
light every pixel is E f cos(theta_i) with f from ``nbrdf eval --method
neural``; in a white furnace an energy-conserving stack returns its
directional albedo."""
from __future__ import annotations

import math

import numpy as np
import pytest

from nbrdf.cli.main import nbrdf_main

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

RES = 24
E = 3.0  # the directional light's irradiance


def _scene(mi, material: str, emitter: dict, integrator: dict, spp: int, sampler: str = "independent"):
    s = {"type": sampler, "sample_count": spp}
    if sampler == "stratified":
        s["jitter"] = False  # one ray through each pixel's centre
    return mi.load_dict({
        "type": "scene", "integrator": integrator, "light": emitter,
        "sphere": {"type": "sphere", "bsdf": {"type": "nbrdf", "material": material}},
        "camera": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[1.0, -2.0, 4.5], target=[0, 0, 0], up=[0, 0, 1]),
                   "film": {"type": "hdrfilm", "width": RES, "height": RES, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"},
                   "sampler": s}})


def _pixel_hits(mi, scene):
    """Per pixel centre (row-major, row 0 at the top): valid hit, and the
    local (toward the viewer) direction, from Mitsuba's own camera rays."""
    import drjit as dr

    sensor = scene.sensors()[0]
    y, x = np.mgrid[0:RES, 0:RES]
    pos = mi.Point2f(((x.ravel() + 0.5) / RES).astype(np.float32), ((y.ravel() + 0.5) / RES).astype(np.float32))
    n = RES * RES
    ray, _ = sensor.sample_ray(0.0, mi.Float(dr.full(mi.Float, 0.5, n)), pos, mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    return si, np.array(si.is_valid())


@pytest.mark.slow
@pytest.mark.ci_slow
@pytest.mark.parametrize("role", ["car_paint", "uncoated"])
def test_directional_light_pixels_equal_neural_f_cos(mi, materials, role, tmp_path):
    direction = np.array([-0.4, 0.5, -0.8])
    direction /= np.linalg.norm(direction)
    scene = _scene(mi, materials[role], {"type": "directional", "direction": direction.tolist(), "irradiance": E},
                   {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0}, spp=1, sampler="stratified")
    img = np.array(mi.render(scene)).reshape(-1, 3)
    si, valid = _pixel_hits(mi, scene)
    view = np.array(si.wi).T  # local, toward the viewer
    light = np.array(si.to_local(mi.Vector3f(*(-direction).astype(np.float32).tolist()))).T
    np.save(tmp_path / "pairs.npy", np.concatenate([light, view], 1)[valid].astype(np.float32))
    assert nbrdf_main(["eval", "--material", materials[role], "--pairs", str(tmp_path / "pairs.npy"),
                       "--out", str(tmp_path / "f.npy"), "--method", "neural"]) == 0
    f = np.zeros((RES * RES, 3), np.float32)
    f[valid] = np.load(tmp_path / "f.npy")
    expected = E * f * np.clip(light[:, 2:3], 0, None)
    # pixels whose centre sees the sphere away from its silhouette (one ray per pixel centre)
    inside = valid & (view[:, 2] > 0.05)
    assert inside.sum() > 0.3 * RES * RES and (expected[inside].max() > 0.05)
    np.testing.assert_array_equal(img[~valid], 0)
    err = np.abs(img[inside] - expected[inside]) / (1e-4 * (1 + np.abs(expected[inside])))
    assert err.max() <= 1.0, f"largest error {err.max():.2f} x the SPEC tolerance"


@pytest.mark.slow
@pytest.mark.ci_slow
def test_white_furnace_of_an_energy_conserving_stack(mi, materials):
    """A smooth clear coat over a white Lambertian base reflects all light
    (the walk's albedo is 1; ``test_mitsuba_reference`` renders it). The
    neural material's furnace image must equal its own directional albedo
    (sampler and eval agree inside Mitsuba); the representation itself is
    bounded (neural/energy.py): its code reflected up to 6 % more than arrives, now at most 1 at every
    incidence (measured 0.93-0.98 at the furnace report's incidences)."""
    import torch

    from nbrdf.neural.material import load_material
    from nbrdf.training.brdfs import brdf_for

    spp = 64
    scene = _scene(mi, materials["white_coat"], {"type": "constant", "radiance": 1.0},
                   {"type": "path", "max_depth": 2}, spp=spp)
    img = np.array(mi.render(scene, seed=1)).reshape(-1, 3)
    si, valid = _pixel_hits(mi, scene)
    view = np.array(si.wi).T
    inside = valid & (view[:, 2] > 0.2)
    # the neural directional albedo at each pixel centre's view direction, 2^14 torch samples at 5 angles
    brdf = brdf_for(load_material(materials["white_coat"]), "neural")
    g = torch.Generator().manual_seed(0)
    theta = np.arccos(np.clip(view[inside, 2], -1, 1))
    grid = np.linspace(theta.min(), theta.max(), 5)
    albedo = []
    for t in grid:
        w = torch.tensor([[math.sin(t), 0.0, math.cos(t)]]).expand(1 << 14, 3)
        albedo.append(float(brdf.sample(w, torch.rand(1 << 14, 3, generator=g)).weight.mean()))
    want = np.interp(theta, grid, albedo)
    got = img[inside].mean(1)
    # pixel noise: 64 independent spp of a weight in [0, 1.3]; the mean over ~300 pixels has sd < 2e-3
    assert abs(got.mean() - want.mean()) < 5e-3, (got.mean(), want.mean())
    assert np.all(np.abs(img[inside] - img[inside].mean(1, keepdims=True)) < 1e-5)  # grey stays grey
    # never more than arrives (the noise of 2^14 samples: about 0.3 %), and not far below the stack's 1
    assert max(albedo) <= 1.0 and np.mean(albedo) > 0.93, albedo


@pytest.mark.slow
def test_symbolic_render_of_the_neural_plugin_warns_once(mi, materials, capfd, monkeypatch):
    """On LLVM the decoder inside a symbolic call loads every weight with a
    gather (record 071): a plain ``mi.render`` still works, and Mitsuba's log
    says once to render in wavefront mode."""
    from nbrdf.mitsuba.modes import SLOW_WARNING

    monkeypatch.setattr(SLOW_WARNING, "warned", False)
    scene = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": 2},
                          "light": {"type": "constant", "radiance": 1.0},
                          "sphere": {"type": "sphere", "bsdf": {"type": "nbrdf", "material": materials["white_coat"]}},
                          "camera": {"type": "perspective", "fov": 25, "to_world": mi.ScalarTransform4f().look_at(
                              origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                              "film": {"type": "hdrfilm", "width": 6, "height": 6},
                              "sampler": {"type": "independent", "sample_count": 4}}})
    capfd.readouterr()
    assert np.array(mi.render(scene))[3, 3].mean() > 0.5
    mi.render(scene, seed=1)
    assert "".join(capfd.readouterr()).count("nbrdf: traced symbolically on the LLVM backend") == 1
