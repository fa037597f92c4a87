"""The one material translation: materials and data-set vectors to batched stacks."""
from __future__ import annotations

import pytest
import torch

from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import parse_material
from nbrdf.neural.stack import (
    CLASSES,
    PARAM_NAMES,
    P,
    material_stack,
    params_coats,
    params_to_material,
    params_to_stack,
    stack_class,
    stack_to_params,
)


def _material(*layers):
    return parse_material({"format": "nbrdf-material/1", "name": "t", "layers": list(layers)})


def _vectors(cls: str, k: int = 5) -> torch.Tensor:
    g = torch.Generator().manual_seed(CLASSES.index(cls))
    p = torch.rand(k, len(PARAM_NAMES), generator=g, dtype=torch.float64) * 0.9 + 0.05
    p[:, P["class"]] = CLASSES.index(cls)
    p[:, [P["top_ior"], P["mid_ior"]]] += 1.05  # legal indices
    return stack_to_params(params_to_stack(p))  # unused columns zeroed


@pytest.mark.parametrize("cls", CLASSES)
def test_vectors_round_trip_through_stacks_and_materials(cls):
    p = _vectors(cls)
    s = params_to_stack(p)
    assert stack_class(s) == cls and s.channels == 1 and s.n == 5
    assert torch.equal(stack_to_params(s), p)
    m = params_to_material(p[2])
    back = material_stack(m)  # the material the vector describes has the same stack
    assert back.layers == s.layers and back.base == s.base
    assert torch.allclose(back.roughness[0], s.roughness[2]) and torch.allclose(back.sigma_t[0], s.sigma_t[2])
    assert torch.allclose(back.albedo[0, :, 0], s.albedo[2, :, 0])


def test_material_stack_reads_every_layer_top_down():
    m = _material({"type": "dielectric", "roughness": 0.1, "ior": 1.4},
                  {"type": "medium", "albedo": [0.9, 0.5, 0.1], "sigma_t": 2.0},
                  {"type": "dielectric", "roughness": 0.3, "ior": 1.6},
                  {"type": "diffuse", "albedo": [0.2, 0.3, 0.4]})
    s = material_stack(m)
    assert s.n == 1 and s.layers == 2 and s.channels == 3 and s.base == "diffuse"
    assert s.roughness.tolist() == [[0.1, 0.3]] and s.ior.tolist() == [[1.4, 1.6]]
    assert s.sigma_t.tolist() == [[2.0, 0.0]]  # no medium under the second interface
    assert s.albedo[0].tolist() == [[0.9, 0.5, 0.1], [0.0, 0.0, 0.0]]
    assert s.base_albedo.tolist() == [[0.2, 0.3, 0.4]] and s.base_r0 is None
    one = s.per_channel()
    assert one.n == 3 and one.channels == 1 and one.base_albedo[:, 0].tolist() == [0.2, 0.3, 0.4]
    assert s.expand(4).n == 4 and s.repeat_interleave(2).albedo.shape == (2, 2, 3)


def test_bad_input_is_one_clear_error():
    with pytest.raises(NbrdfError, match="one class"):
        params_to_stack(torch.cat([_vectors("conductor", 1), _vectors("dielectric", 1)]))
    with pytest.raises(NbrdfError, match=r"\(K, 11\)"):
        params_to_stack(torch.zeros(3, 4))
    with pytest.raises(NbrdfError, match="one colour channel"):
        stack_to_params(material_stack(_material({"type": "conductor", "roughness": 0.2, "r0": 0.5})))


@pytest.mark.parametrize("cls", CLASSES)
def test_the_coat_of_every_class_from_stacks_and_vectors_agrees(cls):
    """The clear coat is the top interface, the bare dielectric itself, or NO_COAT for a bare conductor; the
    stacks' and the flat vectors' readings agree for every class."""
    from nbrdf.neural.coat import NO_COAT

    p = _vectors(cls)
    coat = params_to_stack(p).coat()
    assert coat.shape == (5, 2)
    assert torch.equal(params_coats(p), coat)
    if cls == "conductor":
        assert coat.tolist() == [list(NO_COAT)] * 5
    else:
        assert torch.equal(coat, p[:, [P["top_roughness"], P["top_ior"]]])
        assert (coat[:, 1] > 1).all()
