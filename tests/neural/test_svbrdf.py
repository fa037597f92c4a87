"""Texture-mapped materials -> latent textures: per texel, exactly the uniform path."""
from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import load_material, parse_material
from nbrdf.neural.model import default_model
from nbrdf.neural.svbrdf import TextureValues, latent_texture, read_map


def write_material(tmp_path, rough: np.ndarray, color: np.ndarray, sigma: float | dict = 0.8):
    (tmp_path / "maps").mkdir(exist_ok=True)
    iio.imwrite(tmp_path / "maps" / "rough.png", rough)
    iio.imwrite(tmp_path / "maps" / "color.png", color)
    tex = lambda f, ch, lo, hi: {"texture": f"maps/{f}.png", "channel": ch, "range": [lo, hi]}
    doc = {"format": "nbrdf-material/1", "name": "tiles", "layers": [
        {"type": "dielectric", "roughness": 0.05, "ior": 1.5},
        {"type": "medium", "albedo": [0.9, 0.8, 0.7], "sigma_t": sigma},
        {"type": "conductor", "roughness": tex("rough", "r", 0.1, 0.5),
         "r0": [tex("color", "r", 0, 1), tex("color", "g", 0, 1), 0.5]}]}
    (tmp_path / "m.json").write_text(json.dumps(doc))
    return load_material(tmp_path / "m.json"), doc


def test_texels_equal_the_uniform_material_at_their_values(tmp_path):
    rng = np.random.default_rng(0)
    rough = rng.integers(0, 256, (3, 4), dtype=np.uint8)
    color = rng.integers(0, 256, (3, 4, 3), dtype=np.uint8)
    m, doc = write_material(tmp_path, rough, color)
    model = default_model()
    tex = latent_texture(model, m, chunk=5)  # chunks that split the texels unevenly
    assert tex.size == (3, 4)
    for row, col in [(0, 0), (2, 3), (1, 2)]:
        file_row = 2 - row  # texel row 0 is v = 0, the bottom row of the image file
        uniform = json.loads(json.dumps(doc))
        base = uniform["layers"][2]
        base["roughness"] = 0.1 + 0.4 * rough[file_row, col] / 255
        base["r0"] = [color[file_row, col, 0] / 255, color[file_row, col, 1] / 255, 0.5]
        z = model.material_latent(parse_material(uniform))
        torch.testing.assert_close(tex.levels[0][row, col], z, atol=2e-5, rtol=1e-5)


def test_maps_of_different_sizes_share_the_largest_grid(tmp_path):
    m, _ = write_material(tmp_path, np.full((8, 8), 128, np.uint8), np.full((2, 2, 3), 200, np.uint8))
    values = TextureValues(m)
    assert values.size == (8, 8) and values.count == 64
    r0 = values(m.base.r0, "r0")
    assert r0.shape == (64, 3) and torch.allclose(r0[:, 0], torch.tensor(200 / 255))
    assert torch.allclose(r0[:, 2], torch.tensor(0.5))
    assert values(0.3, "x").shape == (1, 3)


def test_channels_and_bit_depths(tmp_path):
    img = np.zeros((2, 2, 3), np.uint8)
    img[..., 1] = 255
    iio.imwrite(tmp_path / "a.png", img)
    assert np.allclose(read_map(tmp_path / "a.png", "g"), 1.0) and np.allclose(read_map(tmp_path / "a.png", "r"), 0)
    assert np.allclose(read_map(tmp_path / "a.png", "l"), 0.7152, atol=1e-4)
    grey = np.array([[0, 65535], [32768, 0]], np.uint16)  # 16-bit grey: r = g = b = l, full precision
    iio.imwrite(tmp_path / "g.png", grey)
    assert np.allclose(read_map(tmp_path / "g.png", "b"), (grey[::-1] / 65535.0))
    with pytest.raises(NbrdfError, match="channel 'a'"):
        read_map(tmp_path / "a.png", "a")


def test_bad_maps_are_one_line_errors(tmp_path):
    m, _ = write_material(tmp_path, np.zeros((2, 2), np.uint8), np.zeros((2, 2, 3), np.uint8))
    (tmp_path / "maps" / "rough.png").write_bytes(b"not a png")
    with pytest.raises(NbrdfError, match="rough.png: cannot read the texture"):
        latent_texture(default_model(), m)
    with pytest.raises(NbrdfError, match="no texture-mapped parameter"):
        TextureValues(load_material("viewer/assets/materials/default.json"))
    with pytest.raises(NbrdfError, match="latent texture"):
        default_model().material_latent(m)


def test_bundled_svbrdf_builds(tmp_path):
    m = load_material("viewer/assets/materials/worn_tiles.json")
    tex = latent_texture(default_model(), m, size=(16, 16))
    assert tex.size == (16, 16) and len(tex.levels) == 5
    assert m.normal_map is not None and (m.base_dir / m.normal_map).is_file()
