"""Offscreen renders through EGL: every view of the default material, the
GLSL lobe against the torch closed forms, image files, and bad input."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.metrics import lobe_image
from nbrdf.training.reference import single_layer_eval
from nbrdf.viewer.image_io import read_exr, write_image
from nbrdf.viewer.renderer import Renderer, ViewState
from nbrdf.viewer.view_cli import DEFAULT_MATERIAL, main

pytestmark = pytest.mark.gl


def one_layer(layer):
    return parse_material({"format": "nbrdf-material/1", "name": "t", "layers": [layer]})


@pytest.mark.parametrize("layer", [{"type": "conductor", "roughness": 0.3, "r0": [0.9, 0.5, 0.2]},
                                   {"type": "conductor", "roughness": 0.05, "r0": 0.95},
                                   {"type": "dielectric", "roughness": 0.2, "ior": 1.5},
                                   {"type": "diffuse", "albedo": [0.2, 0.4, 0.8]}])
@pytest.mark.parametrize("theta", [0.0, 60.0])
def test_glsl_lobe_equals_closed_form(gl_ctx, layer, theta):
    m = one_layer(layer)
    img = Renderer(gl_ctx, m).render_linear(ViewState(view="lobe", theta_i=theta))
    ref = lobe_image(lambda wi, wo: single_layer_eval(m.base, wi.double(), wo.double()), theta)
    assert img.shape == (64, 64, 3)
    np.testing.assert_allclose(img, ref, rtol=1e-4, atol=1e-6)


def test_default_material_views(gl_ctx):
    r = Renderer(gl_ctx, load_material(DEFAULT_MATERIAL))
    obj = r.render_linear(ViewState(view="object", background=False), (64, 48), spp=4)
    assert obj.shape == (48, 64, 3) and np.isfinite(obj).all()
    centre, corner = obj[24, 32], obj[1, 1]
    assert centre.sum() > 0.02 and corner.sum() == 0  # the sphere, and no background
    sky = r.render_linear(ViewState(view="object"), (64, 48), spp=4)
    np.testing.assert_array_equal(sky[24, 32], obj[24, 32])  # the background never covers the object
    assert (sky[1, 1] > 0).all() and (sky[-2, 1] > 0).all()  # the environment behind it
    assert centre[0] > centre[2]  # copper under the varnish: warm
    sl = r.render_linear(ViewState(view="slice"), (32, 32))
    assert np.isfinite(sl).all() and sl.max() > sl.mean() > 0
    # Specular peak at theta_h = 0 (left column, x), strongest there.
    assert sl[:, 0].mean() > sl[:, -1].mean()


def test_progressive_passes_converge(gl_ctx):
    r = Renderer(gl_ctx, load_material(DEFAULT_MATERIAL))
    a = r.render_linear(ViewState(), (48, 48), spp=2)
    b = r.render_linear(ViewState(), (48, 48), spp=32)
    c = r.render_linear(ViewState(), (48, 48), spp=32)
    np.testing.assert_array_equal(b, c)  # deterministic random numbers
    mask = b.sum(-1) > 0
    assert np.abs(a - b)[mask].mean() < 0.1 and np.abs(a - b)[mask].mean() > 0


@pytest.mark.parametrize("mesh", ["testmesh"])
def test_test_mesh_renders(gl_ctx, mesh):
    r = Renderer(gl_ctx, load_material(DEFAULT_MATERIAL), mesh)
    img = r.render_linear(ViewState(background=False), (48, 48), spp=1)
    cover = (img.sum(-1) > 0).mean()
    assert 0.05 < cover < 0.9


def test_obj_mesh_through_trimesh(gl_ctx, tmp_path):
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    r = Renderer(gl_ctx, load_material(DEFAULT_MATERIAL), str(tmp_path / "tri.obj"))
    assert (r.render_linear(ViewState(background=False), (32, 32), spp=1).sum(-1) > 0).any()


def test_image_files_round_trip(tmp_path):
    img = np.random.default_rng(0).random((5, 7, 3)).astype(np.float32) * 4
    write_image(tmp_path / "a.npy", img)
    write_image(tmp_path / "a.exr", img)
    write_image(tmp_path / "a.png", img)
    np.testing.assert_array_equal(np.load(tmp_path / "a.npy"), img)
    exr = read_exr(tmp_path / "a.exr")
    assert exr.dtype == np.float32
    np.testing.assert_array_equal(exr, img)
    import imageio.v3 as iio

    assert iio.imread(tmp_path / "a.png").shape == (5, 7, 3)


def test_cli_offscreen_outputs(tmp_path, capsys):
    assert main([str(DEFAULT_MATERIAL), "--offscreen", "--out", str(tmp_path / "o.npy"), "--size", "40x30", "--spp", "2"]) == 0
    o = np.load(tmp_path / "o.npy")
    assert o.shape == (30, 40, 3) and o.dtype == np.float32
    assert main(["--offscreen", "--view", "lobe", "--theta-i", "30", "--out", str(tmp_path / "l.npy")]) == 0
    assert np.load(tmp_path / "l.npy").shape == (64, 64, 3)
    assert main(["--offscreen", "--view", "slice", "--size", "16x16", "--out", str(tmp_path / "s.exr")]) == 0
    assert read_exr(tmp_path / "s.exr").shape == (16, 16, 3)


@pytest.mark.parametrize("argv,needle", [
    (["--offscreen", "--out", "x.gif"], "unknown image type"),
    (["--offscreen", "--out", "x.png", "--size", "big"], "--size"),
    (["--offscreen", "--out", "x.png", "--mesh", "/nonexistent.obj"], "no such file"),
    (["--offscreen", "--out", "x.png", "--env", "/nonexistent.hdr"], "no such file"),
    (["/nonexistent.json", "--offscreen", "--out", "x.png"], "no such file"),
    (["--offscreen"], "--out"),
    (["--offscreen", "--out", "x.png", "--point-light", "1,2"], "--point-light"),
    (["--offscreen", "--out", "x.png", "--session", "/nonexistent.json"], "no such file"),
])
def test_cli_bad_input_one_line(tmp_path, capsys, monkeypatch, argv, needle):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def test_cli_invalid_material_and_unreadable_env(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.json").write_text(json.dumps({"format": "nbrdf-material/1", "name": "b",
                                                   "layers": [{"type": "conductor", "roughness": 0.3, "r0": 2}]}))
    assert main(["bad.json", "--offscreen", "--out", "x.png"]) == 2
    assert "layers[0].r0: 2 is outside [0, 1]" in capsys.readouterr().err
    (tmp_path / "env.exr").write_bytes(b"not an exr")
    assert main(["--offscreen", "--out", "x.png", "--env", "env.exr"]) == 2
    assert "--env env.exr: cannot be read" in capsys.readouterr().err


def test_headless_fallback(tmp_path):
    """No display and no --offscreen: one line says so, and the PNG appears."""
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    exe = Path(sys.executable).parent / "nbrdf-view"
    r = subprocess.run([str(exe), "--size", "32x32", "--spp", "1"], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip().splitlines() == ["nbrdf-view: no display found; rendering offscreen to nbrdf-view.png instead"]
    assert (tmp_path / "nbrdf-view.png").stat().st_size > 100


def test_cli_renders_a_session_file(gl_ctx, tmp_path, capsys):
    import imageio.v3 as iio

    from nbrdf.viewer.lookdev import LookDev

    ld = LookDev(gl_ctx, load_material(DEFAULT_MATERIAL))
    try:
        ld.state.view = "slice"
        ld.set_param(2, "roughness", 0.6)
        assert ld.save_session(tmp_path / "s.json")
        assert ld.screenshot(tmp_path / "direct.png", (24, 16), 1)
    finally:
        ld.close()
    assert main(["--offscreen", "--session", str(tmp_path / "s.json"), "--size", "24x16", "--spp", "1",
                 "--out", str(tmp_path / "cli.png")]) == 0
    np.testing.assert_array_equal(iio.imread(tmp_path / "cli.png"), iio.imread(tmp_path / "direct.png"))
    (tmp_path / "bad.json").write_text('{"format": "nbrdf-session/1"}')
    assert main(["--offscreen", "--session", str(tmp_path / "bad.json"), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "malformed session" in err[0]


def test_a_distant_point_light_equals_the_directional_light(gl_ctx):
    from nbrdf.neural.material import parse_material

    m = parse_material({"format": "nbrdf-material/1", "name": "g",
                        "layers": [{"type": "conductor", "roughness": 0.3, "r0": [1.0, 0.78, 0.34]}]})
    r = Renderer(gl_ctx, m)
    sun = ViewState(env_on=False, background=False)
    d = np.asarray(sun.light_dir) / np.linalg.norm(sun.light_dir)
    far = 1.0e3
    point = ViewState(env_on=False, background=False, light_radiance=0.0, point_light=tuple(d * far),
                      point_intensity=sun.light_radiance * far * far)
    a = r.render_linear(sun, (32, 32), spp=1)
    b = r.render_linear(point, (32, 32), spp=1)
    assert a.max() > 0.1
    np.testing.assert_allclose(b, a, rtol=5e-3, atol=1e-3)
    near = r.render_linear(replace_point(point, tuple(d * 2.0), sun.light_radiance * 4.0), (32, 32), spp=1)
    assert np.abs(near - a).mean() > 0.01  # a near light falls off across the sphere


def replace_point(state, pos, intensity):
    from dataclasses import replace

    return replace(state, point_light=pos, point_intensity=intensity)
