"""A material JSON's ``normal_map`` inside the Mitsuba plugins: ``nbrdf``
with the map equals Mitsuba's own ``normalmap`` around ``nbrdf`` without it
(same map; its shadow-terminator term and normal flip off, which the
previewer does not have), in eval, pdf and sample, and in a render; the
sampler stays consistent in the bent frame (``mitsuba.chi2``);
``nbrdf_reference`` walks in the same bent frame; a bad map is one line."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

LAYERS = [{"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "diffuse", "albedo": [0.7, 0.2, 0.1]}]


def _write(path, layers=LAYERS, normal_map=None) -> str:
    m = {"format": "nbrdf-material/1", "name": path.stem, "layers": layers}
    if normal_map is not None:
        m["normal_map"] = normal_map
    path.write_text(json.dumps(m))
    return str(path)


def _png(path, normals: np.ndarray) -> str:
    """Unit normals (H, W, 3), row 0 = the image's top, as an 8-bit map (x -> (x + 1) / 2)."""
    import imageio.v3 as iio

    iio.imwrite(path, np.round((normals * 0.5 + 0.5) * 255).astype(np.uint8))
    return str(path)


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    """A smooth wavy map (tilts up to 27 degrees, varying along u and v: a
    wrong axis, sign or v flip shows), a constant 30-degree tilt, and the
    material with each and without."""
    d = tmp_path_factory.mktemp("normal_maps")
    h, w = 16, 24
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    n = np.stack([0.5 * np.sin(2 * np.pi * u), 0.4 * np.cos(2 * np.pi * v) + 0.1, np.ones_like(u)], -1)
    _png(d / "wavy.png", n / np.linalg.norm(n, axis=-1, keepdims=True))
    t = math.radians(30)
    _png(d / "tilt.png", np.broadcast_to([math.sin(t), 0.0, math.cos(t)], (2, 2, 3)))
    return {"dir": d, "plain": _write(d / "plain.json"), "wavy": _write(d / "wavy.json", normal_map="wavy.png"),
            "tilt": _write(d / "tilt.json", normal_map="tilt.png")}


def _wrapper(mi, png: str, material: str, **props):
    """Mitsuba's ``normalmap`` around ``nbrdf`` (the map read raw, bilinear, repeating)."""
    return mi.load_dict({"type": "normalmap", "flip_invalid_normals": False, "use_shadowing_function": False,
                         "normalmap": {"type": "bitmap", "filename": png, "raw": True, "filter_type": "bilinear",
                                       "wrap_mode": "repeat"},
                         "bsdf": {"type": "nbrdf", "material": material, **props}})


def _cone(rng, n, max_deg) -> np.ndarray:
    th = np.radians(max_deg) * np.sqrt(rng.random(n))
    ph = 2 * np.pi * rng.random(n)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1).astype(np.float32)


def _hits(mi, wi: np.ndarray, uv: np.ndarray):
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = mi.Vector3f(np.ascontiguousarray(wi.T))
    si.uv = mi.Point2f(np.ascontiguousarray(uv.T))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    si.t = mi.Float(1.0)
    si.dp_du, si.dp_dv = mi.Vector3f(1.0, 0.0, 0.0), mi.Vector3f(0.0, 1.0, 0.0)
    return si


def test_bent_frame_equals_mitsubas_normalmap_wrapper(mi, maps):
    """4,096 hits at random uvs (wrapping past [0, 1]), views within 45 degrees
    of the normal (the map's normals all face them: no pull-back), queried
    directions over the hemisphere. Tolerance: float32 arithmetic."""
    rng = np.random.default_rng(11)
    n = 4096
    wi, wo = _cone(rng, n, 45), _cone(rng, n, 89)
    uv = (rng.random((n, 2)) * 3 - 1).astype(np.float32)
    ours = mi.load_dict({"type": "nbrdf", "material": maps["wavy"]})
    theirs = _wrapper(mi, str(maps["dir"] / "wavy.png"), maps["plain"])
    ctx, si, w = mi.BSDFContext(), _hits(mi, wi, uv), mi.Vector3f(np.ascontiguousarray(wo.T))
    f_ours, f_theirs = np.array(ours.eval(ctx, si, w)), np.array(theirs.eval(ctx, si, w))
    assert (f_theirs.sum(0) == 0).mean() > 0.05  # the map puts some queried directions below the bent surface
    np.testing.assert_allclose(f_ours, f_theirs, rtol=2e-5, atol=2e-5 * f_theirs.max())
    p_ours, p_theirs = np.array(ours.pdf(ctx, si, w)), np.array(theirs.pdf(ctx, si, w))
    np.testing.assert_allclose(p_ours, p_theirs, rtol=2e-5, atol=2e-5 * p_theirs.max())
    s1 = mi.Float(rng.random(n).astype(np.float32))
    s2 = mi.Point2f(rng.random((2, n)).astype(np.float32))
    (bs_o, w_o), (bs_t, w_t) = ours.sample(ctx, si, s1, s2), theirs.sample(ctx, si, s1, s2)
    np.testing.assert_allclose(np.array(bs_o.wo), np.array(bs_t.wo), atol=5e-5)
    np.testing.assert_allclose(np.array(bs_o.pdf), np.array(bs_t.pdf), rtol=5e-5, atol=1e-5)
    np.testing.assert_allclose(np.array(w_o), np.array(w_t), rtol=1e-4, atol=1e-4)
    # and the map matters: without it the same queries differ
    plain = np.array(mi.load_dict({"type": "nbrdf", "material": maps["plain"]}).eval(ctx, si, w))
    assert np.abs(plain - f_theirs).max() > 0.1 * f_theirs.max()


