"""Anisotropic materials in the Mitsuba plugins (SPEC section 10): the ``nbrdf`` plugin's eval of a brushed
conductor, bare and under a brushed clear coat, equals the torch path (decoder body; the baked table within its
error) at several rotations, and so do its samples and pdf (the anisotropic coat's visible normals, the body's
stretched proxy); its sampler passes Mitsuba's chi-square test at each rotation and fails it when its rotation
is off by 10 degrees; an isotropic material renders as before; ``nbrdf_reference`` walks anisotropic stacks;
texture-mapped anisotropy is one line."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch
from chi2_adapter import sampler_and_pdf
from hits import directions, interactions

from nbrdf.neural.anisotropy import FRAME_PARAMS, body_glow
from nbrdf.neural.material import load_material

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

N = 4096
METAL = {"type": "conductor", "roughness": 0.3, "r0": [0.9, 0.6, 0.5], "anisotropy": 0.8}
COAT = {"type": "dielectric", "roughness": 0.1, "ior": 1.5, "anisotropy": 0.8}
VARNISH = [{"type": "dielectric", "roughness": 0.05, "ior": 1.5},
           {"type": "medium", "albedo": [0.4, 0.3, 0.2], "sigma_t": 0.5}]  # scatters thinly: a glow (decision 123)
STACKS = {"brushed": [METAL], "coated_brushed": [COAT, METAL], "varnished_brushed": VARNISH + [METAL]}
ROTATIONS = (0.0, 30.0, 90.0)


def _write(path, layers, rotation: float) -> str:
    path.write_text(json.dumps({"format": "nbrdf-material/1", "name": path.stem, "layers": layers,
                                "anisotropy_rotation": rotation}))
    return str(path)


@pytest.fixture(scope="module")
def brushed(tmp_path_factory):
    """(stack, rotation) -> a material JSON; rotation 40 for the chi-square test's wrong sampler."""
    d = tmp_path_factory.mktemp("anisotropic")
    return {(name, rot): _write(d / f"{name}_{rot:g}.json", layers, rot)
            for name, layers in STACKS.items() for rot in ROTATIONS + (40.0,)}


def _within_spec(a: np.ndarray, b: np.ndarray) -> float:
    """Largest |a - b| / (1e-4 (1 + |b|)): at most 1 within SPEC section 7's tolerance."""
    return float((np.abs(a - b) / (1e-4 * (1 + np.abs(b)))).max())


def _eval(mi, bsdf, view, light) -> np.ndarray:
    return np.array(bsdf.eval(mi.BSDFContext(), interactions(mi, view), mi.Vector3f(np.ascontiguousarray(light.T)))).T


def _pairs(seed: int):
    rng = np.random.default_rng(seed)
    light, view = directions(rng, N), directions(rng, N)
    light[:8, 2] *= -1  # a few below the horizon: zero on both sides
    return light, view


@pytest.mark.parametrize("rotation", ROTATIONS)
@pytest.mark.parametrize("stack", STACKS)
def test_eval_equals_the_torch_path(mi, brushed, stack, rotation):
    """Within SPEC 7's tolerance of ``neural_brdf(material).eval``: the decoder at the warped pair times J
    (grazing pairs included, where the warp lifts a direction), the anisotropic coat, a thin varnish's glow."""
    from nbrdf.neural.neural_brdf import neural_brdf

    light, view = _pairs(11)
    path = brushed[(stack, rotation)]
    value = _eval(mi, mi.load_dict({"type": "nbrdf", "material": path}), view, light)
    brdf = neural_brdf(load_material(path))
    assert brdf.z.shape == (3, 34 + FRAME_PARAMS)
    assert (body_glow(brdf.z, 34) > 0).all() == (stack == "varnished_brushed")
    ref = brdf.eval(torch.from_numpy(light), torch.from_numpy(view)).numpy()
    ref = ref * np.clip(light[:, 2:3], 0, None)  # Mitsuba's eval carries cos(theta_i), i the light
    assert _within_spec(value, ref) <= 1.0
    assert np.all(value[:8] == 0)
    assert ref.max() > 0.1  # the pairs reach into the lobes


@pytest.mark.parametrize("stack", STACKS)
def test_table_body_is_the_decoder_within_the_tables_error(mi, brushed, stack):
    """The table is read at the warped pair's angles and times J: against the decoder, the table's stated
    error (``test_mitsuba_body_table``'s bounds); below the horizon both are 0."""
    light, view = _pairs(7)
    path = brushed[(stack, 30.0)]
    dec = _eval(mi, mi.load_dict({"type": "nbrdf", "material": path}), view, light)
    tab = _eval(mi, mi.load_dict({"type": "nbrdf", "material": path, "body": "table"}), view, light)
    rel = np.abs(tab - dec) / (np.abs(dec) + 1e-3)
    assert rel.mean() < 3e-3 and np.quantile(rel, 0.99) < 3e-2, (rel.mean(), np.quantile(rel, 0.99))
    assert np.all(tab[:8] == 0) and dec.max() > 0.1


