"""The ``nbrdf`` plugin equals the torch neural BRDF (SPEC 7's tolerance)
in eval, pdf and sample, follows Mitsuba's conventions, and refuses bad
input in one line."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from hits import directions, interactions

from nbrdf.neural.material import load_material
from nbrdf.training.brdfs import brdf_for

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

N = 4096


def _within_spec(a: np.ndarray, b: np.ndarray) -> float:
    """Largest |a - b| / (1e-4 (1 + |b|)): at most 1 within SPEC section 7's tolerance."""
    return float((np.abs(a - b) / (1e-4 * (1 + np.abs(b)))).max())


@pytest.mark.parametrize("role", ["coated", "car_paint", "uncoated"])
def test_eval_equals_the_torch_neural_brdf(mi, materials, role):
    rng = np.random.default_rng(11)
    light, view = directions(rng, N), directions(rng, N)
    light[:8, 2] *= -1  # a few below the horizon: zero on both sides
    bsdf = mi.load_dict({"type": "nbrdf", "material": materials[role]})
    value = np.array(bsdf.eval(mi.BSDFContext(), interactions(mi, view), mi.Vector3f(light.T))).T
    ref = brdf_for(load_material(materials[role]), "neural").eval(torch.from_numpy(light), torch.from_numpy(view))
    ref = ref.numpy() * np.clip(light[:, 2:3], 0, None)  # Mitsuba's eval carries cos(theta_i), i the light
    assert _within_spec(value, ref) <= 1.0
    assert np.all(value[:8] == 0)
    assert ref.max() > 0.1  # the pairs reach into the lobes


@pytest.mark.parametrize("role", ["coated", "uncoated"])
def test_sample_and_pdf_equal_the_torch_sampler(mi, materials, role):
    rng = np.random.default_rng(5)
    view = directions(rng, N)
    u = rng.random((N, 3)).astype(np.float32)
    bsdf = mi.load_dict({"type": "nbrdf", "material": materials[role]})
    ctx, si = mi.BSDFContext(), interactions(mi, view)
    bs, weight = bsdf.sample(ctx, si, mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2]))
    wo, pdf, weight = np.array(bs.wo).T, np.array(bs.pdf), np.array(weight).T
    ref = brdf_for(load_material(materials[role]), "neural").sample(torch.from_numpy(view), torch.from_numpy(u))
    ok = ref.pdf.numpy() > 0
    assert ok.mean() > 0.5
    np.testing.assert_array_equal(pdf > 0, ok)
    np.testing.assert_allclose(wo[ok], ref.w.numpy()[ok], atol=2e-5)
    assert _within_spec(pdf[ok], ref.pdf.numpy()[ok]) <= 1.0
    assert _within_spec(weight[ok], ref.weight.numpy()[ok]) <= 1.0
    # pdf() and eval_pdf() of the drawn directions are the sampled pdf; the weight is eval / pdf
    p2 = np.array(bsdf.pdf(ctx, si, bs.wo))
    f, p3 = bsdf.eval_pdf(ctx, si, bs.wo)
    np.testing.assert_allclose(p2[ok], pdf[ok], rtol=1e-5)
    np.testing.assert_allclose(np.array(p3)[ok], pdf[ok], rtol=1e-5)
    np.testing.assert_allclose(np.array(f).T[ok] / pdf[ok, None], weight[ok], rtol=1e-4, atol=1e-6)


def test_a_code_file_renders_as_its_material(mi, materials, tmp_path):
    """A code written by ``nbrdf project`` (a MaterialLatent file) loads like the material it came from."""
    from nbrdf.neural.latent import MaterialLatent, save_latent
    from nbrdf.neural.model import default_model

    model = default_model()
    z = model.material_latent(load_material(materials["car_paint"]))
    save_latent(tmp_path / "z.safetensors", MaterialLatent(z, model.decoder_id, {"material": "car paint"}))
    rng = np.random.default_rng(2)
    light, view = directions(rng, 512), directions(rng, 512)
    a = mi.load_dict({"type": "nbrdf", "material": str(tmp_path / "z.safetensors")})
    b = mi.load_dict({"type": "nbrdf", "material": materials["car_paint"]})
    ctx = mi.BSDFContext()
    va = np.array(a.eval(ctx, interactions(mi, view), mi.Vector3f(light.T)))
    vb = np.array(b.eval(ctx, interactions(mi, view), mi.Vector3f(light.T)))
    np.testing.assert_array_equal(va, vb)


@pytest.mark.parametrize("props,message", [
    ({}, 'property "material"'),
    ({"material": "/nonexistent/m.json"}, "m.json"),
    ({"material": "MAPPED"}, "nope.png"),
    ({"material": "GOLD", "weights": "BROKEN"}, "safetensors"),
])
def test_bad_input_is_one_clear_line(mi, materials, tmp_path, props, message):
    if props.get("material") == "MAPPED":  # a texture-mapped material whose map is missing
        import json

        (tmp_path / "mapped.json").write_text(json.dumps({"format": "nbrdf-material/1", "name": "m", "layers": [
            {"type": "dielectric", "roughness": {"texture": "nope.png", "channel": "r", "range": [0.1, 0.3]},
             "ior": 1.5}, {"type": "diffuse", "albedo": 0.5}]}))
        props["material"] = str(tmp_path / "mapped.json")
    if props.get("material") == "GOLD":
        props["material"] = materials["uncoated"]
        (tmp_path / "w.safetensors").write_bytes(b"not a weight file")
        props["weights"] = str(tmp_path / "w.safetensors")
    with pytest.raises(Exception) as info:
        mi.load_dict({"type": "nbrdf", **props})
    # Mitsuba wraps a plugin's exception with its traceback; the last line is the plugin's one line
    last = str(info.value).strip().splitlines()[-1]
    assert last.startswith("PluginError: nbrdf: ")
    assert message in last


def test_a_materialx_document_loads_like_its_stack(mi, tmp_path):
    """``material`` may name an OpenPBR document (SPEC section 11): the plugin evaluates the stack the mapping
    makes, F82-tinted metal under a coloured coat included, within SPEC 7's tolerance of the torch path."""
    from pathlib import Path

    from nbrdf.neural.material import save_material

    src = Path(__file__).resolve().parents[1] / "neural" / "data" / "mtlx" / "openpbr_coated_gold.mtlx"
    m = load_material(src, [])
    save_material(m, tmp_path / "gold.json")
    rng = np.random.default_rng(3)
    light, view = directions(rng, 512), directions(rng, 512)
    a = mi.load_dict({"type": "nbrdf", "material": str(src)})
    b = mi.load_dict({"type": "nbrdf", "material": str(tmp_path / "gold.json")})
    va = np.array(a.eval(mi.BSDFContext(), interactions(mi, view), mi.Vector3f(light.T))).T
    vb = np.array(b.eval(mi.BSDFContext(), interactions(mi, view), mi.Vector3f(light.T))).T
    np.testing.assert_array_equal(va, vb)
    ref = brdf_for(m, "neural").eval(torch.from_numpy(light), torch.from_numpy(view)).numpy() * np.clip(light[:, 2:3], 0, None)
    assert _within_spec(va, ref) <= 1.0 and ref.max() > 0.1
