"""The baked body table (neural/body_table.py) against the decoder it bakes."""
from __future__ import annotations

import math

import pytest
import torch

from nbrdf.neural.body_table import TableSize, bake_body, table_directions, table_lookup
from nbrdf.neural.decoder import DEFAULT_WEIGHTS, Decoder, DecoderSpec, load_decoder, rusink5
from nbrdf.neural.errors import NbrdfError


def decoder() -> Decoder:
    if DEFAULT_WEIGHTS.is_file():
        return load_decoder(DEFAULT_WEIGHTS)
    torch.manual_seed(0)
    return Decoder(DecoderSpec(encoding="lobes11")).eval()


def latent(dec: Decoder, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return dec.latent_mean.expand(3, -1) + 0.5 * torch.randn(3, dec.spec.latent, generator=g)


def random_pairs(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(2, n, 3, generator=g)
    v = v / v.norm(dim=-1, keepdim=True)
    v[..., 2] = v[..., 2].abs()
    return v[0], v[1]


def test_grid_directions_have_the_grid_angles():
    s = TableSize(9, 7, 5)
    wi, wo = table_directions(s)
    assert torch.allclose(wi.norm(dim=-1), torch.ones(()), atol=1e-6)
    r = rusink5(wi.reshape(-1, 3), wo.reshape(-1, 3)).reshape(*s.shape, 5)
    k, m, n = s.shape
    assert torch.allclose(r[0, 3, :, 0], torch.linspace(0, 1, n), atol=1e-4)  # sqrt-mapped theta_h
    # theta_d (the last node, theta_d = pi/2, is wo = -wi: no half vector)
    assert torch.allclose(r[0, :-1, 4, 1], torch.linspace(0, 1, m)[:-1], atol=1e-4)
    phi = torch.linspace(0, 1, k) * (math.pi / 2)
    assert torch.allclose(r[:, 3, 4, 2], torch.cos(2 * phi), atol=1e-4)       # cos 2 phi_d


def test_bake_is_the_decoder_at_the_nodes():
    dec = decoder()
    z = latent(dec)
    s = TableSize(8, 6, 4)
    values = bake_body(dec, z, s)
    wi, wo = table_directions(s)
    with torch.no_grad():
        y = dec.log_f(z[None, None, None, :, :], dec.encode(wi, wo)[..., None, :])
    assert torch.allclose(values, y.clamp(-80, 80), atol=1e-4)
    # The lookup reproduces the nodes (above the horizon).
    up = (wi[..., 2] > 1e-3) & (wo[..., 2] > 1e-3)
    f = table_lookup(values, wi[up], wo[up])
    assert torch.allclose(f, torch.exp(values[up]), rtol=1e-3)


def test_lookup_converges_to_the_decoder_with_the_table_size():
    dec = decoder()
    z = latent(dec, 1)
    wi, wo = random_pairs(20000, 2)
    with torch.no_grad():
        ref = dec.eval_rgb(z, wi, wo)
    errs = []
    for s in (TableSize(16, 8, 4), TableSize(32, 16, 8), TableSize(64, 32, 16)):
        f = table_lookup(bake_body(dec, z, s), wi, wo)
        errs.append(float((f - ref).abs().sum() / ref.abs().sum()))
    assert errs[0] > errs[1] > errs[2], errs
    assert errs[2] < 0.02, errs  # relative L1 of the finest table over random pairs


def test_bad_input():
    dec = decoder()
    with pytest.raises(NbrdfError):
        bake_body(dec, torch.zeros(2, dec.spec.latent))
    with pytest.raises(NbrdfError):
        bake_body(dec, torch.full((3, dec.spec.latent), float("nan")))
    with pytest.raises(NbrdfError):
        bake_body(dec, latent(dec), TableSize(1, 8, 8))


def test_an_ordered_table_tells_the_swapped_pair_apart():
    """An ordered table (a body that is not reciprocal) is read back at its own nodes (but where
    theta_d = 0: there every phi_d is the same pair), and a pair and its swap read different
    nodes; folding the swap (an unordered lookup) does not."""
    size = TableSize(6, 5, 7, ordered=True)
    values = torch.randn(*size.shape, 3, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    wi, wo = (d.reshape(-1, 3).double() for d in table_directions(size))
    up = (wi[:, 2] > 1e-3) & (wo[:, 2] > 1e-3) & ((wi - wo).norm(dim=-1) > 1e-6)
    got = table_lookup(values, wi[up], wo[up], ordered=True)
    assert torch.allclose(got, values.reshape(-1, 3)[up].exp(), rtol=1e-4)
    swapped = table_lookup(values, wo[up], wi[up], ordered=True)
    assert (swapped - got).abs().max() > 0.1
    folded = table_lookup(values, wi[up], wo[up])
    assert not torch.allclose(folded, got, rtol=1e-3)
