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
    p[:, [P["top_ior"], P["mid_ior"], P["ior_3"], P["ior_4"]]] += 1.05  # legal indices
    return stack_to_params(params_to_stack(p))  # unused columns zeroed


@pytest.mark.parametrize("cls", CLASSES)
def test_vectors_round_trip_through_stacks_and_materials(cls):
    p = _vectors(cls)
    s = params_to_stack(p)
    assert stack_class(s) == cls and s.channels == 1 and s.n == 5
    L = s.layers
    assert s.roughness.shape == s.ior.shape == (5, L) and s.albedo.shape == s.sigma_t.shape == (5, L, 1)
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
    assert s.sigma_t.tolist() == [[[2.0] * 3, [0.0] * 3]]  # no medium under the second interface
    assert s.albedo[0].tolist() == [[0.9, 0.5, 0.1], [0.0, 0.0, 0.0]]
    assert s.base_albedo.tolist() == [[0.2, 0.3, 0.4]] and s.base_r0 is None
    one = s.per_channel()
    assert one.n == 3 and one.channels == 1 and one.base_albedo[:, 0].tolist() == [0.2, 0.3, 0.4]
    assert s.expand(4).n == 4 and s.repeat_interleave(2).albedo.shape == (2, 2, 3)


def test_bad_input_is_one_clear_error():
    with pytest.raises(NbrdfError, match="one class"):
        params_to_stack(torch.cat([_vectors("conductor", 1), _vectors("dielectric", 1)]))
    with pytest.raises(NbrdfError, match=r"\(K, 19\)"):
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


def test_every_base_kind_gives_its_parameters_in_the_asked_dtype(tmp_path):
    """Conductor: roughness and r0; diffuse: albedo (roughness fixed at 0.5); a bare dielectric: roughness and
    ior; a latent or measured base: its file only. No interface: empty layer columns, one stack."""
    from nbrdf.neural.material import Material, Medium

    cases = [
        ({"type": "conductor", "roughness": 0.2, "r0": [0.9, 0.6, 0.5]},
         dict(base_roughness=[0.2], base_r0=[[0.9, 0.6, 0.5]])),
        ({"type": "diffuse", "albedo": [0.1, 0.2, 0.3]}, dict(base_roughness=[0.5], base_albedo=[[0.1, 0.2, 0.3]])),
        ({"type": "dielectric", "roughness": 0.05, "ior": 1.7}, dict(base_roughness=[0.05], base_ior=[1.7])),
    ]
    for layer, want in cases:
        for dtype in (torch.float64, torch.float32):
            s = material_stack(_material(layer), dtype=dtype)
            assert s.base == layer["type"] and s.n == 1 and s.layers == 0
            assert s.roughness.shape == (1, 0) and s.ior.shape == (1, 0) and s.sigma_t.shape == (1, 0, 3)
            assert s.albedo.shape == (1, 0, 3)
            for t in s.tensors().values():
                assert t.dtype == dtype
            for k, v in want.items():
                torch.testing.assert_close(getattr(s, k), torch.tensor(v, dtype=dtype))
            unset = {"base_roughness", "base_r0", "base_ior", "base_albedo"} - set(want)
            assert all(getattr(s, k) is None for k in unset)
            assert s.base_path is None
            one = s.per_channel()  # three single-channel stacks, a colour base parameter split by channel
            assert one.n == 3 and one.channels == 1
            for k in ("base_r0", "base_albedo"):
                if k in want:
                    assert getattr(one, k).shape == (3, 1)
                    assert getattr(one, k)[:, 0].tolist() == pytest.approx(want[k][0])
    latent = tmp_path / "z.safetensors"
    latent.write_bytes(b"")
    s = material_stack(parse_material({"format": "nbrdf-material/1", "name": "t",
                                       "layers": [{"type": "latent", "path": "z.safetensors"}]}, tmp_path))
    assert s.base == "latent" and s.base_path == latent and s.n == 1 and s.base_roughness is None
    with pytest.raises(NbrdfError, match="a latent base has no roughness"):
        s.base_param("base_roughness")
    with pytest.raises(NbrdfError, match="^a medium cannot be the base$"):
        material_stack(Material("m", [Medium(0.5, 1.0)]))


