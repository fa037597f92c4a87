"""The ``nbrdf`` plugin's ``body: "table"`` for a texture-mapped material (a
parametric body table over its mapped albedos): at a grid node it is the
neural path's body of the uniform material with those albedos (within the
angular table's error), between nodes within the measured interpolation
bound; what it cannot hold is one line; the globe renders symbolically."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from hits import directions

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

N = 2048


@pytest.fixture(scope="module")
def globe(tmp_path_factory):
    """(the globe material's path, its table kernel) in a private cache."""
    import os

    import mitsuba as mi

    import nbrdf.mitsuba  # noqa: F401
    from nbrdf.mitsuba.generated import globe_material

    old = os.environ.get("XDG_CACHE_HOME")
    os.environ["XDG_CACHE_HOME"] = str(tmp_path_factory.mktemp("cache"))
    try:
        path = str(globe_material())
    finally:
        if old is None:
            os.environ.pop("XDG_CACHE_HOME")
        else:
            os.environ["XDG_CACHE_HOME"] = old
    bsdf = mi.load_dict({"type": "nbrdf", "material": path, "body": "table"})
    return path, bsdf


def _uniform(path: str, a: float, b: float):
    """The globe's material with its medium albedo a and base albedo b uniform (all channels)."""
    from nbrdf.neural.material import parse_material

    spec = json.loads(open(path).read())
    spec["layers"][1]["albedo"] = a
    spec["layers"][2]["albedo"] = b
    return parse_material(spec)


def _compare(mi, kernel, path, a: float, b: float, rng) -> np.ndarray:
    """Relative error (N, 3) of the table's f (body + coat) against
    ``brdf_for(uniform material, "neural")`` at (a, b) on every channel."""
    from nbrdf.training.brdfs import brdf_for

    light, view = directions(rng, N), directions(rng, N)
    x = [[mi.Float(a), mi.Float(b)] for _ in range(3)]
    wi, wo = mi.Vector3f(light.T), mi.Vector3f(view.T)
    body = kernel.decoder.body(wi, wo, x)
    coat = np.array(kernel.coat.eval(wi, wo))
    got = np.stack([np.array(c) + coat for c in body], 1)
    want = brdf_for(_uniform(path, a, b), "neural").eval(torch.from_numpy(light), torch.from_numpy(view)).numpy()
    return np.abs(got - want) / (np.abs(want) + 1e-3)


def test_param_table_at_nodes_is_the_neural_path(mi, globe):
    """At grid nodes only the angular table's error is left (``materials.BODY_TABLE_SIZE``'s
    64 x 32 x 16 grade): measured with the shipped bundle (v8) mean 0.22-0.46 %, 99th percentile
    1.7-4.1 % (three nodes); bounds about twice that, mean 0.9 %, 99th percentile 8 %."""
    from nbrdf.mitsuba.param_table import GRID

    path, bsdf = globe
    kernel = bsdf.kernel
    (lo_a, hi_a), (lo_b, hi_b) = kernel.decoder.ranges
    rng = np.random.default_rng(11)
    got = []
    for i, j in ((0, 0), (GRID[0] - 1, GRID[1] - 1), (4, 9)):
        a = lo_a + i * (hi_a - lo_a) / (GRID[0] - 1)
        b = lo_b + j * (hi_b - lo_b) / (GRID[1] - 1)
        rel = _compare(mi, kernel, path, a, b, rng)
        got.append((i, j, round(float(rel.mean()), 5), round(float(np.quantile(rel, 0.99)), 4)))
    assert all(m < 9e-3 and q < 8e-2 for _, _, m, q in got), got


def test_param_table_between_nodes_within_its_bound(mi, globe):
    """Cell centres (the interpolation's worst place in each cell) over the maps' ranges:
    measured there mean 0.83 %, 99th percentile 2.4 % (over random (a, b): 0.41 %, 1.8 %,
    ``param_table.GRID``); bounds mean 1.6 %, 99th percentile 5 %."""
    from nbrdf.mitsuba.param_table import GRID

    path, bsdf = globe
    kernel = bsdf.kernel
    (lo_a, hi_a), (lo_b, hi_b) = kernel.decoder.ranges
    rng = np.random.default_rng(12)
    rels = []
    for i, j in ((0, 0), (GRID[0] - 2, GRID[1] - 2), (GRID[0] - 2, 0), (5, 3)):
        a = lo_a + (i + 0.5) * (hi_a - lo_a) / (GRID[0] - 1)
        b = lo_b + (j + 0.5) * (hi_b - lo_b) / (GRID[1] - 1)
        rels.append(_compare(mi, kernel, path, a, b, rng))
    rel = np.concatenate(rels)
    assert rel.mean() < 1.6e-2 and np.quantile(rel, 0.99) < 5e-2, (rel.mean(), np.quantile(rel, 0.99))


def test_param_table_eval_at_hits_is_the_latent_texture_at_the_finest_level(mi, globe):
    """At the finest level (pixel_angle 0) both read the hit's texels bilinearly:
    the latent texture mixes codes, the table mixes albedos; on the globe's
    smooth maps they agree to the table's error (measured mean 0.45 %, 99th 2.9 %;
    bounds 1 %, 6 %)."""
    import drjit as dr

    path, table = globe
    decoder = mi.load_dict({"type": "nbrdf", "material": path})
    rng = np.random.default_rng(13)
    light, view = directions(rng, N), directions(rng, N)
    si = dr.zeros(mi.SurfaceInteraction3f, N)
    si.wi = mi.Vector3f(view.T)
    si.uv = mi.Point2f(rng.random((2, N)).astype(np.float32))
    f = [np.array(b.eval(mi.BSDFContext(), si, mi.Vector3f(light.T))).T for b in (table, decoder)]
    rel = np.abs(f[0] - f[1]) / (np.abs(f[1]) + 1e-3)
    assert rel.mean() < 1e-2 and np.quantile(rel, 0.99) < 6e-2, (rel.mean(), np.quantile(rel, 0.99))


def _png(path, rng, shape):
    import imageio.v3 as iio

    iio.imwrite(path, (rng.random(shape) * 255).astype(np.uint8))


@pytest.mark.parametrize("case,expect", [
    ("roughness", "layers[0].roughness: a texture-mapped dielectric roughness cannot be a parametric body table's"),
    ("sigma_t", "layers[1].sigma_t: a texture-mapped medium sigma_t cannot be"),
    ("three", "3 texture-mapped parameters (layers[1].albedo, layers[3].albedo, layers[4].albedo)"),
])
def test_what_a_param_table_cannot_hold_is_one_line(mi, tmp_path, case, expect):
    from nbrdf.mitsuba import PluginError
    from nbrdf.mitsuba.materials import code_kernel

    rng = np.random.default_rng(1)
    _png(tmp_path / "a.png", rng, (4, 6, 3))
    tex = lambda: [{"texture": "a.png", "channel": c, "range": [0, 1]} for c in "rgb"]
    layers = [{"type": "dielectric", "roughness": 0.1, "ior": 1.5},
              {"type": "medium", "albedo": tex(), "sigma_t": 1.0},
              {"type": "diffuse", "albedo": 0.5}]
    if case == "roughness":
        layers[0]["roughness"] = {"texture": "a.png", "channel": "r", "range": [0.05, 0.4]}
    elif case == "sigma_t":
        layers[1]["sigma_t"] = {"texture": "a.png", "channel": "g", "range": [0.5, 2.0]}
    else:
        layers[2:] = [{"type": "dielectric", "roughness": 0.2, "ior": 1.4},
                      {"type": "medium", "albedo": tex(), "sigma_t": 0.5},
                      {"type": "diffuse", "albedo": tex()}]
    p = tmp_path / "m.json"
    p.write_text(json.dumps({"format": "nbrdf-material/1", "name": "m", "layers": layers}))
    with pytest.raises(PluginError) as e:
        code_kernel(str(p), body="table")
    msg = str(e.value)
    assert expect in msg and 'body "decoder"' in msg and "\n" not in msg, msg


def test_globe_scene_renders_symbolically_with_the_table(mi, tmp_path, monkeypatch):
    """``with_method(..., "table")`` gives the globe the parametric table; it renders
    without entering the wavefront mode, finite and lit."""
    from nbrdf.mitsuba import render as render_mod
    from nbrdf.mitsuba import wavefront_mode
    from nbrdf.mitsuba.scenes import load_scene, neural_bodies, with_method

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    entered = []

    def recording():
        entered.append(True)
        return wavefront_mode()

    globe = with_method(load_scene("globe"), "neural", "table")
    assert neural_bodies(globe) == {"table"} and not render_mod.is_wavefront(globe)
    res = render_mod.render(globe, (16, 12), 2, chunk_spp=1, enter_wavefront=recording)
    assert entered == [] and np.isfinite(res.image).all() and res.image[4:10, 5:11].mean() > 0.02


@pytest.mark.slow
def test_param_table_sampler_passes_mitsubas_chi2(mi, globe):
    """The globe with the table, at one hit (uv 0.3, 0.6) viewed 50 degrees off the
    normal: the directions drawn (zero-weight ones, from the table's eval,
    dropped) follow the pdf reported, at significance 1e-3, Mitsuba's default
    1M samples, ``ires=8`` as the uniform materials' test."""
    import math

    import drjit as dr
    from chi2_adapter import sampler_and_pdf
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    _, bsdf = globe
    t = math.radians(50.0)

    def si(n):
        s = dr.zeros(mi.SurfaceInteraction3f, n)
        s.wi = mi.Vector3f(math.sin(t), 0.0, math.cos(t))
        s.uv = mi.Point2f(0.3, 0.6)
        return s

    sample, pdf = sampler_and_pdf(mi, bsdf, si)
    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3, seed=3, ires=8)
    assert test.run(significance_level=1e-3, quiet=True), test.messages


