"""The shared decoder: symmetries by construction, cost accounting, weight files."""
from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from nbrdf.neural.decoder import (
    ENCODINGS,
    LOBE_ALPHAS,
    LOBE_IOR,
    Decoder,
    DecoderSpec,
    encode,
    load_decoder,
    read_bundle,
    save_decoder,
)
from nbrdf.neural.errors import NbrdfError
from nbrdf.training.merl import angles


def rand_dirs(n: int, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(n, 3, generator=g, dtype=torch.float64)
    v = v / v.norm(dim=-1, keepdim=True)
    v[:, 2] = v[:, 2].abs() + 1e-3
    return v / v.norm(dim=-1, keepdim=True)


def rot_z(v: torch.Tensor, a: float) -> torch.Tensor:
    c, s = math.cos(a), math.sin(a)
    return torch.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1], v[:, 2]], -1)


def test_encoding_matches_rusinkiewicz_angles():
    wi, wo = rand_dirs(2000, 1), rand_dirs(2000, 2)
    e = encode(wi, wo)
    th, td, pd = angles(wi, wo)
    torch.testing.assert_close(e[:, 0], torch.sqrt(th * 2 / math.pi), atol=1e-6, rtol=0)
    torch.testing.assert_close(e[:, 1], td * 2 / math.pi, atol=1e-6, rtol=0)
    torch.testing.assert_close(e[:, 2], torch.cos(2 * pd), atol=1e-6, rtol=0)
    torch.testing.assert_close(e[:, 3], wi[:, 2] * wo[:, 2])


@pytest.mark.parametrize("encoding", sorted(ENCODINGS))
def test_decoder_is_reciprocal_isotropic_and_nonnegative(encoding):
    torch.manual_seed(0)
    dec = Decoder(DecoderSpec(encoding=encoding)).double()
    z = torch.randn(500, 32, dtype=torch.float64)
    wi, wo = rand_dirs(500, 3), rand_dirs(500, 4)
    f = dec(z, wi, wo)
    assert (f >= 0).all() and torch.isfinite(f).all()
    torch.testing.assert_close(dec(z, wo, wi), f, rtol=1e-9, atol=0)  # reciprocity
    torch.testing.assert_close(dec(z, rot_z(wi, 0.7), rot_z(wo, 0.7)), f, rtol=1e-9, atol=0)  # isotropy
    mirror = torch.tensor([1.0, -1.0, 1.0], dtype=torch.float64)
    torch.testing.assert_close(dec(z, wi * mirror, wo * mirror), f, rtol=1e-9, atol=0)
    below = wo * torch.tensor([1.0, 1.0, -1.0], dtype=torch.float64)
    assert (dec(z, wi, below) == 0).all()


def test_lobe_features_peak_on_the_half_vectors_outside_and_inside_a_coat():
    """lobes11: rusink5, then 1 / (1 + tan^2 / alpha^2) of the half vector
    and of the half vector of the directions refracted into ior 1.5."""
    wi, wo = rand_dirs(3000, 7), rand_dirs(3000, 8)
    e = encode(wi, wo, "lobes11")
    assert e.shape == (3000, ENCODINGS["lobes11"])
    torch.testing.assert_close(e[:, :5], encode(wi, wo))
    th, _, _ = angles(wi, wo)
    for k, a in enumerate(LOBE_ALPHAS):
        torch.testing.assert_close(e[:, 5 + k], 1 / (1 + torch.tan(th) ** 2 / a ** 2), atol=1e-6, rtol=1e-5)

    def inside(w):
        t = w[:, :2] / LOBE_IOR
        return torch.cat([t, (1 - (t * t).sum(-1, keepdim=True)).sqrt()], -1)

    th_in, _, _ = angles(inside(wi), inside(wo))
    for k, a in enumerate(LOBE_ALPHAS):
        torch.testing.assert_close(e[:, 8 + k], 1 / (1 + torch.tan(th_in) ** 2 / a ** 2), atol=1e-6, rtol=1e-5)
    # the mirror pair peaks at 1 in every bump, inside and out
    mirror = encode(wi[:5], wi[:5] * torch.tensor([-1.0, -1.0, 1.0]), "lobes11")
    torch.testing.assert_close(mirror[:, 5:], torch.ones(5, 6, dtype=mirror.dtype), atol=1e-9, rtol=0)


