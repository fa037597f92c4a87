"""The compare view's MaterialX side (viewer/reference/materialx_view.py): MaterialX's own generated GLSL of the
material's OpenPBR inputs over the window's mesh, camera, lights and environment. Its environment maps read the
previewer's environment where the previewer does (any rotation), a white diffuse OpenPBR is Lambert under a
furnace and under the directional light, an OpenPBR edit redraws it without a new program, the brushing
rotation turns its tangent, and a material it cannot show says why in one line."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from nbrdf.imaging.environment import EnvironmentMap
from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.mtlx import write_mtlx
from nbrdf.neural.openpbr import OpenPbr
from nbrdf.viewer.gpu.materialx_glsl import env_matrix, materialx_environment
from nbrdf.viewer.reference.materialx_view import LABEL, rotated_tangents

C = np.array([0.3, -0.5, 0.7])  # the test sky's gradient: radiance 2 + C . d


def _sky(h: int = 64, w: int = 128) -> np.ndarray:
    theta = (np.arange(h) + 0.5) / h * math.pi
    phi = (np.arange(w) + 0.5) / w * 2 * math.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    return np.repeat((2.0 + d @ C)[..., None], 3, -1).astype(np.float32)


def _materialx_read(img: np.ndarray, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    """MaterialX's ``mx_latlong_map_lookup`` (its GLSL, restated): the map read bilinearly at the direction
    ``u_envMatrix`` x d projected by ``mx_latlong_projection``."""
    e = d @ m[:3, :3].T
    u = np.arctan2(e[:, 0], -e[:, 2]) / (2 * math.pi) + 0.5
    v = -np.arcsin(np.clip(e[:, 1], -1, 1)) / math.pi + 0.5
    h, w = img.shape[:2]
    x, y = u * w - 0.5, np.clip(v * h - 0.5, 0, h - 1)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, x1, y1 = x0 % w, (x0 + 1) % w, np.minimum(y0 + 1, h - 1)
    return (img[y0, x0] * (1 - fx) + img[y0, x1] * fx) * (1 - fy) + (img[y1, x0] * (1 - fx) + img[y1, x1] * fx) * fy


@pytest.mark.parametrize("rotation", [0.0, 37.0, -120.0])
def test_materialx_maps_read_the_environment_where_the_previewer_does(rotation):
    """At any world direction, MaterialX's reads of its radiance and irradiance maps through ``u_envMatrix`` give
    the previewer's environment turned by ``rotation`` (environment.glsl: env_rotate(d, -rotation)): the
    radiance 2 + C . d' and the irradiance over pi 2 + (2/3) C . d' at d' = the unturned direction, to 1 %
    (a turn of the wrong sign or a swapped axis is off by up to 40 %)."""
    rad, irr = materialx_environment(EnvironmentMap(_sky()))
    m = env_matrix(rotation)
    d = np.random.default_rng(7).normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    a = math.radians(-rotation)
    unturned = np.stack([math.cos(a) * d[:, 0] - math.sin(a) * d[:, 1],
                         math.sin(a) * d[:, 0] + math.cos(a) * d[:, 1], d[:, 2]], -1)
    assert np.allclose(_materialx_read(rad, m, d)[:, 0], 2.0 + unturned @ C, rtol=0.01)
    assert np.allclose(_materialx_read(irr, m, d)[:, 0], 2.0 + unturned @ C * 2 / 3, rtol=0.01)


def test_the_brushing_rotation_turns_the_tangent_toward_the_bitangent():
    n = np.array([[0.0, 0.0, 1.0]] * 2)
    t = np.array([[1.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, -1.0]])
    assert np.allclose(rotated_tangents(n, t, 90.0), [[0, 1, 0], [0, -1, 0]], atol=1e-6)
    assert np.allclose(rotated_tangents(n, t, 0.0), t[:, :3])


def _openpbr_lookdev(gl_ctx, tmp_path, p: OpenPbr, name: str = "white"):
    from nbrdf.viewer.session.lookdev import LookDev

    path = tmp_path / f"{name}.mtlx"
    write_mtlx(p, name, path)
    return LookDev(gl_ctx, load_material(path, []))


def _object(ld, state, size):
    """MaterialX's image (H, W, 4), row 0 on top, and the view's world normals and mask (the G-buffer)."""
    w, h = size
    tex = ld.materialx_part.image(ld.material, state, w, h)
    img = np.frombuffer(tex.read(), np.float32).reshape(h, w, 4)[::-1]
    normal, _, mask, _ = ld.compare_part.surface(state, size)
    return img, normal, mask


def _interior(mask: np.ndarray) -> np.ndarray:
    """The mask less its edge pixels (a rasteriser's silhouette is not the G-buffer's to the pixel)."""
    m = mask.copy()
    m[1:] &= mask[:-1]
    m[:-1] &= mask[1:]
    m[:, 1:] &= mask[:, :-1]
    m[:, :-1] &= mask[:, 1:]
    return m


@pytest.mark.gl
def test_white_diffuse_openpbr_is_lambert_under_a_furnace_and_a_light(gl_ctx, tmp_path):
    """A white diffuse OpenPBR (no specular) in a uniform environment of radiance 1 reflects 1 (MaterialX's
    irradiance map of the previewer's environment; the mean within 3 %, every pixel in [0.85, 1.03]: MaterialX's
    energy-compensated Oren-Nayar darkens grazing pixels by up to 10 %), and under the directional light
    alone E max(n . l, 0) / pi at the G-buffer's normals (the ratio in [0.85, 1.03], median > 0.93, where the
    light gives a quarter of its peak or more): the camera, the light's direction and its intensity bound as the
    previewer's (a light from the wrong side or of the wrong intensity fails by far)."""
    ld = _openpbr_lookdev(gl_ctx, tmp_path, OpenPbr(base_color=(1.0, 1.0, 1.0), specular_weight=0.0))
    try:
        size = (48, 40)
        ld.frame(size[0] / size[1])
        ld.renderer.set_environment(np.ones((16, 32, 3), np.float32))
        furnace = replace(ld.state, env_on=True, env_intensity=1.0, light_radiance=0.0, point_light=None)
        img, _, mask = _object(ld, furnace, size)
        inside = _interior(mask)
        rgb = img[inside, :3]
        assert inside.sum() > 300 and abs(rgb.mean() - 1.0) < 0.03 and rgb.min() > 0.85 and rgb.max() < 1.03, rgb.mean()
        assert np.all(img[~mask & _interior(~mask), 3] == 0.0) and np.all(img[inside, 3] == 1.0)
        lit = replace(furnace, env_on=False, light_radiance=3.0)
        img, normal, mask = _object(ld, lit, size)
        inside = _interior(mask)
        ld_ = np.asarray(lit.light_dir) / np.linalg.norm(lit.light_dir)
        want = 3.0 * np.maximum(normal[inside] @ ld_, 0.0) / math.pi
        lit_px = want > 0.25 * want.max()
        ratio = img[inside, 0][lit_px] / want[lit_px]
        assert lit_px.sum() > 100 and ratio.min() > 0.85 and ratio.max() < 1.03 and np.median(ratio) > 0.93, ratio
    finally:
        ld.close()


