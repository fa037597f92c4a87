"""Latent blends and textures: bilinear lookups, 2 x 2 mip averages, trilinear by footprint."""
from __future__ import annotations

import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.latent_texture import LatentTexture, blend


def test_blend_is_a_normalised_weighted_sum():
    a, b = torch.zeros(3, 32), torch.ones(3, 32)
    assert torch.allclose(blend([a, b], [1, 3]), torch.full((3, 32), 0.75))
    with pytest.raises(NbrdfError):
        blend([a, b], [1.0, float("nan")])


def test_mip_levels_average_two_by_two():
    g = torch.Generator().manual_seed(0)
    tex = LatentTexture(torch.randn(8, 4, 3, 32, generator=g))
    assert [tuple(lv.shape[:2]) for lv in tex.levels] == [(8, 4), (4, 2), (2, 1), (1, 1)]
    lv0, lv1 = tex.levels[0], tex.levels[1]
    assert torch.allclose(lv1[1, 0], lv0[2:4, 0:2].mean((0, 1)), atol=1e-6)
    assert torch.allclose(tex.levels[-1][0, 0], lv0.mean((0, 1)), atol=1e-5)


def test_bilinear_hits_texel_centres_and_interpolates_between():
    g = torch.Generator().manual_seed(1)
    tex = LatentTexture(torch.randn(4, 4, 3, 32, generator=g))
    lv = tex.levels[0]
    uv = torch.tensor([[(2 + 0.5) / 4, (1 + 0.5) / 4], [3 / 4, (1 + 0.5) / 4]])
    out = tex.bilinear(uv)
    assert torch.allclose(out[0], lv[1, 2], atol=1e-6)
    assert torch.allclose(out[1], 0.5 * (lv[1, 2] + lv[1, 3]), atol=1e-6)


def test_trilinear_picks_the_level_of_the_footprint():
    g = torch.Generator().manual_seed(2)
    tex = LatentTexture(torch.randn(16, 16, 3, 32, generator=g))
    uv = torch.rand(10, 2, generator=g)
    assert torch.allclose(tex.trilinear(uv, 1 / 16), tex.bilinear(uv, 0), atol=1e-6)
    assert torch.allclose(tex.trilinear(uv, 4 / 16), tex.bilinear(uv, 2), atol=1e-6)
    mid = tex.trilinear(uv, 2 ** 0.5 / 16)
    assert torch.allclose(mid, 0.5 * (tex.bilinear(uv, 0) + tex.bilinear(uv, 1)), atol=1e-5)
    assert torch.allclose(tex.trilinear(uv, 10.0), tex.levels[-1][0, 0].expand(10, 3, 32), atol=1e-5)


def test_bad_textures_are_rejected():
    with pytest.raises(NbrdfError, match=r"\(H, W, 3, 34\)"):
        LatentTexture(torch.zeros(4, 4, 32))
    bad = torch.zeros(2, 2, 3, 32)
    bad[0, 0, 0, 0] = float("nan")
    with pytest.raises(NbrdfError, match="NaN"):
        LatentTexture(bad)