def test_a_normal_facing_away_is_pulled_back_to_the_silhouette(mi, maps):
    """The previewer's rule: a bent normal with n . wi < 1e-3 is moved toward
    the viewer until n . wi = 1e-3, so a view 80 degrees off the normal,
    opposite the 30-degree tilt, still sees the surface (Mitsuba's wrapper
    without its flip sees nothing there)."""
    from nbrdf.mitsuba.normal_map import MIN_COS, NormalMapKernel

    wi = np.array([[-math.sin(math.radians(80)), 0.0, math.cos(math.radians(80))]], np.float32)
    si = _hits(mi, wi, np.array([[0.25, 0.25]], np.float32))
    nrm = NormalMapKernel(maps["dir"] / "tilt.png").normal(si)
    n = np.array(nrm).reshape(3)
    assert abs(np.linalg.norm(n) - 1) < 1e-5
    assert abs(float(n @ wi[0]) - MIN_COS) < 1e-4
    assert n[0] > 0 and n[2] > 0  # still tilted the map's way
    wo = mi.Vector3f(np.ascontiguousarray(_cone(np.random.default_rng(2), 64, 60).T))
    f = np.array(mi.load_dict({"type": "nbrdf", "material": maps["tilt"]}).eval(mi.BSDFContext(), _hits(
        mi, np.repeat(wi, 64, 0), np.full((64, 2), 0.25, np.float32)), wo))
    assert np.isfinite(f).all() and f.max() > 0


def test_reference_walks_in_the_bent_frame(mi, maps):
    """``nbrdf_reference`` with the map at (wi, wo) is the walk without it at the
    bent directions: same seed, same paths, so equal (eval and sample)."""
    from nbrdf.mitsuba.normal_map import NormalMapKernel

    rng = np.random.default_rng(5)
    n = 512
    wi, wo = _cone(rng, n, 45), _cone(rng, n, 89)
    uv = rng.random((n, 2)).astype(np.float32)
    ours = mi.load_dict({"type": "nbrdf_reference", "material": maps["wavy"], "seed": 3})
    plain = mi.load_dict({"type": "nbrdf_reference", "material": maps["plain"], "seed": 3})
    si = _hits(mi, wi, uv)
    frame = NormalMapKernel(maps["dir"] / "wavy.png").frame(si)
    w = mi.Vector3f(np.ascontiguousarray(wo.T))
    bent_si = _hits(mi, np.array(frame.to_local(si.wi)).T.astype(np.float32), uv)
    bent_wo = frame.to_local(w)
    ctx = mi.BSDFContext()
    f = np.array(ours.eval(ctx, si, w))
    ok = (np.array(bent_wo.z) > 0) & (wo[:, 2] > 0)
    g = np.array(plain.eval(ctx, bent_si, bent_wo)) * ok
    np.testing.assert_allclose(f, g, rtol=1e-5, atol=1e-6)
    assert (f.sum(0) > 0).mean() > 0.5
    s1 = mi.Float(rng.random(n).astype(np.float32))
    s2 = mi.Point2f(rng.random((2, n)).astype(np.float32))
    (bs, weight), (bs_p, weight_p) = ours.sample(ctx, si, s1, s2), plain.sample(ctx, bent_si, s1, s2)
    expect = np.array(frame.to_world(bs_p.wo))
    live = np.array(bs.pdf) > 0
    assert live.mean() > 0.5
    np.testing.assert_allclose(np.array(bs.wo)[:, live], expect[:, live], atol=2e-5)
    np.testing.assert_allclose(np.array(bs.pdf)[live], np.array(bs_p.pdf)[live], rtol=1e-5)
    np.testing.assert_allclose(np.array(weight)[:, live], np.array(weight_p)[:, live], rtol=1e-5, atol=1e-6)
    assert (np.array(bs.wo)[2][live] > 0).all()


CHI2_CASES = [0.0, 45.0]