@pytest.mark.gl
def test_an_openpbr_edit_redraws_the_materialx_side_without_a_new_program(gl_ctx, tmp_path):
    """Side by side against MaterialX: the right half is MaterialX's image, labelled as such; an edit of
    base_color redraws it (red falls by the edit's factor on a diffuse white, within 5 %) with the same program."""
    ld = _openpbr_lookdev(gl_ctx, tmp_path, OpenPbr(base_color=(0.8, 0.8, 0.8), specular_weight=0.0))
    try:
        size = (32, 24)
        ld.frame(size[0] / size[1])
        assert ld.set_compare("side") and ld.set_against("materialx")
        state = ld.state
        before, _, mask = _object(ld, state, size)
        prog, version = ld.materialx_part._prog, ld.materialx_part.version
        assert ld.set_openpbr("base_color", [0.2, 0.8, 0.8])
        after, _, _ = _object(ld, state, size)
        inside = _interior(mask)
        ratio = after[inside, 0].sum() / before[inside, 0].sum()
        assert abs(ratio - 0.25) < 0.05 * 0.25 and ld.materialx_part._prog is prog and ld.materialx_part.version > version
        assert ld.compare_part.label_list("side", 0.5, LABEL)[1].text == LABEL
        assert "MaterialX" in ld.reference_status() and ld.materialx_part.placeholder is None
        doc = ld.session()
        assert doc["view"]["against"] == "materialx"
    finally:
        ld.close()


