"""``neural.param_table``: which parameters a parametric body table varies and
over what range, and its nodes' codes are the uniform materials' codes."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch


def _material(tmp_path, medium_albedo, base_albedo=0.5):
    import imageio.v3 as iio

    from nbrdf.neural.material import load_material

    img = np.zeros((4, 6, 3), np.uint8)
    img[..., 0] = 51   # 0.2
    img[:2, :, 0] = 204  # 0.8
    img[..., 1] = 128
    iio.imwrite(tmp_path / "a.png", img)
    spec = {"format": "nbrdf-material/1", "name": "m", "layers": [
        {"type": "dielectric", "roughness": 0.1, "ior": 1.5},
        {"type": "medium", "albedo": medium_albedo, "sigma_t": 1.0},
        {"type": "diffuse", "albedo": base_albedo}]}
    (tmp_path / "m.json").write_text(json.dumps(spec))
    return load_material(tmp_path / "m.json")


def test_ranges_follow_the_maps_texels_or_the_references(tmp_path):
    from nbrdf.neural.param_table import MIN_SPAN, table_params
    from nbrdf.neural.svbrdf import TextureValues

    tex = [{"texture": "a.png", "channel": c, "range": [0, 1]} for c in "rg"] + [0.3]
    m = _material(tmp_path, tex, {"texture": "a.png", "channel": "g", "range": [0.2, 0.6]})
    p = table_params(m, TextureValues(m))
    assert p.places == ("layers[1].albedo", "layers[2].albedo")
    (lo_a, hi_a), (lo_b, hi_b) = p.ranges
    assert lo_a == pytest.approx(0.2, abs=1e-6) and hi_a == pytest.approx(0.8, abs=1e-6)  # r 0.2-0.8, g 0.5
    assert lo_b == pytest.approx(0.2 + 0.4 * 128 / 255, abs=1e-6) and hi_b - lo_b == pytest.approx(MIN_SPAN)
    assert table_params(m).ranges == ((0.0, 1.0), (0.2, 0.6))


def test_node_codes_are_the_uniform_materials_codes(tmp_path):
    """Node (i, j)'s code is the networks' code of the material with those albedos, whatever the other channels
    hold (``material_latent`` before settling: a latent texture's codes are neither settled nor bounded,
    docs/decisions/114 and 122)."""
    from nbrdf.neural.material import parse_material
    from nbrdf.neural.model import default_model
    from nbrdf.neural.param_table import ParamGrid, node_codes, node_values, table_params

    tex = [{"texture": "a.png", "channel": c, "range": [0, 1]} for c in "rgb"]
    m = _material(tmp_path, tex, tex)
    model = default_model()
    p = table_params(m)
    grid = ParamGrid(3, 2)
    codes = node_codes(model, m, p, grid)
    a, b = node_values(p, grid)
    for i, j in ((0, 0), (2, 1), (1, 0)):
        spec = json.loads((tmp_path / "m.json").read_text())
        spec["layers"][1]["albedo"] = [float(a[i]), 0.9, 0.1]
        spec["layers"][2]["albedo"] = [float(b[j]), 0.3, 0.7]
        z = model.material_latent(parse_material(spec), conserve=False)
        torch.testing.assert_close(codes[i, j], z[0], rtol=1e-5, atol=1e-5)