def test_per_texel_values_take_channel_0_of_shared_parameters_and_name_their_place():
    """With a values function (a texture-mapped material: one row per texel), every parameter comes from its
    own place, shared ones (roughness, ior) from channel 0, and rows broadcast against uniform ones."""
    m = _material({"type": "dielectric", "roughness": 0.1, "ior": 1.4},
                  {"type": "medium", "albedo": 0.5, "sigma_t": 2.0},
                  {"type": "dielectric", "roughness": 0.3, "ior": 1.6},
                  {"type": "medium", "albedo": 0.25, "sigma_t": 4.0},
                  {"type": "conductor", "roughness": 0.2, "r0": 0.9})
    seen = []
    code = {"layers[0].roughness": 1, "layers[0].ior": 2, "layers[1].albedo": 3, "layers[1].sigma_t": 4,
            "layers[2].roughness": 5, "layers[2].ior": 6, "layers[3].albedo": 7, "layers[3].sigma_t": 8,
            "layers[4].roughness": 9, "layers[4].r0": 10, "layers[4].f82_tint": 11, "layers[4].anisotropy": 12,
            "layers[0].anisotropy": 13, "layers[2].anisotropy": 14}

    def values(v, place):
        seen.append(place)
        k = code[place]
        rows = 4 if place == "layers[2].roughness" else 1  # one texture-mapped parameter
        return torch.tensor([[k, k + 0.25, k + 0.5]], dtype=torch.float64).expand(rows, 3) + \
            torch.arange(rows, dtype=torch.float64)[:, None] * 100

    s = material_stack(m, values, dtype=torch.float32)
    assert sorted(seen) == sorted(code)
    assert seen[:3] == ["layers[4].roughness", "layers[4].r0", "layers[4].f82_tint"]  # the base first, then bottom up
    assert s.n == 4 and all(t.dtype == torch.float32 for t in s.tensors().values())
    assert s.roughness.tolist() == [[1.0, 5.0 + 100 * t] for t in range(4)]
    assert s.ior[:, 0].tolist() == [2.0] * 4 and s.ior[:, 1].tolist() == [6.0] * 4
    assert s.sigma_t.tolist() == [[[4.0, 4.25, 4.5], [8.0, 8.25, 8.5]]] * 4  # per channel
    assert s.albedo[0].tolist() == [[3.0, 3.25, 3.5], [7.0, 7.25, 7.5]]
    assert s.base_roughness.tolist() == [9.0] * 4 and s.base_r0[3].tolist() == [10.0, 10.25, 10.5]
    assert s.base_f82[3].tolist() == [11.0, 11.25, 11.5]
    assert s.base_anisotropy.tolist() == [12.0] * 4 and s.anisotropy.tolist() == [[13.0, 14.0]] * 4


def test_a_texture_mapped_parameter_without_values_is_named(tmp_path):
    from nbrdf.neural.stack import uniform_values

    (tmp_path / "r.png").write_bytes(b"")  # the parser checks that the file exists, not what it holds
    tex = {"texture": "r.png", "range": [0.1, 0.5]}
    m = parse_material({"format": "nbrdf-material/1", "name": "t", "layers": [
        {"type": "dielectric", "roughness": 0.1, "ior": 1.5}, {"type": "medium", "albedo": 0.5, "sigma_t": tex},
        {"type": "conductor", "roughness": 0.3, "r0": 0.9}]}, tmp_path)
    with pytest.raises(NbrdfError, match=r"^layers\[1\]\.sigma_t: a texture-mapped parameter has no single value; "
                                         r"evaluate a uniform material"):
        material_stack(m)
    with pytest.raises(NbrdfError, match=r"^x\.y: a texture-mapped parameter has no single value; hint$"):
        uniform_values(m.layers[1].sigma_t, "x.y", "hint")
    with pytest.raises(ValueError, match="expand needs one stack, got 2"):
        material_stack(_material({"type": "diffuse", "albedo": 0.5})).expand(2).expand(3)


def test_files_written_before_the_deep_classes_read_as_they_were():
    """A vector of the paper's 11 columns decodes to the stack its 19-column padding does, and the deep
    classes hold 3 and 4 coats over a conductor."""
    from nbrdf.neural.stack import PAPER_WIDTH, pad_params

    p = _vectors("three_layer")
    old = p[:, :PAPER_WIDTH]
    assert torch.equal(pad_params(old), p)
    a, b = params_to_stack(old), params_to_stack(p)
    assert torch.equal(a.roughness, b.roughness) and torch.equal(a.sigma_t, b.sigma_t)
    assert params_to_stack(_vectors("four_layer")).layers == 3 and params_to_stack(_vectors("five_layer")).layers == 4
