"""The layering network's slab description: closed forms checked against
their definitions, old bundles load as the basic feature set, and a network
widened to the slab features computes exactly what it did before."""
from __future__ import annotations

import json
from dataclasses import asdict

import pytest
import torch
from safetensors import safe_open

from nbrdf.neural.decoder import DEFAULT_WEIGHTS
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.layering import (
    LATENT,
    MEDIUM_SETS,
    LayeringNet,
    LayeringSpec,
    diffuse_transmittance,
    kubelka_munk,
    layering_spec,
    medium_features,
)
from nbrdf.neural.model import NeuralModel, load_model, save_model
from nbrdf.neural.nets import MLPSpec


def _stacks(n: int = 64, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    top = torch.stack([0.01 + 0.5 * torch.rand(n, generator=g), 1.1 + torch.rand(n, generator=g)], -1)
    bottom = torch.cat([torch.randn(n, LATENT, generator=g), top.flip(0)], -1)
    return top, bottom, torch.rand(n, generator=g), 5 * torch.rand(n, generator=g)


def test_diffuse_transmittance_is_the_cosine_weighted_beer_lambert_integral():
    """2 E3(tau) = 2 int_0^1 mu exp(-tau / mu) dmu, by a 200k-point midpoint
    rule (error ~1e-10) over the legal range of sigma_t."""
    tau = torch.linspace(0, 5, 41, dtype=torch.float64)
    mu = (torch.arange(200_000, dtype=torch.float64) + 0.5) / 200_000
    want = 2 * (mu * torch.exp(-tau[:, None] / mu)).mean(1)
    got = diffuse_transmittance(tau)
    assert got[0] == 1.0
    assert torch.allclose(got, want, atol=1e-6, rtol=0)
    assert (got.diff() < 0).all()


def test_kubelka_munk_limits_and_energy():
    """Conservative slab: R = tau / (1 + tau), R + T = 1; absorbing only:
    R = 0, T = exp(-2 tau) (K = 2 sigma_a); any slab: R, T >= 0, R + T <= 1,
    continuous at albedo 1."""
    tau = torch.linspace(0, 5, 26, dtype=torch.float64)
    r, t = kubelka_munk(torch.ones_like(tau), tau)
    assert torch.allclose(r, tau / (1 + tau), atol=1e-12) and torch.allclose(r + t, torch.ones_like(tau))
    r, t = kubelka_munk(torch.zeros_like(tau), tau)
    assert (r == 0).all() and torch.allclose(t, torch.exp(-2 * tau), rtol=1e-10)
    a = torch.rand(2000, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    tt = 5 * torch.rand(2000, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    r, t = kubelka_munk(a, tt)
    assert (r >= 0).all() and (t >= 0).all() and (r + t <= 1 + 1e-12).all()
    r1, t1 = kubelka_munk(torch.full_like(tau, 1 - 1e-9), tau)
    r2, t2 = kubelka_munk(torch.ones_like(tau), tau)
    assert torch.allclose(r1, r2, atol=1e-6) and torch.allclose(t1, t2, atol=1e-6)


def test_feature_sets_extend_each_other():
    _, _, albedo, sigma_t = _stacks()
    basic, slab = medium_features(albedo, sigma_t), medium_features(albedo, sigma_t, "slab")
    assert basic.shape == (64, MEDIUM_SETS["basic"]) and slab.shape == (64, MEDIUM_SETS["slab"])
    assert torch.equal(slab[:, :MEDIUM_SETS["basic"]], basic) and torch.isfinite(slab).all()
    with pytest.raises(NbrdfError, match="medium features 'thick' are unknown"):
        medium_features(albedo, sigma_t, "thick")


def test_the_shipped_bundle_is_basic_and_a_file_without_the_feature_set_loads_as_basic(tmp_path):
    """The shipped layering network is ``basic`` with its 43 inputs; a file written before
    feature sets existed (no ``medium`` in its spec, as v7) loads as ``basic``, unchanged."""
    from safetensors.torch import save_file

    with safe_open(str(DEFAULT_WEIGHTS), framework="pt") as fh:
        meta = dict(fh.metadata())
        tensors = {k: fh.get_tensor(k) for k in fh.keys()}
    ops = json.loads(meta["operations"])
    spec = ops["specs"]["layering"]
    assert spec.get("medium", "basic") == "basic"
    net = load_model(DEFAULT_WEIGHTS).layering
    assert net.spec.medium == "basic" and net.spec.inputs == spec["inputs"] == 43
    spec.pop("medium", None)
    assert LayeringNet(MLPSpec(**spec)).spec == net.spec
    meta["operations"] = json.dumps(ops)
    save_file(tensors, str(tmp_path / "old.safetensors"), metadata=meta)
    old = load_model(tmp_path / "old.safetensors").layering
    assert old.spec == net.spec
    for a, b in zip(old.state_dict().values(), net.state_dict().values()):
        assert torch.equal(a, b)


def test_a_widened_network_starts_exactly_where_it_was_and_can_learn_the_new_inputs():
    old = load_model(DEFAULT_WEIGHTS).layering
    new = old.widened("slab")
    assert new.spec.medium == "slab" and new.spec.inputs == old.spec.inputs + 3
    top, bottom, albedo, sigma_t = _stacks()
    assert torch.equal(new(top, bottom, albedo, sigma_t), old(top, bottom, albedo, sigma_t))
    new.mlp.net[0].weight.requires_grad_(True)
    new(top, bottom, albedo, sigma_t)[:, :LATENT].square().sum().backward()
    assert new.mlp.net[0].weight.grad[:, -3:].abs().sum() > 0  # the added inputs reach the loss
    with pytest.raises(NbrdfError, match="cannot widen"):
        new.widened("basic")


def test_a_slab_network_round_trips_through_a_bundle(tmp_path):
    model = load_model(DEFAULT_WEIGHTS)
    widened = NeuralModel(model.decoder, leaf=model.leaf, layering=model.layering.widened("slab"))
    save_model(widened, tmp_path / "slab.safetensors", like=DEFAULT_WEIGHTS)
    back = load_model(tmp_path / "slab.safetensors").layering
    assert back.spec == widened.layering.spec and back.spec.medium == "slab"
    top, bottom, albedo, sigma_t = _stacks(seed=3)
    assert torch.equal(back(top, bottom, albedo, sigma_t), widened.layering(top, bottom, albedo, sigma_t))


def test_a_spec_that_does_not_fit_its_features_is_named():
    with pytest.raises(NbrdfError, match="does not fit medium features 'slab'"):
        LayeringSpec(**{**asdict(layering_spec()), "medium": "slab"})
    with pytest.raises(NbrdfError, match="unknown"):
        layering_spec(medium="thin")


def test_a_conductors_tint_stays_out_of_the_layering_network_and_in_a_bare_code():
    """Record 119: under an interface a tinted conductor is layered from the plain conductor's code (the tint's
    edge term lies outside the critical cone the base is reached in; the tinted codes lie off the layering
    network's training set), so the coated code is the plain one's exactly; a bare conductor's code keeps its
    tint (it differs from the plain one)."""
    from nbrdf.neural.material import parse_material
    from nbrdf.neural.model import default_model

    def stack(tint, coated):
        base = {"type": "conductor", "roughness": 0.2, "r0": [0.9, 0.6, 0.3], "f82_tint": tint}
        layers = [{"type": "dielectric", "roughness": 0.05, "ior": 1.5}, base] if coated else [base]
        return parse_material({"format": "nbrdf-material/1", "name": "m", "layers": layers})

    model = default_model()
    coated = [model.material_latent(stack(t, True)) for t in ([0.5, 0.7, 0.9], 1.0)]
    bare = [model.material_latent(stack(t, False)) for t in ([0.5, 0.7, 0.9], 1.0)]
    assert torch.equal(coated[0], coated[1])
    assert (bare[0] - bare[1]).abs().max() > 1e-3