@pytest.mark.parametrize("width,depth", [(64, 3), (32, 2), (48, 4)])
def test_mac_and_parameter_counts(width, depth):
    spec = DecoderSpec(width=width, depth=depth)
    dec = Decoder(spec)
    linears = list(dec.hidden) + [dec.out]
    macs = sum(l.in_features * l.out_features for l in linears)
    assert spec.macs(latent_share_cached=False) == macs
    assert spec.macs() == macs - 32 * width
    assert spec.parameters() == sum(p.numel() for p in dec.parameters())


def test_default_decoder_fits_the_shader_budget():
    assert DecoderSpec().macs(latent_share_cached=False) <= 16_384


def test_latent_share_is_the_first_layer_split():
    torch.manual_seed(1)
    dec = Decoder().double()
    z = torch.randn(7, 32, dtype=torch.float64)
    feats = encode(rand_dirs(7, 5), rand_dirs(7, 6))
    full = dec.hidden[0](torch.cat([z, feats], -1))
    torch.testing.assert_close(dec.latent_share(z) + feats @ dec.hidden[0].weight[:, 32:].T, full)


def test_weight_file_round_trip_and_id(tmp_path):
    torch.manual_seed(2)
    dec = Decoder(DecoderSpec(width=32, depth=2))
    wid = save_decoder(dec, tmp_path / "d.safetensors", trained_on={"x": 1}, accuracy={"psnr": 40})
    back = load_decoder(tmp_path / "d.safetensors")
    assert back.spec == dec.spec and back.weights_id() == wid
    _, meta = read_bundle(tmp_path / "d.safetensors")
    assert meta["format"] == "nbrdf-decoder/1" and '"psnr": 40' in meta["accuracy"]
    other = Decoder(DecoderSpec(width=32, depth=2))
    assert other.weights_id() != wid


def _tamper(path, **changes):
    from safetensors.torch import save_file

    from nbrdf.neural.decoder import read_bundle as rb

    tensors, meta = rb(path)
    for k, v in changes.items():
        if k == "meta":
            meta.update(v)
        else:
            tensors[k] = v
    save_file(tensors, str(path), metadata=meta)


@pytest.mark.parametrize("case", ["missing", "garbage", "format", "shape", "nan", "arch", "id"])
def test_bad_weight_files_give_one_clear_error(tmp_path, case):
    p = tmp_path / "d.safetensors"
    dec = Decoder(DecoderSpec(width=32, depth=2))
    save_decoder(dec, p)
    if case == "missing":
        p = tmp_path / "nope.safetensors"
    elif case == "garbage":
        p.write_bytes(b"\x00\x01not a safetensors file")
    elif case == "format":
        _tamper(p, meta={"format": "something/9"})
    elif case == "shape":
        _tamper(p, **{"decoder.out.weight": torch.zeros(1, 7)})
    elif case == "nan":
        _tamper(p, **{"decoder.out.bias": torch.tensor([float("nan")])})
    elif case == "arch":
        _tamper(p, meta={"architecture": '{"width": 32, "depth": 2, "encoding": "fourier99"}'})
    elif case == "id":
        _tamper(p, **{"decoder.out.bias": torch.tensor([0.123])})
    with pytest.raises(NbrdfError) as e:
        load_decoder(p)
    assert "\n" not in str(e.value)


@settings(max_examples=25, deadline=None)
@given(st.floats(0.0, 1.5), st.floats(0.0, 1.5), st.floats(-3.2, 3.2))
def test_encoding_is_finite_everywhere(ti, to, phi):
    wi = torch.tensor([[math.sin(ti), 0.0, math.cos(ti)]], dtype=torch.float64)
    wo = torch.tensor([[math.sin(to) * math.cos(phi), math.sin(to) * math.sin(phi), math.cos(to)]],
                      dtype=torch.float64)
    e = encode(wi, wo)
    assert torch.isfinite(e).all() and (e[:, :2] >= 0).all() and (e[:, :2] <= 1 + 1e-9).all()
    assert (e[:, 2].abs() <= 1 + 1e-9).all()
