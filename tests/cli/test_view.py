"""``nbrdf-view`` (SPEC section 8): offscreen outputs of every view, the
headless fallback, sessions, and bad input ending in one line, exit status 2."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nbrdf.cli.view import build_parser, main, parse_args
from nbrdf.imaging.image_io import read_exr
from nbrdf.imaging.tonemap import ToneMap
from nbrdf.neural.material import load_material
from nbrdf.neural.methods import Method
from nbrdf.viewer.modes import BrdfMode, View
from nbrdf.viewer.options import DEFAULT_MATERIAL, ViewOptions


def test_flags_default_to_the_view_options():
    """No flags: exactly the dataclass defaults (one place for defaults)."""
    assert parse_args([]) == ViewOptions()
    opts = parse_args(["m.json", "--view", "lobe", "--tonemap", "linear", "--brdf", "neural", "--size", "64x32",
                       "--point-light", "1,2,3", "--background", "none", "--theta-i", "-0"])
    assert opts.state.view is View.LOBE and opts.state.tonemap is ToneMap.LINEAR and opts.brdf is BrdfMode.NEURAL
    assert opts.size == (64, 32) and opts.state.point_light == (1.0, 2.0, 3.0) and opts.background == "none"
    assert opts.material == Path("m.json")


def test_help_lists_every_option_and_the_mode_words():
    text = build_parser().format_help()
    for flag in ("--mesh", "--env", "--env-rotation", "--env-intensity", "--point-light", "--point-intensity",
                 "--session", "--background", "--no-ground", "--view", "--theta-i", "--offscreen", "--out", "--size", "--spp",
                 "--exposure", "--tonemap", "--brdf"):
        assert flag in text, flag
    assert "{object,lobe,slice}" in text and "{auto,analytic,neural,projected,belcour}" in text


@pytest.mark.gl
def test_cli_offscreen_outputs(tmp_path, capsys):
    assert main([str(DEFAULT_MATERIAL), "--offscreen", "--out", str(tmp_path / "o.npy"), "--size", "40x30", "--spp", "2"]) == 0
    o = np.load(tmp_path / "o.npy")
    assert o.shape == (30, 40, 3) and o.dtype == np.float32
    assert main(["--offscreen", "--view", "lobe", "--theta-i", "30", "--out", str(tmp_path / "l.npy")]) == 0
    assert np.load(tmp_path / "l.npy").shape == (64, 64, 3)
    assert main(["--offscreen", "--view", "slice", "--size", "16x16", "--out", str(tmp_path / "s.exr")]) == 0
    assert read_exr(tmp_path / "s.exr").shape == (16, 16, 3)


@pytest.mark.gl
@pytest.mark.parametrize("argv,needle", [
    (["--offscreen", "--out", "x.gif"], "unknown image type"),
    (["--offscreen", "--out", "x.png", "--size", "big"], "--size"),
    (["--offscreen", "--out", "x.png", "--mesh", "/nonexistent.obj"], "no such file"),
    (["--offscreen", "--out", "x.png", "--env", "/nonexistent.hdr"], "no such file"),
    (["/nonexistent.json", "--offscreen", "--out", "x.png"], "no such file"),
    (["--offscreen"], "--out"),
    (["--offscreen", "--out", "x.png", "--point-light", "1,2"], "--point-light"),
    (["--offscreen", "--out", "x.png", "--session", "/nonexistent.json"], "no such file"),
    (["--offscreen", "--out", "x.png", "--brdf", "belcor"], "--brdf"),
])
def test_cli_bad_input_one_line(tmp_path, capsys, monkeypatch, argv, needle):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


@pytest.mark.gl
def test_cli_brdf_belcour_lobe_is_the_python_model(tmp_path, capsys):
    """``--brdf belcour`` shades the car paint with Belcour's GLSL model: its lobe view is
    ``brdf_for(m, "belcour")``'s (SPEC section 9's lobe image) within the GPU tolerance."""
    import torch

    from nbrdf.neural.metrics import lobe_image
    from nbrdf.training.brdfs import brdf_for

    car_paint = DEFAULT_MATERIAL.parent / "car_paint.json"
    out = tmp_path / "l.npy"
    assert main([str(car_paint), "--offscreen", "--view", "lobe", "--theta-i", "40", "--brdf", "belcour",
                 "--out", str(out)]) == 0
    assert capsys.readouterr().err == ""
    f = brdf_for(load_material(car_paint), Method.BELCOUR)
    ref = lobe_image(lambda wi, wo: f.eval(wi.float().double(), wo.float().double()).to(torch.float64), 40.0)
    img = np.load(out)
    assert ref.max() > 1.0
    np.testing.assert_allclose(img, ref, rtol=1e-4, atol=1e-4)
    neural = tmp_path / "n.npy"
    assert main([str(car_paint), "--offscreen", "--view", "lobe", "--theta-i", "40", "--out", str(neural)]) == 0
    assert np.abs(np.load(neural) - img).mean() > 1e-3  # the flag changes the model shown


@pytest.mark.gl
def test_cli_brdf_belcour_falls_back_to_neural_with_one_line(tmp_path, capsys):
    from nbrdf.viewer.gpu.belcour_gpu import MAX_ATOMS

    layers = [{"type": "dielectric", "roughness": 0.1, "ior": 1.2}] * MAX_ATOMS + [{"type": "diffuse", "albedo": 0.5}]
    (tmp_path / "deep.json").write_text(json.dumps({"format": "nbrdf-material/1", "name": "d", "layers": layers}))
    out = tmp_path / "d.npy"
    assert main([str(tmp_path / "deep.json"), "--offscreen", "--view", "lobe", "--brdf", "belcour",
                 "--out", str(out)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"at most {MAX_ATOMS} layers" in err[0] and "neural BRDF instead" in err[0], err
    assert np.load(out).max() > 0


@pytest.mark.gl
def test_cli_invalid_material_and_unreadable_env(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.json").write_text(json.dumps({"format": "nbrdf-material/1", "name": "b",
                                                   "layers": [{"type": "conductor", "roughness": 0.3, "r0": 2}]}))
    assert main(["bad.json", "--offscreen", "--out", "x.png"]) == 2
    assert "layers[0].r0: 2 is outside [0, 1]" in capsys.readouterr().err
    (tmp_path / "env.exr").write_bytes(b"not an exr")
    assert main(["--offscreen", "--out", "x.png", "--env", "env.exr"]) == 2
    assert "--env env.exr: cannot be read" in capsys.readouterr().err


@pytest.mark.gl
def test_headless_fallback(tmp_path):
    """No display and no --offscreen: one line says so, and the PNG appears."""
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    exe = Path(sys.executable).parent / "nbrdf-view"
    r = subprocess.run([str(exe), "--size", "32x32", "--spp", "1"], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip().splitlines() == ["nbrdf-view: no display found; rendering offscreen to nbrdf-view.png instead"]
    assert (tmp_path / "nbrdf-view.png").stat().st_size > 100


@pytest.mark.gl
def test_cli_renders_a_session_file(gl_ctx, tmp_path, capsys):
    import imageio.v3 as iio

    from nbrdf.viewer.session.lookdev import LookDev

    ld = LookDev(gl_ctx, load_material(DEFAULT_MATERIAL))
    try:
        ld.state.view = "slice"
        ld.set_param(2, "roughness", 0.6)
        assert ld.save_session(tmp_path / "s.json")
        assert ld.write_screenshot(tmp_path / "direct.png", (24, 16), 1)
    finally:
        ld.close()
    assert main(["--offscreen", "--session", str(tmp_path / "s.json"), "--size", "24x16", "--spp", "1",
                 "--out", str(tmp_path / "cli.png")]) == 0
    np.testing.assert_array_equal(iio.imread(tmp_path / "cli.png"), iio.imread(tmp_path / "direct.png"))
    (tmp_path / "bad.json").write_text('{"format": "nbrdf-session/1"}')
    assert main(["--offscreen", "--session", str(tmp_path / "bad.json"), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "malformed session" in err[0]




@pytest.mark.gl
def test_turntable_writes_one_turn_of_frames(tmp_path, capsys):
    """--turntable N: N frames of one camera turn, as numbered images, a GIF or an .mp4; each frame differs."""
    import imageio.v2 as iio

    gold = Path(DEFAULT_MATERIAL).parent / "rough_gold.json"
    common = [str(gold), "--offscreen", "--size", "24x24", "--spp", "1", "--turntable", "4"]
    assert main(common + ["--out", str(tmp_path / "f_%02d.png")]) == 0
    frames = [iio.imread(tmp_path / f"f_{k:02d}.png").astype(float) for k in range(4)]
    assert not (tmp_path / "f_04.png").exists()
    assert all(np.abs(frames[0] - f).mean() > 1.0 for f in frames[1:])  # the camera moved
    assert main(common + ["--out", str(tmp_path / "t.gif")]) == 0
    assert len(iio.mimread(tmp_path / "t.gif")) == 4
    assert main(common + ["--out", str(tmp_path / "t.mp4")]) == 0
    assert iio.get_reader(tmp_path / "t.mp4").count_frames() == 4
    for argv, needle in ((["--out", str(tmp_path / "t.png")], "must be .mp4, .gif or a frame pattern"),
                         (["--out", str(tmp_path / "t.gif"), "--view", "lobe"], "--view object"),
                         (["--out", str(tmp_path / "f_%d_%d.png")], "one integer field")):
        assert main(common + argv) == 2
        err = capsys.readouterr().err.strip()
        assert needle in err and "\n" not in err


@pytest.mark.gl
def test_a_gltf_mesh_brings_its_material(tmp_path, capsys):
    """--mesh model.glb with no MATERIAL: every primitive, z-up, shaded with the file's converted material
    (a one-line note per property without an equivalent); a MATERIAL given wins."""
    from nbrdf.viewer.scene.gltf_import import import_gltf
    from nbrdf.viewer.scene.mesh import load_mesh

    glb = Path(DEFAULT_MATERIAL).parents[1] / "meshes" / "car_paint_pebble.glb"
    mesh = load_mesh(glb)
    assert np.isfinite(mesh.tangents).all() and np.isfinite(mesh.normals).all()
    assert len(mesh.indices) == 3 * sum(len(p.mesh.faces) for p in import_gltf(glb))
    material, notes = ViewOptions(mesh=str(glb)).load_material()
    assert material.layers[0].type == "dielectric" and material.base.type == "conductor" and notes
    assert ViewOptions(material=DEFAULT_MATERIAL.parent / "rough_gold.json", mesh=str(glb)).load_material()[1] == []
    out = tmp_path / "g.npy"
    assert main(["--mesh", str(glb), "--offscreen", "--size", "24x24", "--spp", "1", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "occlusionTexture" in err and len(err.strip().splitlines()) == len(notes)
    img = np.load(out)
    assert np.isfinite(img).all() and (img[..., 0] > img[..., 2]).mean() > 0.2  # red car paint on screen


class _LimitedContext:
    """A context whose reported limits are those of ``ctx`` scaled down (the limit check alone)."""

    def __init__(self, ctx, side: int):
        self._ctx = ctx
        self.info = dict(ctx.info, GL_MAX_RENDERBUFFER_SIZE=side)

    def __getattr__(self, name):
        return getattr(self._ctx, name)


@pytest.mark.gl
def test_a_size_beyond_the_renderbuffer_limit_names_the_limit(gl_ctx):
    from nbrdf.neural.errors import NbrdfError
    from nbrdf.viewer.gpu.gl import check_target_size

    check_target_size(gl_ctx, (64, 48))  # within every limit: no error
    with pytest.raises(NbrdfError, match=r"--size 65x48: .*at most 64x64 \(GL_MAX_RENDERBUFFER_SIZE"):
        check_target_size(_LimitedContext(gl_ctx, 64), (65, 48))


@pytest.mark.gl
def test_cli_size_the_context_cannot_render_is_one_line_exit_2(gl_ctx, tmp_path, capsys, monkeypatch):
    if "llvmpipe" not in gl_ctx.info.get("GL_RENDERER", ""):
        pytest.skip("the 4 GiB float target is refused by llvmpipe; a GPU may allocate it")
    monkeypatch.chdir(tmp_path)
    assert main(["--offscreen", "--out", "x.png", "--size", "16384x16384"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--size 16384x16384" in err[0] and "internal error" not in err[0], err
    assert not (tmp_path / "x.png").exists()