def test_param_table_body_is_the_torch_twin(mi, globe):
    """The Dr.Jit lookup (slabs stacked along depth, node-aligned) reads the same
    nodes and weights as ``neural.param_table.param_table_lookup`` (a small table:
    3 x 3 nodes, 16 x 8 x 4 angles, where a slab bleeding into the next or a
    half-texel offset would be off by far more than float rounding)."""
    from nbrdf.mitsuba.param_table import ParamTableBody
    from nbrdf.neural.body_table import TableSize
    from nbrdf.neural.material import load_material
    from nbrdf.neural.model import default_model
    from nbrdf.neural.param_table import ParamGrid, bake_param_body, param_table_lookup, table_params

    path, _ = globe
    material = load_material(path)
    params = table_params(material)
    values = bake_param_body(default_model(), material, params, ParamGrid(3, 3), TableSize(16, 8, 4))
    body = ParamTableBody(values.numpy(), params.ranges)
    rng = np.random.default_rng(14)
    light, view = directions(rng, N), directions(rng, N)
    x = rng.random((N, 2)).astype(np.float32) * 1.2 - 0.1  # a tenth beyond each end: clamped at the last node
    got = np.array(body.body(mi.Vector3f(light.T), mi.Vector3f(view.T), [[mi.Float(x[:, 0]), mi.Float(x[:, 1])]])[0])
    want = param_table_lookup(values, params, torch.from_numpy(x), torch.from_numpy(light), torch.from_numpy(view))
    np.testing.assert_allclose(got, want.numpy(), rtol=1e-3, atol=1e-7)  # fp32 coordinates at a coarse grid