@pytest.mark.slow
@pytest.mark.parametrize("theta", CHI2_CASES)
def test_sampler_with_a_tilted_normal_passes_mitsubas_chi2(mi, maps, theta):
    """The coated material under a constant 30-degree tilt, viewed along the
    normal and 45 degrees off it opposite the tilt (75 degrees in the bent
    frame): the directions drawn (those below the unperturbed surface
    dropped) follow the pdf reported, at significance 1e-3 over the set,
    Mitsuba's default 1M samples, ``ires=8`` as the untilted test."""
    from chi2_adapter import sampler_and_pdf
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    bsdf = mi.load_dict({"type": "nbrdf", "material": maps["tilt"]})
    wi = np.array([[-math.sin(math.radians(theta)), 0.0, math.cos(math.radians(theta))]], np.float32)

    def si(n):
        return _hits(mi, np.repeat(wi, n, 0), np.full((n, 2), 0.3, np.float32))

    sample, pdf = sampler_and_pdf(mi, bsdf, si)
    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3, seed=3, ires=8)
    assert test.run(significance_level=1e-3, test_count=len(CHI2_CASES), quiet=True), test.messages


@pytest.mark.slow
def test_render_equals_mitsubas_normalmap_wrapper(mi, maps):
    """A sphere under the studio environment and a key light (direct lighting,
    32 x 32, 64 spp, the same seed): the plugin's own map and Mitsuba's
    wrapper give the same image, up to float rounding, wherever the sphere
    faces the camera within 55 degrees (no bent normal faces away there: the
    map tilts at most 27 degrees). Nearer the silhouette the previewer's
    pull-back lights what the wrapper (its flip off) leaves black."""
    import drjit as dr

    from nbrdf.mitsuba import wavefront_mode
    from nbrdf.mitsuba.scenes import ENV_TO_WORLD, environment_bitmap

    T = mi.ScalarTransform4f
    res = 32

    def scene(bsdf):
        return mi.load_dict({
            "type": "scene", "integrator": {"type": "direct"},
            "env": {"type": "envmap", "bitmap": environment_bitmap("studio", 1.0, (64, 32)), "to_world": T(ENV_TO_WORLD)},
            "key": {"type": "directional", "direction": [-0.4, 0.3, -0.8], "irradiance": 2.0},
            "sphere": {"type": "sphere", "bsdf": bsdf},
            "camera": {"type": "perspective", "fov": 30, "to_world": T().look_at(origin=[0, -5, 1.5], target=[0, 0, 0],
                                                                                   up=[0, 0, 1]),
                       "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"},
                                "pixel_format": "rgb"},
                       "sampler": {"type": "independent", "sample_count": 64}}})

    def render(bsdf):
        with wavefront_mode():
            return np.array(mi.render(scene(bsdf), seed=7))

    ours = render({"type": "nbrdf", "material": maps["wavy"]})
    theirs = render({"type": "normalmap", "flip_invalid_normals": False, "use_shadowing_function": False,
                     "normalmap": {"type": "bitmap", "filename": str(maps["dir"] / "wavy.png"), "raw": True,
                                   "filter_type": "bilinear", "wrap_mode": "repeat"},
                     "bsdf": {"type": "nbrdf", "material": maps["plain"]}})
    plain = render({"type": "nbrdf", "material": maps["plain"]})
    # the pixels whose whole square sees the sphere within 55 degrees of its normal (corners checked)
    sc = scene({"type": "nbrdf", "material": maps["plain"]})
    facing = np.ones((res, res), bool)
    for dx in (0.0, 1.0):
        for dy in (0.0, 1.0):
            y, x = np.meshgrid(np.arange(res) + dy, np.arange(res) + dx, indexing="ij")
            pos = mi.Point2f(np.ascontiguousarray(np.stack([x.ravel(), y.ravel()]) / res, np.float32))
            ray, _ = sc.sensors()[0].sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
            si = sc.ray_intersect(ray)
            cos = np.where(np.array(si.is_valid()), np.array(dr.dot(si.n, -ray.d)), 0.0)
            facing &= (cos > np.cos(np.radians(55))).reshape(res, res)
    assert facing.sum() > 100
    np.testing.assert_allclose(ours[facing], theirs[facing], rtol=1e-3, atol=1e-4 * theirs[facing].max())
    rel = np.abs(plain[facing] - theirs[facing]).max(-1) / theirs[facing].max(-1)
    assert np.median(rel) > 0.02  # the map shows


@pytest.mark.parametrize("plugin", ["nbrdf", "nbrdf_reference"])
@pytest.mark.parametrize("case,message", [("missing", "not found"), ("gray", "needs RGB"),
                                          ("broken", "cannot read")])
def test_a_bad_normal_map_is_one_clear_line(mi, tmp_path, plugin, case, message):
    import imageio.v3 as iio

    if case == "gray":
        iio.imwrite(tmp_path / "n.png", np.full((4, 4), 128, np.uint8))
    elif case == "broken":
        (tmp_path / "n.png").write_bytes(b"not an image")
    path = _write(tmp_path / "m.json", normal_map="n.png")
    with pytest.raises(Exception) as info:
        mi.load_dict({"type": plugin, "material": path})
    last = str(info.value).strip().splitlines()[-1]  # Mitsuba adds a traceback; the last line is the plugin's
    assert last.startswith(f"PluginError: {plugin}: ") and "normal_map" in last and message in last, last
    assert "n.png" in last
