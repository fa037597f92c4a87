"""Texture-mapped materials in Mitsuba: the ``nbrdf`` plugin's latent texture
lookups (bilinear and trilinear by the ray cone) equal the torch latent
texture decoded by the torch decoder; its sampler stays consistent per hit;
``nbrdf_reference`` builds the hit's layer stack from the maps."""
from __future__ import annotations

import json

import numpy as np
import pytest
from hits import directions

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")


@pytest.fixture(scope="module")
def textured(tmp_path_factory):
    """A 6 x 4 texel material: varnish of mapped roughness over a medium of
    mapped albedo over a diffuse base (small, so the latent texture is quick)."""
    import imageio.v3 as iio

    d = tmp_path_factory.mktemp("textured")
    rng = np.random.default_rng(5)
    iio.imwrite(d / "alb.png", (rng.random((4, 6, 3)) * 255).astype(np.uint8))
    iio.imwrite(d / "rough.png", (rng.random((4, 6)) * 255).astype(np.uint8))
    mat = {"format": "nbrdf-material/1", "name": "tex", "layers": [
        {"type": "dielectric", "roughness": {"texture": "rough.png", "channel": "r", "range": [0.05, 0.4]},
         "ior": 1.5},
        {"type": "medium", "albedo": [{"texture": "alb.png", "channel": c, "range": [0, 1]} for c in "rgb"],
         "sigma_t": 1.0},
        {"type": "diffuse", "albedo": 0.6}]}
    (d / "tex.json").write_text(json.dumps(mat))
    return str(d / "tex.json")


def _torch_reference(path, uv_mitsuba, light, view, footprint=None):
    """f cos per pair from the torch latent texture (v flipped: Mitsuba's v 0 is the image's top)."""
    import torch

    from nbrdf.neural.material import load_material
    from nbrdf.neural.model import default_model
    from nbrdf.neural.neural_brdf import latent_brdf
    from nbrdf.neural.svbrdf import latent_texture

    model = default_model()
    tex = latent_texture(model, load_material(path))
    uv = torch.from_numpy(np.stack([uv_mitsuba[:, 0], 1 - uv_mitsuba[:, 1]], 1))
    codes = tex.bilinear(uv, 0) if footprint is None else tex.trilinear(uv, torch.from_numpy(footprint))
    out = np.zeros((len(light), 3))
    for k in range(len(light)):
        b = latent_brdf(model.decoder, codes[k], None, model.sampler)
        out[k] = b.eval(torch.from_numpy(light[k:k + 1]), torch.from_numpy(view[k:k + 1])).numpy()[0] * light[k, 2]
    return out


def _hits(mi, uv, view, t=1.0):
    import drjit as dr

    n = len(uv)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(np.ascontiguousarray(view.T))
    si.uv = mi.Point2f(np.ascontiguousarray(uv.T))
    si.t = mi.Float(t)
    si.dp_du = mi.Vector3f(1.0, 0.0, 0.0)
    si.dp_dv = mi.Vector3f(0.0, 1.0, 0.0)
    return si


@pytest.mark.parametrize("pixel_angle", [0.0, 0.04])
def test_textured_eval_equals_torch_latent_texture(mi, textured, pixel_angle):
    """pixel_angle 0: bilinear on the finest level; 0.04 rad at distances 0.5-32
    (uv extent 1 per unit): footprints 0.02-1.3 uv, i.e. every level of the
    6 x 4 texture's 4 and between them. Tolerance: float32 decoding."""
    rng = np.random.default_rng(7)
    n = 64
    light, view = directions(rng, n, lift=0.2), directions(rng, n, lift=0.2)
    uv = (rng.random((n, 2)) * 1.6 - 0.3).astype(np.float32)  # outside [0, 1] too: wraps
    t = np.geomspace(0.5, 32.0, n).astype(np.float32)
    bsdf = mi.load_dict({"type": "nbrdf", "material": textured, "pixel_angle": pixel_angle})
    f = np.array(bsdf.eval(mi.BSDFContext(), _hits(mi, uv, view, mi.Float(t)), mi.Vector3f(np.ascontiguousarray(light.T)))).T
    ref = _torch_reference(textured, uv, light, view, None if pixel_angle == 0 else (t * pixel_angle).astype(np.float32))
    np.testing.assert_allclose(f, ref, rtol=2e-4, atol=1e-6)


def test_textured_sampler_pdf_matches_its_samples(mi, textured):
    """The pdf a sample reports is the plugin's pdf of that direction at that
    hit (per-hit coat): sample and pdf agree lane by lane."""
    import drjit as dr

    rng = np.random.default_rng(3)
    n = 256
    view = directions(rng, n, lift=0.2)
    uv = rng.random((n, 2)).astype(np.float32)
    bsdf = mi.load_dict({"type": "nbrdf", "material": textured})
    si = _hits(mi, uv, view)
    ctx = mi.BSDFContext()
    bs, _ = bsdf.sample(ctx, si, mi.Float(rng.random(n).astype(np.float32)),
                        mi.Point2f(np.ascontiguousarray(rng.random((2, n)).astype(np.float32))))
    pdf = np.array(bsdf.pdf(ctx, si, bs.wo))
    dr.eval(bs.pdf)
    ok = np.array(bs.pdf) > 0
    assert ok.mean() > 0.8
    np.testing.assert_allclose(np.array(bs.pdf)[ok], pdf[ok], rtol=1e-4)


