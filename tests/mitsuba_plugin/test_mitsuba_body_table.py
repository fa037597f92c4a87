"""The ``nbrdf`` plugin's ``body: "table"``: the body read from a baked table
equals the torch table lookup (its CPU twin) and the decoder within the
table's stated error; the coat and the sampler are unchanged, so sample
weights stay eval / pdf; a bad option is one line."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from hits import directions, interactions

pytest.importorskip("mitsuba", reason="the optional extra 'mitsuba' is not installed (pip install -e '.[mitsuba]')")

N = 8192


def _eval(mi, bsdf, view, light) -> np.ndarray:
    return np.array(bsdf.eval(mi.BSDFContext(), interactions(mi, view), mi.Vector3f(np.ascontiguousarray(light.T)))).T


@pytest.mark.parametrize("role", ["uncoated", "car_paint"])
def test_table_body_is_the_baked_table_lookup(mi, materials, role):
    """The Dr.Jit texture fetch reads the same nodes as ``neural.body_table.table_lookup``
    (node i at i / (n - 1); a half-texel offset would be off by percents at the lobe)."""
    from nbrdf.mitsuba.kernel import TableBody
    from nbrdf.mitsuba.materials import BODY_TABLE_SIZE
    from nbrdf.neural.body_table import bake_body, table_lookup
    from nbrdf.neural.material_code import load_code

    rng = np.random.default_rng(3)
    light, view = directions(rng, N), directions(rng, N)
    model, code = load_code(materials[role], None)
    values = bake_body(model.decoder, code, BODY_TABLE_SIZE)
    body = TableBody(values.numpy())
    got = np.stack([np.array(c) for c in body.body(mi.Vector3f(light.T), mi.Vector3f(view.T))], 1)
    want = table_lookup(values, torch.from_numpy(light), torch.from_numpy(view)).numpy()
    np.testing.assert_allclose(got, want, rtol=2e-4, atol=1e-7)


@pytest.mark.parametrize("role", ["coated", "car_paint", "uncoated"])
def test_table_eval_is_the_decoder_within_the_tables_error(mi, materials, role):
    """Stated (``materials.BODY_TABLE_SIZE``): mean relative error 0.08-0.15 % over random pairs,
    99th percentile 0.8-1.5 %; bounds at 2x those. Below the horizon both are 0."""
    rng = np.random.default_rng(7)
    light, view = directions(rng, N), directions(rng, N)
    light[:8, 2] *= -1
    dec = _eval(mi, mi.load_dict({"type": "nbrdf", "material": materials[role]}), view, light)
    tab = _eval(mi, mi.load_dict({"type": "nbrdf", "material": materials[role], "body": "table"}), view, light)
    rel = np.abs(tab - dec) / (np.abs(dec) + 1e-3)
    assert rel.mean() < 3e-3 and np.quantile(rel, 0.99) < 3e-2, (rel.mean(), np.quantile(rel, 0.99))
    assert np.all(tab[:8] == 0) and dec.max() > 0.1


def test_table_sampler_is_the_decoders_and_weight_is_eval_over_pdf(mi, materials):
    """The sampler does not depend on the body: the same directions and pdfs as
    the decoder's; the weight is the table's eval / pdf (the estimator stays unbiased
    for the table's BRDF)."""
    rng = np.random.default_rng(5)
    view = directions(rng, N)
    u = rng.random((N, 3)).astype(np.float32)
    ctx, si = mi.BSDFContext(), interactions(mi, view)
    out = {}
    for body in ("decoder", "table"):
        bsdf = mi.load_dict({"type": "nbrdf", "material": materials["coated"], "body": body})
        bs, weight = bsdf.sample(ctx, si, mi.Float(u[:, 0]), mi.Point2f(u[:, 1], u[:, 2]))
        f, p = bsdf.eval_pdf(ctx, si, bs.wo)
        out[body] = np.array(bs.wo).T, np.array(bs.pdf), np.array(weight).T, np.array(f).T, np.array(p)
    (wo_d, pdf_d, _, _, _), (wo_t, pdf_t, w_t, f_t, p_t) = out["decoder"], out["table"]
    ok = pdf_t > 0
    assert ok.mean() > 0.5
    np.testing.assert_array_equal(wo_t, wo_d)
    np.testing.assert_array_equal(pdf_t, pdf_d)
    np.testing.assert_allclose(p_t[ok], pdf_t[ok], rtol=1e-5)
    np.testing.assert_allclose(f_t[ok] / pdf_t[ok, None], w_t[ok], rtol=1e-4, atol=1e-6)


def test_bad_body_option_is_one_line(mi, materials):
    from nbrdf.mitsuba import PluginError

    with pytest.raises(Exception) as e:
        mi.load_dict({"type": "nbrdf", "material": materials["coated"], "body": "mlp"})
    # Mitsuba wraps a plugin's exception with its traceback; the last line is the plugin's one line
    last = str(e.value).strip().splitlines()[-1]
    assert last == "PluginError: nbrdf: body 'mlp' is not one of 'decoder', 'table'"
    # the plugin's own error class when built directly
    from nbrdf.mitsuba.materials import code_kernel

    with pytest.raises(PluginError, match="body 'mlp'"):
        code_kernel(materials["coated"], body="mlp")


def test_a_texture_mapped_roughness_refuses_a_table(mi, tmp_path):
    """A parametric table holds mapped albedos only (``test_mitsuba_param_table``); a
    mapped coat roughness is one line pointing to the decoder."""
    import imageio.v3 as iio

    from nbrdf.mitsuba import PluginError
    from nbrdf.mitsuba.materials import code_kernel

    iio.imwrite(tmp_path / "r.png", np.full((4, 4), 128, np.uint8))
    p = tmp_path / "m.json"
    p.write_text('{"format": "nbrdf-material/1", "name": "m", "layers": [{"type": "dielectric", "roughness": '
                 '{"texture": "r.png", "channel": "r", "range": [0.05, 0.4]}, "ior": 1.5}, '
                 '{"type": "diffuse", "albedo": 0.5}]}')
    with pytest.raises(PluginError) as e:
        code_kernel(str(p), body="table")
    msg = str(e.value)
    assert "layers[0].roughness" in msg and 'body "decoder"' in msg and "\n" not in msg
