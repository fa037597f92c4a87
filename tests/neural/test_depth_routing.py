"""Depth-routed layering (neural/model.py ``layering_deep``, training ``route_depth``): stacks of
``DEEP_INTERFACES`` interfaces or more take the bundle's deep network, shallower ones its
layering network unchanged; the deep network travels in half precision and loads back; a
bundle whose codes live in another space is refused."""
from __future__ import annotations

import copy

import pytest
import torch
from safetensors import safe_open

from nbrdf.neural.decoder import DEFAULT_WEIGHTS
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import parse_material
from nbrdf.neural.model import DEEP_INTERFACES, load_model, save_model
from nbrdf.training.train_operations import route_depth

FORMAT = "nbrdf-material/1"


def _stack(coats: int) -> dict:
    """A material of ``coats`` clear coats (each with an absorbing medium below) over gold."""
    layers: list[dict] = []
    for k in range(coats):
        layers.append({"type": "dielectric", "roughness": 0.1 + 0.05 * k, "ior": 1.5})
        layers.append({"type": "medium", "albedo": [0.0, 0.0, 0.0], "sigma_t": 0.2})
    layers.append({"type": "conductor", "roughness": 0.3, "r0": [1.0, 0.78, 0.34]})
    return parse_material({"format": FORMAT, "name": f"{coats} coats", "layers": layers})


@pytest.fixture(scope="module")
def bundles(tmp_path_factory):
    """The shipped bundle and a fake deep fine-tune of it (its layering network perturbed)."""
    tmp = tmp_path_factory.mktemp("routing")
    deep = load_model()
    deep.layering_deep = None  # a plain layering fine-tune: its one network layers every depth
    with torch.no_grad():
        for p in deep.layering.parameters():
            p.add_(0.05 * torch.randn(p.shape, generator=torch.Generator().manual_seed(p.numel())))
    save_model(deep, tmp / "deep.safetensors", like=DEFAULT_WEIGHTS)
    out = route_depth(DEFAULT_WEIGHTS, tmp / "deep.safetensors", tmp / "routed.safetensors")
    return load_model(), load_model(tmp / "deep.safetensors"), load_model(out), tmp


def test_each_depth_takes_its_network(bundles):
    base, deep, routed, _ = bundles
    for coats in range(1, 5):
        m = _stack(coats)
        # the networks' codes (a settled code also moves with the albedo network: neural/energy.py settle)
        z = routed.material_latent(m, conserve=False)
        if coats < DEEP_INTERFACES:
            assert torch.equal(z, base.material_latent(m, conserve=False))  # the shallow stacks: bit for bit the base's
            assert torch.equal(routed.material_latent(m), base.material_latent(m))
        else:
            # the deep network (stored in half precision): its codes, not the base's
            assert torch.allclose(z, deep.material_latent(m, conserve=False), atol=2e-2, rtol=2e-2)
            assert (z - base.material_latent(m, conserve=False)).abs().max() > 0.1


def test_the_deep_network_is_stored_in_half_precision(bundles):
    *_, tmp = bundles
    with safe_open(str(tmp / "routed.safetensors"), "pt") as f:
        deep_keys = [k for k in f.keys() if k.startswith("layering_deep.")]
        assert deep_keys and all(f.get_tensor(k).dtype == torch.float16 for k in deep_keys)
        assert f.get_tensor("layering.mlp.net.0.weight").dtype == torch.float32


def test_a_bundle_of_another_code_space_is_refused(bundles, tmp_path):
    *_, tmp = bundles
    other = load_model()
    other.leaf = copy.deepcopy(other.leaf)
    with torch.no_grad():
        next(other.leaf.parameters()).add_(0.01)
    save_model(other, tmp_path / "other_leaf.safetensors", like=DEFAULT_WEIGHTS)
    with pytest.raises(NbrdfError, match="leaf encoders differ"):
        route_depth(DEFAULT_WEIGHTS, tmp_path / "other_leaf.safetensors", tmp_path / "x.safetensors")