@pytest.mark.slow
def test_textured_reference_is_the_walk_of_the_hits_texel(mi, textured, tmp_path):
    """At texel centres the maps' bilinear value is the texel's: the plugin's
    estimates equal ``reference_eval`` of the uniform material with those
    values. 16 calls of 128 paths per pair (few paths per call give skewed,
    heavy-tailed means: 24 x 16 paths read 0.5 sigma low on this scattering
    stack, while 4096 paths agree within 0.5 %). z over 2 texels x 12 pairs x
    3 channels (channels share paths: about 24 independent values): |mean z|
    < 4 / sqrt(24), mean z^2 < 1.8 (z of 16 calls is t with 15 degrees of
    freedom, variance 1.15). A 10 % error in the albedo read gives z about 7."""
    import imageio.v3 as iio
    import torch

    from nbrdf.mitsuba import wavefront_mode
    from nbrdf.neural.material import load_material
    from nbrdf.training.reference import reference_eval

    base = tmp_path
    img = iio.imread(str(textured).replace("tex.json", "alb.png")).astype(np.float64) / 255
    rough = iio.imread(str(textured).replace("tex.json", "rough.png")).astype(np.float64) / 255
    rng = np.random.default_rng(11)
    n, calls, spp = 12, 16, 128
    bsdf = mi.load_dict({"type": "nbrdf_reference", "material": textured, "spp": spp, "seed": 2})
    zs = []
    for row, col in ((0, 1), (3, 4)):  # image rows from the top
        light, view = directions(rng, n, lift=0.2), directions(rng, n, lift=0.2)
        uv = np.tile(np.array([[(col + 0.5) / 6, (row + 0.5) / 4]], np.float32), (n, 1))
        with wavefront_mode():
            runs = np.stack([np.array(bsdf.eval(mi.BSDFContext(), _hits(mi, uv, view),
                                                mi.Vector3f(np.ascontiguousarray(light.T)))).T / light[:, 2:3]
                             for _ in range(calls)])
        mean, se = runs.mean(0), runs.std(0, ddof=1) / np.sqrt(calls)
        uniform = {"format": "nbrdf-material/1", "name": "texel", "layers": [
            {"type": "dielectric", "roughness": 0.05 + rough[row, col] * 0.35, "ior": 1.5},
            {"type": "medium", "albedo": img[row, col].tolist(), "sigma_t": 1.0},
            {"type": "diffuse", "albedo": 0.6}]}
        (base / "u.json").write_text(json.dumps(uniform))
        ref, ref_se = reference_eval(load_material(base / "u.json"), torch.from_numpy(light), torch.from_numpy(view),
                                     spp=4096, seed=5)
        zs.append((mean - ref.numpy()) / np.sqrt(se ** 2 + ref_se.numpy() ** 2))
    z = np.concatenate(zs)
    assert abs(z.mean()) < 4 / np.sqrt(z.size / 3), z.mean()
    assert (z ** 2).mean() < 1.8, (z ** 2).mean()


def test_textured_reference_refuses_a_single_textured_layer(mi, tmp_path):
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "a.png", np.full((2, 2), 128, np.uint8))
    (tmp_path / "m.json").write_text(json.dumps({"format": "nbrdf-material/1", "name": "x", "layers": [
        {"type": "diffuse", "albedo": {"texture": "a.png", "channel": "r", "range": [0, 1]}}]}))
    with pytest.raises(Exception, match="needs a layer stack"):
        mi.load_dict({"type": "nbrdf_reference", "material": str(tmp_path / "m.json")})


@pytest.mark.slow
def test_textured_scene_renders_in_wavefront_mode(mi, textured, tmp_path):
    """A textured neural sphere path traced in wavefront mode with mip-mapping:
    lanes that a call masks off gather level sizes of 0, which once made the
    kernel divide by zero (SIGFPE, the interpreter killed)."""
    from nbrdf.mitsuba.render import render
    from nbrdf.mitsuba.scenes import load_scene

    (tmp_path / "s.json").write_text(json.dumps({
        "camera": {"origin": [0, -4, 1], "target": [0, 0, 0.5], "fov": 30},
        "environment": "studio", "max_depth": 3,
        "shapes": [{"type": "sphere", "center": [0, 0, 0.5], "radius": 0.5, "material": textured},
                   {"type": "torus", "center": [0, 0, 0.2], "radius": 1.2, "tube": 0.2, "material": textured,
                    "normal_map": {"name": "knurled", "tiles": [4, 1]}},
                   {"type": "rectangle", "size": [4, 4], "material": {"diffuse": 0.4}}]}))
    res = render(load_scene(str(tmp_path / "s.json")), (12, 9), 2, chunk_spp=1)
    assert np.isfinite(res.image).all() and res.image.mean() > 0