@pytest.mark.gl
def test_a_material_without_openpbr_inputs_says_why(gl_ctx):
    """A stack written in the project's JSON has no OpenPBR inputs: MaterialX's side is the placeholder with one
    line, the status says the same, and a bad choice of side is one line that changes nothing."""
    import moderngl

    from nbrdf.viewer.session.lookdev import LookDev

    ld = LookDev(gl_ctx, parse_material({"format": "nbrdf-material/1", "name": "coat", "layers": [
        {"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "diffuse", "albedo": 0.5}]}))
    try:
        assert ld.set_compare("side") and ld.set_against("materialx")
        assert not ld.set_against("mitsuba") and "mitsuba" in ld.error
        tex = gl_ctx.texture((32, 16), 4)
        fbo = gl_ctx.framebuffer([tex])
        ld.update()
        ld.render(fbo, (32, 16))
        assert ld.materialx_part.placeholder is not None and "no OpenPBR inputs" in ld.materialx_part.placeholder
        assert ld.reference_status() == ld.materialx_part.placeholder
        assert isinstance(ld.materialx_part.image(ld.material, ld.state, 8, 8), moderngl.Texture)
    finally:
        ld.close()


@pytest.mark.gl
def test_a_base_colour_image_is_read_where_the_stack_reads_it(gl_ctx, tmp_path):
    """A document with an image on base_color (red in the file's bottom half, blue in its top half): MaterialX's
    side reads the same image at the same uv as the neural side -- where one shows red over blue, so does the
    other (at least 90 % of the object's pixels agree; a flipped v agrees on about half)."""
    import imageio.v3 as iio

    from nbrdf.viewer.session.lookdev import LookDev

    img = np.zeros((16, 16, 3), np.uint8)
    img[:8] = (40, 60, 230)  # the file's top rows: blue
    img[8:] = (230, 40, 40)  # its bottom rows: red
    iio.imwrite(tmp_path / "halves.png", img)
    write_mtlx(OpenPbr(specular_weight=0.0), "h", tmp_path / "halves.mtlx", base_color_image="halves.png")
    ld = LookDev(gl_ctx, load_material(tmp_path / "halves.mtlx", []), threaded=False)  # its latent texture at once
    try:
        size = (96, 48)
        ld.frame(1.0)
        ld.update_state(camera=replace(ld.state.camera, pitch=10.0))
        assert ld.set_compare("side") and ld.set_against("materialx")
        ld.compare_part.show_labels = False  # the names would cover the top of the spheres
        fbo = gl_ctx.simple_framebuffer(size, components=4)
        for _ in range(4):
            ld.update()
            ld.render(fbo, size, 2)
        assert ld.materialx_part.placeholder is None, ld.materialx_part.placeholder
        shown = np.frombuffer(fbo.read(components=3), np.uint8).reshape(size[1], size[0], 3)[::-1].astype(int)
        neural, mx = shown[:, :48], shown[:, 48:]
        _, _, mask, _ = ld.compare_part.surface(ld.state, (48, 48))
        inside = _interior(mask)
        red_n = neural[..., 0] > neural[..., 2]
        red_m = mx[..., 0] > mx[..., 2]
        assert red_n[inside].mean() > 0.2 and (~red_n[inside]).mean() > 0.2  # both halves of the image in view
        assert (red_n == red_m)[inside].mean() > 0.9, (red_n == red_m)[inside].mean()
    finally:
        ld.close()


@pytest.mark.gl
def test_a_base_colour_image_gone_since_opening_is_one_line_on_the_side(gl_ctx, tmp_path):
    """The image file is deleted after the material opened: MaterialX's side shows the placeholder with one line
    naming the file, and the view goes on (no exception out of the frame)."""
    import imageio.v3 as iio

    from nbrdf.viewer.session.lookdev import LookDev

    iio.imwrite(tmp_path / "c.png", np.full((4, 4, 3), 128, np.uint8))
    write_mtlx(OpenPbr(), "c", tmp_path / "c.mtlx", base_color_image="c.png")
    ld = LookDev(gl_ctx, load_material(tmp_path / "c.mtlx", []), threaded=False)
    try:
        (tmp_path / "c.png").unlink()
        ld.materialx_part.image(ld.material, ld.state, 16, 16)
        assert ld.materialx_part.placeholder is not None and "c.png" in ld.materialx_part.placeholder
        assert "\n" not in ld.materialx_part.placeholder
    finally:
        ld.close()