@pytest.mark.parametrize("stack", STACKS)
def test_sample_and_pdf_equal_the_torch_sampler(mi, brushed, stack):
    """The same uniforms draw the same directions with the same pdf as ``neural_brdf(material).sample``
    (SPEC 7's tolerance), and the weight is eval / pdf."""
    from nbrdf.neural.neural_brdf import neural_brdf

    rng = np.random.default_rng(5)
    view = directions(rng, N, lift=0.2)
    u = rng.random((N, 3)).astype(np.float32)
    path = brushed[(stack, 30.0)]
    bsdf = mi.load_dict({"type": "nbrdf", "material": path})
    ctx, si = mi.BSDFContext(), interactions(mi, view)
    bs, weight = bsdf.sample(ctx, si, mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2]))
    wo, pdf = np.array(bs.wo).T, np.array(bs.pdf)
    ref = neural_brdf(load_material(path)).sample(torch.from_numpy(view), torch.from_numpy(u))
    ok = ref.pdf.numpy() > 0
    assert ok.mean() > 0.5
    np.testing.assert_array_equal(pdf > 0, ok)
    np.testing.assert_allclose(wo[ok], ref.w.numpy()[ok], atol=2e-5)
    assert _within_spec(pdf[ok], ref.pdf.numpy()[ok]) <= 1.0
    f, p = bsdf.eval_pdf(ctx, si, bs.wo)
    np.testing.assert_allclose(np.array(p)[ok], pdf[ok], rtol=1e-5)
    np.testing.assert_allclose(np.array(f).T[ok] / pdf[ok, None], np.array(weight).T[ok], rtol=1e-4, atol=1e-6)


def _chi2(mi, sample_bsdf, pdf_bsdf, theta_deg: float = 50.0):
    """Mitsuba's chi-square test of ``sample_bsdf``'s sampler against ``pdf_bsdf``'s pdf at one incidence
    (``test_mitsuba_chi2``'s settings)."""
    import drjit as dr
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    wi = [math.sin(math.radians(theta_deg)), 0.0, math.cos(math.radians(theta_deg))]

    def si(n):
        s = dr.zeros(mi.SurfaceInteraction3f, n)
        s.wi = mi.Vector3f(*wi)
        return s

    sample, _ = sampler_and_pdf(mi, sample_bsdf, si)
    _, pdf = sampler_and_pdf(mi, pdf_bsdf, si)
    return ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3, seed=3, ires=8)


@pytest.mark.parametrize("stack,rotation", [("coated_brushed", r) for r in ROTATIONS] + [("brushed", 30.0)])
def test_sampler_passes_mitsubas_chi2(mi, brushed, stack, rotation):
    """The anisotropic coat's visible-normal sampling (in its turned frame) and the body's stretched proxy
    draw what the pdf says: p > 1e-3."""
    bsdf = mi.load_dict({"type": "nbrdf", "material": brushed[(stack, rotation)]})
    test = _chi2(mi, bsdf, bsdf)
    assert test.run(significance_level=1e-3, quiet=True), test.messages
    assert test.p_value > 1e-3


@pytest.mark.parametrize("stack", STACKS)
def test_chi2_rejects_a_sampler_turned_by_10_degrees(mi, brushed, stack):
    """The test's power: directions drawn at rotation 30 against the pdf at rotation 40 give p < 1e-6
    (the coat's lobe and the body's proxy; the proxy alone for the bare conductor)."""
    drawn = mi.load_dict({"type": "nbrdf", "material": brushed[(stack, 30.0)]})
    claimed = mi.load_dict({"type": "nbrdf", "material": brushed[(stack, 40.0)]})
    test = _chi2(mi, drawn, claimed)
    assert not test.run(significance_level=1e-3, quiet=True)
    assert test.p_value < 1e-6, test.p_value


def test_an_isotropic_material_renders_as_before(mi, materials, tmp_path):
    """No tail, no warp, the isotropic coat: an explicit anisotropy 0 and a rotation change no bit of eval,
    pdf or sample (the rotation alone changes nothing, SPEC section 10)."""
    from nbrdf.mitsuba.materials import code_kernel

    doc = json.loads(Path(materials["coated"]).read_text())
    doc["layers"][0]["anisotropy"] = 0.0
    doc["anisotropy_rotation"] = 30.0
    (tmp_path / "zero.json").write_text(json.dumps(doc))
    kernel = code_kernel(materials["coated"])
    assert kernel.warp is None and kernel.coat.stretch is None
    rng = np.random.default_rng(4)
    light, view = directions(rng, N), directions(rng, N)
    u = rng.random((N, 3)).astype(np.float32)
    ctx, si = mi.BSDFContext(), interactions(mi, view)
    out = []
    for path in (materials["coated"], str(tmp_path / "zero.json")):
        bsdf = mi.load_dict({"type": "nbrdf", "material": path})
        bs, weight = bsdf.sample(ctx, si, mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2]))
        f, p = bsdf.eval_pdf(ctx, si, mi.Vector3f(light.T))
        out.append([np.array(x) for x in (bs.wo, bs.pdf, weight, f, p)])
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("rotation", ROTATIONS)
def test_reference_of_a_lone_brushed_conductor_is_its_closed_form(mi, brushed, rotation):
    """``nbrdf_reference`` of a lone layer is its closed form (no noise), in the local frame whose x the
    rotation turns counter-clockwise: the rotated material at (wi, wo) is the unrotated one at the pair
    seen from the turned tangent (``neural.anisotropy.to_frame``)."""
    from nbrdf.neural.anisotropy import to_frame
    from nbrdf.training.reference import single_layer_eval

    light, view = _pairs(3)
    bsdf = mi.load_dict({"type": "nbrdf_reference", "material": brushed[("brushed", rotation)]})
    value = _eval(mi, bsdf, view, light)
    wi, wo = torch.from_numpy(light).double(), torch.from_numpy(view).double()
    layer = load_material(brushed[("brushed", 0.0)]).layers[0]
    ref = single_layer_eval(layer, to_frame(wi, rotation), to_frame(wo, rotation)).numpy()
    ref = ref * np.clip(light[:, 2:3], 0, None)
    assert _within_spec(value, ref) <= 1.0 and ref.max() > 0.1
    assert np.all(value[:8] == 0)


def test_reference_walks_an_anisotropic_stack(mi, brushed):
    """The brushed coat over brushed metal through ``nbrdf_reference`` (fresh paths per call) agrees with the
    walk's own estimate (``test_mitsuba_reference``'s z statistics over 48 pairs x 3 channels)."""
    import drjit as dr

    from nbrdf.training.reference import reference_eval

    calls, spp, n = 24, 16, 48
    rng = np.random.default_rng(21)
    light, view = directions(rng, n, lift=0.2), directions(rng, n, lift=0.2)
    path = brushed[("coated_brushed", 30.0)]
    bsdf = mi.load_dict({"type": "nbrdf_reference", "material": path, "spp": spp, "seed": 4})
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(np.ascontiguousarray(view.T))
    wo = mi.Vector3f(np.ascontiguousarray(light.T))
    runs = np.stack([np.array(bsdf.eval(mi.BSDFContext(), si, wo)).T / light[:, 2:3] for _ in range(calls)])
    mean, se = runs.mean(0), runs.std(0, ddof=1) / np.sqrt(calls)
    ref, ref_se = (t.numpy() for t in reference_eval(load_material(path), torch.from_numpy(light),
                                                      torch.from_numpy(view), spp=4096, seed=9))
    z = (mean - ref) / np.sqrt(se ** 2 + ref_se ** 2)
    assert abs(z.mean()) < 4 / np.sqrt(z.size), z.mean()
    assert (z ** 2).mean() < 1.6, (z ** 2).mean()


@pytest.mark.parametrize("plugin", ["nbrdf", "nbrdf_reference"])
def test_texture_mapped_anisotropy_is_one_line(mi, tmp_path, plugin):
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "a.png", np.full((4, 4, 3), 128, np.uint8))
    _write(tmp_path / "m.json", [COAT, {"type": "medium", "sigma_t": 1.0, "albedo": [
        {"texture": "a.png", "channel": c, "range": [0, 1]} for c in "rgb"]}, METAL], 30.0)
    with pytest.raises(Exception) as info:
        mi.load_dict({"type": plugin, "material": str(tmp_path / "m.json")})
    # Mitsuba wraps a plugin's exception with its traceback; the last line is the plugin's one line
    last = str(info.value).strip().splitlines()[-1]
    assert last == (f"PluginError: {plugin}: layers[0].anisotropy: anisotropy is not yet supported by the Mitsuba "
                    "plugins' texture-mapped materials")
